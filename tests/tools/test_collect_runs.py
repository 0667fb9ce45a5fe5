"""analysis.collect_runs and gratnet.config.changed_flags: a run's record is read back from its files, and
its command rebuilds its configuration."""

from __future__ import annotations

import argparse
import json
import shlex
import subprocess
import sys
from pathlib import Path

import pytest

from analysis.collect_runs import HEADLINE, collect_run, markdown_table, parse_run
from gratnet.config import add_arguments, changed_flags, config_to_dict, from_arguments
from gratnet.errors import GratNetError
from tests.helpers import REPO
from trainer.train_config import TrainConfig


def _parse(words: list[str]) -> TrainConfig:
    parser = argparse.ArgumentParser()
    add_arguments(parser, TrainConfig)
    return from_arguments(TrainConfig, parser.parse_args(words))


def test_changed_flags_rebuild_the_config_and_name_only_what_differs():
    assert changed_flags(TrainConfig()) == []
    config = TrainConfig(architecture="grid", grid_features=4, grid_level_t="11,11,21", range_power=4.0,
                         epochs=14, split="all", grid_interpolation="smoothstep")
    words = changed_flags(config)
    assert words[:2] == ["--architecture", "grid"] and "--epochs" in words and "--preset" not in words
    assert _parse(words) == config


def _fake_run(folder: Path, *, evaluated_into_eval: bool = True, budget: bool = True) -> Path:
    folder.mkdir(parents=True)
    train = config_to_dict(TrainConfig(architecture="grid", grid_features=3, epochs=2))
    (folder / "model.config.json").write_text(json.dumps({"train": train, "volume": "/x/vol-s21.exr"}))
    (folder / "history.json").write_text(json.dumps({
        "epochs": [{"epoch": 1, "train_loss": 2e-6, "slice_flip": 0.05},
                   {"epoch": 2, "train_loss": 1e-6, "slice_flip": 0.04}],
        "train_seconds": 12.5, "parameters": 1000, "grid_bytes": 5_000_000, "volume_bytes": 100_000_000}))
    views = [{"slice": HEADLINE, "flip": 0.02, "psnr_xyz": 45.0, "oracle_flip": 0.006},
             {"slice": "(30°, 0°) 5000 RU", "flip": 0.03, "psnr_xyz": 40.0, "oracle_flip": 0.008}]
    metrics_dir = folder / "eval" if evaluated_into_eval else folder
    metrics_dir.mkdir(exist_ok=True)
    (metrics_dir / "metrics.json").write_text(json.dumps({"model": {}, "brdf_slices": views}))
    if budget:
        (folder / "error_budget.json").write_text(json.dumps({"target": 0.0123, "views": [
            {"label": HEADLINE, "network": {"flip": 0.02, "sigma_px": 2e-3}, "shuffled": {"flip": 0.018},
             "scale_at_target": 0.5, "white_sigma_at_target": 1e-3}]}))
    return folder


def test_a_run_is_read_back_from_its_files(tmp_path):
    record = collect_run(_fake_run(tmp_path / "a"), "a run")
    assert record["run"] == "a run" and record["final_loss"] == 1e-6 and record["train_seconds"] == 12.5
    assert record["epoch_slice_flip_128"] == [0.05, 0.04]
    assert record["flip"] == {HEADLINE: 0.02, "(30°, 0°) 5000 RU": 0.03}
    assert record["oracle_flip"][HEADLINE] == 0.006
    assert record["error_budget"][HEADLINE]["k_at_0.0123"] == 0.5
    command = shlex.split(record["command"])
    assert command[:5] == ["gratnet", "train", "vol-s21.exr", "--out", "RUN"]
    assert _parse(command[5:]) == TrainConfig(architecture="grid", grid_features=3, epochs=2)
    table = markdown_table([record])
    assert "| a run | 5.00 MB (5.0 %) |" in table and "| 0.0250 | 1.50× | 45.0 dB |" in table


def test_a_shipped_asset_layout_and_no_budget_are_accepted(tmp_path):
    record = collect_run(_fake_run(tmp_path / "b", evaluated_into_eval=False, budget=False), "b")
    assert "error_budget" not in record and record["flip"][HEADLINE] == 0.02


def test_a_folder_without_the_files_is_refused_with_one_message(tmp_path):
    (tmp_path / "empty").mkdir()
    with pytest.raises(GratNetError, match="model.config.json"):
        collect_run(tmp_path / "empty", "x")
    result = subprocess.run([sys.executable, "-m", "analysis.collect_runs", str(tmp_path / "missing")],
                            cwd=REPO, capture_output=True, text=True)
    assert result.returncode != 0 and "not a folder" in result.stderr and "Traceback" not in result.stderr


def test_labels_default_to_the_folder_name():
    assert parse_run("out/run-a") == (Path("out/run-a"), "run-a")
    assert parse_run("out/run-a=four features") == (Path("out/run-a"), "four features")


def test_the_figure_is_written_for_runs_with_and_without_per_epoch_flip(tmp_path):
    from analysis.collect_runs import plot_runs

    with_flip = collect_run(_fake_run(tmp_path / "a"), "a")
    without = collect_run(_fake_run(tmp_path / "b"), "b")
    without["epoch_slice_flip_128"] = [None, None]
    plot_runs([with_flip, without], tmp_path / "curves.png")
    assert (tmp_path / "curves.png").stat().st_size > 1000


def test_a_run_stopped_before_its_end_is_read_from_its_checkpoint(tmp_path):
    import torch

    run = tmp_path / "stopped"
    run.mkdir()
    config = TrainConfig(architecture="grid", grid_levels=1, grid_resolution=5, grid_t_resolution=3,
                         grid_features=2, epochs=10)
    torch.save({"config": config_to_dict(config),
                "history": {"epochs": [{"epoch": 1, "train_loss": 3e-6, "slice_flip": 0.1}], "train_seconds": 9.0}},
               run / "checkpoint.pt")
    record = collect_run(run, "stopped")
    assert record["stopped_after_epoch"] == 1 and record["epochs_planned"] == 10
    assert record["grid_bytes"] == 3 * 5 * 5 * 2 * 2 and record["flip"] == {}
    assert record["epoch_slice_flip_128"] == [0.1] and "--epochs 10" in record["command"]
    finished = collect_run(_fake_run(tmp_path / "a"), "a")
    table = markdown_table([record, finished])
    assert "| stopped (stopped after epoch 1 of 10) | 0.00 MB | 3e-06 | 9 s | — | — |" in table
    assert HEADLINE in table.splitlines()[0]
