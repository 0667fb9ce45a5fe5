"""The environment light of the GL runtime (issue 43; shaders/environment.glsl, viewer/environment_light.py).

Analytic and independent checks first: a far camera with a tiny field of view sees a plane under one view
direction, so every covered pixel estimates the same integral ∫ A · XYZ · L dωi (physics.md eq. 9) and their mean
is a Monte Carlo estimate over pixels × samples; numpy integrates the same by dense quadrature over the hemisphere
(the model by gratnet.modelfile, the map by gratnet.environment). Then the consistency the contract states: a
small bright disc of environment lights a pixel as a directional light of the same irradiance. A small random
network keeps the quadrature cheap; the GL context is Mesa llvmpipe on a CPU-only machine.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from gratnet.environment import Environment, texel_coordinates
from gratnet.errors import GratNetError
from tests.helpers import covered_mean, hemisphere_integral, random_model, smooth_random_model, structured_map
from viewer.camera import Camera, Light, world_direction
from viewer.meshes import compact_disc, plane
from viewer.scene import SceneRenderer

ELEVATION, AZIMUTH = 50.0, -60.0
FAR = Camera(200.0, AZIMUTH, ELEVATION, fov_deg=0.037)  # ωo the same at every pixel (to 1e-4 rad)
SIZE = (32, 32)
NO_LIGHT = Light.directional(0.0, 0.0, 0.0)
# The deferred path against the forward one, per pixel, as a share of the picture's peak: sample k is rasterized
# k·H rows up in the stacked G-buffer, so its interpolated point and frame differ in the last float32 bits
# (tests/runtime/test_deferred.py), which the grating's fine structure amplifies; measured ≤ 6e-5 on llvmpipe. A
# wrong pass index or pixel key differs by the noise itself, tens of % of the peak.
PATH_TOLERANCE = 2e-4


@pytest.fixture(scope="module")
def model():
    return random_model([163, 16, 3], seed=3)


@pytest.fixture(scope="module")
def scene(ctx, model):
    with SceneRenderer(ctx, model, render_path="forward") as renderer:
        yield renderer


@pytest.mark.parametrize("sampling", ["mis", "light", "material", "resampled"])
def test_environment_matches_quadrature_over_the_hemisphere(scene, model, sampling):
    environment = Environment("test", structured_map(), rotation_degrees=30.0, scale=1.0, source="test")
    rgba = scene.render_rgba(plane(), FAR, NO_LIGHT, SIZE, 1.0, 1.5, samples=64, environment=environment, seed=1,
                             sampling=sampling)
    mean, error = covered_mean(rgba)
    expected = hemisphere_integral(model, environment, world_direction(90.0 - ELEVATION, AZIMUTH))
    assert np.all(np.abs(mean - expected) <= 4.0 * error + 2e-3 * np.abs(expected)), (mean, error, expected)
    assert np.all(error < 0.05 * np.abs(expected))  # the estimate is informative: a few % per channel


@pytest.fixture(scope="module")
def smooth_scene(ctx):
    """A random network of low frequencies only: A · XYZ is smooth across a small disc."""
    with SceneRenderer(ctx, smooth_random_model(), render_path="forward") as renderer:
        yield renderer


def test_small_bright_disc_lights_as_a_directional_light(smooth_scene):
    """A disc of 0.5° radius around (θ, φ) = (35°, 40°) of constant white radiance L: its irradiance on a plane
    facing it is E = ∫ L dω (from the map itself); the environment render equals the render under a directional
    light of intensity E from the disc's centre, within the second-order change of A · XYZ across the disc."""
    scene = smooth_scene
    height = 1024
    centre = world_direction(35.0, 40.0)
    probe = Environment("probe", np.ones((height, 2 * height, 3), np.float32))
    texels = probe.directions(*texel_coordinates(height, 2 * height))
    inside = np.degrees(np.arccos(np.clip(texels @ centre, -1.0, 1.0))) < 0.5
    radiance = np.repeat(np.where(inside, 1000.0, 0.0)[..., None], 3, axis=-1).astype(np.float32)
    environment = Environment("disc", radiance, 0.0, 1.0, "test")
    # E = ∫ L dω by quadrature of the map's own (bilinear) radiance around the disc.
    steps = 400
    local_t = np.radians(1.0) * (np.arange(steps) + 0.5) / steps
    local_p = 2 * np.pi * (np.arange(steps) + 0.5) / steps
    lt, lp = np.meshgrid(local_t, local_p, indexing="ij")
    axis_x = np.cross([0.0, 0.0, 1.0], centre)
    axis_x /= np.linalg.norm(axis_x)
    axis_y = np.cross(centre, axis_x)
    directions = (np.cos(lt)[..., None] * centre + (np.sin(lt) * np.cos(lp))[..., None] * axis_x
                  + (np.sin(lt) * np.sin(lp))[..., None] * axis_y)
    luminance = environment.radiance(directions.reshape(-1, 3)).reshape(*lt.shape, 3)[..., 1]
    irradiance = float(np.sum(luminance * np.sin(lt)) * (np.radians(1.0) / steps) * (2 * np.pi / steps))
    camera = Camera(200.0, -90.0, 60.0, fov_deg=0.037)
    light = Light("directional", tuple(float(c) for c in centre), irradiance)
    expected = scene.render_rgba(plane(), camera, light, SIZE, 1.0, 1.5)
    rgba = scene.render_rgba(plane(), camera, NO_LIGHT, SIZE, 1.0, 1.5, samples=64, environment=environment, seed=2)
    mean, error = covered_mean(rgba)
    wanted = expected[..., :3][expected[..., 3] == 1.0].mean(axis=0)
    assert np.all(np.abs(mean - wanted) <= 4.0 * error + 1e-3 * wanted), (mean, error, wanted)
    assert np.all(error < 0.01 * wanted)


def test_samples_are_passes_of_one_estimator(scene):
    """N samples rendered at once equal the mean of the same N passes rendered one at a time (progressive
    accumulation), and a seed gives the same picture every time."""
    environment = Environment("test", structured_map(32), 0.0, 1.0, "test")
    together = scene.render_rgba(plane(), FAR, NO_LIGHT, SIZE, 1.0, 1.5, samples=4, environment=environment, seed=5)
    apart = [scene.render_rgba(plane(), FAR, NO_LIGHT, SIZE, 1.0, 1.5, first_sample=k, environment=environment,
                               seed=5) for k in range(4)]
    np.testing.assert_allclose(together, np.mean(apart, axis=0), rtol=1e-5, atol=1e-6)
    again = scene.render_rgba(plane(), FAR, NO_LIGHT, SIZE, 1.0, 1.5, samples=4, environment=environment, seed=5)
    np.testing.assert_array_equal(together, again)
    other = scene.render_rgba(plane(), FAR, NO_LIGHT, SIZE, 1.0, 1.5, samples=4, environment=environment, seed=6)
    assert not np.array_equal(together, other)


def test_bands_with_their_pixel_origin_make_the_whole_picture(scene):
    """A picture drawn as bands of rows (the viewer's refinement: viewer.scheduling.BandCamera, each band its own
    render target) keys its light samples by the whole picture's pixels: the bands equal the whole render."""
    from viewer.scheduling import BandCamera

    environment = Environment("test", structured_map(32), 0.0, 1.0, "test")
    camera = Camera(0.25, -60.0, 50.0)
    width, height = 24, 20
    whole = scene.render_rgba(plane(), camera, NO_LIGHT, (width, height), 1.0, 1.5, samples=3, environment=environment,
                              seed=4)
    bands = []
    for row0, row1 in ((0, 7), (7, 15), (15, 20)):
        band = BandCamera(camera.distance, camera.azimuth_deg, camera.elevation_deg, camera.target, camera.fov_deg,
                          camera.near, camera.far, full_aspect=width / height, height=height, row0=row0, row1=row1)
        bands.append(scene.render_rgba(plane(), band, NO_LIGHT, (width, row1 - row0), 1.0, 1.5, samples=3,
                                       environment=environment, seed=4, pixel_origin=(0, height - row1)))
    together = np.concatenate(bands, axis=0)
    assert np.abs(whole[..., :3]).max() > 0
    # A band's projection moves each pixel's point and frame in the last float32 bits, which resampling's sum of
    # candidate weights amplifies to ~1e-4 (measured ≤ 1e-4); a pixel keyed wrongly differs by the noise itself.
    np.testing.assert_allclose(together, whole, rtol=5e-4, atol=1e-6 * float(np.abs(whole).max()))


def test_delta_light_takes_its_turn(scene, model):
    """With a directional light of intensity > 0 beside the environment, every three passes hold one of each
    strategy per pixel: the mean is the light's render plus the environment's integral."""
    environment = Environment("test", structured_map(), 0.0, 1.0, "test")
    light = Light.directional(30.0, 120.0, 2.0)
    alone = scene.render_rgba(plane(), FAR, light, SIZE, 1.0, 1.5)
    both = scene.render_rgba(plane(), FAR, light, SIZE, 1.0, 1.5, samples=48, environment=environment, seed=3)
    mean, error = covered_mean(both)
    expected = hemisphere_integral(model, environment, world_direction(90.0 - ELEVATION, AZIMUTH))
    expected = expected + alone[..., :3][alone[..., 3] == 1.0].mean(axis=0)
    assert np.all(np.abs(mean - expected) <= 4.0 * error + 2e-3 * np.abs(expected)), (mean, error, expected)


def assert_paths_agree(deferred: np.ndarray, forward: np.ndarray, share: float = PATH_TOLERANCE) -> None:
    """Coverage equal (to the rounding of the mean: k · (1/N) against k / N), exposed XYZ within ``share`` of the
    forward picture's peak at every pixel."""
    np.testing.assert_allclose(deferred[..., 3], forward[..., 3], rtol=0, atol=1e-6)
    peak = float(np.abs(forward[..., :3]).max())
    assert peak > 0
    np.testing.assert_allclose(deferred[..., :3], forward[..., :3], rtol=0, atol=share * peak)


@pytest.mark.parametrize("weights", ["texture", "ssbo"])
def test_the_deferred_path_gives_the_forward_estimate(ctx, model, weights, monkeypatch):
    """An environment and a directional light on the disc (background, edges, a spread of frames): the deferred
    render of passes 3 … 7 equals the forward one per pixel, also when the samples take several G-buffer chunks
    (each chunk's passes numbered on), and a one-sample render (rasterized as the forward path's) more tightly."""
    import viewer.deferred

    environment = Environment("test", structured_map(32), 30.0, 1.0, "test")
    light = Light.directional(30.0, 120.0, 2.0)
    camera, size = Camera(0.2, -90.0, 50.0), (24, 20)
    with SceneRenderer(ctx, model, weights_path="texture", render_path="forward", deferred_weights=weights) as scene:
        def render(path: str, samples: int = 5, first_sample: int = 3) -> np.ndarray:
            return scene.render_rgba(compact_disc(), camera, light, size, 1.0, 1.5, samples=samples,
                                     first_sample=first_sample, environment=environment, seed=5, render_path=path)

        forward = render("forward")
        assert np.any((forward[..., 3] > 0) & (forward[..., 3] < 1))  # edge pixels: the samples moved
        assert_paths_agree(render("deferred"), forward)
        monkeypatch.setattr(viewer.deferred, "CHUNK_TEXELS", 2 * size[0] * size[1])  # chunks of 2, 2 and 1
        assert_paths_agree(render("deferred"), forward)
        single = render("forward", 1, 4)
        assert not np.allclose(single, render("forward", 1, 5))  # each pass its own estimate: the index matters
        assert_paths_agree(render("deferred", 1, 4), single, 1e-5)


def test_deferred_bands_with_their_pixel_origin_make_the_forward_picture(ctx, model):
    """Bands of rows on the deferred path (each its own render, keyed by its pixel_origin) equal the whole
    picture on the forward path."""
    from viewer.scheduling import BandCamera

    environment = Environment("test", structured_map(32), 0.0, 1.0, "test")
    camera = Camera(0.25, -60.0, 50.0)
    width, height = 24, 20
    with SceneRenderer(ctx, model, weights_path="texture", render_path="deferred",
                       deferred_weights="texture") as scene:
        # A scene asked for one path (as the viewer's window is) leaves sampled light forward; a render may ask.
        assert scene.path_for_render(True)[0] == "forward" and scene.path_for_render(False)[0] == "deferred"
        assert scene.path_for_render(True, "deferred") == ("deferred", "requested")
    with SceneRenderer(ctx, model, weights_path="texture") as automatic:  # auto: deferred on a CPU rasterizer
        from viewer.renderer import is_software_rasterizer

        assert automatic.path_for_render(True)[0] == ("deferred" if is_software_rasterizer(ctx) else "forward")
    with SceneRenderer(ctx, model, weights_path="texture", render_path="deferred",
                       deferred_weights="texture") as scene:
        whole = scene.render_rgba(plane(), camera, NO_LIGHT, (width, height), 1.0, 1.5, samples=3, first_sample=2,
                                  environment=environment, seed=4)
        bands = []
        for row0, row1 in ((0, 7), (7, 15), (15, 20)):
            band = BandCamera(camera.distance, camera.azimuth_deg, camera.elevation_deg, camera.target,
                              camera.fov_deg, camera.near, camera.far, full_aspect=width / height, height=height,
                              row0=row0, row1=row1)
            bands.append(scene.render_rgba(plane(), band, NO_LIGHT, (width, row1 - row0), 1.0, 1.5, samples=3,
                                           first_sample=2, environment=environment, seed=4,
                                           pixel_origin=(0, height - row1), render_path="deferred"))
    assert_paths_agree(np.concatenate(bands, axis=0), whole)


def test_environment_refuses_bad_seeds_and_sampling(scene):
    environment = Environment("test", structured_map(16), 0.0, 1.0, "test")
    with pytest.raises(GratNetError, match="seed"):
        scene.render_rgba(plane(), FAR, NO_LIGHT, SIZE, environment=environment, seed=-1)
    with pytest.raises(GratNetError, match="environment sampling"):
        scene.render_rgba(plane(), FAR, NO_LIGHT, SIZE, environment=environment, sampling="uniform")


def test_gl_and_mitsuba_integrate_the_same_environment(tmp_path, scene, model):
    """The plane under the structured map, path-traced by Mitsuba 3 (``direct`` integrator, its envmap emitter and
    the plugin's table sampler, orthographic camera along the far camera's axis) and rendered by GL: the means over
    the covered pixels agree within four combined standard errors (physics.md eq. 9: one integral, two renderers)."""
    pytest.importorskip("mitsuba", reason="the mitsuba extra is not installed")
    from gratnet.modelfile import save_model
    from mitsuba_plugin import scene as mitsuba_scene
    from mitsuba_plugin.runtime import llvm_usable, set_variant
    from mitsuba_plugin.shading import xyz_to_linear_srgb_matrix as row_matrix

    variant = "llvm_ad_rgb" if llvm_usable() else "scalar_rgb"
    mi = set_variant(variant)
    path = tmp_path / "model.npz"
    save_model(path, model)
    environment = Environment("test", structured_map(), rotation_degrees=30.0, scale=1.0, source="test")
    size, spp = (16, 64) if variant == "llvm_ad_rgb" else (8, 32)
    mitsuba = mitsuba_scene.build_scene(
        mi, plane(), mitsuba_scene.bsdf_dict(path, 1.5),
        mitsuba_scene.sensor(mi, Camera(1.0, AZIMUTH, ELEVATION), size, size, spp, orthographic_half_height=0.02),
        mitsuba_scene.emitters(None, environment), integrator="direct")
    rgb = mitsuba_scene.render_passes(mi, mitsuba, spp).astype(np.float64).reshape(-1, 3)
    mitsuba_xyz = rgb @ np.linalg.inv(row_matrix())
    mitsuba_mean = mitsuba_xyz.mean(axis=0)
    mitsuba_error = mitsuba_xyz.std(axis=0) / math.sqrt(len(mitsuba_xyz))

    rgba = scene.render_rgba(plane(), FAR, NO_LIGHT, SIZE, 1.0, 1.5, samples=64, environment=environment, seed=7)
    gl_mean, gl_error = covered_mean(rgba)
    bound = 4.0 * np.hypot(gl_error, mitsuba_error) + 5e-3 * np.abs(gl_mean)
    print(f"GL {gl_mean} ± {gl_error}, Mitsuba ({variant}) {mitsuba_mean} ± {mitsuba_error}")
    assert np.all(np.abs(gl_mean - mitsuba_mean) <= bound), (gl_mean, gl_error, mitsuba_mean, mitsuba_error)


def test_render_cli_renders_an_environment_on_the_deferred_path(ctx, tmp_path):
    """``gratnet render --environment --render-path deferred`` (refused before issue 43's deferred estimator) writes
    the forward render's picture and says which path it took; ``auto`` takes deferred on a software rasterizer
    (forward elsewhere) and says why."""
    import json

    from gratnet.cli import main
    from viewer.scene_config import read_render_exr

    common = ["render", "--material", "blazed", "--mesh", "cd", "--camera", "0.25,-90,45", "--environment", "studio",
              "--light", "40,80", "--exposure", "5000", "--size", "24,16", "--spp", "3", "--seed", "2",
              "--weights-path", "texture", "--deferred-weights", "texture", "--quiet"]
    pictures = {}
    from viewer.renderer import is_software_rasterizer

    automatic = "deferred" if is_software_rasterizer(ctx) else "forward"  # the same driver as the CLI's context
    for path in ("deferred", "forward", "auto"):
        out = tmp_path / f"{path}.exr"
        assert main([*common, "--render-path", path, "--out", str(out)]) == 0
        pictures[path] = read_render_exr(out)
        config = json.loads((tmp_path / f"{path}.config.json").read_text())
        assert config["render_path"]["path"] == (automatic if path == "auto" else path)
    reason = json.loads((tmp_path / "auto.config.json").read_text())["render_path"]["reason"]
    assert ("software rasterizer" in reason) == (automatic == "deferred") and "sampled light" in reason
    np.testing.assert_array_equal(pictures["auto"], pictures[automatic])
    peak = float(np.abs(pictures["forward"]).max())
    assert peak > 0
    np.testing.assert_allclose(pictures["deferred"], pictures["forward"], rtol=0, atol=PATH_TOLERANCE * peak)
