"""Graph-replayed training (trainer/cudagraph.py) against the eager step it replaces.

On the CPU (CI): the graphed step's device-side work (schedule from a step counter, gather by index, running
loss) run eagerly, step for step against trainer.train.train_step with torch's scheduler. On a CUDA device:
whole trainings with --cuda-graph on and off, and a resume across the two.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from gratnet.errors import GratNetError
from trainer.objective import cosine_factor
from trainer.train import build_model, make_optimizer, make_scheduler, split_samples, train, train_step
from trainer.train_config import TrainConfig

cuda = pytest.mark.skipif(not torch.cuda.is_available(), reason="needs a CUDA device")


@pytest.mark.parametrize("architecture", ["mlp", "grid"])
def test_the_device_schedule_and_step_match_the_eager_ones(tiny_volume, architecture):
    """Seven steps of GraphedSteps' step body (on the CPU, uncaptured) give the eager trainer's weights, rates and
    running loss: the cosine schedule of make_scheduler (torch's CosineAnnealingLR for the MLP, LambdaLR for
    grids) recomputed from a step counter, and the loss's moving average."""
    from trainer.cudagraph import GraphedSteps

    volume, _ = tiny_volume
    config = TrainConfig(architecture=architecture, hidden="16,8", grid_levels=1, grid_resolution=11,
                         grid_t_resolution=3, epochs=1, batch_size=64, split="all", device="cpu")
    samples, _ = split_samples(volume, config)
    coordinates, targets = torch.from_numpy(samples.coordinates), torch.from_numpy(samples.targets)
    encoding = config.encoding_for(volume)
    steps, batches = 7, [torch.arange(k * 64, (k + 1) * 64) for k in range(7)]

    torch.manual_seed(0)
    eager = build_model(config, encoding)
    optimizer = make_optimizer(eager, config)
    scheduler = make_scheduler(optimizer, config, steps, architecture == "grid")
    running, rates = None, []
    for batch in batches:
        value = train_step(eager, optimizer, scheduler, coordinates[batch], targets[batch], encoding).double()
        running = value if running is None else 0.98 * running + 0.02 * value
        rates.append(scheduler.get_last_lr()[0])

    torch.manual_seed(0)
    graphed = build_model(config, encoding)
    optimizer = make_optimizer(graphed, config)
    base_rates = [float(group["lr"]) for group in optimizer.param_groups]
    steps_object = GraphedSteps(graphed, optimizer, base_rates, steps, config.final_learning_rate_ratio, 0, encoding,
                                None, coordinates, targets, batch_size=1)  # no batch fills it: every step eager
    for group in optimizer.param_groups:  # capturable Adam runs on CUDA devices only; the math is the same
        group["capturable"] = False
    graphed_rates = []
    for batch in batches:
        steps_object.step(batch)
        graphed_rates.append(steps_object.learning_rate())
    np.testing.assert_allclose(graphed_rates, rates, rtol=1e-12)
    assert steps_object.done == steps and float(steps_object.counter) == steps
    np.testing.assert_allclose(float(steps_object.running), float(running), rtol=1e-5)
    for mine, theirs in zip(graphed.state_dict().values(), eager.state_dict().values(), strict=True):
        np.testing.assert_allclose(mine.numpy(), theirs.numpy(), rtol=1e-4, atol=1e-6)


def test_cosine_factor_runs_from_one_down_to_the_ratio():
    assert cosine_factor(0, 10, 0.02) == 1.0
    assert math.isclose(cosine_factor(5, 10, 0.02), 0.51)
    assert cosine_factor(10, 10, 0.02) == cosine_factor(99, 10, 0.02) == pytest.approx(0.02)


def test_cuda_graph_on_without_a_cuda_device_is_refused(tiny_volume, tmp_path):
    with pytest.raises(GratNetError, match="--cuda-graph on needs a CUDA device"):
        TrainConfig(cuda_graph="on", device="cpu")
    with pytest.raises(GratNetError, match="--cuda-graph must be"):
        TrainConfig(cuda_graph="yes")
    if not torch.cuda.is_available():
        volume, _ = tiny_volume
        with pytest.raises(GratNetError, match="--cuda-graph on needs a CUDA device"):
            train(volume, TrainConfig(preset="tiny", epochs=1, split="all", cuda_graph="on"), tmp_path,
                  progress=False)


def test_a_graphed_checkpoint_resumes_only_graphed(tiny_volume, tmp_path):
    """A checkpoint with no torch scheduler (a graphed run's) is refused by an eager resume in one line."""
    volume, _ = tiny_volume
    config = TrainConfig(preset="tiny", epochs=2, batch_size=512, test_slices="2", device="cpu")
    train(volume, TrainConfig(preset="tiny", epochs=1, batch_size=512, test_slices="2", device="cpu"), tmp_path,
          progress=False)
    state = torch.load(tmp_path / "checkpoint.pt", weights_only=False)
    assert state["steps"] == state["scheduler"]["last_epoch"]  # the step count, recorded since graph replay
    state["scheduler"], state["config"]["epochs"] = None, 2
    torch.save(state, tmp_path / "checkpoint.pt")
    with pytest.raises(GratNetError, match="--cuda-graph"):
        train(volume, config, tmp_path, resume=True, progress=False)


@cuda
@pytest.mark.parametrize("architecture", ["mlp", "grid"])
def test_graphed_training_matches_eager_training_on_cuda(tiny_volume, tmp_path, architecture):
    """Two epochs (warm-up, capture, replays and each epoch's partial batch) with the graph and without: the same
    losses and weights to float tolerance (grid_sample's backward adds atomically, so not bit for bit)."""
    volume, _ = tiny_volume
    base = dict(architecture=architecture, hidden="32,16", grid_levels=2, grid_resolution=11, grid_t_resolution=3,
                epochs=2, batch_size=100, test_slices="2", device="cuda", loss_visible_y="1e-9,1e-2",
                loss_visible_weight=4.0)
    runs = {}
    for mode in ("off", "on"):
        _, model_file, history = train(volume, TrainConfig(**base, cuda_graph=mode), tmp_path / mode, progress=False)
        assert history["cuda_graph"] == (mode == "on")
        runs[mode] = (model_file, history)
    (eager, eager_history), (graphed, graphed_history) = runs["off"], runs["on"]
    for key in ("train_loss", "held_out_loss", "learning_rate"):
        np.testing.assert_allclose([e[key] for e in graphed_history["epochs"]],
                                   [e[key] for e in eager_history["epochs"]], rtol=2e-4)
    for mine, theirs in zip(graphed.weights + graphed.grids, eager.weights + eager.grids, strict=True):
        np.testing.assert_allclose(np.asarray(mine, np.float32), np.asarray(theirs, np.float32), rtol=1e-2,
                                   atol=1e-4)


@cuda
def test_an_eager_checkpoint_resumes_graphed_on_cuda(tiny_volume, tmp_path, stop_in_epoch_two):
    """An eager run stopped after epoch 1 of 2, resumed with the graph and without: the same model."""
    import shutil

    volume, _ = tiny_volume
    base = dict(preset="tiny", epochs=2, batch_size=100, test_slices="2", device="cuda")
    with pytest.raises(KeyboardInterrupt):
        train(volume, TrainConfig(**base, cuda_graph="off"), tmp_path / "off", progress=False,
              per_epoch=stop_in_epoch_two)
    shutil.copytree(tmp_path / "off", tmp_path / "on")
    models = {mode: train(volume, TrainConfig(**base, cuda_graph=mode), tmp_path / mode, resume=True,
                          progress=False)[1] for mode in ("off", "on")}
    for mine, theirs in zip(models["on"].weights, models["off"].weights, strict=True):
        np.testing.assert_allclose(mine, theirs, rtol=1e-3, atol=1e-5)
