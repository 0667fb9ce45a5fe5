"""Seeds × datasets (issue 34): scripts/reproduce_paper_models.sh with SEEDS, and analysis.seed_summary."""

from __future__ import annotations

import json
import shlex
import statistics
import subprocess
from pathlib import Path

import pytest

from analysis.seed_summary import summarise
from tests.helpers import REPO

SCRIPT = REPO / "scripts" / "reproduce_paper_models.sh"


def _seed(runs: Path, name: str, seed: int, scale: float) -> None:
    """A finished seed: the shipped metrics with every FLIP scaled by ``scale``."""
    metrics = json.loads((REPO / "assets" / name / "metrics.json").read_text())
    for entry in metrics["brdf_slices"]:
        entry["flip"] *= scale
    folder = runs / name / f"seed-{seed}"
    folder.mkdir(parents=True)
    (folder / "metrics.json").write_text(json.dumps(metrics))


def test_the_summary_is_the_seeds_mean_and_spread_against_the_papers_column(tmp_path):
    for seed, scale in enumerate((0.9, 1.0, 1.3)):
        _seed(tmp_path, "paper-snake", seed, scale)
    row, = summarise(tmp_path)
    shipped = next(entry["flip"] for entry in json.loads((REPO / "assets/paper-snake/metrics.json").read_text())
                   ["brdf_slices"] if entry["slice"] == "(0°, 0°) 2000 RU")
    assert row["mean"] == pytest.approx(shipped * (0.9 + 1.0 + 1.3) / 3)
    assert row["std"] > 0 and row["min"] == pytest.approx(0.9 * shipped) and row["max"] == pytest.approx(1.3 * shipped)
    assert row["paper"] == 0.0221 and row["paper_column"].startswith("corn snake")
    assert row["mean_beats_paper"] is (row["mean"] <= 0.0221)
    every = statistics.fmean(entry["flip"] for entry in json.loads(
        (REPO / "assets/paper-snake/metrics.json").read_text())["brdf_slices"])  # the mean over every view
    assert row["views_mean"] == pytest.approx(every * (0.9 + 1.0 + 1.3) / 3)
    assert row["views_std"] == pytest.approx(every * statistics.stdev((0.9, 1.0, 1.3)))


def _dry(tmp_path: Path, *names: str, **environment: str) -> list[list[str]]:
    result = subprocess.run(["bash", str(SCRIPT), *names], capture_output=True, text=True, check=True,
                            env={"DRY_RUN": "1", "OUT": str(tmp_path), "PATH": "/usr/bin:/bin", **environment})
    return [shlex.split(line[2:]) for line in result.stdout.splitlines() if line.startswith("+ ")]


def test_seeds_run_each_recipe_per_seed_skip_finished_runs_and_honour_the_budget(tmp_path):
    commands = _dry(tmp_path, "paper-cd", SEEDS="0 2", DEVICE="cuda")
    trains = [command for command in commands if "train" in command]
    assert [train[train.index("--out") + 1] for train in trains] == [
        str(tmp_path / "runs/paper-cd/seed-0"), str(tmp_path / "runs/paper-cd/seed-2")]
    for seed, train in zip((0, 2), trains, strict=True):
        assert train[train.index("--seed") + 1] == str(seed)
        assert train[len(train) - 1 - train[::-1].index("--device") + 1] == "cuda"  # the last --device wins
    assert commands[-1][1:3] == ["-m", "analysis.seed_summary"]
    (tmp_path / "runs/paper-cd/seed-0").mkdir(parents=True)
    (tmp_path / "runs/paper-cd/seed-0/metrics.json").write_text("{}")
    again = [command for command in _dry(tmp_path, "paper-cd", SEEDS="0 2") if "train" in command]
    assert len(again) == 1 and again[0][again[0].index("--seed") + 1] == "2"
    slow_python = tmp_path / "slow_python"  # the recipe's parsing takes 1.2 s: the 1 s budget is spent after it
    slow_python.write_text("#!/bin/bash\nsleep 1.2\nexec python3 \"$@\"\n")
    slow_python.chmod(0o755)
    result = subprocess.run(["bash", str(SCRIPT), "paper-cd"], capture_output=True, text=True, check=True,
                            env={"DRY_RUN": "1", "OUT": str(tmp_path), "PATH": "/usr/bin:/bin", "SEEDS": "0 2",
                                 "TIME_BUDGET_S": "1", "PYTHON": str(slow_python)})
    assert "1 run(s) left" in result.stdout and not any("train" in line for line in result.stdout.splitlines())
