"""The training objective that both training loops share: the eager step (trainer/train.py) and the step
replayed as a CUDA graph (trainer/cudagraph.py) differentiate :func:`batch_loss` and follow the learning-rate
schedule of :func:`cosine_factor`.

- the loss of a batch: LogCosh of the network's raw outputs against the range-transformed XYZ targets,
  optionally display-weighted (:class:`VisibleWeight`, the config's ``--loss-visible-y`` band);
- the schedule: each parameter group's rate times a cosine factor from 1 down to the final ratio.
"""

from __future__ import annotations

import math

import torch

from gratnet.encoding import EncodingSpec, encode
from trainer.model import FunnelMLP, GridNetwork, log_cosh_loss
from trainer.train_config import TrainConfig


def cosine_factor(step: int, steps: int, ratio: float) -> float:
    """The schedule's factor on each group's initial rate at ``step``: cosine from 1 down to ``ratio`` over
    ``steps``, then ``ratio`` (trainer/cudagraph.py computes the same on the device)."""
    return ratio + (1.0 - ratio) * 0.5 * (1.0 + math.cos(math.pi * min(step, steps) / steps))


class VisibleWeight:
    """The display-weighted loss's per-sample weight: ``weight`` where the target's range-transformed CIE Y
    lies in ``band`` (TrainConfig.visible_band), else 1: two comparisons on the device."""

    def __init__(self, band: tuple[float, float], weight: float) -> None:
        self.low, self.high = band
        self.weight = weight

    def __call__(self, targets: torch.Tensor) -> torch.Tensor:
        y = targets[:, 1]  # the range-transformed CIE Y
        inside = (y >= self.low) & (y <= self.high)
        return torch.where(inside, self.weight, 1.0).to(targets.dtype)


def visible_weight(config: TrainConfig) -> VisibleWeight | None:
    """The config's display weighting, or None when it is off (no band, or weight 1)."""
    band = config.visible_band()
    if band is None or config.loss_visible_weight == 1.0:
        return None
    return VisibleWeight(band, config.loss_visible_weight)


def _raw_outputs(model: FunnelMLP | GridNetwork, coordinates: torch.Tensor, encoding: EncodingSpec) -> torch.Tensor:
    """The network's raw outputs at network coordinates: a grid network takes them as they are, the MLP encoded."""
    return model(coordinates) if isinstance(model, GridNetwork) else model(encode(coordinates, encoding))


def batch_loss(model: FunnelMLP | GridNetwork, coordinates: torch.Tensor, targets: torch.Tensor,
               encoding: EncodingSpec, weighting: VisibleWeight | None = None) -> torch.Tensor:
    """The training loss of a batch (LogCosh, display-weighted when ``weighting`` is given), with its graph: the
    eager step and the CUDA-graph step (trainer/cudagraph.py) both differentiate this."""
    weight = None if weighting is None else weighting(targets)
    return log_cosh_loss(_raw_outputs(model, coordinates, encoding), targets, weight)
