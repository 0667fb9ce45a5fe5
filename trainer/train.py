"""Training the funnel MLP on a ground-truth volume: LogCosh loss, Adam, cosine schedule, checkpoints.

Samples are the volume's (u*, v*, t) grid points with u² + v² ≤ 4 (the rest is unreachable); inputs go
through the same contract as the runtime (gratnet/encoding.py): key vector → network coordinates →
sinusoidal encoding; targets are the range-transformed XYZ.
"""

from __future__ import annotations

import copy
import dataclasses
import json
import logging
import math
import os
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import torch
from tqdm.auto import tqdm

from gratnet.atomic import atomic_path, make_folder, write_text_atomic
from gratnet.config import config_to_dict, saved_config_dict
from gratnet.encoding import EncodingSpec, RangeSpec, encode, network_coordinates, range_forward
from gratnet.errors import GratNetError
from gratnet.modelfile import ModelFile
from gratnet.shadowing import METADATA_KEY as SLOPE_COVARIANCE_KEY
from gratnet.shadowing import check_slope_covariance
from gratnet.volume import Volume, volume_axes
from trainer.allocator import keep_freed_memory
from trainer.cudagraph import GraphedSteps
from trainer.model import FunnelMLP, GridNetwork, log_cosh_loss, parse_hidden
from trainer.objective import VisibleWeight, batch_loss, cosine_factor, visible_weight
from trainer.sampling import grid_to_key, slice_w
from trainer.train_config import TrainConfig
from trainer.unseen import silence_unseen_features


@dataclasses.dataclass
class Samples:
    """Network coordinates (N, 3) and targets (N, 3), float32; the volume slice of each sample (N,)."""

    coordinates: np.ndarray
    targets: np.ndarray
    slice_index: np.ndarray

    def __len__(self) -> int:
        return len(self.targets)

    def subset(self, keep: np.ndarray) -> Samples:
        """The samples at ``keep`` (a mask or indices)."""
        return Samples(self.coordinates[keep], self.targets[keep], self.slice_index[keep])


def slice_parameters(volume: Volume) -> np.ndarray:
    """The slice parameter t_s ∈ [0, 1] of each of the volume's w-slices (its metadata's, else s/(S − 1))."""
    return np.asarray(volume.metadata.get("slice_t") or list(np.linspace(0, 1, volume.slices)), dtype=np.float64)


def volume_samples(volume: Volume, range_spec: RangeSpec) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Every reachable sample: network coordinates (N, 3), targets (N, 3), slice index (N,)."""
    scheme = volume.metadata.get("scheme")
    if scheme not in ("regular", "simple", "simple-max"):
        raise GratNetError(f"volume has no known sampling scheme in its metadata (got {scheme!r})")
    key = grid_to_key(volume_axes(volume.resolution), scheme)
    u_grid, v_grid = np.meshgrid(key, key, indexing="xy")
    reachable = u_grid**2 + v_grid**2 <= 4.0 + 1e-12
    t_values = slice_parameters(volume)
    coordinates, targets, slice_index = [], [], []
    for index, t in enumerate(t_values):
        w = slice_w(scheme, float(t), key, key)
        coordinates.append(network_coordinates(u_grid[reachable], v_grid[reachable], w[reachable], scheme))
        targets.append(range_forward(volume.xyz[index][reachable].astype(np.float64), range_spec))
        slice_index.append(np.full(int(reachable.sum()), index, dtype=np.int16))
    return (
        np.concatenate(coordinates).astype(np.float32),
        np.concatenate(targets).astype(np.float32),
        np.concatenate(slice_index),
    )


def split_samples(volume: Volume, config: TrainConfig) -> tuple[Samples, Samples | None]:
    """Training and held-out samples according to ``config.split``."""
    coordinates, targets, slice_index = volume_samples(volume, config.range_spec())
    rng = np.random.default_rng(config.seed)
    if config.split == "slices":
        test_mask = np.isin(slice_index, config.held_out_slices(volume.slices))
    elif config.split == "random":  # test_fraction in (0, 1): checked by TrainConfig
        test_mask = rng.random(len(targets)) < config.test_fraction
    else:
        test_mask = np.zeros(len(targets), dtype=bool)
    everything = Samples(coordinates, targets, slice_index)
    train = everything.subset(~test_mask)
    if len(train) == 0:  # else 0 steps per epoch, and a model of random weights is written as if trained
        reason = (f"the {volume.resolution}² grid has no sample with u² + v² ≤ 4" if len(targets) == 0
                  else f"--split {config.split} holds out all {len(targets)} samples")
        raise GratNetError(f"no training samples: {reason}; hold out fewer slices or use a larger volume")
    if config.max_train_samples and len(train) > config.max_train_samples:
        train = train.subset(rng.choice(len(train), config.max_train_samples, replace=False))
    test = everything.subset(test_mask) if test_mask.any() else None
    return train, test


def pick_device(name: str) -> torch.device:
    """'auto' → CUDA when present, else CPU."""
    if name == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    if name.startswith("cuda") and not torch.cuda.is_available():
        raise GratNetError("--device cuda was asked for, but torch sees no CUDA device")
    return torch.device(name)


def uses_cuda_graph(config: TrainConfig, device: torch.device) -> bool:
    """Whether the run replays its steps as a CUDA graph (--cuda-graph; auto: on a CUDA device)."""
    if config.cuda_graph == "on" and device.type != "cuda":
        raise GratNetError(f"--cuda-graph on needs a CUDA device; training runs on {device}")
    return config.cuda_graph == "on" or (config.cuda_graph == "auto" and device.type == "cuda")


def build_model(config: TrainConfig, encoding: EncodingSpec) -> FunnelMLP | GridNetwork:
    """The network of ``config.architecture`` (torch's global seed must be set before)."""
    hidden = parse_hidden(config.preset, config.hidden)
    if config.architecture == "grid":
        return GridNetwork(encoding, config.grid_shapes(), hidden, config.activation, config.output_activation,
                           config.grid.init, config.grid.dtype, config.grid.interpolation)
    return FunnelMLP(encoding.features, hidden, config.activation, config.output_activation)


def fused_adam(device: torch.device) -> bool:
    """Whether Adam runs as one fused kernel on ``device``: on the CPU, where torch's default (foreach) Adam makes
    about eight passes over every parameter per step and took half of a grid network's step (docs/benchmarks.md,
    "Fused Adam on the CPU"). The same arithmetic per element, up to float rounding. CUDA keeps its default: the
    graphed step (trainer/cudagraph.py) was measured with it."""
    return device.type == "cpu"


def make_optimizer(model: FunnelMLP | GridNetwork, config: TrainConfig,
                   fused: bool | None = None) -> torch.optim.Optimizer:
    """Adam over the model's parameter groups; ``fused`` overrides :func:`fused_adam`'s choice for the model's
    device (False: torch's default implementation, which the benchmark and a test compare against)."""
    if fused is None:
        fused = fused_adam(next(model.parameters()).device)
    if isinstance(model, GridNetwork):  # the grids learn at their own rate
        return torch.optim.Adam([{"params": model.mlp.parameters(), "lr": config.learning_rate},
                                 {"params": model.grids.parameters(), "lr": config.grid.learning_rate,
                                  "eps": config.grid.adam_epsilon}],
                                eps=config.adam_epsilon, fused=fused or None)
    return torch.optim.Adam(model.parameters(), lr=config.learning_rate, eps=config.adam_epsilon,
                            fused=fused or None)


def make_scheduler(optimizer: torch.optim.Optimizer, config: TrainConfig, steps: int,
               grid: bool) -> torch.optim.lr_scheduler.LRScheduler:
    """Cosine from each group's rate down to ``final_learning_rate_ratio`` of it over ``steps``."""
    if grid:  # two groups: a factor, so that each ends at its own rate × the ratio
        ratio = config.final_learning_rate_ratio
        return torch.optim.lr_scheduler.LambdaLR(optimizer, lambda step: cosine_factor(step, steps, ratio))
    return torch.optim.lr_scheduler.CosineAnnealingLR(
        optimizer, T_max=steps, eta_min=config.learning_rate * config.final_learning_rate_ratio
    )


def train_step(model: FunnelMLP | GridNetwork, optimizer: torch.optim.Optimizer,
               scheduler: torch.optim.lr_scheduler.LRScheduler, coordinates: torch.Tensor, targets: torch.Tensor,
               encoding: EncodingSpec, weighting: VisibleWeight | None = None) -> torch.Tensor:
    """One optimisation step on a batch already on the model's device; returns the loss, detached (reading
    it is the caller's choice: on a GPU that is a host sync)."""
    loss = batch_loss(model, coordinates, targets, encoding, weighting)
    optimizer.zero_grad(set_to_none=True)
    loss.backward()
    optimizer.step()
    scheduler.step()
    return loss.detach()


@torch.no_grad()
def held_out_loss(
    model: FunnelMLP | GridNetwork,
    samples: Samples,
    encoding: EncodingSpec,
    device: torch.device,
    batch_size: int,
    limit: int = 1_000_000,
) -> float:
    """Mean LogCosh loss of the runtime's (clamped) prediction on up to ``limit`` held-out samples."""
    count = min(len(samples), limit)
    total = 0.0
    for start in range(0, count, batch_size):
        stop = min(count, start + batch_size)
        coordinates = torch.from_numpy(samples.coordinates[start:stop]).to(device)
        targets = torch.from_numpy(samples.targets[start:stop]).to(device)
        inputs = coordinates if isinstance(model, GridNetwork) else encode(coordinates, encoding)
        total += float(log_cosh_loss(model.predict(inputs), targets)) * (stop - start)
    return total / max(count, 1)


#: The volume's metadata a model file carries (what `gratnet evaluate` and the renderers read of it).
VOLUME_METADATA_KEYS = ("source", "sigma_s_um", "window_extent_um", "dx_um", "patch_size_um", "resolution", "slices",
                        "scheme", "wavelengths_nm", "illuminant", "observer", "repeat")


def model_volume_metadata(volume_metadata: dict[str, Any]) -> dict[str, Any]:
    """What a model records of its volume: :data:`VOLUME_METADATA_KEYS`, and the height field's slope covariance
    (gratnet.shadowing) where the volume has it (`gratnet train` fills it in for an older volume:
    trainer.train_cli.with_slope_covariance)."""
    recorded = {key: volume_metadata.get(key) for key in VOLUME_METADATA_KEYS}
    if volume_metadata.get(SLOPE_COVARIANCE_KEY) is not None:
        recorded[SLOPE_COVARIANCE_KEY] = list(check_slope_covariance(volume_metadata[SLOPE_COVARIANCE_KEY]))
    return recorded


def trained_model_file(model: FunnelMLP | GridNetwork, config: TrainConfig, volume: Volume,
                       history: dict[str, Any]) -> ModelFile:
    """The model file of ``model`` (moved to the CPU), trained with ``config`` on ``volume``: weights, encoding,
    range, the volume's metadata, the training's configuration and ``history``, and the display defaults."""
    from gratnet.showcase import with_display

    model_file = model.cpu().to_model_file(
        encoding=config.encoding_for(volume),
        range=config.range_spec(),
        scheme=volume.metadata["scheme"],
        metadata={
            "volume": model_volume_metadata(volume.metadata),
            "training": {
                "config": config_to_dict(config),
                **{k: v for k, v in history.items() if k != "epochs"},
                "final": history["epochs"][-1] if history.get("epochs") else None,
            },
        },
    )
    # Where the diffraction lands and the exposure that shows it, for the renderers' defaults (docs/formats.md).
    return with_display(model_file)


def read_checkpoint(path: str | os.PathLike[str], device: str | torch.device = "cpu") -> dict[str, Any]:
    """A `gratnet train` checkpoint.pt (model and optimiser state, config, history), its tensors on ``device``."""
    try:
        return torch.load(path, map_location=device, weights_only=False)
    except (OSError, RuntimeError, EOFError, ValueError) as error:
        raise GratNetError(f"cannot read the checkpoint {path}: {error}") from error


def restore_generator(generator: torch.Generator, state: dict[str, Any], path: os.PathLike[str],
                      fallback_seed: int) -> None:
    """Set ``generator`` (the shuffle's and the off-lattice draws') to its state saved in checkpoint ``state``.

    A checkpoint written before that state was saved is still resumed, as it was then: the generator re-seeded
    with ``fallback_seed`` (seed + epochs done), with a warning that the rest of the run will not be the one an
    uninterrupted run would have made (its weights, Adam and schedule are still restored exactly).
    """
    saved = state.get("generator")
    if saved is None:
        logging.getLogger("gratnet.train").warning(
            "%s predates saved shuffling state: resuming with the shuffle re-seeded, so epochs %d and later will "
            "differ from an uninterrupted run (start afresh without --resume for an exact run)",
            path, state["epoch"] + 1)
        generator.manual_seed(fallback_seed)
        return
    generator.set_state(saved.cpu())  # map_location moved it onto the device


@dataclasses.dataclass
class _Run:
    """One training run's state, passed between the steps of :func:`train`."""

    volume: Volume
    config: TrainConfig
    out_dir: Path
    device: torch.device
    encoding: EncodingSpec
    range_spec: RangeSpec
    weighting: VisibleWeight | None
    train_samples: Samples
    test_samples: Samples | None
    graphed: bool
    model: FunnelMLP | GridNetwork
    optimizer: torch.optim.Optimizer
    base_rates: list[float]
    steps_per_epoch: int
    schedule_steps: int
    # A graphed run keeps its schedule on the device (trainer/cudagraph.py): no torch scheduler.
    scheduler: torch.optim.lr_scheduler.LRScheduler | None
    # The one generator of the shuffle and the off-lattice draws: a resume restores its state, so that the
    # epochs after it draw what an uninterrupted run draws (the split's numpy generator is re-made from the seed).
    generator: torch.Generator
    history: dict[str, Any] = dataclasses.field(default_factory=lambda: {"epochs": [], "train_seconds": 0.0})
    start_epoch: int = 0
    done: int = 0  # steps taken (the eager loop's count; a graphed run's is graph.done)
    # Set by _stage_data: the samples on the device, and what refills them off the lattice each epoch.
    coordinates: torch.Tensor | None = None
    targets: torch.Tensor | None = None
    lattice: tuple[torch.Tensor, torch.Tensor] | None = None
    off_lattice: Any = None  # trainer.offlattice.OffLattice
    drawn: int = 0
    graph: GraphedSteps | None = None

    @property
    def checkpoint_path(self) -> Path:
        return self.out_dir / "checkpoint.pt"

    def learning_rate(self) -> float:
        if self.graph is not None:
            return self.graph.learning_rate()
        assert self.scheduler is not None  # an eager run has its torch scheduler
        return float(self.scheduler.get_last_lr()[0])


def _set_up(volume: Volume, config: TrainConfig, out_dir: str | os.PathLike[str]) -> _Run:
    """A fresh run: the device, the samples and their split, the network, Adam and its schedule, all seeded."""
    out = make_folder(out_dir)
    device = pick_device(config.device)
    if device.type == "cpu":  # each step's large buffers stay mapped: no page faults per step (trainer/allocator.py)
        keep_freed_memory()
    torch.manual_seed(config.seed)
    encoding, range_spec = config.encoding_for(volume), config.range_spec()
    weighting = visible_weight(config)
    train_samples, test_samples = split_samples(volume, config)
    graphed = uses_cuda_graph(config, device)
    model = build_model(config, encoding).to(device)
    if config.zero_unseen_features and not config.off_lattice:  # off-lattice points see every feature
        silenced = silence_unseen_features(model, train_samples.coordinates, encoding)
        tqdm.write(f"--zero-unseen-features: first-layer inputs {silenced} stay at zero weight")
    optimizer = make_optimizer(model, config)
    base_rates = [float(group["lr"]) for group in optimizer.param_groups]
    steps_per_epoch = math.ceil(len(train_samples) / config.batch_size)
    schedule_steps = steps_per_epoch * config.epochs
    scheduler = None if graphed else make_scheduler(optimizer, config, schedule_steps, isinstance(model, GridNetwork))
    return _Run(volume, config, out, device, encoding, range_spec, weighting, train_samples, test_samples, graphed,
                model, optimizer, base_rates, steps_per_epoch, schedule_steps, scheduler,
                torch.Generator().manual_seed(config.seed))


def _resume(run: _Run) -> None:
    """Continue ``run`` from its checkpoint.pt, made by the same configuration: the weights, Adam, the schedule,
    the history, torch's random state and the shuffle's generator, as an uninterrupted run would have them."""
    path, config = run.checkpoint_path, run.config
    state = read_checkpoint(path, run.device)
    # Neither the per-epoch diagnostic nor graph replay changes the training: they may differ on resume.
    free = ("epoch_flip_size", "cuda_graph")
    # Options added since a checkpoint was written take their defaults, which is how it was trained; one saved
    # before the grid options were nested (flat grid_* keys) reads as one saved after.
    # One exception: a checkpoint from before --zero-unseen-features (default on since 2026-11-28) trained without.
    recorded = {"zero_unseen_features": False, **state["config"]}
    saved = {key: value for key, value in saved_config_dict(TrainConfig, recorded).items() if key not in free}
    wanted = {key: value for key, value in config_to_dict(config).items() if key not in free}
    if saved != wanted:
        differing = ", ".join(sorted(key for key in {*saved, *wanted} if saved.get(key) != wanted.get(key)))
        raise GratNetError(f"{path} was made with a different configuration ({differing}); start afresh without "
                           "--resume")
    if state["scheduler"] is None and run.scheduler is not None:
        raise GratNetError(f"{path} was trained with --cuda-graph (on a GPU): resume it on a CUDA device, or start "
                           "afresh without --resume")
    run.model.load_state_dict(state["model"])
    run.optimizer.load_state_dict(state["optimizer"])
    for group in run.optimizer.param_groups:  # the saved groups carry the writer's choice; this device's wins
        group["fused"], group["foreach"] = run.optimizer.defaults["fused"], run.optimizer.defaults["foreach"]
    if run.scheduler is not None:
        run.scheduler.load_state_dict(state["scheduler"])
    # Steps taken: recorded since graph replay; before, the scheduler's count.
    run.done = int(state.get("steps", state["scheduler"]["last_epoch"] if state["scheduler"] else 0))
    run.history, run.start_epoch = state["history"], state["epoch"]
    torch.set_rng_state(state["torch_rng"].cpu())  # map_location moved it onto the device
    if run.start_epoch < config.epochs:  # else nothing is left to draw
        restore_generator(run.generator, state, path, config.seed + run.start_epoch)


def _stage_data(run: _Run) -> None:
    """The whole training set resident on the device, indexed there (no per-step host gather or copy); the
    off-lattice draws' buffers; the CUDA graph of the step, when the run replays one."""
    samples, device = run.train_samples, run.device
    run.coordinates = torch.from_numpy(samples.coordinates).to(device)
    run.targets = torch.from_numpy(samples.targets).to(device)
    run.lattice = (run.coordinates, run.targets)
    run.drawn = round(run.config.off_lattice * len(samples))
    if run.drawn:
        from trainer.offlattice import OffLattice

        run.off_lattice = OffLattice(samples.coordinates, samples.targets, samples.slice_index,
                                     2.0 * slice_parameters(run.volume) - 1.0, run.volume.resolution, device)
        # Each epoch's samples are refilled in place (a CUDA graph holds these buffers' addresses).
        run.coordinates, run.targets = torch.empty_like(run.coordinates), torch.empty_like(run.targets)
    if run.graphed:
        run.graph = GraphedSteps(run.model, run.optimizer, run.base_rates, run.schedule_steps,
                                 run.config.final_learning_rate_ratio, run.done, run.encoding, run.weighting,
                                 run.coordinates, run.targets, run.config.batch_size)


def _train_epoch(run: _Run, epoch: int, progress: bool) -> tuple[dict[str, Any], float]:
    """One pass over the training samples (drawn afresh off the lattice first, when asked): the epoch's record
    (loss, seconds, learning rate) and its seconds unrounded."""
    config, device, samples = run.config, run.device, run.train_samples
    coordinates, targets = run.coordinates, run.targets
    assert coordinates is not None and targets is not None and run.lattice is not None  # _stage_data's
    started = time.perf_counter()
    if run.off_lattice is not None:  # a random (1 − F) of the lattice samples, and F·N fresh points between them
        kept = len(samples) - run.drawn
        keep = torch.randperm(len(samples), generator=run.generator)[:kept].to(device)
        coordinates[:kept], targets[:kept] = run.lattice[0][keep], run.lattice[1][keep]
        coordinates[kept:], targets[kept:] = run.off_lattice.draw(run.drawn, run.generator)
    order = torch.randperm(len(samples), generator=run.generator).to(device)
    running = torch.zeros((), dtype=torch.float64, device=device)  # on the device: no per-step sync
    if run.graph is not None:
        run.graph.begin_epoch()
        running = run.graph.running
    bar = tqdm(range(run.steps_per_epoch), desc=f"epoch {epoch + 1}/{config.epochs}", disable=not progress,
               leave=False, unit="batch")
    for step in bar:
        batch = order[step * config.batch_size : (step + 1) * config.batch_size]
        if run.graph is not None:
            run.graph.step(batch)  # updates graph.running, which ``running`` is
        else:
            assert run.scheduler is not None  # an eager run has its torch scheduler
            value = train_step(run.model, run.optimizer, run.scheduler, coordinates[batch],
                               targets[batch], run.encoding, run.weighting).double()
            running = 0.98 * running + 0.02 * value if step else value
            run.done += 1
        if progress and step % 20 == 0:  # the only host sync of the loop, and only with a progress bar
            bar.set_postfix(loss=f"{float(running):.3e}", lr=f"{run.learning_rate():.2e}")
    seconds = time.perf_counter() - started
    record = {"epoch": epoch + 1, "train_loss": float(running), "seconds": round(seconds, 2),
              "learning_rate": run.learning_rate()}
    return record, seconds


def _score_epoch(run: _Run, per_epoch: Callable[[ModelFile], dict[str, Any]] | None) -> dict[str, Any]:
    """What joins an epoch's record beside its training (not counted as training time): the held-out loss, when
    samples are held out, and what ``per_epoch`` makes of the weights' model file."""
    scores: dict[str, Any] = {}
    if run.test_samples is not None:
        scores["held_out_loss"] = held_out_loss(run.model, run.test_samples, run.encoding, run.device,
                                                run.config.batch_size)
    if per_epoch is not None:
        snapshot = copy.deepcopy(run.model).cpu().to_model_file(encoding=run.encoding, range=run.range_spec,
                                                                scheme=run.volume.metadata["scheme"], metadata={})
        scores.update(per_epoch(snapshot))
    return scores


def _save_checkpoint(run: _Run, epochs_done: int) -> None:
    """checkpoint.pt after ``epochs_done`` epochs, written atomically: what :func:`_resume` restores."""
    with atomic_path(run.checkpoint_path) as temporary:
        torch.save(
            {
                "model": run.model.state_dict(),
                "optimizer": run.optimizer.state_dict(),
                "scheduler": run.scheduler.state_dict() if run.scheduler is not None else None,
                "steps": run.graph.done if run.graph is not None else run.done,
                "history": run.history,
                "epoch": epochs_done,
                "config": config_to_dict(run.config),
                "torch_rng": torch.get_rng_state(),
                "generator": run.generator.get_state(),
            },
            temporary,
        )


def _finish(run: _Run) -> tuple[FunnelMLP | GridNetwork, ModelFile, dict[str, Any]]:
    """The run's summary into its history; model.npz and history.json written."""
    from gratnet.modelfile import save_model

    model, history, samples = run.model, run.history, run.train_samples
    history.update(
        {
            "parameters": model.parameter_count,
            "layer_sizes": model.sizes,
            "device": str(run.device),
            "cuda_graph": run.graphed,
            "train_samples": len(samples),
            "held_out_samples": len(run.test_samples or []),
            "samples_per_second": round(len(samples) * len(history["epochs"]) / max(history["train_seconds"], 1e-9)),
        }
    )
    if isinstance(model, GridNetwork):
        history.update({"grid_shapes": [list(shape) for shape in run.config.grid_shapes()],
                        "grid_bytes": model.grid_bytes, "volume_bytes": int(run.volume.xyz.size * 4)})
    model_file = trained_model_file(model, run.config, run.volume, history)
    save_model(run.out_dir / "model.npz", model_file)
    write_text_atomic(run.out_dir / "history.json", json.dumps(history, indent=2) + "\n")
    return model, model_file, history


def train(
    volume: Volume,
    config: TrainConfig,
    out_dir: str | os.PathLike[str],
    resume: bool = False,
    progress: bool = True,
    per_epoch: Callable[[ModelFile], dict[str, Any]] | None = None,
) -> tuple[FunnelMLP | GridNetwork, ModelFile, dict[str, Any]]:
    """Train on ``volume``; writes checkpoint.pt (every epoch), model.npz and history.json to ``out_dir``.

    ``resume`` continues from ``out_dir``'s checkpoint.pt when there is one. ``per_epoch`` (optional) gets the
    model file of the weights after each epoch; what it returns (e.g. a slice's FLIP) joins that epoch's record in
    history.json. Its time is not counted as training time. An interruption (Ctrl-C) leaves the last finished
    epoch's checkpoint.

    The steps: :func:`_set_up`, :func:`_resume`, :func:`_stage_data`; per epoch :func:`_train_epoch`,
    :func:`_score_epoch` and :func:`_save_checkpoint`; :func:`_finish`.
    """
    run = _set_up(volume, config, out_dir)
    if resume and run.checkpoint_path.exists():
        _resume(run)
    _stage_data(run)
    for epoch in range(run.start_epoch, config.epochs):
        record, seconds = _train_epoch(run, epoch, progress)
        record.update(_score_epoch(run, per_epoch))
        run.history["epochs"].append(record)
        run.history["train_seconds"] = round(run.history["train_seconds"] + seconds, 2)
        if progress:
            tqdm.write(f"epoch {epoch + 1}: " + ", ".join(f"{k} {v:.4g}" for k, v in record.items() if k != "epoch"))
        _save_checkpoint(run, epoch + 1)
    return _finish(run)
