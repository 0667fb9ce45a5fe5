"""Feature-grid networks on the GPU: shaders/featuregrid.glsl (manual and hardware filtering, the baked and
deferred paths) against the numpy evaluator. The grids' interpolation, model file and training:
contract/test_grid.py."""

from __future__ import annotations

import numpy as np
import pytest

from gratnet.encoding import EncodingSpec, RangeSpec, network_coordinates
from gratnet.errors import GratNetError
from gratnet.modelfile import ModelFile, evaluate_keys
from gratnet.precision import OWN_KEYS, DriverErrors, assert_within, driver_bound
from tests.helpers import random_grid_model

# ------------------------------------------------------------------------------------------------
# GLSL (shaders/featuregrid.glsl) against the numpy evaluator


#: A texture unit's filtered lookups (gratnet.precision.HARDWARE_FILTER) at the shader's own float32 keys.
HARDWARE_FILTER_OWN_KEYS = DriverErrors(key_error=0.0, grid_texel_error=2.0**-8)


def _keys(count: int = 400) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(9)
    u, v = rng.uniform(-1.4, 1.4, (2, count))
    w = -rng.uniform(0, 1, count) * np.sqrt(np.clip(4 - u**2 - v**2, 0, None))
    keys = np.stack([u, v, w], -1).astype(np.float32).astype(np.float64)  # the GPU gets float32 keys
    keys[:3] = [[0.0, 0.0, 0.0], [0.0, 0.0, -2.0], [2.0, 0.0, 0.0]]  # grid corners and faces
    return keys[:, 0], keys[:, 1], keys[:, 2]


@pytest.mark.parametrize(("features", "levels", "dtype", "interpolation"),
                         [(2, 3, "float16", "linear"), (4, 2, "float32", "linear"), (3, 1, "float16", "linear"),
                          (2, 3, "float16", "smoothstep"), (4, 1, "float32", "smoothstep"),
                          # Two RGBA textures per level (featuregrid.glsl's chunks): full, and a partial last one.
                          (6, 3, "float16", "linear"), (5, 2, "float32", "smoothstep"), (8, 1, "float16", "linear")])
@pytest.mark.parametrize("grid_filter", ["manual", "hardware"])
def test_gpu_grid_model_matches_numpy(ctx, features, levels, dtype, interpolation, grid_filter):
    from viewer.renderer import NetworkRenderer

    model = random_grid_model(features, levels, dtype)
    model.grid_interpolation = interpolation
    u, v, w = _keys()
    expected = evaluate_keys(model, u, v, w)
    renderer = NetworkRenderer(ctx, model, weights_path="texture", grid_filter=grid_filter)
    try:
        assert renderer.weights_path == "texture"
        actual = renderer.evaluate_keys(u, v, w)
    finally:
        renderer.release()
    assert np.all(expected.max(axis=0) > 0)
    # float32 in the shader at the same float32 keys (docs/physics.md, "Float32 error budget"); the hardware
    # filter may quantise its weights (8 bits on NVIDIA: up to 0.31 % relative measured on an H100).
    bound = driver_bound(model, u, v, w, OWN_KEYS if grid_filter == "manual" else HARDWARE_FILTER_OWN_KEYS)
    np.testing.assert_allclose(bound.xyz, expected, rtol=1e-12)
    assert_within(actual, expected, bound.bound, f"XYZ values ({grid_filter} filter)")


@pytest.mark.parametrize(("features", "picked"), [(4, (4, 5, 0)),
                                                 # level 1 features 5, 0 and level 0 feature 4: second textures
                                                 (6, (11, 6, 4)),
                                                 # level 1 features 15 (fourth texture), 8 (third), level 0 feature 13
                                                 (16, (31, 24, 13)),
                                                 # 12 features: level 1 feature 11 and 4, level 0 feature 9 (third)
                                                 (12, (23, 16, 9))])
def test_gpu_grid_features_alone_match_numpy(ctx, features, picked):
    """A network that outputs three grid features: the interpolation itself, without the MLP's mixing."""
    from gratnet.modelfile import mlp_forward, network_inputs
    from viewer.renderer import NetworkRenderer

    rng = np.random.default_rng(6)
    spec = EncodingSpec.for_grid(101, 5, 4, 2)
    grids = [rng.uniform(0, 1, (5, nodes, nodes, features)).astype(np.float16) for nodes in (7, 33)]
    weights = np.zeros((3, 2 * features + spec.features), np.float32)
    weights[[0, 1, 2], list(picked)] = 1.0  # input column = level · C + feature
    model = ModelFile([2 * features + spec.features, 3], [weights], [np.zeros(3, np.float32)], "relu", "none", spec,
                      RangeSpec(), "simple-max", grids=grids)
    u, v, w = _keys(2000)
    for interpolation in ("linear", "smoothstep"):
        model.grid_interpolation = interpolation
        expected = mlp_forward(model, network_inputs(model, network_coordinates(u, v, w, "simple-max")))
        for grid_filter in ("manual", "hardware"):
            renderer = NetworkRenderer(ctx, model, weights_path="texture", grid_filter=grid_filter)
            try:
                actual = renderer.network_outputs(u, v, w)
            finally:
                renderer.release()
            # GPUs may filter with 8-bit weights: 2⁻⁸ texel × the node differences, up to 1 here (3 axes).
            bound = driver_bound(model, u, v, w, OWN_KEYS if grid_filter == "manual" else HARDWARE_FILTER_OWN_KEYS)
            assert_within(actual, expected, bound.outputs_bound, f"grid features ({interpolation}, {grid_filter})")


@pytest.mark.parametrize(("features", "levels"), [(4, 2), (6, 3)])
def test_gpu_grid_brdf_slice_matches_numpy(ctx, features, levels):
    from gratnet.brdf import a_term, direction, slice_view_directions
    from viewer.renderer import NetworkRenderer

    size, theta, phi, exposure = 24, 30.0, 40.0, 2.0
    model = random_grid_model(features, levels, "float16")
    views, inside = slice_view_directions(size)
    light = direction(theta, phi)
    key = -(light + views)
    xyz = evaluate_keys(model, key[..., 0], key[..., 1], key[..., 2]) * inside[..., None]
    expected = exposure * a_term(light, views, 1.5)[..., None] * xyz
    renderer = NetworkRenderer(ctx, model, weights_path="texture")
    try:
        exposed = renderer.render_brdf_slice(theta, phi, size, exposure, 1.5)
    finally:
        renderer.release()
    np.testing.assert_allclose(exposed, expected, rtol=1e-4, atol=1e-3 * float(np.abs(expected).max()))


@pytest.mark.parametrize(("features", "levels", "interpolation", "diagonals"),
                         [(3, 2, "linear", True), (3, 2, "smoothstep", True), (6, 3, "linear", True),
                          (5, 2, "smoothstep", True), (4, 2, "smoothstep", False)])
def test_baked_path_evaluates_grid_models_like_numpy(ctx, features, levels, interpolation, diagonals):
    """The baked MLP reads the grid features (featuregrid.glsl, included before mlp.glsl) as its first inputs:
    the same outputs as numpy. Only when asked for: auto keeps grid models on the texture path."""
    from viewer.renderer import NetworkRenderer, choose_weights_path

    model = random_grid_model(features, levels, "float16", diagonals=diagonals)
    model.grid_interpolation = interpolation
    assert choose_weights_path(ctx, model, "auto") == "texture"
    assert choose_weights_path(ctx, model, "baked") == "baked"
    u, v, w = _keys()
    expected = evaluate_keys(model, u, v, w)
    last = levels * -(-features // 4) - 1  # the last chunk of the last level
    with NetworkRenderer(ctx, model, weights_path="baked") as renderer:
        assert renderer.weights_path == "baked" and f"g_grid_features[{last}]" in renderer.baked_source
        assert f"g_grid_features[{last + 1}]" not in renderer.baked_source
        baked = renderer.evaluate_keys(u, v, w)
    np.testing.assert_allclose(baked, expected, rtol=1e-4, atol=1e-12)
    with pytest.raises(GratNetError, match="grid filter"):
        NetworkRenderer(ctx, model, grid_filter="cubic")


@pytest.mark.parametrize(("features", "levels", "interpolation"),
                         [(4, 2, "linear"), (4, 2, "smoothstep"), (6, 3, "linear"), (5, 2, "smoothstep")])
def test_deferred_path_renders_grid_models_like_the_forward_path(ctx, features, levels, interpolation):
    """The deferred compute pass fetches the same grids (mlp.glsl includes featuregrid.glsl) for every weights
    source it reads the MLP from, and equals the forward path at every pixel of a disc scene."""
    from viewer.camera import Camera, Light
    from viewer.meshes import compact_disc
    from viewer.scene import SceneRenderer

    model = random_grid_model(features, levels, "float16")
    model.grid_interpolation = interpolation
    mesh, camera, light = compact_disc(segments=32), Camera(0.2, -90.0, 50.0), Light.directional(30.0, 180.0)
    forward = SceneRenderer(ctx, model, weights_path="texture", render_path="forward")
    try:
        assert forward.network.weights_path == "texture"
        expected = forward.render_rgba(mesh, camera, light, (24, 18), 10.0, 1.5)
    finally:
        forward.release()
    assert np.all(np.isfinite(expected)) and expected[..., :3].max() > 0
    for weights in ("texture", "ssbo", "baked"):
        deferred = SceneRenderer(ctx, model, weights_path="baked" if weights == "baked" else "texture",
                                 render_path="deferred", deferred_weights=weights)
        try:
            assert deferred.render_path == "deferred"
            actual = deferred.render_rgba(mesh, camera, light, (24, 18), 10.0, 1.5)
        finally:
            deferred.release()
        np.testing.assert_allclose(actual, expected, rtol=1e-5, atol=1e-6 * np.abs(expected).max())


def test_grid_textures_beyond_the_context_are_refused(ctx):
    """A model whose levels × ceil(C/4) grid textures do not fit the context's texture units is refused with a
    clear message before any shader is compiled (here: 2 textures per level, one level too many)."""
    from viewer.renderer import NetworkRenderer, check_grid_texture_units

    per_stage = min(int(ctx.info["GL_MAX_TEXTURE_IMAGE_UNITS"]), int(ctx.info["GL_MAX_COMPUTE_TEXTURE_IMAGE_UNITS"]))
    levels = (per_stage - 4) // 2 + 1  # 4: the other samplers a program may have
    rng = np.random.default_rng(8)
    spec = EncodingSpec.for_grid(21, 5, 2, 1)
    sizes = [levels * 6 + spec.features, 3]
    model = ModelFile(sizes, [rng.normal(size=(3, sizes[0])).astype(np.float32)], [np.zeros(3, np.float32)],
                      "relu", "clamp", spec, RangeSpec(), "simple-max",
                      grids=[rng.normal(size=(2, 3, 3, 6)).astype(np.float16) for _ in range(levels)])
    with pytest.raises(GratNetError, match=f"needs {2 * levels} grid textures .* use fewer levels or features"):
        NetworkRenderer(ctx, model, weights_path="texture")
    # The limits themselves, and GL 4.3's minima where the context does not say (16 samplers per stage).
    limits = {"GL_MAX_COMBINED_TEXTURE_IMAGE_UNITS": 96, "GL_MAX_TEXTURE_IMAGE_UNITS": 32,
              "GL_MAX_COMPUTE_TEXTURE_IMAGE_UNITS": 32}
    check_grid_texture_units(limits, 28)
    for info, textures in ((limits, 29), ({**limits, "GL_MAX_COMBINED_TEXTURE_IMAGE_UNITS": 20}, 13), ({}, 13)):
        with pytest.raises(GratNetError, match=f"needs {textures} grid textures"):
            check_grid_texture_units(info, textures)
    check_grid_texture_units({}, 12)
