"""gratnet.cost's GPU bytes are the bytes of the GL objects the renderer really creates for a model."""

from __future__ import annotations

import numpy as np
import pytest

from gratnet.cost import ModelCost
from gratnet.encoding import EncodingSpec, RangeSpec
from gratnet.modelfile import ModelFile, load_model
from tests.helpers import ASSETS


def _grid_model(features: int, dtype: str) -> ModelFile:
    """Three levels of different node counts (t too), ``features`` per node: a partial RGBA chunk when not 4k."""
    rng = np.random.default_rng(2)
    spec = EncodingSpec.for_grid(101, 5, 3, 2)
    grids = [rng.normal(size=(t_nodes, nodes, nodes, features)).astype(dtype)
             for nodes, t_nodes in ((5, 4), (9, 3), (17, 2))]
    sizes = [3 * features + spec.features, 13, 7, 3]
    weights = [(rng.normal(size=(b, a)) / np.sqrt(a)).astype(np.float32) for a, b in zip(sizes[:-1], sizes[1:],
                                                                                          strict=True)]
    return ModelFile(sizes, weights, [np.zeros(b, np.float32) for b in sizes[1:]], "silu", "clamp", spec, RangeSpec(),
                     "simple-max", grids=grids)


def _uploaded_bytes(renderer: object) -> tuple[int, int]:
    """(weight texture bytes, grid texture bytes) as read back from the renderer's own GL textures."""
    textures = renderer.material_textures()  # type: ignore[attr-defined]
    weights = sum(len(texture.read()) for texture, unit in textures if unit == 0)
    grids = sum(len(texture.read()) for texture, unit in textures if unit != 0)
    return weights, grids


@pytest.mark.parametrize(("features", "dtype"), [(6, "float16"), (4, "float32"), (3, "float16"), (8, "float32")])
def test_gpu_bytes_are_the_renderers_textures(ctx, features, dtype):
    from viewer.renderer import NetworkRenderer

    model = _grid_model(features, dtype)
    cost = ModelCost.of(model)
    renderer = NetworkRenderer(ctx, model, weights_path="texture")
    try:
        weights, grids = _uploaded_bytes(renderer)
    finally:
        renderer.release()
    assert (weights, grids) == (cost.weight_texture_bytes, cost.grid_texture_bytes)
    assert weights + grids == cost.bytes_gpu
    assert weights == renderer.packed_weights.nbytes


def test_gpu_bytes_of_a_shipped_pure_mlp_are_its_weight_texture(ctx):
    from viewer.renderer import NetworkRenderer

    model = load_model(ASSETS / "blazed" / "model.npz")
    renderer = NetworkRenderer(ctx, model, weights_path="texture")
    try:
        assert _uploaded_bytes(renderer) == (ModelCost.of(model).bytes_gpu, 0)
    finally:
        renderer.release()
