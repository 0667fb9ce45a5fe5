"""analysis.pareto (issue 42): speed against error from data alone: quality points, frame times, table baselines."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

from analysis import pareto
from gratnet.cost import MEGABYTE
from tests.helpers import REPO
from trainer.evaluate import STANDARD_SLICE_LABELS


def _metrics(flips: list[float]) -> dict:
    return {"brdf_slices": [{"slice": label, "flip": flip} for label, flip in zip(STANDARD_SLICE_LABELS, flips,
                                                                                   strict=True)]
            + [{"slice": "(45°, 60°) 5000 RU", "flip": 0.9, "extra_view": True}]}


@pytest.fixture
def two_points(tmp_path: Path) -> tuple[Path, Path, Path]:
    """paper-cd with an accurate and a fast point (the shipped model file twice, made-up metrics), a frame record
    for both and a table baseline."""
    assets = tmp_path / "assets"
    for folder, flips in ((assets / "paper-cd", [0.01, 0.02, 0.02, 0.02, 0.03]),
                          (assets / "paper-cd" / "fast", [0.012, 0.025, 0.025, 0.025, 0.038])):
        folder.mkdir(parents=True)
        shutil.copy(REPO / "assets" / "paper-cd" / "model.npz", folder / "model.npz")
        (folder / "metrics.json").write_text(json.dumps(_metrics(flips)))
    frames = tmp_path / "frames.json"
    frames.write_text(json.dumps({"width": 1920, "height": 1080, "models": [
        {"material": "paper-cd", "quality": "accurate", "ms": 10_000.0},
        {"material": "paper-cd", "quality": "fast", "ms": 2_500.0},
        {"material": "paper-snake", "quality": "accurate", "ms": 1.0}]}))
    (tmp_path / "lut_baseline_paper-cd.json").write_text(json.dumps([
        {"what": "network", "mb": 3.9, "ms_per_frame": 99.0, "flip_slices": [0.01] * 5, "flip_mean": 0.02},
        {"what": "look-up 1001² × 11", "mb": 66.1, "ms_per_frame": 160.0, "flip_slices": [0.004] * 5,
         "flip_mean": 0.005}]))
    return assets, frames, tmp_path / "lut_baseline_{name}.json"


def test_points_carry_each_quality_point_its_frame_and_the_tables(two_points):
    assets, frames, lut = two_points
    points = {point.kind: point for point in pareto.collect(assets, frames, str(lut))}
    assert set(points) == {"accurate", "fast", "look-up"}
    accurate, fast, table = points["accurate"], points["fast"], points["look-up"]
    assert accurate.flip == pytest.approx(0.02) and accurate.flip_0_0 == pytest.approx(0.01)  # five slices, no extra
    assert fast.flip == pytest.approx(0.025)
    # The frame record wins over the table run's network frame; each point its own quality's row.
    assert (accurate.ms, fast.ms) == (10_000.0, 2_500.0)
    size = (REPO / "assets" / "paper-cd" / "model.npz").stat().st_size
    assert accurate.megabytes == pytest.approx(size / MEGABYTE)
    assert (table.ms, table.megabytes, table.flip) == (160.0, 66.1, 0.005)


def test_without_a_frame_record_the_accurate_point_takes_the_table_runs_network_frame(two_points, tmp_path):
    assets, _, lut = two_points
    points = {point.kind: point for point in pareto.collect(assets, tmp_path / "none.json", str(lut))}
    assert points["accurate"].ms == 99.0 and points["accurate"].source == "lut_baseline_paper-cd.json"
    assert points["fast"].ms is None  # never invented


def test_advice_follows_the_error_ratio(two_points):
    assets, frames, lut = two_points
    points = pareto.collect(assets, frames, str(lut))
    sentence = pareto.advice(points, "paper-cd")
    assert "1.25× the accurate" in sentence and "pick fast for interaction" in sentence
    worse = [pareto.Point(**{**point.to_dict(), "flip": point.flip * 2}) if point.kind == "fast" else point
             for point in points]
    assert "only where speed rules" in pareto.advice(worse, "paper-cd")
    only_accurate = [point for point in points if point.kind != "fast"]
    assert "no fast point is shipped yet" in pareto.advice(only_accurate, "paper-cd")


def test_figures_and_section_name_every_family(two_points, tmp_path):
    assets, frames, lut = two_points
    points = pareto.collect(assets, frames, str(lut))
    written = pareto.write_figures(points, tmp_path / "images")
    assert [path.name for path in written] == ["pareto_gratings.png"]
    assert written[0].read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    section = "\n".join(pareto.pareto_section(points))
    assert "### gratings" in section and "images/pareto_gratings.png" in section and "- paper-cd:" in section
