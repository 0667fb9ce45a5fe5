"""`gratnet bench`: the Pareto front, the error figures it reads, and a tiny end-to-end run."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from bench.slices import BenchConfig, ModelEntry, markdown_table, pareto_front
from gratnet.cli import main
from gratnet.cost import ModelCost
from gratnet.encoding import EncodingSpec, RangeSpec
from gratnet.modelfile import ModelFile, save_model
from tests.helpers import REPO


def test_pareto_front_keeps_exactly_the_points_nothing_beats():
    points = [(1.0, 0.5), (2.0, 0.4), (2.5, 0.45), (3.0, 0.1), (0.5, 0.9), (4.0, 0.1)]
    front = pareto_front(points)
    assert front == [4, 0, 1, 3]  # by cost; (2.5, 0.45) and (4.0, 0.1) are dominated
    for index, (cost, error) in enumerate(points):
        dominated = any(c <= cost and e <= error and (c, e) != (cost, error) for c, e in points)
        assert (index in front) == (not dominated)


def test_model_entry_reads_the_error_of_the_five_evaluation_slices():
    entry = ModelEntry.load(REPO / "assets" / "blazed" / "model.npz")
    metrics = json.loads((REPO / "assets" / "blazed" / "metrics.json").read_text())["brdf_slices"]
    assert entry.material == "blazed"
    assert entry.flip_normal == pytest.approx(metrics[0]["flip"])
    assert entry.flip_mean == pytest.approx(np.mean([row["flip"] for row in metrics]))
    assert min(row["flip"] for row in metrics) <= entry.flip_mean <= max(row["flip"] for row in metrics)


def test_model_entry_counts_the_five_evaluation_slices_beside_further_views():
    """paper-scratches was evaluated on eight views: the five paper slices first, then three more. Its error is
    the five slices' (the bench once reported none for any metrics.json that held more than five)."""
    entry = ModelEntry.load(REPO / "assets" / "paper-scratches" / "model.npz")
    metrics = json.loads((REPO / "assets" / "paper-scratches" / "metrics.json").read_text())["brdf_slices"]
    assert len(metrics) > 5
    assert entry.flip_normal == pytest.approx(metrics[0]["flip"])
    assert entry.flip_mean == pytest.approx(np.mean([row["flip"] for row in metrics[:5]]))
    assert entry.psnr_mean == pytest.approx(np.mean([row["psnr_xyz"] for row in metrics[:5]]))


@pytest.mark.parametrize("field, value", [("sizes", "512,x"), ("sizes", "1"), ("weights_paths", "texture,fast")])
def test_bad_config_is_one_clear_error(field, value):
    from gratnet.errors import GratNetError

    config = BenchConfig(**{field: value})
    with pytest.raises(GratNetError, match=field.replace("_", "-")):
        config.size_list()
        config.path_list()


def _tiny_model(path: Path) -> Path:
    rng = np.random.default_rng(3)
    encoding = EncodingSpec.for_grid(33, 5, frequencies=3, t_frequencies=2)
    sizes = [encoding.features, 12, 8, 3]
    model = ModelFile(
        layer_sizes=sizes,
        weights=[(rng.standard_normal((b, a)) / np.sqrt(a)).astype(np.float32)
                 for a, b in zip(sizes[:-1], sizes[1:], strict=True)],
        biases=[(0.1 * rng.standard_normal(b)).astype(np.float32) for b in sizes[1:]],
        activation="silu", output_activation="clamp", encoding=encoding, range=RangeSpec(), scheme="simple-max",
        metadata={"volume": {"source": "generator:sinusoidal(period_um=1.6667)"}},
    )
    save_model(path, model)
    return path


def test_bench_end_to_end_writes_table_plot_and_config(tmp_path, capsys, ctx):  # ctx: skipped without GL
    pytest.importorskip("torch")
    model = _tiny_model(tmp_path / "tiny" / "model.npz")
    out = tmp_path / "bench"
    code = main(["bench", str(model), "--out", str(out), "--sizes", "16,24", "--repeats", "1", "--no-scenes",
                 "--quiet"])
    assert code == 0
    results = json.loads((out / "bench.json").read_text())
    assert {row["size"] for row in results} == {16, 24}
    for row in results:
        sizes = row["layer_sizes"]
        assert row["macs_per_pixel"] == sum(a * b for a, b in zip(sizes[:-1], sizes[1:], strict=True))
        assert row["seconds"] > 0 and row["shader_gmac_per_s"] > 0 and row["torch_cpu_gmac_per_s"] > 0
        assert row["material"] == "sinusoidal" and row["flip_mean"] is None  # no metrics.json beside it
        assert row["bytes_on_disk"] == model.stat().st_size and row["grid_values_read_per_pixel"] == 0
        assert row["bytes_gpu"] == ModelCost.of_file(model).bytes_gpu > 0
    assert (out / "pareto.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    table = (out / "bench.md").read_text()
    assert "| tiny |" in table and "| MACs/pixel | grid values read | MB on disk | MB on GPU |" in table
    assert f"| {results[0]['macs_per_pixel']} | 0 | {model.stat().st_size / 1e6:.3g} |" in table
    assert json.loads((out / "bench.config.json").read_text())["bench"]["sizes"] == "16,24"


def test_markdown_table_has_one_row_per_result():
    row = {"model": "m", "material": "cd", "parameters": 10, "macs_per_pixel": 9, "size": 512, "weights_path": "baked",
           "seconds": 0.02, "shader_gmac_per_s": 1.5, "torch_cpu_gmac_per_s": 3.0, "shader_over_torch_cpu": 0.5,
           "flip_mean": None, "flip_0_0": 0.01, "psnr_mean_db": 30.0}
    table = markdown_table([row, {**row, "size": 1001}])
    lines = table.strip().splitlines()
    assert len(lines) == 4 and lines[0].count("|") == lines[1].count("|") == lines[2].count("|")
    assert "| 1001² |" in lines[3] and "| 20 |" in lines[2] and "| — |" in lines[2]


def test_paper_size_comparison_names_the_cheapest_model_at_or_below_the_paper_sizes_error():
    from bench.slices import paper_size_comparison

    def row(model, hidden, macs, flip, material="blazed"):
        return {"model": model, "layer_sizes": [163, *hidden, 3], "macs_per_pixel": macs, "flip_mean": flip,
                "material": material}

    paper = (464, 288, 176)
    results = [row("paper", paper, 290000, 0.010), row("tiny", (21,), 4000, 0.030), row("funnel", (176,), 60000, 0.009),
               row("medium", (280,), 79000, 0.008), row("other", paper, 290000, 0.02, material="cd")]
    lines = paper_size_comparison(results, paper)
    assert len(lines) == 2
    assert "cheapest model at or below that error is funnel (60,000 MACs/pixel, 20.7% of it" in lines[0]
    assert lines[1].startswith("- cd:") and "is other" in lines[1]  # only itself matches on the cd


# --------------------------------------------------------------------------------------------------
# Mesh scenes (bench.scenes)


def test_scene_bench_times_every_combination_and_records_the_device(tmp_path, ctx):  # ctx: skipped without GL
    from bench.scenes import available_render_paths

    model = _tiny_model(tmp_path / "tiny" / "model.npz")
    out = tmp_path / "bench"
    code = main(["bench", str(model), "--out", str(out), "--no-slices", "--scene-sizes", "24x16,12x12",
                 "--spp", "1,2", "--weights-paths", "texture", "--render-paths", "all", "--repeats", "2", "--quiet"])
    assert code == 0
    lines = (out / "scenes.jsonl").read_text().splitlines()
    rows = [json.loads(line) for line in lines]
    paths = available_render_paths()
    assert len(rows) == 2 * 2 * len(paths)  # sizes × samples × render paths
    assert {(row["width"], row["height"], row["spp"]) for row in rows} == {(24, 16, 1), (24, 16, 2), (12, 12, 1),
                                                                            (12, 12, 2)}
    for row in rows:
        assert row["gl_renderer"] and row["gl_renderer"] != "unknown" and row["weights_path"] == "texture"
        assert len(row["times_s"]) == 2 and row["seconds"] > 0 and row["gpu_seconds"] > 0  # frames ≪ 4 s
        assert 0 < row["covered_pixels"] <= row["width"] * row["height"]
        # Each sample that hits the disc is one evaluation: about spp × covered pixels.
        assert row["evaluations"] == pytest.approx(row["spp"] * row["covered_pixels"], rel=0.3)
        assert {key: row[key] for key in ModelCost.of_file(model).to_dict()} == ModelCost.of_file(model).to_dict()
    table = (out / "scenes.md").read_text().splitlines()
    assert len(table) == 2 + len(rows) and "| 24×16 |" in table[2]
    assert not (out / "pareto.png").exists()  # --no-slices: no slice outputs
    assert json.loads((out / "bench.config.json").read_text())["bench"]["spp"] == "1,2"


@pytest.mark.parametrize("field, value, flag", [
    ("scene_sizes", "1920", "--scene-sizes"), ("scene_sizes", "0x5", "--scene-sizes"), ("spp", "0", "--spp"),
    ("spp", "1.5", "--spp"), ("spp", "2000", "--spp"), ("render_paths", "fast", "--render-paths"),
])
def test_bad_scene_config_is_one_clear_error(field, value, flag):
    from gratnet.errors import GratNetError

    config = BenchConfig(**{field: value})
    with pytest.raises(GratNetError, match=flag):
        config.scene_size_list()
        config.spp_list()
        config.render_path_list()


def test_a_render_path_this_build_lacks_is_refused_before_work(monkeypatch):
    import bench.scenes
    from gratnet.errors import GratNetError

    monkeypatch.setattr(bench.scenes, "available_render_paths", lambda: ("forward",))
    with pytest.raises(GratNetError, match="offers forward; not deferred"):
        BenchConfig(render_paths="forward,deferred").render_path_list()
    assert BenchConfig(render_paths="all").render_path_list() == ["forward"]


def test_torch_reference_feeds_a_feature_grid_model_its_grid_features():
    """The torch timing of a feature-grid model evaluates the same inputs as the runtime (grid features, then the
    encoding): it once fed the MLP the encoding alone, which a grid model's first layer cannot take."""
    pytest.importorskip("torch")
    from bench.slices import torch_throughput

    rng = np.random.default_rng(3)
    spec = EncodingSpec.for_grid(21, 5, 2, 1)
    grids = [rng.uniform(-1, 1, (3, nodes, nodes, 6)).astype(np.float16) for nodes in (5, 9)]
    sizes = [2 * 6 + spec.features, 8, 3]
    weights = [rng.normal(size=(b, a)).astype(np.float32) for a, b in zip(sizes[:-1], sizes[1:], strict=True)]
    model = ModelFile(sizes, weights, [np.zeros(b, np.float32) for b in sizes[1:]], "relu", "clamp", spec,
                      RangeSpec(), "simple-max", grids=grids)
    keys = np.stack([rng.uniform(-1, 1, 100), rng.uniform(-1, 1, 100), rng.uniform(-2, -1, 100)], axis=1)
    result = torch_throughput(model, keys.astype(np.float32), "cpu", repeats=1, max_seconds=1.0)
    assert result["seconds"] > 0 and result["mlp_seconds"] > 0
