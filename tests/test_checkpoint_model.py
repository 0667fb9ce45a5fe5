"""benchmarks/checkpoint_model.py: a checkpoint's model file equals the one the trainer writes at its end."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np

from gratnet.modelfile import load_model
from trainer.train import train
from trainer.train_config import TrainConfig

ROOT = Path(__file__).resolve().parents[1]


def test_the_last_checkpoint_gives_the_trained_model(tiny_volume, tmp_path):
    volume, volume_path = tiny_volume
    config = TrainConfig(architecture="grid", preset="tiny", grid_levels=2, grid_resolution=9, grid_t_resolution=5,
                         epochs=1, batch_size=512, split="all", device="cpu")
    train(volume, config, tmp_path / "run", progress=False)
    out = tmp_path / "from_checkpoint.npz"
    result = subprocess.run([sys.executable, "benchmarks/checkpoint_model.py", str(tmp_path / "run" / "checkpoint.pt"),
                             str(volume_path), "--out", str(out)], cwd=ROOT, capture_output=True, text=True)
    assert result.returncode == 0, result.stderr
    rebuilt, trained = load_model(out), load_model(tmp_path / "run" / "model.npz")
    for a, b in zip(rebuilt.weights + rebuilt.biases + list(rebuilt.grids),
                    trained.weights + trained.biases + list(trained.grids), strict=True):
        np.testing.assert_array_equal(a, b)
    assert rebuilt.encoding == trained.encoding and rebuilt.layer_sizes == trained.layer_sizes
    assert rebuilt.metadata["volume"] == trained.metadata["volume"]  # what `gratnet evaluate` reads


def test_a_missing_checkpoint_is_one_message(tmp_path):
    result = subprocess.run([sys.executable, "benchmarks/checkpoint_model.py", str(tmp_path / "none.pt"),
                             str(tmp_path / "v.exr"), "--out", str(tmp_path / "m.npz")], cwd=ROOT,
                            capture_output=True, text=True)
    assert result.returncode != 0 and "no such file" in result.stderr and "Traceback" not in result.stderr
