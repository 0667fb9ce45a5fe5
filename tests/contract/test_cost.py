"""gratnet.cost: a model's cost per pixel and in bytes, counted by hand on tiny models of known sizes."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

from gratnet.cost import ModelCost, grid_texture_bytes, weight_texture_bytes
from gratnet.encoding import EncodingSpec, RangeSpec
from gratnet.errors import GratNetError
from gratnet.modelfile import ModelFile, pack_texture, save_model
from tests.helpers import REPO

#: L = 2 frequencies for each of the four spatial groups, L_t = 1 for t: 3 + 2·(4·2 + 1) = 21 encoded features.
SPEC = EncodingSpec(frequencies=2, t_frequencies=1, scale=1.5, t_scale=1.0)


def _model(hidden: list[int], grids: list[np.ndarray] | None = None) -> ModelFile:
    grids = grids or []
    features = sum(grid.shape[-1] for grid in grids)
    sizes = [features + SPEC.features, *hidden, 3]
    rng = np.random.default_rng(1)
    weights = [rng.normal(size=(b, a)).astype(np.float32) for a, b in zip(sizes[:-1], sizes[1:], strict=True)]
    biases = [np.zeros(b, np.float32) for b in sizes[1:]]
    return ModelFile(sizes, weights, biases, "relu", "clamp", SPEC, RangeSpec(), "simple-max", grids=grids)


def test_a_pure_mlp_costs_its_layers_and_its_weight_texture():
    model = _model([5, 6])  # 21 → 5 → 6 → 3
    cost = ModelCost.of(model)
    assert cost.mlp_macs == 21 * 5 + 5 * 6 + 6 * 3 == 153
    assert cost.grid_interpolation_macs == cost.grid_values_read == cost.grid_texture_bytes == 0
    assert cost.macs_per_pixel == 153
    assert cost.encoding_terms == 2 * (4 * 2 + 1) == 18  # sin and cos of 8 spatial and 1 t frequency
    # Rows: out blocks 2 + 2 + 1 = 5; texels per row: the widest layer's 4·⌈21/4⌉ + 1 = 25; 16 bytes a texel.
    assert cost.weight_texture_bytes == 5 * 25 * 16 == cost.bytes_gpu
    assert cost.weight_texture_bytes == pack_texture(model)[0].nbytes  # the texture packing really makes
    assert cost.bytes_on_disk is None


def test_a_grid_model_counts_eight_corners_per_feature_and_its_grid_bytes():
    """Two float16 levels of 6 features (a full and a partial RGBA chunk), of different node counts along t."""
    grids = [np.zeros((3, 5, 5, 6), np.float16), np.zeros((2, 9, 9, 6), np.float16)]
    model = _model([8], grids)  # 12 grid features + 21 → 8 → 3
    cost = ModelCost.of(model)
    assert cost.mlp_macs == 33 * 8 + 8 * 3
    assert cost.grid_interpolation_macs == 8 * 12 == cost.grid_values_read
    assert cost.macs_per_pixel == 33 * 8 + 8 * 3 + 96
    assert cost.grid_texture_bytes == (3 * 5 * 5 * 6 + 2 * 9 * 9 * 6) * 2 == grid_texture_bytes(grids)
    assert cost.bytes_gpu == cost.weight_texture_bytes + cost.grid_texture_bytes
    assert cost.weight_texture_bytes == weight_texture_bytes(model.layer_sizes) == pack_texture(model)[0].nbytes
    wide = ModelCost.of(_model([8], [grid.astype(np.float32) for grid in grids]))
    assert wide.grid_texture_bytes == 2 * cost.grid_texture_bytes  # float32 grids: 4 bytes a value


def test_the_file_size_dict_and_summary(tmp_path):
    model = _model([5, 6], [np.ones((2, 3, 3, 4), np.float32)])
    path = tmp_path / "model.npz"
    save_model(path, model)
    cost = ModelCost.of_file(path)
    assert cost.bytes_on_disk == path.stat().st_size
    assert cost == ModelCost.of(model, path)
    data = cost.to_dict()
    json.dumps(data, allow_nan=False)
    assert data["macs_per_pixel"] == cost.mlp_macs + cost.grid_interpolation_macs
    assert data["grid_values_read_per_pixel"] == 32 and data["bytes_gpu"] == cost.bytes_gpu
    summary = cost.summary()
    assert summary.startswith(f"{cost.macs_per_pixel:,} MACs/pixel ({cost.mlp_macs:,} MLP + 32 grid)")
    assert f"{cost.bytes_on_disk / 1e6:.3g} MB on disk" in summary and "MB on the GPU" in summary
    assert "on disk" not in ModelCost.of(model).summary()  # no path, no file size


def test_thousands_are_grouped_in_the_summary():
    cost = ModelCost(mlp_macs=5000, grid_interpolation_macs=752, encoding_terms=160, grid_values_read=192,
                     weight_texture_bytes=100_000, grid_texture_bytes=7_000_000, bytes_on_disk=6_250_000)
    assert cost.summary() == ("5,752 MACs/pixel (5,000 MLP + 752 grid), 160 sin/cos, 192 grid values read, "
                              "6.25 MB on disk, 7.1 MB on the GPU")


@pytest.mark.parametrize("bad", ["missing", "folder"])
def test_a_path_that_is_no_file_is_one_clear_error(tmp_path, bad):
    path = tmp_path / "model.npz"
    if bad == "folder":
        path.mkdir()
    with pytest.raises(GratNetError, match="model file .*model.npz"):
        ModelCost.of(_model([4]), path)


def test_an_invalid_model_is_one_clear_error():
    model = _model([4])
    model.layer_sizes = [99, 4, 3]  # does not match its weights
    with pytest.raises(GratNetError):
        ModelCost.of(model)


def test_the_module_needs_neither_torch_nor_gl():
    code = ("import sys, gratnet.cost; bad = {'torch', 'moderngl'} & set(sys.modules); "
            "assert not bad, bad")
    subprocess.run([sys.executable, "-c", code], cwd=REPO, check=True)
