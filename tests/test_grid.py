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
    with pytest.raises(GratNetError):
        level_resolutions(2, 1, 11)


def test_torch_grid_sample_matches_the_numpy_evaluator():
    torch.manual_seed(0)
    encoding = EncodingSpec.for_grid(21, 5, 3, 2)
    network = GridNetwork(encoding, [(3, 5, 5, 4), (5, 9, 9, 4)], [8], init=1.0, grid_dtype="float32")
    points = torch.rand(300, 3, dtype=torch.float64) * 2 - 1
    with torch.no_grad():
        expected = network.double().features(points).numpy()
    grids = network.to_model_file(encoding=encoding, range=RangeSpec(), scheme="simple-max").grids
    np.testing.assert_allclose(grid_features(grids, points.numpy()), expected, rtol=0, atol=1e-6)


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


def test_grid_training_smoke_and_torch_numpy_round_trip(tmp_path):
    from trainer.fourier import OpticsConfig
    from trainer.generators import generate
    from trainer.groundtruth import VolumeConfig, compute_volume

    optics = OpticsConfig(sigma_s_um=1.5, wavelength_step_nm=100.0)
    volume = compute_volume(generate("blazed", size_um=5.0), VolumeConfig(resolution=21, slices=5,
                            sampling="simple-max"), optics, progress=False)
    config = TrainConfig(architecture="grid", hidden="16,16", frequencies=4, t_frequencies=2, grid_levels=2,
                         grid_resolution=11, grid_t_resolution=5, epochs=2, batch_size=256, split="all",
                         grid_dtype="float32", seed=1)
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
