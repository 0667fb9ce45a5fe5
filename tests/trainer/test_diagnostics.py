"""Diagnostics: the interpolation oracle, the region split and the training curves."""

from __future__ import annotations

import json

import numpy as np
import pytest

from gratnet.errors import GratNetError
from gratnet.volume import Volume, volume_axes, write_volume
from trainer.brdfslice import SliceConfig, slice_geometry
from trainer.diagnostics import (
    REGIONS,
    interpolate_volume,
    oracle_brdf_slice,
    region_errors,
    region_labels,
    specular_radius,
)
from trainer.sampling import grid_to_key, slice_t, slice_w


def _smooth(u_star: np.ndarray, v_star: np.ndarray, t: np.ndarray) -> np.ndarray:
    """A smooth XYZ function of the grid coordinates (u*, v*, t)."""
    u_star, v_star, t = np.broadcast_arrays(u_star, v_star, t)
    return np.stack([1.0 + 0.3 * np.sin(1.3 * u_star) * np.cos(0.9 * v_star) + 0.2 * t,
                     0.5 + 0.1 * u_star * v_star - 0.3 * t**2,
                     2.0 + np.cos(u_star + 0.5 * t)], axis=-1)


def _analytic_volume(scheme: str, resolution: int = 161, slices: int = 11) -> Volume:
    axis = volume_axes(resolution)
    t = slice_t(slices)
    values = _smooth(axis[None, None, :], axis[None, :, None], t[:, None, None])
    return Volume(values.astype(np.float32), {"scheme": scheme, "slice_t": [float(x) for x in t]})


@pytest.mark.parametrize("scheme", ["regular", "simple", "simple-max"])
def test_oracle_reproduces_a_smooth_function_of_the_grid_coordinates(scheme):
    volume = _analytic_volume(scheme)
    rng = np.random.default_rng(3)
    # Random reachable key vectors; the grid coordinates they map to, by the scheme's formulas (physics.md).
    u_star, v_star = rng.uniform(-1.4, 1.4, (2, 2000))
    t = rng.uniform(0, 1, 2000)
    u, v = grid_to_key(u_star, scheme), grid_to_key(v_star, scheme)
    w = -t * np.sqrt(4 - u**2 - v**2) if scheme == "simple-max" else -2 * t
    expected = _smooth(u_star, v_star, t)
    error = np.abs(interpolate_volume(volume, u, v, w) - expected).max()
    assert error < 2e-3  # trilinear: O(h²) with h = 0.025 in u*, 0.1 in t
    # At the grid's own nodes it returns the stored samples.
    key = grid_to_key(volume_axes(161), scheme)
    w_node = slice_w(scheme, 0.3, key[40:43], key[70:71])  # slice 3 of 11: t = 0.3
    nodes = interpolate_volume(volume, key[40:43], np.full(3, key[70]), w_node[0])
    np.testing.assert_allclose(nodes, volume.xyz[3, 70, 40:43], rtol=1e-6)


def test_oracle_of_a_one_slice_volume_is_bilinear():
    volume = _analytic_volume("regular", slices=1)
    u = np.array([0.013, -0.7, 1.1])
    result = interpolate_volume(volume, u, u[::-1], np.zeros(3))
    np.testing.assert_allclose(result, _smooth(u, u[::-1], np.zeros(3)), atol=2e-3)


def _synthetic_reference(config: SliceConfig) -> np.ndarray:
    """A slice with a specular spot at the specular pixel, one bright order, a faint floor, darkness elsewhere."""
    light, views, inside = slice_geometry(config)
    key = -(light + views)
    reference = np.zeros(views.shape)
    # Light at θ = 30°, φ = 0: u = −(0.5 + x) spans [−1.5, 0.5] over the view disc.
    reference[..., 1] = np.where(np.hypot(key[..., 0] + 0.4, key[..., 1]) < 0.15, 1.0, 0.0)  # an order at u = −0.4
    reference[..., 1] += np.where(np.abs(key[..., 0] + 1.0) < 0.2, 0.01, 0.0)  # a faint band: floor
    reference[..., 1] += np.where(np.hypot(key[..., 0], key[..., 1]) < 0.01, 50.0, 0.0)  # the specular peak
    reference[..., 0] = reference[..., 2] = reference[..., 1]
    return np.where(inside[..., None], reference, 0.0)


def test_regions_partition_the_disc_and_find_peak_order_floor_and_background():
    config = SliceConfig(30.0, 0.0, size=64, exposure=1.0)
    reference = _synthetic_reference(config)
    labels = region_labels(reference, config, sigma_s_um=16.25)
    _, _, inside = slice_geometry(config)
    assert set(np.unique(labels[inside])) <= set(range(len(REGIONS)))
    assert (labels[~inside] == -1).all()
    light, views, _ = slice_geometry(config)
    key = -(light + views)

    def label_at(u: float, v: float) -> str:
        index = np.unravel_index(np.argmin(np.hypot(key[..., 0] - u, key[..., 1] - v) + 9 * ~inside), inside.shape)
        return REGIONS[labels[index]]

    assert label_at(0.0, 0.0) == "specular"
    assert label_at(-0.4, 0.0) == "orders"
    assert label_at(-1.0, 0.3) == "floor"
    assert label_at(0.2, 0.5) == "dark"
    # The specular region is the disc of radius ρ around the specular key, here 3 pixels (ρ = 3 · 2/64).
    assert specular_radius(16.25, 64) == pytest.approx(6 / 64)
    errors = region_errors(reference, reference * 1.1, labels)
    assert sum(errors[name]["fraction"] for name in REGIONS) == pytest.approx(1.0)
    assert errors["orders"]["relative_l1"] == pytest.approx(0.1)
    assert errors["dark"]["relative_l1"] is None  # nothing to be relative to


@pytest.fixture(scope="module")
def tiny_run(tmp_path_factory):
    """A 1-epoch tiny training through the CLI, with the per-epoch slice FLIP, and its report."""
    from gratnet.cli import main
    from trainer.fourier import OpticsConfig
    from trainer.generators import generate
    from trainer.groundtruth import VolumeConfig, compute_volume

    folder = tmp_path_factory.mktemp("tiny")
    optics = OpticsConfig(sigma_s_um=1.5, wavelength_step_nm=100.0)
    volume = compute_volume(generate("blazed", size_um=5.0), VolumeConfig(resolution=21, slices=5,
                            sampling="simple-max"), optics, progress=False)
    write_volume(folder / "tiny.exr", volume)
    status = main(["train", str(folder / "tiny.exr"), "--out", str(folder / "run"), "--preset", "tiny",
                   "--epochs", "1", "--batch-size", "512", "--test-slices", "2", "--epoch-flip-size", "16",
                   "--size", "16", "--cache-dir", str(folder / "cache"), "--quiet"])
    assert status == 0
    return folder


def test_training_records_slice_flip_and_plots_the_curves(tiny_run):
    run = tiny_run / "run"
    history = json.loads((run / "history.json").read_text())
    assert len(history["epochs"]) == 1
    assert 0.0 <= history["epochs"][0]["slice_flip"] <= 1.0
    assert (run / "training_curves.png").stat().st_size > 1000
    report = (run / "report.md").read_text()
    assert "training_curves.png" in report and "Error by region" in report and "brdf_regions.png" in report


def test_the_training_report_states_the_models_cost(tiny_run):
    """`gratnet train` evaluates with its model file's path: the cost includes the file's bytes."""
    from gratnet.cost import ModelCost

    cost = ModelCost.of_file(tiny_run / "run" / "model.npz")
    metrics = json.loads((tiny_run / "run" / "metrics.json").read_text())
    assert metrics["cost"] == {**cost.to_dict(), "summary": cost.summary()} and cost.bytes_on_disk
    assert cost.summary() in (tiny_run / "run" / "report.md").read_text().split("## Metrics")[0]


def test_report_holds_the_oracle_and_the_regions_beside_the_network(tiny_run):
    metrics = json.loads((tiny_run / "run" / "metrics.json").read_text())
    rows = metrics["brdf_slices"]
    assert len(rows) == 5
    for row in rows:
        assert 0.0 <= row["oracle"]["flip"] <= 1.0 and row["oracle_flip"] == row["oracle"]["flip"]
        fractions = [row["regions"][name]["fraction"] for name in REGIONS]
        assert sum(fractions) == pytest.approx(1.0)


def test_further_views_are_scored_beside_the_papers_five(tiny_run):
    """`gratnet evaluate --views` adds slices, marked extra_view, with the same metrics, regions and oracle."""
    from gratnet.cli import main

    out = tiny_run / "views"
    assert main(["evaluate", str(tiny_run / "run" / "model.npz"), "--out", str(out), "--volume",
                 str(tiny_run / "tiny.exr"), "--volume-slices", "2", "--views", "45,60,500; 15,200,300", "--size", "16",
                 "--cache-dir", str(tiny_run / "cache"), "--quiet"]) == 0
    rows = json.loads((out / "metrics.json").read_text())["brdf_slices"]
    assert [row["slice"] for row in rows[5:]] == ["(45°, 60°) 500 RU", "(15°, 200°) 300 RU"]
    assert not any(row.get("extra_view") for row in rows[:5]) and all(row["extra_view"] for row in rows[5:])
    for row in rows[5:]:
        assert 0.0 <= row["flip"] <= 1.0 and 0.0 <= row["oracle_flip"] <= 1.0
    # The paper's five are the same numbers as without --views (same model, same cached ground truth).
    baseline = json.loads((tiny_run / "run" / "metrics.json").read_text())["brdf_slices"]
    assert [row["flip"] for row in rows[:5]] == [row["flip"] for row in baseline]


def test_volume_slices_beyond_the_volume_are_refused_in_one_line(tiny_run, capsys):
    from gratnet.cli import main

    status = main(["evaluate", str(tiny_run / "run" / "model.npz"), "--out", str(tiny_run / "bad"), "--volume",
                   str(tiny_run / "tiny.exr"), "--volume-slices", "4,7", "--no-brdf-slices", "--quiet"])
    assert status != 0
    assert "--volume-slices 7: the volume has 5 slices (0 to 4)" in capsys.readouterr().err


@pytest.mark.parametrize("views", ["45,60", "95,0,500", "10,0,-1", "a,b,c"])
def test_bad_views_are_refused_in_one_line(views):
    from trainer.evaluate import EvaluateConfig

    with pytest.raises(GratNetError, match="--views"):
        EvaluateConfig(views=views)


def test_oracle_runs_on_a_shipped_models_tiny_volume(tmp_path):
    """`gratnet evaluate` of a shipped model with a tiny volume of its own surface reports the oracle."""
    from gratnet.cli import main
    from gratnet.modelfile import load_model
    from tests.helpers import REPO
    from trainer.fourier import OpticsConfig
    from trainer.groundtruth import VolumeConfig, compute_volume
    from trainer.loaders import load_heightfield

    model_path = REPO / "assets" / "blazed" / "model.npz"
    metadata = load_model(model_path).metadata["volume"]
    field = load_heightfield(metadata["source"])
    # The model's own surface and scheme; a small window and coarse spectrum keep the test fast.
    optics = OpticsConfig(sigma_s_um=2.0, wavelength_step_nm=100.0)
    volume = compute_volume(field, VolumeConfig(resolution=41, slices=3, sampling=metadata["scheme"]), optics,
                            progress=False)
    write_volume(tmp_path / "blazed.exr", volume)
    status = main(["evaluate", str(model_path), "--volume", str(tmp_path / "blazed.exr"), "--volume-slices", "1",
                   "--size", "24", "--cache-dir", str(tmp_path / "cache"), "--out", str(tmp_path / "report"),
                   "--quiet"])
    assert status == 0
    metrics = json.loads((tmp_path / "report" / "metrics.json").read_text())
    assert all(0.0 <= row["oracle"]["flip"] <= 1.0 for row in metrics["brdf_slices"])
    # The shipped history beside the model is plotted.
    assert (tmp_path / "report" / "training_curves.png").is_file()
    oracle = oracle_brdf_slice(volume, SliceConfig(0.0, 0.0, size=24, exposure=2000.0))
    assert oracle.shape == (24, 24, 3) and np.isfinite(oracle).all() and oracle.max() > 0


def test_evaluate_scores_by_default_only_the_slices_the_training_held_out(tiny_run):
    """Without --volume-slices, `gratnet evaluate` scores the model's own held-out slices (here --test-slices 2),
    and none for a model trained on every slice (--split all): those would not test anything."""
    from gratnet.cli import main
    from gratnet.modelfile import load_model, save_model
    from trainer.train_cli import held_out_slices

    out = tiny_run / "default-slices"
    assert main(["evaluate", str(tiny_run / "run" / "model.npz"), "--out", str(out), "--volume",
                 str(tiny_run / "tiny.exr"), "--no-brdf-slices", "--quiet"]) == 0
    rows = json.loads((out / "metrics.json").read_text())["volume_slices"]
    assert [row["slice"].split(" (")[0] for row in rows] == ["volume slice 2"]
    model = load_model(tiny_run / "run" / "model.npz")
    model.metadata["training"]["config"]["split"] = "all"
    save_model(tiny_run / "all.npz", model)
    assert held_out_slices(model.metadata) == [] and held_out_slices({}) == [4, 7, 10]
    assert main(["evaluate", str(tiny_run / "all.npz"), "--out", str(tiny_run / "all-eval"), "--volume",
                 str(tiny_run / "tiny.exr"), "--no-brdf-slices", "--quiet"]) == 0
    assert "volume_slices" not in json.loads((tiny_run / "all-eval" / "metrics.json").read_text())
