"""Feature-grid networks: trilinear interpolation (analytic), torch vs numpy, the model file, a smoke train."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch

from gratnet.encoding import EncodingSpec, RangeSpec, network_coordinates, range_inverse
from gratnet.errors import GratNetError
from gratnet.featuregrid import grid_features, level_resolutions
from gratnet.modelfile import ModelFile, evaluate_keys, load_model, save_model
from trainer.model import GridNetwork
from trainer.train import train
from trainer.train_config import TrainConfig


def _nodes(count: int) -> np.ndarray:
    return np.linspace(-1.0, 1.0, count)


def _linear_grid(shape: tuple[int, int, int], coefficients: np.ndarray) -> np.ndarray:
    """(T, R_v, R_u, C) grid whose feature k is Σ a_k·c + b_k sampled at the nodes (c_u, c_v, c_t)."""
    t_nodes, v_nodes, u_nodes = shape
    c_t, c_v, c_u = np.meshgrid(_nodes(t_nodes), _nodes(v_nodes), _nodes(u_nodes), indexing="ij")
    points = np.stack([c_u, c_v, c_t], axis=-1)
    return points @ coefficients[:3] + coefficients[3]


def test_trilinear_interpolation_reproduces_a_linear_field_exactly():
    rng = np.random.default_rng(1)
    coefficients = rng.normal(size=(4, 3))  # rows: d/dc_u, d/dc_v, d/dc_t, offset; 3 features
    grids = [_linear_grid((3, 5, 5), coefficients), _linear_grid((11, 17, 17), coefficients)]
    points = rng.uniform(-1.0, 1.0, (500, 3))
    points[:4] = [[-1, -1, -1], [1, 1, 1], [1, -1, 0.3], [0.0, 1.0, -1.0]]  # corners and faces: the last cells
    expected = points @ coefficients[:3] + coefficients[3]
    features = grid_features(grids, points)
    assert features.shape == (500, 6)
    np.testing.assert_allclose(features[:, :3], expected, rtol=0, atol=1e-12)
    np.testing.assert_allclose(features[:, 3:], expected, rtol=0, atol=1e-12)


def test_nodes_sit_at_both_ends_and_outside_points_clamp():
    rng = np.random.default_rng(2)
    grid = rng.normal(size=(4, 6, 6, 2))  # a non-linear field: node values must come back exactly
    t_index, v_index, u_index = np.meshgrid(np.arange(4), np.arange(6), np.arange(6), indexing="ij")
    points = np.stack([_nodes(6)[u_index], _nodes(6)[v_index], _nodes(4)[t_index]], axis=-1)
    np.testing.assert_allclose(grid_features([grid], points), grid, rtol=0, atol=1e-12)
    outside = np.array([[-3.0, 5.0, 2.0]])
    np.testing.assert_allclose(grid_features([grid], outside)[0], grid[-1, -1, 0], rtol=0, atol=1e-12)


def test_level_resolutions_halve_the_intervals():
    assert level_resolutions(3, 251, 11) == [(63, 11), (126, 11), (251, 11)]
    assert level_resolutions(1, 501, 6) == [(501, 6)]
    # One t count per level, and a coarser step between levels.
    assert level_resolutions(3, 1001, [11, 11, 2], step=4) == [(63, 11), (251, 11), (1001, 2)]
    for bad in ([11, 2], [11, 11, 1]):
        with pytest.raises(GratNetError, match="≥ 2 nodes along t on each"):
            level_resolutions(3, 1001, bad)
    with pytest.raises(GratNetError, match="level step ≥ 2"):
        level_resolutions(3, 1001, 11, step=1)
    # The trainer's flags reach it: --grid-level-t per level, --grid-level-step between levels.
    from trainer.train_config import TrainConfig

    config = TrainConfig(architecture="grid", grid_levels=3, grid_resolution=1001, grid_level_t="11,11,2",
                         grid_level_step=4, grid_features=2)
    assert config.grid_shapes() == [(11, 63, 63, 2), (11, 251, 251, 2), (2, 1001, 1001, 2)]
    for bad, message in (("11,x,2", "comma-separated integers"), ("11,2", "on each of its levels")):
        with pytest.raises(GratNetError, match=message):
            TrainConfig(architecture="grid", grid_levels=3, grid_level_t=bad)
    with pytest.raises(GratNetError):
        level_resolutions(2, 1, 11)


def test_the_grid_options_are_one_nested_config_under_their_flat_names():
    """TrainConfig.grid is a GridConfig; the flags (--grid-levels …), keywords (grid_levels=) and a config saved
    with flat grid_* keys (before the nesting) all reach it, and a saved config holds it as one dict."""
    import argparse
    import dataclasses

    from gratnet.config import add_arguments, changed_flags, config_to_dict, from_arguments, saved_config_dict
    from trainer.train_config import GridConfig, TrainConfig

    nested = TrainConfig(architecture="grid", grid=GridConfig(levels=2, features=4, interpolation="smoothstep"))
    assert TrainConfig(architecture="grid", grid_levels=2, grid_features=4, grid_interpolation="smoothstep") == nested
    assert nested.grid.levels == nested.grid_levels == 2 and nested.grid_shapes()[0][3] == 4
    assert dataclasses.replace(nested, grid_features=3).grid == GridConfig(levels=2, features=3,
                                                                            interpolation="smoothstep")
    parser = argparse.ArgumentParser()
    add_arguments(parser, TrainConfig)
    words = changed_flags(nested)
    assert words == ["--architecture", "grid", "--grid-levels", "2", "--grid-features", "4", "--grid-interpolation",
                     "smoothstep"]
    assert from_arguments(TrainConfig, parser.parse_args(words)) == nested
    saved = config_to_dict(nested)
    assert saved["grid"]["features"] == 4 and "grid_features" not in saved
    flat = {key: value for key, value in saved.items() if key != "grid"}
    flat.update({f"grid_{key}": value for key, value in saved["grid"].items()})
    assert TrainConfig(**saved) == TrainConfig(**flat) == nested
    assert saved_config_dict(TrainConfig, flat) == saved
    # The grid's checks are the same flags' and only for the grid architecture.
    assert TrainConfig(grid_features=99).grid.features == 99
    with pytest.raises(GratNetError, match="--grid-features must be from 1 to 16, got 99"):
        TrainConfig(architecture="grid", grid=GridConfig(features=99))
    with pytest.raises(GratNetError, match="--grid-adam-epsilon must be a positive number"):
        TrainConfig(grid_adam_epsilon=0.0)


def test_smoothstep_interpolation_is_the_smoothstep_of_the_cell_fraction():
    # One axis varies (u: a ramp 0, 1, 2, … over the nodes); between nodes i and i + 1 smoothstep gives
    # i + s²(3 − 2s) for the cell fraction s, equal to linear at the nodes and the cell midpoints, with zero
    # slope at the nodes (C¹ across the faces, where linear has a kink).
    nodes = 5
    grid = np.broadcast_to(np.arange(nodes, dtype=np.float64)[None, None, :, None], (2, 3, nodes, 1)).copy()
    s = np.linspace(0.0, 1.0, 11)
    position = 1.0 + s  # within cell [1, 2]
    c_u = position / (0.5 * (nodes - 1)) - 1.0
    points = np.stack([c_u, np.zeros_like(c_u), np.full_like(c_u, 0.3)], axis=-1)
    smooth = grid_features([grid], points, "smoothstep")[:, 0]
    np.testing.assert_allclose(smooth, 1.0 + s * s * (3 - 2 * s), atol=1e-12)
    np.testing.assert_allclose(grid_features([grid], points)[:, 0], position, atol=1e-12)
    with pytest.raises(GratNetError, match="grid interpolation must be one of linear, smoothstep"):
        grid_features([grid], points, "cubic")


@pytest.mark.parametrize(("interpolation", "features"), [("linear", 4), ("smoothstep", 4), ("linear", 6)])
def test_torch_grid_sample_matches_the_numpy_evaluator(interpolation, features):
    torch.manual_seed(0)
    encoding = EncodingSpec.for_grid(21, 5, 3, 2)
    network = GridNetwork(encoding, [(3, 5, 5, features), (5, 9, 9, features)], [8], init=1.0,
                          grid_dtype="float32", interpolation=interpolation)
    points = torch.rand(300, 3, dtype=torch.float64) * 2.2 - 1.1  # some outside [−1, 1]: clamped alike
    with torch.no_grad():
        expected = network.double().features(points).numpy()
    model = network.to_model_file(encoding=encoding, range=RangeSpec(), scheme="simple-max")
    assert model.grid_interpolation == interpolation
    np.testing.assert_allclose(grid_features(model.grids, points.numpy(), interpolation), expected, rtol=0,
                               atol=1e-6)
    if interpolation == "smoothstep":  # and the two interpolations do differ between the nodes
        assert np.abs(grid_features(model.grids, points.numpy()) - expected).max() > 1e-2


def _grid_model(dtype: str = "float16") -> ModelFile:
    rng = np.random.default_rng(3)
    encoding = EncodingSpec.for_grid(21, 5, 2, 1)
    grids = [rng.normal(size=(3, 4, 4, 2)).astype(dtype), rng.normal(size=(3, 7, 7, 2)).astype(dtype)]
    sizes = [4 + encoding.features, 6, 3]
    return ModelFile(
        layer_sizes=sizes,
        weights=[rng.normal(size=(b, a)).astype(np.float32) for a, b in zip(sizes[:-1], sizes[1:], strict=True)],
        biases=[rng.normal(size=b).astype(np.float32) for b in sizes[1:]],
        activation="silu", output_activation="clamp", encoding=encoding, range=RangeSpec(), scheme="simple-max",
        metadata={"note": "test"}, grids=grids,
    )


@pytest.mark.parametrize("dtype", ["float16", "float32"])
def test_model_file_round_trip_with_grids(tmp_path, dtype):
    model = _grid_model(dtype)
    save_model(tmp_path / "grid.npz", model)
    loaded = load_model(tmp_path / "grid.npz")
    assert loaded == model and loaded.grids[0].dtype == np.dtype(dtype)
    assert loaded.grid_bytes == sum(grid.nbytes for grid in model.grids)
    with np.load(tmp_path / "grid.npz") as archive:
        header = json.loads(str(archive["metadata_json"]))
    assert header["format_version"] == 2 and header["grid"] == {"levels": [[3, 4, 4, 2], [3, 7, 7, 2]],
                                                                "dtype": dtype}
    rng = np.random.default_rng(4)
    u, v = rng.uniform(-1.2, 1.2, (2, 50))
    w = -rng.uniform(0, 1, 50) * np.sqrt(4 - u**2 - v**2)
    np.testing.assert_array_equal(evaluate_keys(loaded, u, v, w), evaluate_keys(model, u, v, w))


def test_smoothstep_is_recorded_in_the_header_and_read_back(tmp_path):
    model = _grid_model("float16")
    model.grid_interpolation = "smoothstep"
    save_model(tmp_path / "smooth.npz", model)
    loaded = load_model(tmp_path / "smooth.npz")
    assert loaded == model and loaded.grid_interpolation == "smoothstep"
    with np.load(tmp_path / "smooth.npz") as archive:
        header = json.loads(str(archive["metadata_json"]))
    assert header["grid"]["interpolation"] == "smoothstep"
    from gratnet.modelfile import network_inputs

    points = np.array([[0.31, 0.12, -0.2], [-0.7, 0.4, 0.5]])  # between nodes: the loaded file interpolates so
    assert np.abs(network_inputs(loaded, points) - network_inputs(_grid_model("float16"), points)).max() > 1e-2
    model.grid_interpolation = "cubic"
    with pytest.raises(GratNetError, match="grid interpolation must be one of linear, smoothstep"):
        save_model(tmp_path / "bad.npz", model)


def test_pure_mlp_files_stay_version_1(tmp_path):
    model = _grid_model()
    mlp = ModelFile(layer_sizes=[model.encoding.features, 3], weights=[np.zeros((3, model.encoding.features),
                    np.float32)], biases=[np.zeros(3, np.float32)], activation="relu", output_activation="clamp",
                    encoding=model.encoding, range=model.range, scheme="simple")
    save_model(tmp_path / "mlp.npz", mlp)
    with np.load(tmp_path / "mlp.npz") as archive:
        header = json.loads(str(archive["metadata_json"]))
        assert "grid" not in header and header["format_version"] == 1 and "grid_0" not in archive.files


def test_bad_grids_are_refused_with_a_clear_message(tmp_path):
    model = _grid_model()
    model.grids[1] = model.grids[1][..., :1]
    with pytest.raises(GratNetError, match="every level must match"):
        save_model(tmp_path / "bad.npz", model)
    model = _grid_model()
    model.grids[0] = model.grids[0].astype(np.float64)
    with pytest.raises(GratNetError, match="float16 or float32"):
        save_model(tmp_path / "bad.npz", model)
    model = _grid_model()
    model.layer_sizes = [model.encoding.features, 6, 3]
    with pytest.raises(GratNetError, match="grid features"):
        save_model(tmp_path / "bad.npz", model)
    # A file whose header disagrees with its grid arrays.
    save_model(tmp_path / "good.npz", _grid_model())
    with np.load(tmp_path / "good.npz") as archive:
        arrays = {name: archive[name] for name in archive.files}
    header = json.loads(str(arrays["metadata_json"]))
    header["grid"]["levels"][1] = [3, 8, 8, 2]
    arrays["metadata_json"] = np.array(json.dumps(header))
    np.savez(tmp_path / "corrupt.npz", **arrays)
    with pytest.raises(GratNetError, match="do not match the header's grid"):
        load_model(tmp_path / "corrupt.npz")


def test_up_to_16_features_per_level_and_17_refused(tmp_path):
    """C = 16 (four RGBA textures per level in the shader) saves and loads; C = 17 is refused with the limit named,
    by the model-file writer and loader and by the trainer's --grid-features."""
    rng = np.random.default_rng(7)
    encoding = EncodingSpec.for_grid(21, 5, 2, 1)

    def model_with(features: int) -> ModelFile:
        sizes = [2 * features + encoding.features, 3]
        return ModelFile(sizes, [rng.normal(size=(3, sizes[0])).astype(np.float32)], [np.zeros(3, np.float32)],
                         "relu", "clamp", encoding, RangeSpec(), "simple-max",
                         grids=[rng.normal(size=(2, n, n, features)).astype(np.float16) for n in (3, 5)])

    save_model(tmp_path / "sixteen.npz", model_with(16))
    assert [grid.shape for grid in load_model(tmp_path / "sixteen.npz").grids] == [(2, 3, 3, 16), (2, 5, 5, 16)]
    message = r"1 ≤ C ≤ 16 features \(the shader reads a level as ceil\(C/4\) RGBA textures\)"
    with pytest.raises(GratNetError, match=message):
        save_model(tmp_path / "seventeen.npz", model_with(17))
    # A file with 17 features per level (written past the writer's check): the loader refuses it alike.
    with np.load(tmp_path / "sixteen.npz") as archive:
        arrays = {name: archive[name] for name in archive.files}
    header = json.loads(str(arrays["metadata_json"]))
    for level, nodes in enumerate((3, 5)):
        arrays[f"grid_{level}"] = np.zeros((2, nodes, nodes, 17), np.float16)
        header["grid"]["levels"][level] = [2, nodes, nodes, 17]
    arrays["metadata_json"] = np.array(json.dumps(header))
    np.savez(tmp_path / "seventeen.npz", **arrays)
    with pytest.raises(GratNetError, match=message):
        load_model(tmp_path / "seventeen.npz")
    assert TrainConfig(architecture="grid", grid_features=16).grid_shapes()[0][3] == 16
    for bad in (0, 17):
        with pytest.raises(GratNetError, match=f"--grid-features must be from 1 to 16, got {bad}"):
            TrainConfig(architecture="grid", grid_features=bad)


def test_grid_training_smoke_and_torch_numpy_round_trip(tmp_path):
    from trainer.fourier import OpticsConfig
    from trainer.generators import generate
    from trainer.groundtruth import VolumeConfig, compute_volume

    optics = OpticsConfig(sigma_s_um=1.5, wavelength_step_nm=100.0)
    volume = compute_volume(generate("blazed", size_um=5.0), VolumeConfig(resolution=21, slices=5,
                            sampling="simple-max"), optics, progress=False)
    config = TrainConfig(architecture="grid", hidden="16,16", frequencies=4, t_frequencies=2, grid_levels=2,
                         grid_resolution=11, grid_t_resolution=5, grid_features=4, epochs=2, batch_size=256,
                         split="all", grid_dtype="float32", seed=1)
    model, model_file, history = train(volume, config, tmp_path, progress=False)
    losses = [record["train_loss"] for record in history["epochs"]]
    assert all(np.isfinite(losses)) and losses[-1] < losses[0]
    assert history["grid_bytes"] == (5 * 6 * 6 + 5 * 11 * 11) * 4 * 4 and history["parameters"] == model.parameter_count
    loaded = load_model(tmp_path / "model.npz")
    assert [grid.shape for grid in loaded.grids] == [(5, 6, 6, 4), (5, 11, 11, 4)]
    rng = np.random.default_rng(0)
    u, v = rng.uniform(-1.3, 1.3, (2, 64))
    w = -rng.uniform(0, 1, 64) * np.sqrt(4 - u**2 - v**2)
    with torch.no_grad():
        coordinates = torch.from_numpy(network_coordinates(u, v, w, "simple-max")).float()
        expected = range_inverse(model.predict(coordinates).double(), model_file.range).numpy()
    np.testing.assert_allclose(evaluate_keys(loaded, u, v, w), expected, rtol=2e-4, atol=1e-12)
