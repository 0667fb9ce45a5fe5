"""``gratnet train --resume`` continues exactly (issue 36): a run interrupted after epoch k and resumed ends with
the weights and the per-epoch metrics of the run that was never interrupted, bit for bit, on the CPU.

Interrupts are made four ways: an exception raised between two epochs (the ``per_epoch`` hook: after epoch k's
checkpoint, before epoch k + 1's), a checkpoint write that fails half-way (the disk fills up), and a real
``gratnet train`` process stopped with SIGKILL or SIGINT (Ctrl-C) as soon as its first checkpoint is on disk.
Old checkpoints (no saved shuffling state) still resume, with a warning.
"""

from __future__ import annotations

import errno
import json
import logging
import os
import signal
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import torch

from gratnet.errors import GratNetError
from gratnet.modelfile import load_model
from tests.helpers import REPO
from trainer.train import read_checkpoint, train
from trainer.train_config import TrainConfig

#: Per-epoch records that may differ between two identical runs (wall-clock time).
TIMINGS = ("seconds",)


def _config(**overrides: Any) -> TrainConfig:
    """Four epochs of the tiny preset, 22 steps an epoch, a held-out slice (so a held-out loss per epoch)."""
    return TrainConfig(**{"preset": "tiny", "epochs": 4, "batch_size": 64, "test_slices": "2", "device": "cpu",
                          "seed": 3, **overrides})


def _stop_after(epochs: int) -> Callable[[object], dict]:
    """A ``per_epoch`` hook that interrupts the run in epoch ``epochs + 1``, after epoch ``epochs``'s checkpoint."""
    calls: list[int] = []

    def hook(_model_file: object) -> dict:
        calls.append(1)
        if len(calls) > epochs:
            raise KeyboardInterrupt
        return {}

    return hook


def _records(history: dict[str, Any]) -> list[dict[str, Any]]:
    return [{key: value for key, value in record.items() if key not in TIMINGS} for record in history["epochs"]]


def _assert_same_run(mine: tuple[Any, Any, dict], theirs: tuple[Any, Any, dict]) -> None:
    """The same weights (torch.equal, every tensor) and the same per-epoch metrics (==, floats included)."""
    (model, model_file, history), (their_model, their_file, their_history) = mine, theirs
    state, their_state = model.state_dict(), their_model.state_dict()
    assert state.keys() == their_state.keys()
    for name in state:
        assert torch.equal(state[name], their_state[name]), name
    assert all(np.array_equal(a, b) for a, b in zip(model_file.weights, their_file.weights, strict=True))
    assert _records(history) == _records(their_history)
    assert len(history["epochs"]) == len(their_history["epochs"])


@pytest.mark.parametrize("options", [{}, {"off_lattice": 0.5}, {"split": "random", "test_fraction": 0.2}],
                         ids=["lattice", "off-lattice", "random-split"])
@pytest.mark.parametrize("stopped_after", [1, 2])
def test_a_resumed_run_is_the_uninterrupted_run(tiny_volume, tmp_path, options, stopped_after):
    volume, _ = tiny_volume
    config = _config(**options)
    whole = train(volume, config, tmp_path / "whole", progress=False)
    with pytest.raises(KeyboardInterrupt):
        train(volume, config, tmp_path / "cut", progress=False, per_epoch=_stop_after(stopped_after))
    assert read_checkpoint(tmp_path / "cut" / "checkpoint.pt")["epoch"] == stopped_after
    resumed = train(volume, config, tmp_path / "cut", resume=True, progress=False)
    _assert_same_run(resumed, whole)
    # The epochs before the interrupt come from the checkpoint's history, the rest were trained again: all 4.
    assert [record["epoch"] for record in resumed[2]["epochs"]] == [1, 2, 3, 4]


def test_two_resumes_in_a_row_are_the_uninterrupted_run(tiny_volume, tmp_path):
    """Interrupted after epoch 1, resumed and interrupted again after epoch 3, resumed to the end."""
    volume, _ = tiny_volume
    config = _config(off_lattice=0.25)
    whole = train(volume, config, tmp_path / "whole", progress=False)
    with pytest.raises(KeyboardInterrupt):
        train(volume, config, tmp_path / "cut", progress=False, per_epoch=_stop_after(1))
    with pytest.raises(KeyboardInterrupt):
        train(volume, config, tmp_path / "cut", resume=True, progress=False, per_epoch=_stop_after(2))
    assert read_checkpoint(tmp_path / "cut" / "checkpoint.pt")["epoch"] == 3
    _assert_same_run(train(volume, config, tmp_path / "cut", resume=True, progress=False), whole)


def test_a_checkpoint_write_that_fails_half_way_leaves_the_previous_one(tiny_volume, tmp_path, monkeypatch):
    """Epoch 3's checkpoint write runs out of disk space after a few bytes: the run stops with one error, the
    checkpoint on disk is still epoch 2's (whole and readable), no temporary is left, and resuming from it gives
    the uninterrupted run."""
    volume, _ = tiny_volume
    config = _config()
    whole = train(volume, config, tmp_path / "whole", progress=False)
    real_save = torch.save
    saves: list[int] = []

    def save_until_the_disk_fills(state: Any, target: Any, *arguments: Any, **options: Any) -> None:
        saves.append(1)
        if len(saves) < 3:
            real_save(state, target, *arguments, **options)
            return
        Path(target).write_bytes(b"PK\x03\x04 half a checkpoint")
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(torch, "save", save_until_the_disk_fills)
    with pytest.raises(GratNetError, match="No space left on device"):
        train(volume, config, tmp_path / "cut", progress=False)
    monkeypatch.setattr(torch, "save", real_save)
    assert sorted(path.name for path in (tmp_path / "cut").iterdir()) == ["checkpoint.pt"]
    assert read_checkpoint(tmp_path / "cut" / "checkpoint.pt")["epoch"] == 2
    _assert_same_run(train(volume, config, tmp_path / "cut", resume=True, progress=False), whole)


def test_an_old_checkpoint_without_the_shuffling_state_resumes_with_a_warning(tiny_volume, tmp_path, caplog):
    volume, _ = tiny_volume
    config = _config()
    with pytest.raises(KeyboardInterrupt):
        train(volume, config, tmp_path, progress=False, per_epoch=_stop_after(2))
    checkpoint = tmp_path / "checkpoint.pt"
    state = torch.load(checkpoint, weights_only=False)
    del state["generator"]  # as written before issue 36
    torch.save(state, checkpoint)
    with caplog.at_level(logging.WARNING, logger="gratnet"):
        _, _, history = train(volume, config, tmp_path, resume=True, progress=False)
    warnings = [record.getMessage() for record in caplog.records if record.levelno == logging.WARNING]
    assert len(warnings) == 1 and "predates saved shuffling state" in warnings[0] and "epochs 3 and later" in \
        warnings[0]
    assert [record["epoch"] for record in history["epochs"]] == [1, 2, 3, 4]


def test_a_checkpoint_saved_before_the_grid_options_were_nested_resumes(tiny_volume, tmp_path):
    """A checkpoint whose config holds the grid options as flat grid_* keys (as written before TrainConfig.grid)
    resumes a run of the same options, and still refuses one whose grid options differ."""
    volume, _ = tiny_volume
    config = _config(architecture="grid", epochs=2, grid_levels=1, grid_resolution=5, grid_t_resolution=2)
    with pytest.raises(KeyboardInterrupt):
        train(volume, config, tmp_path, progress=False, per_epoch=_stop_after(1))
    checkpoint = tmp_path / "checkpoint.pt"
    state = torch.load(checkpoint, weights_only=False)
    assert state["config"]["grid"]["levels"] == 1
    grid = state["config"].pop("grid")
    state["config"].update({f"grid_{key}": value for key, value in grid.items()})
    torch.save(state, checkpoint)
    with pytest.raises(GratNetError, match="different configuration"):
        train(volume, _config(architecture="grid", epochs=2, grid_levels=1, grid_resolution=5, grid_t_resolution=3),
              tmp_path, resume=True, progress=False)
    _, _, history = train(volume, config, tmp_path, resume=True, progress=False)
    assert [record["epoch"] for record in history["epochs"]] == [1, 2]


# --------------------------------------------------------------------------------------------------
# A real process, killed


TRAIN_FLAGS = ["--preset", "tiny", "--epochs", "30", "--batch-size", "64", "--test-slices", "2", "--seed", "5",
               "--device", "cpu", "--off-lattice", "0.25", "--no-brdf-slices", "--size", "16", "--quiet"]


def _cli(arguments: list[str]) -> subprocess.Popen:
    """``gratnet ARGUMENTS`` in a fresh process (one thread: the three processes compute alike)."""
    environment = {**os.environ, "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1",
                   "PYTHONPATH": os.pathsep.join(filter(None, [str(REPO), os.environ.get("PYTHONPATH")]))}
    script = "import sys, torch\nfrom gratnet.cli import main\ntorch.set_num_threads(1)\nsys.exit(main(sys.argv[1:]))"
    return subprocess.Popen([sys.executable, "-c", script, *arguments], env=environment, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)


def _finish(process: subprocess.Popen) -> None:
    stdout, stderr = process.communicate(timeout=300)
    assert process.returncode == 0, stderr


@pytest.fixture(scope="module")
def uninterrupted(tiny_volume: tuple[object, Path], tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The folder of the command that was never interrupted."""
    _, volume_path = tiny_volume
    folder = tmp_path_factory.mktemp("whole")
    _finish(_cli(["train", str(volume_path), "--out", str(folder), *TRAIN_FLAGS]))
    return folder


@pytest.mark.parametrize("stop", [signal.SIGKILL, signal.SIGINT], ids=["SIGKILL", "SIGINT"])
def test_a_stopped_training_resumed_is_the_uninterrupted_one(tiny_volume, tmp_path, uninterrupted, stop):
    """The signal as soon as the first checkpoint is on disk, then ``gratnet train --resume``: model, history and
    metrics equal the uninterrupted command's. SIGKILL: no handler runs, nothing is cleaned up. SIGINT (Ctrl-C):
    exit status 130 and one line that says which epoch the checkpoint holds and how to continue."""
    _, volume_path = tiny_volume
    stopped = tmp_path / "stopped"
    process = _cli(["train", str(volume_path), "--out", str(stopped), *TRAIN_FLAGS])
    deadline = time.monotonic() + 120
    while not (stopped / "checkpoint.pt").exists() and process.poll() is None and time.monotonic() < deadline:
        time.sleep(0.002)
    process.send_signal(stop)
    _, stderr = process.communicate(timeout=60)
    epoch = read_checkpoint(stopped / "checkpoint.pt")["epoch"]
    assert 1 <= epoch < 30, "the training ended before it could be stopped"
    if stop == signal.SIGKILL:
        assert process.returncode == -signal.SIGKILL
    else:
        assert process.returncode == 130, stderr
        assert stderr.strip().splitlines() == [f"gratnet train: interrupted; {stopped / 'checkpoint.pt'} holds epoch "
                                               f"{epoch} of 30: the same command with --resume continues from "
                                               f"there, as the uninterrupted run would have"]
    assert not (stopped / "model.npz").exists() and not (stopped / "metrics.json").exists()
    _finish(_cli(["train", str(volume_path), "--out", str(stopped), *TRAIN_FLAGS, "--resume"]))

    mine, theirs = load_model(stopped / "model.npz"), load_model(uninterrupted / "model.npz")
    assert all(np.array_equal(a, b) for a, b in zip(mine.weights, theirs.weights, strict=True))
    histories = [json.loads((folder / "history.json").read_text()) for folder in (stopped, uninterrupted)]
    assert _records(histories[0]) == _records(histories[1]) and len(histories[0]["epochs"]) == 30
    metrics = [json.loads((folder / "metrics.json").read_text()) for folder in (stopped, uninterrupted)]
    assert _without_timings(metrics[0]) == _without_timings(metrics[1])


def _without_timings(value: Any) -> Any:
    """``value`` (JSON) without the entries that measure time or name the output folder (and the model file's size
    with its cost summary: the file records the training times)."""
    if isinstance(value, dict):
        return {key: _without_timings(item) for key, item in value.items()
                if "second" not in key and key not in ("epochs", "out", "model", "bytes_on_disk", "summary")}
    if isinstance(value, list):
        return [_without_timings(item) for item in value]
    return value
