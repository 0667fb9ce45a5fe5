"""`gratnet evaluate` states the model's cost (gratnet.cost) in metrics.json and report.md, and with --frame-time its
CD frame time, measured by `gratnet bench` in a child process."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

import trainer.evaluate
from gratnet.cost import ModelCost
from gratnet.encoding import EncodingSpec, RangeSpec
from gratnet.errors import GratNetError
from gratnet.modelfile import ModelFile, save_model
from trainer.evaluate import EvaluateConfig, evaluate_model, measure_frame_time


def _grid_model(path: Path) -> tuple[ModelFile, Path]:
    rng = np.random.default_rng(4)
    spec = EncodingSpec.for_grid(33, 5, frequencies=3, t_frequencies=2)
    grids = [(0.3 * rng.standard_normal((t_nodes, nodes, nodes, 3))).astype(np.float16)
             for nodes, t_nodes in ((5, 3), (9, 2))]
    sizes = [6 + spec.features, 12, 3]
    weights = [(rng.standard_normal((b, a)) / np.sqrt(a)).astype(np.float32) for a, b in zip(sizes[:-1], sizes[1:],
                                                                                              strict=True)]
    model = ModelFile(sizes, weights, [np.full(b, 0.5, np.float32) for b in sizes[1:]], "silu", "clamp", spec,
                      RangeSpec(), "simple-max", metadata={"volume": {"source": "generator:blazed"}}, grids=grids)
    path.parent.mkdir(parents=True, exist_ok=True)
    save_model(path, model)
    return model, path


def test_metrics_and_report_state_the_cost(tmp_path):
    model, path = _grid_model(tmp_path / "run" / "model.npz")
    results = evaluate_model(model, tmp_path / "report", EvaluateConfig(brdf_slices=False), model_path=path)
    metrics = json.loads((tmp_path / "report" / "metrics.json").read_text())
    cost = ModelCost.of_file(path)
    assert metrics["cost"] == {**cost.to_dict(), "summary": cost.summary()} == results["cost"]
    assert metrics["cost"]["bytes_on_disk"] == path.stat().st_size
    assert metrics["model"]["grid_interpolation_macs"] == cost.grid_interpolation_macs == 8 * 6  # one definition
    assert "frame_time_1080p" not in metrics["cost"]  # off by default
    report = (tmp_path / "report" / "report.md").read_text()
    model_part = report.split("## Model", 1)[1].split("## Metrics", 1)[0]
    assert cost.summary() in model_part and f"{model.parameter_count:,} parameters" in model_part


def test_a_frame_time_without_a_file_is_reported_not_fatal(tmp_path, capsys):
    model, _ = _grid_model(tmp_path / "run" / "model.npz")
    results = evaluate_model(model, tmp_path / "report", EvaluateConfig(brdf_slices=False, frame_time=True))
    assert "has no file to time" in results["cost"]["frame_time_1080p"]["error"]
    assert results["cost"]["bytes_on_disk"] is None
    assert "warning: frame time" in capsys.readouterr().err
    assert "not measured: frame time" in (tmp_path / "report" / "report.md").read_text()


def test_measuring_a_missing_file_is_one_clear_error(tmp_path):
    with pytest.raises(GratNetError, match="frame time: model file .* does not exist"):
        measure_frame_time(tmp_path / "none.npz")


def test_frame_time_is_measured_by_bench_in_a_child(tmp_path, monkeypatch, ctx):  # ctx: skipped without GL
    """The whole --frame-time path at a small size: evaluate runs `gratnet bench` and records its frame."""
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))  # the child's render-path verdict stays here
    monkeypatch.setattr(trainer.evaluate, "FRAME_TIME_SIZE", (48, 32))
    monkeypatch.setattr(trainer.evaluate, "FRAME_TIME_REPEATS", 2)
    model, path = _grid_model(tmp_path / "run" / "model.npz")
    results = evaluate_model(model, tmp_path / "report", EvaluateConfig(brdf_slices=False, frame_time=True),
                             model_path=path)
    frame = results["cost"]["frame_time_1080p"]
    assert "error" not in frame, frame
    assert (frame["width"], frame["height"], frame["mesh"], frame["spp"]) == (48, 32, "cd", 1)
    assert len(frame["times_ms"]) == 2 and min(frame["times_ms"]) <= frame["ms"] <= max(frame["times_ms"])
    assert frame["render_path"] in ("forward", "deferred") and frame["weights_path"] in ("texture", "baked")
    assert frame["gl_renderer"] == str(ctx.info["GL_RENDERER"])
    assert frame["command"].startswith(f"gratnet bench {path} --no-slices")
    assert "--scene-sizes 48x32" in frame["command"]
    assert len(frame["load_average_before"]) == 3
    report = (tmp_path / "report" / "report.md").read_text()
    assert f"48×32 CD frame on this machine: {frame['ms']:.4g} ms" in report


def test_gratnet_evaluate_counts_the_files_bytes(tmp_path):
    from gratnet.cli import main

    _, path = _grid_model(tmp_path / "run" / "model.npz")
    assert main(["evaluate", str(path), "--no-brdf-slices", "--out", str(tmp_path / "report"), "--quiet"]) == 0
    metrics = json.loads((tmp_path / "report" / "metrics.json").read_text())
    assert metrics["cost"]["bytes_on_disk"] == path.stat().st_size and "frame_time_1080p" not in metrics["cost"]
