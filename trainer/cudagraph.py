"""The training step replayed as one CUDA graph (``gratnet train --cuda-graph``).

At the batch sizes that train feature grids best (2,048–8,192 samples:
docs/experiments/2026-11-23-smaller-batches-h100.md) a step is about a hundred kernels of microseconds each,
and the GPU waits on Python to launch them. Captured once with torch.cuda.CUDAGraph, a step is two launches:
the batch's indices copied into a fixed buffer, and the replay. The captured step is
:func:`trainer.train.train_step` with what it did on the host moved onto the device, so that the graph can
hold it:

- the batch is gathered from the resident data set by the index buffer;
- the learning rate is the same cosine schedule as :func:`trainer.train.make_scheduler`
  (:func:`trainer.objective.cosine_factor`), computed from a step counter on the device into Adam's
  ``capturable`` tensor rates;
- the running loss (the progress bar's) is updated in the graph.

A batch of another size (an epoch's last, partial one) runs the same step eagerly.
"""

from __future__ import annotations

import math

import torch

from gratnet.encoding import EncodingSpec
from trainer.model import FunnelMLP, GridNetwork
from trainer.objective import VisibleWeight, batch_loss, cosine_factor

#: Eager steps before the capture (on a side stream, as torch's documentation asks): they let autograd,
#: cuBLAS and Adam make their state. They are ordinary training steps, counted as such.
WARMUP_STEPS = 3


class GraphedSteps:
    """Training steps of one run: ``step(batch)`` per batch of indices into the resident data set."""

    def __init__(self, model: FunnelMLP | GridNetwork, optimizer: torch.optim.Optimizer, base_rates: list[float],
                 schedule_steps: int, final_ratio: float, done: int, encoding: EncodingSpec,
                 weighting: VisibleWeight | None, coordinates: torch.Tensor, targets: torch.Tensor,
                 batch_size: int) -> None:
        """``base_rates``: each parameter group's initial learning rate; ``done``: steps already taken (on
        resume); ``weighting``: the display weighting or None."""
        device = coordinates.device
        self.model, self.optimizer, self.encoding, self.weighting = model, optimizer, encoding, weighting
        self.coordinates, self.targets = coordinates, targets
        self.schedule_steps, self.final_ratio = schedule_steps, final_ratio
        # Adam reads its rate from the device in the graph: capturable, with tensor rates (its step counts move
        # to the device too, also when they come from a checkpoint of an eager run).
        for group, rate in zip(optimizer.param_groups, base_rates, strict=True):
            group["lr"] = torch.tensor(rate, dtype=torch.float32, device=device)
            group["capturable"] = True
        for state in optimizer.state.values():
            if "step" in state:
                state["step"] = state["step"].to(device=device, dtype=torch.float32)
        self.first_rate = base_rates[0]  # host side, for learning_rate()
        self.base_rates = torch.tensor(base_rates, dtype=torch.float64, device=device)
        self.counter = torch.tensor(float(done), dtype=torch.float64, device=device)
        self.done = done
        self.index = torch.zeros(batch_size, dtype=torch.long, device=device)
        self.running = torch.zeros((), dtype=torch.float64, device=device)
        self.fresh = torch.ones((), dtype=torch.bool, device=device)
        self.graph: torch.cuda.CUDAGraph | None = None
        self.warm = 0

    def begin_epoch(self) -> None:
        """The next step starts the running loss afresh (as the eager loop's first step of an epoch does)."""
        self.fresh.fill_(True)

    def learning_rate(self) -> float:
        """The first group's rate of the next step (host side, no device read: for the progress bar and history)."""
        return self.first_rate * cosine_factor(self.done, self.schedule_steps, self.final_ratio)

    def _step(self, index: torch.Tensor) -> None:
        """One optimisation step on the samples at ``index``: device work only, capturable."""
        steps = float(self.schedule_steps)
        progress = torch.clamp(self.counter, max=steps) / steps
        factor = self.final_ratio + (1.0 - self.final_ratio) * 0.5 * (1.0 + torch.cos(math.pi * progress))
        rates = (self.base_rates * factor).float()
        for number, group in enumerate(self.optimizer.param_groups):
            group["lr"].copy_(rates[number])
        loss = batch_loss(self.model, self.coordinates[index], self.targets[index], self.encoding, self.weighting)
        loss.backward()
        self.optimizer.step()
        self.counter += 1.0
        value = loss.detach().double()
        self.running.copy_(torch.where(self.fresh, value, 0.98 * self.running + 0.02 * value))
        self.fresh.fill_(False)

    def step(self, batch: torch.Tensor) -> None:
        """One step on the samples at ``batch`` (indices on the device)."""
        if len(batch) != len(self.index):  # an epoch's last, partial batch: eagerly, into the same gradients
            self.optimizer.zero_grad(set_to_none=self.graph is None)
            self._step(batch)
        elif self.graph is None and self.warm < WARMUP_STEPS:
            stream = torch.cuda.Stream(device=batch.device)
            stream.wait_stream(torch.cuda.current_stream(batch.device))
            with torch.cuda.stream(stream):
                self.optimizer.zero_grad(set_to_none=True)
                self._step(batch)
            torch.cuda.current_stream(batch.device).wait_stream(stream)
            self.warm += 1
        else:
            if self.graph is None:
                # Gradients set to None, so that the graph's backward writes them (in its own memory pool)
                # rather than accumulating: every replay then starts from fresh gradients.
                self.optimizer.zero_grad(set_to_none=True)
                self.graph = torch.cuda.CUDAGraph()
                with torch.cuda.graph(self.graph):
                    self._step(self.index)
            self.index.copy_(batch)
            self.graph.replay()
        self.done += 1
