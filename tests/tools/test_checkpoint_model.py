"""analysis.checkpoint_model: a checkpoint's model file equals the one the trainer writes at its end; several
checkpoints of one run give their weights' mean."""

from __future__ import annotations

import shutil
import subprocess
import sys

import numpy as np

from gratnet.modelfile import load_model
from tests.helpers import REPO
from trainer.train import train
from trainer.train_config import TrainConfig


def run_script(*arguments: object) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "analysis.checkpoint_model", *map(str, arguments)], cwd=REPO,
                          capture_output=True, text=True)


def tiny_grid(**overrides: object) -> TrainConfig:
    """A small grid network that trains in seconds on the tiny volume."""
    return TrainConfig(architecture="grid", preset="tiny", grid_levels=2, grid_resolution=9, grid_t_resolution=5,
                       batch_size=512, split="all", device="cpu", **overrides)  # type: ignore[arg-type]


def test_the_last_checkpoint_gives_the_trained_model(tiny_volume, tmp_path):
    volume, volume_path = tiny_volume
    train(volume, tiny_grid(epochs=1), tmp_path / "run", progress=False)
    out = tmp_path / "from_checkpoint.npz"
    result = run_script(tmp_path / "run" / "checkpoint.pt", volume_path, "--out", out)
    assert result.returncode == 0, result.stderr
    rebuilt, trained = load_model(out), load_model(tmp_path / "run" / "model.npz")
    for a, b in zip(rebuilt.weights + rebuilt.biases + list(rebuilt.grids),
                    trained.weights + trained.biases + list(trained.grids), strict=True):
        np.testing.assert_array_equal(a, b)
    assert rebuilt.encoding == trained.encoding and rebuilt.layer_sizes == trained.layer_sizes
    assert rebuilt.metadata["volume"] == trained.metadata["volume"]  # what `gratnet evaluate` reads


def test_a_missing_checkpoint_is_one_message(tmp_path):
    result = run_script(tmp_path / "none.pt", tmp_path / "v.exr", "--out", tmp_path / "m.npz")
    assert result.returncode != 0 and "no such file" in result.stderr and "Traceback" not in result.stderr


def test_two_epochs_checkpoints_average_to_their_weights_mean(tiny_volume, tmp_path, stop_in_epoch_two):
    volume, volume_path = tiny_volume
    config = tiny_grid(epochs=2)
    run = tmp_path / "run"
    try:
        train(volume, config, run, progress=False, per_epoch=stop_in_epoch_two)
    except KeyboardInterrupt:
        pass
    shutil.copy(run / "checkpoint.pt", tmp_path / "epoch1.pt")
    train(volume, config, run, resume=True, progress=False)
    assert run_script(tmp_path / "epoch1.pt", volume_path, "--out", tmp_path / "e1.npz").returncode == 0
    result = run_script(tmp_path / "epoch1.pt", run / "checkpoint.pt", volume_path, "--out", tmp_path / "mean.npz")
    assert result.returncode == 0, result.stderr
    assert "mean of epochs 1, 2" in result.stdout
    first, last, mean = (load_model(path) for path in (tmp_path / "e1.npz", run / "model.npz", tmp_path / "mean.npz"))
    for a, b, m in zip(first.weights + first.biases + list(first.grids), last.weights + last.biases + list(last.grids),
                       mean.weights + mean.biases + list(mean.grids), strict=True):
        assert not np.array_equal(a, b)  # epoch 2 moved every array, so the mean is a new one
        # The grids are stored as float16: the mean of the float32 weights, rounded once.
        np.testing.assert_allclose(m, (a.astype(np.float64) + b) / 2, rtol=2e-3, atol=1e-6)
    assert mean.metadata["training"]["averaged_epochs"] == [1, 2]


def test_checkpoints_of_different_runs_or_one_epoch_twice_are_refused(tiny_volume, tmp_path):
    volume, volume_path = tiny_volume
    for seed in (0, 1):
        train(volume, tiny_grid(epochs=1, seed=seed), tmp_path / f"seed{seed}", progress=False)
    result = run_script(tmp_path / "seed0" / "checkpoint.pt", tmp_path / "seed1" / "checkpoint.pt", volume_path,
                        "--out", tmp_path / "m.npz")
    assert result.returncode != 0 and "different configurations" in result.stderr
    assert "Traceback" not in result.stderr and not (tmp_path / "m.npz").exists()
    checkpoint = tmp_path / "seed0" / "checkpoint.pt"
    result = run_script(checkpoint, checkpoint, volume_path, "--out", tmp_path / "m.npz")
    assert result.returncode != 0 and "repeat an epoch" in result.stderr
    assert "Traceback" not in result.stderr and not (tmp_path / "m.npz").exists()
