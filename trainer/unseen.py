"""The encoding's unseen features: inputs that vanish at every training sample (docs/physics.md, "Network").

The encoding's scales put its top frequencies at the training lattice's Nyquist rate (EncodingSpec.for_grid): on
the lattice, c = −1 + 2k/(R − 1), the top spatial frequency's phase π·(R − 1)/2·c is a whole multiple of π, and so
is the top t frequency's at the slices, and the diagonal groups' (c_u ± c_v lie on a lattice too). Their sines are
therefore zero at every sample (float32 rounding, ≲ 1e-4, aside). The loss never sees them: their first-layer
columns get rounding-noise gradients, which Adam with ε = 1e-8 turns into no step at all
(docs/experiments/2026-11-25-scratches-adam-epsilon.md), so they keep the random weights they were initialised with
and add random sinusoids between the samples: stripes along u*, v* and arcs of constant t in every view, which
measured 14–67 % of the eight-view FLIP of the models screened on paper-cd (docs/experiments/
2026-11-27-fast-models-screen.md, fifth pass).

Two forms of one rule:

- :func:`silence_unseen_features` (training, torch): the columns start at zero and a gradient mask keeps them
  there (``gratnet train``, default; ``--no-zero-unseen-features`` turns it off);
- :func:`silence_model_file` (a trained model file, numpy): the same columns set to zero afterwards, which leaves
  every training sample's output as it was (the inputs are zero there) and removes the sinusoids between them.
"""

from __future__ import annotations

import numpy as np
import torch

from gratnet.encoding import EncodingSpec, encode
from gratnet.errors import GratNetError
from gratnet.modelfile import ModelFile
from gratnet.volume import volume_axes
from trainer.model import FunnelMLP, GridNetwork

__all__ = ["UNSEEN_FEATURE", "silence_model_file", "silence_unseen_features", "unseen_columns", "unseen_features"]

#: A feature whose largest magnitude over the training samples is below this is unseen: a top frequency's sine
#: there is float32 rounding of a whole multiple of π (≲ 1e-4 at 1571 rad), every other feature of order 1.
UNSEEN_FEATURE = 1e-3
_BATCH = 65536


def unseen_features(coordinates: np.ndarray, encoding: EncodingSpec) -> list[int]:
    """The indices of ``encoding``'s features whose magnitude stays below :data:`UNSEEN_FEATURE` at every one of
    ``coordinates`` (network coordinates (N, 3), float32 as training holds them)."""
    largest = np.zeros(encoding.features)
    for start in range(0, coordinates.shape[0], _BATCH):
        largest = np.maximum(largest, np.abs(encode(coordinates[start:start + _BATCH], encoding)).max(axis=0))
    return np.flatnonzero(largest < UNSEEN_FEATURE).tolist()


def silence_unseen_features(model: FunnelMLP | GridNetwork, coordinates: np.ndarray,
                            encoding: EncodingSpec) -> list[int]:
    """Zero the first-layer weights of the encoding's features that vanish at every one of ``coordinates`` (the
    training samples, network coordinates (N, 3)) and keep them zero (a gradient hook). Returns the silenced input
    columns of the first layer (grid features are never silenced)."""
    first = (model.mlp if isinstance(model, GridNetwork) else model).linear_layers()[0]
    grid = first.in_features - encoding.features
    unseen = [grid + index for index in unseen_features(coordinates, encoding)]
    if not unseen:
        return []
    mask = torch.ones_like(first.weight)
    mask[:, unseen] = 0.0
    with torch.no_grad():
        first.weight.mul_(mask)
    first.weight.register_hook(lambda gradient: gradient * mask)
    return unseen


def lattice_coordinates(model: ModelFile, samples: int = 200_000, seed: int = 0) -> np.ndarray:
    """Network coordinates (N, 3) of ``samples`` random points of the training lattice the model file records
    (``metadata.volume``: its resolution R, its slices' t, else S evenly spaced), plus the lattice's corners."""
    volume = model.metadata.get("volume") if isinstance(model.metadata, dict) else None
    if not isinstance(volume, dict) or "resolution" not in volume or "slices" not in volume:
        raise GratNetError("the model file records no training volume (metadata.volume.resolution, slices): its "
                           "training lattice is unknown")
    axis = volume_axes(int(volume["resolution"])) / 2.0  # c = u*/2
    slice_t = np.asarray(volume.get("slice_t") or np.linspace(0.0, 1.0, int(volume["slices"])), dtype=np.float64)
    rng = np.random.default_rng(seed)
    points = np.stack([rng.choice(axis, samples), rng.choice(axis, samples), 2.0 * rng.choice(slice_t, samples) - 1.0],
                      axis=-1)
    corners = np.array([[u, v, 2.0 * t - 1.0] for u in axis[[0, -1]] for v in axis[[0, -1]] for t in slice_t])
    return np.concatenate([points, corners]).astype(np.float32)


def unseen_columns(model: ModelFile) -> list[int]:
    """The first-layer input columns of ``model``'s encoding features that vanish on its training lattice."""
    return [model.grid_feature_count + index for index in unseen_features(lattice_coordinates(model), model.encoding)]


def silence_model_file(model: ModelFile) -> list[int]:
    """Set ``model``'s first-layer weights of its unseen features to zero, in place; returns those columns."""
    columns = unseen_columns(model)
    if columns:
        weight = np.array(model.weights[0], dtype=np.float32)
        weight[:, columns] = 0.0
        model.weights[0] = weight
    return columns
