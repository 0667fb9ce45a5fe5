"""analysis.fast_points: each fast point's figures against issue 42's floors, with verdicts that follow from the
data (the fast point's files, the baseline record, the compare and frame records), checked on a copy of the shipped
paper-cd fast point and baselines made up here."""

from __future__ import annotations

import json
import shutil
import subprocess
from pathlib import Path

import pytest

from analysis.fast_points import baseline_from_history, fast_section, mesh_flip, view_flips
from gratnet.cost import ModelCost
from tests.helpers import REPO

FAST = REPO / "assets" / "paper-cd" / "fast"
pytestmark = pytest.mark.skipif(not (FAST / "model.npz").is_file(), reason="no shipped fast point")


def _cells(line: str) -> list[str]:
    return [cell.strip() for cell in line.strip().strip("|").split("|")]


def _assets(tmp_path: Path) -> Path:
    assets = tmp_path / "assets"
    shutil.copytree(FAST, assets / "paper-cd" / "fast")
    return assets


def _baseline(tmp_path: Path, **changes: float) -> Path:
    """A baseline at which the fast point's figures are exactly half of the baseline's (ratios 0.50×), then
    ``changes``."""
    flip_0_0, flip_views = view_flips(json.loads((FAST / "metrics.json").read_text()))
    entry = {"macs_per_pixel": 10 * ModelCost.of_file(FAST / "model.npz").macs_per_pixel, "flip_0_0": 2 * flip_0_0,
             "flip_views_mean": 2 * flip_views, "mesh_flip_mean": 2 * 0.01, **changes}
    path = tmp_path / "baseline.json"
    path.write_text(json.dumps({"revision": "0123456789abcdef", "command": "made up", "datasets": {"paper-cd": entry}}))
    return path


def _compare(tmp_path: Path, flip: float = 0.01) -> Path:
    folder = tmp_path / "compare"
    folder.mkdir(exist_ok=True)
    views = [{"mesh": "cd", "flip_covered": flip}, {"mesh": "sphere", "flip_covered": flip}]
    (folder / "paper-cd.json").write_text(json.dumps({"material": "paper-cd", "views": views}))
    return folder


def _frames(fast_ms: float, accurate_ms: float, runs: tuple[str, str] = ("A", "A")) -> dict:
    rows = [{"material": "paper-cd", "quality": "fast", "ms": fast_ms, "run": runs[0]},
            {"material": "paper-cd", "quality": "accurate", "ms": accurate_ms, "run": runs[1]}]
    return {"date": "B", "width": 1920, "height": 1080, "models": rows}


def _row(lines: list[str]) -> tuple[dict[str, int], list[str]]:
    header = next(line for line in lines if line.startswith("| dataset |"))
    row = next(line for line in lines if line.startswith("| paper-cd |"))
    return {name: index for index, name in enumerate(_cells(header))}, _cells(row)


def test_a_point_under_every_floor_meets_all(tmp_path):
    lines = fast_section(_assets(tmp_path), _baseline(tmp_path), _compare(tmp_path), tmp_path / "none.json",
                         _frames(1000.0, 4000.0))
    column, row = _row(lines)
    assert row[column["floors met"]] == "**all**"
    assert "(0.50×)" in row[column["FLIP (0°, 0°) (ratio)"]] and "(0.50×)" in row[column["mean of 8 views (ratio)"]]
    assert row[column["mesh FLIP (ratio)"]].startswith("0.0100 (0.50×; [picture](images/compare_paper-cd_fast.png")
    assert row[column["1080p CD frame, fast / accurate (speed-up)"]] == "1,000 / 4,000 ms (4.00×)"
    assert row[column["MACs/pixel (share)"]].endswith("(10%)")


@pytest.mark.parametrize(("changes", "frames", "cell", "mark"), [
    ({"flip_0_0": 1e-6}, (1000.0, 4000.0), "FLIP (0°, 0°) (ratio)", "**over**"),
    ({"flip_views_mean": 1e-6}, (1000.0, 4000.0), "mean of 8 views (ratio)", "**over**"),
    ({"mesh_flip_mean": 0.007}, (1000.0, 4000.0), "mesh FLIP (ratio)", "**over**"),  # 0.01 / 0.007 = 1.43×
    ({}, (1000.0, 2500.0), "1080p CD frame, fast / accurate (speed-up)", "**under**"),  # 2.5×
])
def test_each_floor_missed_is_marked_and_counted(tmp_path, changes, frames, cell, mark):
    lines = fast_section(_assets(tmp_path), _baseline(tmp_path, **changes), _compare(tmp_path),
                         tmp_path / "none.json", _frames(*frames))
    column, row = _row(lines)
    assert mark in row[column[cell]]
    assert row[column["floors met"]] == "5 of 6"


def test_frames_of_two_runs_give_no_speed_up(tmp_path):
    """The speed-up counts only when both points were timed in one run."""
    lines = fast_section(_assets(tmp_path), _baseline(tmp_path), _compare(tmp_path), tmp_path / "none.json",
                         _frames(1000.0, 4000.0, runs=("A", "C")))
    column, row = _row(lines)
    assert row[column["1080p CD frame, fast / accurate (speed-up)"]] == "—" and row[column["floors met"]] == "5 of 6"


def test_without_a_compare_record_the_mesh_floor_is_not_met(tmp_path):
    empty = tmp_path / "empty"
    empty.mkdir()
    lines = fast_section(_assets(tmp_path), _baseline(tmp_path), empty, tmp_path / "none.json",
                         _frames(1000.0, 4000.0))
    column, row = _row(lines)
    assert row[column["mesh FLIP (ratio)"]] == "—" and row[column["floors met"]] == "5 of 6"


def test_seeds_are_read_from_the_seed_summary(tmp_path):
    seeds = tmp_path / "seeds.json"
    seeds.write_text(json.dumps([{"dataset": "paper-cd/fast", "seeds": ["seed-0", "seed-1", "seed-2"], "mean": 0.0125,
                                  "std": 0.0004, "views_mean": 0.0161, "views_std": 0.0003}]))
    lines = fast_section(_assets(tmp_path), _baseline(tmp_path), _compare(tmp_path), seeds, _frames(1.0, 4.0))
    column, row = _row(lines)
    assert row[column["seeds"]] == "3: 0.0125 ± 0.0004; 8 views 0.0161 ± 0.0003"


def test_no_fast_point_no_section(tmp_path):
    (tmp_path / "assets").mkdir()
    assert fast_section(tmp_path / "assets", _baseline(tmp_path), _compare(tmp_path), tmp_path / "x.json", None) == []


def test_mesh_flip_and_view_flips_are_plain_means():
    assert mesh_flip({"views": [{"flip_covered": 0.1}, {"flip_covered": 0.3}]}) == pytest.approx(0.2)
    entries = [{"slice": "(30°, 0°) 5000 RU", "flip": 0.2}, {"slice": "(0°, 0°) 2000 RU", "flip": 0.1},
               {"slice": "(45°, 60°) 5000 RU", "flip": 0.6}]  # the (0°, 0°) slice found by its label
    assert view_flips({"brdf_slices": entries}) == pytest.approx((0.1, 0.3))


def test_the_baseline_is_read_from_history():
    """At HEAD the record repeats the shipped files' own figures (skipped without the repository's history)."""
    try:
        baseline = baseline_from_history("HEAD")
    except (subprocess.CalledProcessError, FileNotFoundError):
        pytest.skip("no git history here")
    entry = baseline["datasets"]["paper-cd"]
    metrics = json.loads(subprocess.run(["git", "show", "HEAD:assets/paper-cd/metrics.json"], cwd=REPO, check=True,
                                        capture_output=True).stdout)
    assert (entry["flip_0_0"], entry["flip_views_mean"]) == view_flips(metrics)
    assert entry["macs_per_pixel"] == ModelCost.of_file(REPO / "assets" / "paper-cd" / "model.npz").macs_per_pixel
    assert entry["views"] == 8 and entry["mesh_views"] == 9

