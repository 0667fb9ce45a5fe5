"""The deferred render path (viewer/deferred.py, shaders/deferred.glsl) against the forward path and numpy.

GPU tests need an OpenGL 4.3 context through EGL (Mesa llvmpipe on a CPU-only machine) and skip with the
reason when there is none. A small random net (163 → 16 → 8 → 3, ~3k MACs: every weights source compiles in
seconds, and its 18 KiB of weights fit llvmpipe's 32 KiB of compute shared memory) and tiny images.
"""

from __future__ import annotations

import json
from collections.abc import Iterator

import numpy as np
import pytest

from gratnet.cli import main
from gratnet.errors import GratNetError
from gratnet.precision import DriverErrors, assert_within
from tests.helpers import check_plane_against_numpy, random_model
from viewer.antialias import sample_offsets
from viewer.camera import Camera, Light
from viewer.meshes import Mesh, compact_disc, plane

EXPOSURE = 3.0
WEIGHTS = ("texture", "ssbo", "shared", "baked")
DISC_CAMERA = Camera(distance=0.2, azimuth_deg=-90.0, elevation_deg=50.0)
DISC_LIGHT = Light.directional(40.0, 80.0)


@pytest.fixture(scope="module")
def model():
    return random_model([163, 16, 8, 3], activation="silu", scheme="simple-max", seed=4)


def lit_relative_error(actual: np.ndarray, reference: np.ndarray) -> np.ndarray:
    """Relative error per channel on pixels at least 1e-3 of the reference's peak (FP16_RELATIVE_ERROR's)."""
    peak = reference.max()
    lit = reference.max(axis=-1) > 1e-3 * peak
    return np.abs(actual - reference)[lit] / np.maximum(np.abs(reference[lit]), 1e-3 * peak)


def path_tolerance(forward, model, mesh, camera: Camera, light: Light, size: tuple[int, int], exposure: float,
                   neighbourhood: int = 0) -> np.ndarray:
    """How far the deferred path's RGBA may differ from the forward path's on one driver, ``(H, W, 4)``: two
    programs (the G-buffer's and the forward fragment stage) compile the same key code differently, so they
    are two float32 evaluations: ``driver_bound`` at the forward key layer (16 u of key error), times exposure ·
    intensity · A (directional light), 0 for coverage. ``neighbourhood`` > 0: the largest bound within that many
    pixels (jittered samples shade up to half a pixel away from the centre's key)."""
    from gratnet.precision import driver_bound

    assert light.kind == "directional"
    _, key_a = forward.render_layers(mesh, camera, light, size, exposure)
    key = key_a[..., :3].astype(np.float64)
    bound = driver_bound(model, key[..., 0], key[..., 1], key[..., 2]).bound
    tolerance = exposure * light.intensity * key_a[..., 3:4].astype(np.float64) * bound
    for _ in range(neighbourhood):
        grown = tolerance.copy()
        for axis in (0, 1):
            for shift in (-1, 1):
                grown = np.maximum(grown, np.roll(tolerance, shift, axis=axis))
        tolerance = grown
    return np.concatenate([tolerance, np.zeros((*size[::-1], 1))], axis=-1)


@pytest.fixture(scope="module")
def scenes(ctx, model) -> Iterator[dict[str, object]]:
    """One deferred SceneRenderer per weights source of the compute pass, and a forward one (texture)."""
    from viewer.scene import SceneRenderer

    made = {weights: SceneRenderer(ctx, model, weights_path="baked" if weights == "baked" else "texture",
                                   render_path="deferred", deferred_weights=weights) for weights in WEIGHTS}
    made["forward"] = SceneRenderer(ctx, model, weights_path="texture", render_path="forward")
    made["forward_baked"] = SceneRenderer(ctx, model, weights_path="baked", render_path="forward")
    yield made
    for scene in made.values():
        scene.release()


@pytest.mark.parametrize("weights", WEIGHTS)
def test_deferred_matches_forward_and_numpy_at_every_pixel(scenes, model, weights):
    camera = Camera(distance=0.25, azimuth_deg=-70.0, elevation_deg=40.0, fov_deg=40.0)
    light = Light.point([0.0, 0.08, 0.1], intensity=0.02)
    mesh = plane(2.0)
    deferred = scenes[weights].render_rgba(mesh, camera, light, (20, 16), EXPOSURE, 1.5)
    forward = scenes["forward_baked" if weights == "baked" else "forward"].render_rgba(mesh, camera, light, (20, 16),
                                                                                      EXPOSURE, 1.5)
    assert deferred.shape == (16, 20, 4) and deferred.dtype == np.float32
    assert np.all(deferred[..., 3] == 1.0)
    # Same float32 inputs, the same GLSL: equal up to the compilers' different instruction choices.
    np.testing.assert_allclose(deferred, forward, rtol=1e-5, atol=1e-7 * np.abs(forward).max())
    # Against numpy as test_scene checks the forward path (geometry, then shading at the forward path's key
    # layer): the G-buffer's key comes from another compile of the same code, so within DriverErrors' key error.
    _, key_a = scenes["forward"].render_layers(mesh, camera, light, (20, 16), EXPOSURE, 1.5)
    check_plane_against_numpy(deferred, key_a, model, camera, light, (20, 16), EXPOSURE, DriverErrors())


@pytest.mark.parametrize("weights", ["ssbo-fp16", "shared-fp16"])
def test_fp16_weights_stay_within_the_documented_bound(ctx, model, scenes, weights):
    from viewer.deferred import FP16_RELATIVE_ERROR
    from viewer.scene import SceneRenderer

    size = (40, 32)
    reference = scenes["ssbo"].render(compact_disc(), DISC_CAMERA, DISC_LIGHT, size, EXPOSURE).astype(np.float64)
    with SceneRenderer(ctx, model, weights_path="texture", render_path="deferred", deferred_weights=weights) as scene:
        half = scene.render(compact_disc(), DISC_CAMERA, DISC_LIGHT, size, EXPOSURE).astype(np.float64)
    error = lit_relative_error(half, reference)
    assert error.size > 100
    assert 0.0 < error.max() <= FP16_RELATIVE_ERROR  # > 0: the weights really were rounded to halves
    np.testing.assert_array_equal(half == 0, reference == 0)


def test_texture_weights_beside_a_baked_network(ctx, model, scenes):
    """``deferred_weights='texture'`` in a scene whose fragment programs bake the weights: the compute pass reads
    the packed texels (the baked network's weight texture is a 1-texel placeholder: it once rendered black)."""
    from viewer.scene import SceneRenderer

    expected = scenes["texture"].render(compact_disc(), DISC_CAMERA, DISC_LIGHT, (24, 20), EXPOSURE)
    other = ctx.texture((1, 1), 4, np.zeros(4, np.float32).tobytes(), dtype="f4")
    other.use(location=0)  # unit 0 is global state: not the texture scene's weights, left by its render
    try:
        with SceneRenderer(ctx, model, weights_path="baked", render_path="deferred",
                           deferred_weights="texture") as scene:
            image = scene.render(compact_disc(), DISC_CAMERA, DISC_LIGHT, (24, 20), EXPOSURE)
    finally:
        other.release()
    assert expected.max() > 0
    np.testing.assert_array_equal(image, expected)  # the same programs, the same texels


def test_disc_with_background_and_back_faces_equals_forward_with_the_same_counters(scenes):
    for light in (DISC_LIGHT, Light.directional(100.0, 0.0)):  # lit; light below the horizon: A = 0 everywhere
        counts_forward: dict[str, int] = {}
        counts_deferred: dict[str, int] = {}
        forward = scenes["forward"].render_rgba(compact_disc(), DISC_CAMERA, light, (48, 40), EXPOSURE,
                                                statistics=counts_forward)
        deferred = scenes["ssbo"].render_rgba(compact_disc(), DISC_CAMERA, light, (48, 40), EXPOSURE,
                                              statistics=counts_deferred)
        np.testing.assert_array_equal(deferred[..., 3], forward[..., 3])  # the same pixels covered
        assert 0 < np.count_nonzero(forward[..., 3]) < 48 * 40  # disc and background (hole, corners)
        tolerance = path_tolerance(scenes["forward"], scenes["forward"].model, compact_disc(), DISC_CAMERA, light,
                                   (48, 40), EXPOSURE)
        assert_within(deferred, forward, tolerance, "deferred against forward")
        assert counts_deferred == counts_forward
        assert counts_deferred["evaluations"] == np.count_nonzero(np.any(deferred[..., :3] != 0, axis=-1))
    assert counts_deferred["evaluations"] == 0 and counts_deferred["skipped_a_zero"] == counts_deferred["fragments"]
    # Seen from below, the disc shows its back face: covered and black on both paths.
    below = Camera(distance=0.2, azimuth_deg=-90.0, elevation_deg=-50.0)
    image = scenes["texture"].render_rgba(compact_disc(), below, DISC_LIGHT, (16, 16), EXPOSURE)
    assert np.any(image[..., 3] == 1.0) and np.all(image[..., :3] == 0.0)


def test_skip_threshold_skips_the_same_pixels_and_keeps_the_display(scenes, model):
    from gratnet.bounds import DISPLAY_SKIP_THRESHOLD, BoundParameters, OutputBounds, display_skip_matrix
    from viewer.scene import SceneRenderer

    # A true bound that varies per cell: the clamp output activation keeps XYZ ≤ the range's white.
    white = np.asarray(model.range.white, dtype=np.float32)
    factor = 1.0 + np.arange(4 * 6 * 6, dtype=np.float32).reshape(4, 6, 6, 1) % 3
    bounds = OutputBounds((white * factor).astype(np.float32), BoundParameters(cells_uv=6, t_cells=4))
    # An exposure that leaves about half the disc below the display's smallest step.
    _, key_a = scenes["forward"].render_layers(compact_disc(), DISC_CAMERA, DISC_LIGHT, (40, 32), 1.0)
    a_values = key_a[..., 3][key_a[..., 3] > 0]
    peak = float(np.max(display_skip_matrix() @ white) * 2.0)
    exposure = DISPLAY_SKIP_THRESHOLD / (peak * float(np.median(a_values)))
    images, counts = {}, {}
    for name in ("forward", "ssbo"):
        scene: SceneRenderer = scenes[name]  # type: ignore[assignment]
        scene.network.set_output_bounds(bounds)
        counts[name] = {}
        images[name] = scene.render(compact_disc(), DISC_CAMERA, DISC_LIGHT, (40, 32), exposure,
                                    skip_threshold=DISPLAY_SKIP_THRESHOLD, statistics=counts[name])
    exact = scenes["ssbo"].render(compact_disc(), DISC_CAMERA, DISC_LIGHT, (40, 32), exposure)
    # The same pixels skipped, but for pixels whose skip test sits within float32 rounding of the threshold (the
    # two programs compute A apart by ulps): there the evaluated one must display black as the skipped one does.
    skipped_differently = np.any((images["ssbo"] == 0) != (images["forward"] == 0), axis=-1)
    for name in ("ssbo", "forward"):
        shown = SceneRenderer.display_srgb8(images[name])
        assert np.all(shown[skipped_differently] == 0), name
    assert skipped_differently.sum() <= 0.01 * skipped_differently.size
    assert abs(counts["ssbo"]["skipped_bound"] - counts["forward"]["skipped_bound"]) <= skipped_differently.sum()
    assert counts["ssbo"]["fragments"] == counts["forward"]["fragments"]
    assert 0 < counts["ssbo"]["skipped_bound"] < counts["ssbo"]["fragments"]
    assert counts["ssbo"]["evaluations"] == counts["ssbo"]["fragments"] - counts["ssbo"]["skipped_bound"]
    tolerance = path_tolerance(scenes["forward"], model, compact_disc(), DISC_CAMERA, DISC_LIGHT, (40, 32), exposure)
    both = ~skipped_differently[..., None]
    assert_within(np.where(both, images["ssbo"], 0.0), np.where(both, images["forward"], 0.0), tolerance[..., :3],
                  "deferred against forward")
    np.testing.assert_array_equal(SceneRenderer.display_srgb8(images["ssbo"]), SceneRenderer.display_srgb8(exact))


@pytest.mark.parametrize("chunked", [False, True])
def test_samples_average_single_jittered_renders(scenes, monkeypatch, chunked):
    import viewer.deferred

    scene = scenes["texture"]
    mesh = compact_disc()
    size = (24, 20)
    if chunked:  # two samples per G-buffer: the mean accumulates over two chunks
        monkeypatch.setattr(viewer.deferred, "CHUNK_TEXELS", 2 * size[0] * size[1])
    offsets = sample_offsets(4)
    mean = scene.render_rgba(mesh, DISC_CAMERA, DISC_LIGHT, size, EXPOSURE, offsets_px=offsets)
    singles = [scene.render_rgba(mesh, DISC_CAMERA, DISC_LIGHT, size, EXPOSURE, offsets_px=offsets[k:k + 1])
               for k in range(4)]
    expected = np.mean(np.asarray(singles, dtype=np.float64), axis=0)
    # Sample k is rasterized k·H rows up in the G-buffer: its varyings are interpolated at other window
    # coordinates, so its key vector differs in the last float32 bits (seen: 3e-5 relative in the output):
    # within the float32 bound at the keys of the pixel and its neighbours (a sample lies ≤ ½ pixel away).
    tolerance = path_tolerance(scenes["forward"], scene.model, mesh, DISC_CAMERA, DISC_LIGHT, size, EXPOSURE, 1)
    assert_within(mean, expected, tolerance, "mean of samples")
    assert np.any((mean[..., 3] > 0) & (mean[..., 3] < 1))  # edge pixels: partial coverage
    assert not np.allclose(singles[0], singles[1])  # the offsets moved the image
    # One sample at (0, 0) is the un-jittered render, bit for bit.
    centre = scene.render_rgba(mesh, DISC_CAMERA, DISC_LIGHT, size, EXPOSURE, offsets_px=np.zeros((1, 2)))
    np.testing.assert_array_equal(centre, scene.render_rgba(mesh, DISC_CAMERA, DISC_LIGHT, size, EXPOSURE))


def test_overdraw_costs_no_evaluation_on_the_deferred_path(scenes):
    from tests.helpers import two_planes

    camera = Camera(distance=0.3, azimuth_deg=0.0, elevation_deg=90.0, fov_deg=30.0)
    light = Light.directional(20.0, 0.0)
    counts: dict[str, int] = {}
    deferred = scenes["ssbo"].render_rgba(two_planes(), camera, light, (48, 48), EXPOSURE, statistics=counts)
    forward = scenes["forward"].render_rgba(two_planes(), camera, light, (48, 48), EXPOSURE)
    covered = int(np.count_nonzero(deferred[..., 3] > 0))
    assert counts["evaluations"] == counts["fragments"] == covered  # the near plane only, no pre-pass needed
    np.testing.assert_allclose(deferred, forward, rtol=1e-5, atol=1e-7 * np.abs(forward).max())


def test_empty_mesh_background_and_tiny_sizes(scenes):
    scene = scenes["ssbo"]
    base = plane(0.1)
    empty = Mesh(base.positions, base.normals, base.tangents, base.uvs, np.zeros((0, 3), dtype=np.uint32))
    counts: dict[str, int] = {}
    image = scene.render_rgba(empty, DISC_CAMERA, DISC_LIGHT, (8, 6), EXPOSURE, statistics=counts)
    assert image.shape == (6, 8, 4) and np.all(image == 0.0) and counts["evaluations"] == 0
    away = Camera(distance=0.2, azimuth_deg=-90.0, elevation_deg=50.0, target=(5.0, 0.0, 0.0))  # looks past it
    assert np.all(scene.render_rgba(compact_disc(), away, DISC_LIGHT, (8, 6), EXPOSURE) == 0.0)
    for size in ((1, 1), (3, 2), (2, 7)):
        deferred = scene.render_rgba(plane(1.0), DISC_CAMERA, DISC_LIGHT, size, EXPOSURE)
        forward = scenes["forward"].render_rgba(plane(1.0), DISC_CAMERA, DISC_LIGHT, size, EXPOSURE)
        assert deferred.shape == (size[1], size[0], 4)
        np.testing.assert_allclose(deferred, forward, rtol=1e-5, atol=1e-12)


def test_bad_render_path_weights_and_offsets_raise(ctx, model, scenes):
    from viewer.scene import SceneRenderer

    with pytest.raises(GratNetError, match="render path must be one of"):
        SceneRenderer(ctx, model, weights_path="texture", render_path="fast")
    with pytest.raises(GratNetError, match="deferred weights must be one of"):
        SceneRenderer(ctx, model, weights_path="texture", deferred_weights="cache")
    with pytest.raises(GratNetError, match="weights_path='baked'"):
        SceneRenderer(ctx, model, weights_path="texture", deferred_weights="baked")
    huge = random_model([163, 8, 3], seed=1)
    huge.weights[0][0, 0] = 1e5
    with pytest.raises(GratNetError, match="fp16"):
        SceneRenderer(ctx, huge, weights_path="texture", deferred_weights="ssbo-fp16")
    with pytest.raises(GratNetError, match="sample offsets"):
        scenes["ssbo"].render_rgba(plane(1.0), DISC_CAMERA, DISC_LIGHT, (4, 4), 1.0, offsets_px=np.zeros((2, 3)))


def test_auto_measures_once_and_caches_the_verdict(ctx, model, tmp_path, monkeypatch):
    from viewer.scene import SceneRenderer, render_path_cache_file

    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    with SceneRenderer(ctx, model, weights_path="texture") as scene:
        assert scene.render_path in ("forward", "deferred")
        reason = scene.render_path_reason
        assert reason.startswith(scene.render_path) and " ms vs " in reason
    entries = json.loads(render_path_cache_file().read_text())
    (key, entry), = entries.items()
    assert entry["path"] == scene.render_path and {"forward_ms", "deferred_ms"} <= set(entry)
    assert str(ctx.info["GL_RENDERER"]) in key and "163-16-8-3" in key
    with SceneRenderer(ctx, model, weights_path="texture") as again:
        assert again.render_path == scene.render_path and again.render_path_reason.endswith("(cached)")
    with SceneRenderer(ctx, model, weights_path="texture", render_path="forward") as forced:
        assert (forced.render_path, forced.render_path_reason) == ("forward", "requested")


def test_render_cli_render_path_flag_and_config(ctx, tmp_path, capsys):
    out = tmp_path / "disc.png"
    common = ["render", "--material", "blazed", "--mesh", "cd", "--light", "45,0", "--camera", "0.25,-90,45",
              "--exposure", "5000", "--size", "24,16", "--weights-path", "texture"]
    assert main([*common, "--render-path", "deferred", "--out", str(out)]) == 0
    config = json.loads((tmp_path / "disc.config.json").read_text())
    assert config["render"]["render_path"] == "deferred"
    assert config["render_path"] == {"path": "deferred", "reason": "requested"}
    assert main([*common, "--render-path", "fastest", "--out", str(tmp_path / "bad.png")]) == 2
    assert "render-path" in capsys.readouterr().err


def test_compute_compile_errors_name_the_real_file_and_line(ctx, tmp_path):
    from viewer.glsl import compile_compute

    (tmp_path / "helper.glsl").write_text("float helper() {\n    return undefined_name;\n}\n")
    (tmp_path / "broken.glsl").write_text('#ifdef COMPUTE_SHADER\nlayout(local_size_x = 1) in;\n'
                                          '#include "helper.glsl"\nvoid main() {}\n#endif\n')
    with pytest.raises(GratNetError, match=r"compute program 'broken'.*helper\.glsl:2:"):
        compile_compute(ctx, "broken", {}, tmp_path)
