"""Area lights in the GL runtime (issue 43; gratnet/area_lights.py, shaders/area_lights.glsl, environment.glsl).

Independent checks first: a far camera with a tiny field of view sees a few centimetres of a plane around the
origin under one view direction, so every covered pixel estimates the same integral ∫ A · XYZ · L dωi over the
lights' solid angles, and their mean is a Monte Carlo estimate over pixels × passes. numpy integrates the same by
dense quadrature over each light's own parameters (a rectangle's area, with cos θ_light / d²; a sphere's cone), not
by the shaders' sampling. Then the consistency the contract states: a small sphere lights like a point light of
intensity π r² L, and GL and Mitsuba integrate the same light. A small random network keeps the quadrature cheap.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from gratnet.area_lights import AreaLight, parse_area_light
from gratnet.brdf import a_term
from gratnet.environment import Environment
from gratnet.modelfile import evaluate_keys
from tests.helpers import covered_mean, hemisphere_integral, random_model, smooth_random_model, structured_map
from viewer.camera import Camera, Light, world_direction
from viewer.meshes import compact_disc, plane
from viewer.renderer import xyz_to_linear_srgb_matrix
from viewer.scene import SceneRenderer

ELEVATION, AZIMUTH = 50.0, -60.0
FAR = Camera(200.0, AZIMUTH, ELEVATION, fov_deg=0.01)  # 3.5 cm of the plane, ωo the same at every pixel
SIZE = (32, 32)
NO_LIGHT = Light.directional(0.0, 0.0, 0.0)
WO = world_direction(90.0 - ELEVATION, AZIMUTH)
# A coloured rectangle up and to the side, tilted towards the origin, and a sphere elsewhere.
RECT = "rect:1.2,0.6,1.5,-1.2,-0.6,-1.5,1.0,0.6,2,1,0.5"
SPHERE = "sphere:-0.8,-1.1,1.3,0.25,0.5,1.5,3"
# The deferred path against the forward one, per pixel, as a share of the picture's peak (as in
# tests/runtime/test_environment_light.py: float32 differences of the stacked G-buffer's samples, measured ≤ 6e-5 on
# llvmpipe, where a wrong pass index or pixel key differs by the noise itself).
PATH_TOLERANCE = 2e-4


@pytest.fixture(scope="module")
def model():
    return random_model([163, 16, 3], seed=3)


@pytest.fixture(scope="module")
def scene(ctx, model):
    with SceneRenderer(ctx, model, render_path="forward") as renderer:
        yield renderer


def light_directions(light: AreaLight, steps: int = 400) -> tuple[np.ndarray, np.ndarray]:
    """Directions from the origin towards ``light`` and the solid angle each stands for (midpoint rule over the
    light's own parameters: a rectangle's area with cos θ_light / d², a sphere's cone in polar angle × azimuth)."""
    centre = np.asarray(light.centre)
    if light.kind == "rect":
        u, v = np.asarray(light.axis_u), np.asarray(light.axis_v)
        s = (np.arange(steps) + 0.5) / steps * 2 - 1
        a, b = np.meshgrid(s, s, indexing="ij")
        points = centre + a[..., None] * u + b[..., None] * v
        normal = np.cross(u, v) / np.linalg.norm(np.cross(u, v))
        distance = np.linalg.norm(points, axis=-1)
        directions = points / distance[..., None]
        cosine = np.clip(directions @ -normal, 0.0, None)  # the emitting side faces the origin
        area = 4 * np.linalg.norm(np.cross(u, v)) / steps**2
        return directions.reshape(-1, 3), (area * cosine / distance**2).ravel()
    radius = light.axis_u[0]
    d = np.linalg.norm(centre)
    theta_max = math.asin(radius / d)
    t = (np.arange(steps) + 0.5) / steps * theta_max
    p = (np.arange(2 * steps) + 0.5) / (2 * steps) * 2 * np.pi
    tt, pp = np.meshgrid(t, p, indexing="ij")
    axis = centre / d
    x = np.cross([0.0, 0.0, 1.0], axis)
    x /= np.linalg.norm(x)
    y = np.cross(axis, x)
    directions = (np.cos(tt)[..., None] * axis + (np.sin(tt) * np.cos(pp))[..., None] * x
                  + (np.sin(tt) * np.sin(pp))[..., None] * y)
    weights = np.sin(tt) * (theta_max / steps) * (2 * np.pi / (2 * steps))
    return directions.reshape(-1, 3), weights.ravel()


def light_integral(model, lights: list[AreaLight], ior: float = 1.5) -> np.ndarray:
    """∫ A(ωi, ωo) · XYZ(−(ωi + ωo)) ⊙ L(ωi) dωi over the lights (CIE XYZ; the colour product in linear sRGB)."""
    to_rgb = xyz_to_linear_srgb_matrix()
    total = np.zeros(3)
    for light in lights:
        wi, weights = light_directions(light)
        keep = (wi[:, 2] > 0) & (weights > 0)
        wi, weights = wi[keep], weights[keep]
        key = -(wi + WO)
        xyz = evaluate_keys(model, key[:, 0], key[:, 1], key[:, 2])
        a = a_term(wi, np.broadcast_to(WO, wi.shape), ior)
        rgb = (xyz @ to_rgb.T) * np.asarray(light.radiance)
        total += np.linalg.inv(to_rgb) @ np.einsum("nc,n->c", rgb, a * weights)
    return total


@pytest.mark.parametrize("sampling", ["mis", "light", "material", "resampled"])
def test_rectangle_matches_quadrature_over_its_area(scene, model, sampling):
    light = parse_area_light(RECT)
    rgba = scene.render_rgba(plane(), FAR, NO_LIGHT, SIZE, 1.0, 1.5, samples=64, seed=1, sampling=sampling,
                             area_lights=(light,))
    mean, error = covered_mean(rgba)
    expected = light_integral(model, [light])
    assert np.all(np.abs(mean - expected) <= 4.0 * error + 2e-3 * np.abs(expected)), (mean, error, expected)
    assert np.all(error < 0.06 * np.abs(expected))


def test_several_lights_add_up(scene, model):
    """A rectangle, a sphere and a directional light at once: the mean is the directional light's render plus both
    lights' integrals."""
    lights = [parse_area_light(RECT), parse_area_light(SPHERE)]
    delta = Light.directional(30.0, 120.0, 2.0)
    alone = scene.render_rgba(plane(), FAR, delta, SIZE, 1.0, 1.5)
    rgba = scene.render_rgba(plane(), FAR, delta, SIZE, 1.0, 1.5, samples=64, seed=2, area_lights=tuple(lights))
    mean, error = covered_mean(rgba)
    expected = light_integral(model, lights) + alone[..., :3][alone[..., 3] == 1.0].mean(axis=0)
    assert np.all(np.abs(mean - expected) <= 4.0 * error + 2e-3 * np.abs(expected)), (mean, error, expected)


@pytest.mark.parametrize("sampling", ["mis", "resampled"])
def test_environment_and_area_light_add_up(scene, model, sampling):
    """An environment and a rectangle at once: the mean is the environment's hemisphere integral plus the
    rectangle's. Under ``resampled`` the environment's passes hold all of its light and material sampling serves
    the rectangle alone: an environment counted twice or not at all would miss by its whole integral."""
    light = parse_area_light(RECT)
    environment = Environment("test", structured_map(), 30.0, 1.0, "test")
    rgba = scene.render_rgba(plane(), FAR, NO_LIGHT, SIZE, 1.0, 1.5, samples=96, seed=4, sampling=sampling,
                             environment=environment, area_lights=(light,))
    mean, error = covered_mean(rgba)
    expected = light_integral(model, [light]) + hemisphere_integral(model, environment, WO)
    assert np.all(np.abs(mean - expected) <= 4.0 * error + 2e-3 * np.abs(expected)), (mean, error, expected)
    assert np.all(error < 0.05 * np.abs(expected))


@pytest.fixture(scope="module")
def smooth_scene(ctx):
    """A random network of low frequencies only: A · XYZ is smooth across a small sphere."""
    with SceneRenderer(ctx, smooth_random_model(), render_path="forward") as renderer:
        yield renderer


def test_small_sphere_lights_as_a_point_light(smooth_scene):
    """A sphere of radius r and radiance L has intensity π r² L towards every direction: 0.2 mm across and 0.6 m
    away it lights the plane as a point light of that intensity at its centre (the cap's solid angle computed
    without cancellation: r²/d² ≈ 3e-8 is below float32's epsilon)."""
    scene = smooth_scene
    centre, radius, radiance = (0.25, -0.2, 0.5), 1e-4, 4e7
    sphere = parse_area_light(f"sphere:{centre[0]},{centre[1]},{centre[2]},{radius},{radiance}")
    camera = Camera(0.3, -90.0, 60.0, fov_deg=20.0)  # a spread of points and views: the match is per pixel
    point = Light("point", centre, math.pi * radius**2 * radiance)
    expected = scene.render_rgba(plane(), camera, point, SIZE, 1.0, 1.5, samples=8)  # the same sub-pixel offsets
    rgba = scene.render_rgba(plane(), camera, NO_LIGHT, SIZE, 1.0, 1.5, samples=8, seed=3, area_lights=(sphere,),
                             sampling="light")
    covered = (expected[..., 3] == 1.0) & (rgba[..., 3] == 1.0)
    assert covered.sum() > 100
    # Light sampling of a 1 mm sphere: every sample lands within 0.1° of the centre; no noise to speak of.
    np.testing.assert_allclose(rgba[..., :3][covered], expected[..., :3][covered], rtol=2e-3,
                               atol=1e-6 * float(expected[..., :3].max()))


def test_samples_are_passes_and_seeded(scene):
    lights = (parse_area_light(RECT), parse_area_light(SPHERE))
    together = scene.render_rgba(plane(), FAR, NO_LIGHT, SIZE, 1.0, 1.5, samples=3, seed=5, area_lights=lights)
    apart = [scene.render_rgba(plane(), FAR, NO_LIGHT, SIZE, 1.0, 1.5, first_sample=k, seed=5, area_lights=lights)
             for k in range(3)]
    np.testing.assert_allclose(together, np.mean(apart, axis=0), rtol=1e-5, atol=1e-6)


@pytest.mark.parametrize("weights", ["texture", "tiled"])
def test_the_deferred_path_gives_the_forward_estimate(ctx, model, weights):
    """The rectangle, the sphere and a directional light on the disc: the deferred render of passes 2 … 6 (either
    shading kernel: SHADE with the texture weights, SHADE_TILED) equals the forward one per pixel, and so does a
    band of rows drawn alone with its pixel_origin."""
    from viewer.scheduling import BandCamera

    lights = (parse_area_light(RECT), parse_area_light(SPHERE))
    delta = Light.directional(30.0, 120.0, 2.0)
    camera, (width, height) = Camera(0.2, -90.0, 50.0), (24, 20)
    with SceneRenderer(ctx, model, weights_path="texture", render_path="forward", deferred_weights=weights) as scene:
        def render(path: str, view: Camera = camera, size: tuple[int, int] = (width, height),
                   pixel_origin: tuple[int, int] = (0, 0)) -> np.ndarray:
            return scene.render_rgba(compact_disc(), view, delta, size, 1.0, 1.5, samples=5, first_sample=2, seed=6,
                                     area_lights=lights, render_path=path, pixel_origin=pixel_origin)

        forward, deferred = render("forward"), render("deferred")
        np.testing.assert_allclose(deferred[..., 3], forward[..., 3], rtol=0, atol=1e-6)  # k · (1/N) against k / N
        peak = float(np.abs(forward[..., :3]).max())
        assert peak > 0 and np.any((forward[..., 3] > 0) & (forward[..., 3] < 1))
        np.testing.assert_allclose(deferred[..., :3], forward[..., :3], rtol=0, atol=PATH_TOLERANCE * peak)
        band = BandCamera(camera.distance, camera.azimuth_deg, camera.elevation_deg, camera.target, camera.fov_deg,
                          camera.near, camera.far, full_aspect=width / height, height=height, row0=6, row1=13)
        rows = render("deferred", band, (width, 7), (0, height - 13))
        np.testing.assert_allclose(rows[..., :3], forward[6:13, :, :3], rtol=0, atol=PATH_TOLERANCE * peak)
        np.testing.assert_allclose(rows[..., 3], forward[6:13, :, 3], rtol=0, atol=1e-6)


def test_gl_and_mitsuba_integrate_the_same_area_lights(tmp_path, scene, model):
    """The plane under the rectangle and the sphere, path-traced by Mitsuba 3 (``direct``: its area emitters and the
    plugin's table sampler, orthographic camera along the far camera's axis) and rendered by GL: the means over the
    covered pixels agree within four combined standard errors."""
    pytest.importorskip("mitsuba", reason="the mitsuba extra is not installed")
    from gratnet.modelfile import save_model
    from mitsuba_plugin import scene as mitsuba_scene
    from mitsuba_plugin.runtime import llvm_usable, set_variant
    from mitsuba_plugin.shading import xyz_to_linear_srgb_matrix as row_matrix

    variant = "llvm_ad_rgb" if llvm_usable() else "scalar_rgb"
    mi = set_variant(variant)
    path = tmp_path / "model.npz"
    save_model(path, model)
    lights = (parse_area_light(RECT), parse_area_light(SPHERE))
    size, spp = (16, 64) if variant == "llvm_ad_rgb" else (8, 32)
    mitsuba = mitsuba_scene.build_scene(
        mi, plane(), mitsuba_scene.bsdf_dict(path, 1.5),
        mitsuba_scene.sensor(mi, Camera(1.0, AZIMUTH, ELEVATION), size, size, spp, orthographic_half_height=0.02),
        mitsuba_scene.emitters(None, None, lights), integrator="direct")
    rgb = mitsuba_scene.render_passes(mi, mitsuba, spp).astype(np.float64).reshape(-1, 3)
    mitsuba_xyz = rgb @ np.linalg.inv(row_matrix())
    mitsuba_mean = mitsuba_xyz.mean(axis=0)
    mitsuba_error = mitsuba_xyz.std(axis=0) / math.sqrt(len(mitsuba_xyz))

    rgba = scene.render_rgba(plane(), FAR, NO_LIGHT, SIZE, 1.0, 1.5, samples=64, seed=7, area_lights=lights)
    gl_mean, gl_error = covered_mean(rgba)
    bound = 4.0 * np.hypot(gl_error, mitsuba_error) + 5e-3 * np.abs(gl_mean)
    print(f"GL {gl_mean} ± {gl_error}, Mitsuba ({variant}) {mitsuba_mean} ± {mitsuba_error}")
    assert np.all(np.abs(gl_mean - mitsuba_mean) <= bound), (gl_mean, gl_error, mitsuba_mean, mitsuba_error)
