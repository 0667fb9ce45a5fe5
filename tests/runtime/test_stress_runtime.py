"""Adversarial sweep of the GLSL runtime (issue 5, "Numerical stability"): grazing and normal incidence,
|w| → 0, u² + v² → 4, exposures 1e-3 … 1e6, huge and zero IOR, degenerate mesh frames.

Every float framebuffer must be free of NaN and inf. "Continuous" is checked against the physics, not as
"goes to 0": with A = R²G/(R0²w²) and G = (1 + ωi·ωo)²/(cosθi cosθo),

- for a fixed view, A ∝ 1/cosθi as the light reaches the horizon, so A·XYZ itself diverges (the Kirchhoff
  model has no shadowing). What stays continuous is the reflected radiance under a light of fixed
  irradiance, cosθi·A·XYZ: it converges to a finite limit as θi → 90⁻. We require successive values of a
  θi sweep towards 90° to agree within 2 % (the network's key moves by < 2e-4 between them), and the
  slice to be exactly 0 at and beyond the horizon (physics.md: "A = 0 when either direction is below the
  horizon"; shaders/brdf.glsl: "at or below").
- at the |w| = 1e-6 cut-off, A is forced to 0. Just above it A takes its analytic value, which depends on
  the pair of directions: (R/R0)² ≤ 1/R0² (625 for IOR 1.5) for the forward mirror pair, 1/cos⁴θ (1.6e25
  at the cut-off) for the retro-reflection pair. The shader must follow that float64 value to 1e-3
  (no cancellation spikes, no overflow) right up to the cut-off; the jump there is the documented one.

GL tests use the module-scoped ``ctx`` fixture and the shipped blazed model (small, and its programs are
already compiled by the other GL suites); renders are ≤ 32².
"""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np
import pytest

from gratnet.brdf import a_term, direction, fresnel_dielectric
from gratnet.modelfile import load_model
from tests.helpers import REPO
from viewer.camera import Camera, Light, world_direction
from viewer.meshes import Mesh, compact_disc, plane, sphere

BLAZED = REPO / "assets" / "blazed" / "model.npz"
EXPOSURES = (1e-3, 1.0, 1e6)
IORS = (1.5, None, 0.0, 1e6, 1e-6, 0.5, 1e20, 1e-20)


# --------------------------------------------------------------------------------------------------
# No GPU: the directions and the A-term the GPU programs are fed


@pytest.mark.parametrize("phi", [0.0, 45.0, 90.0, 180.0, 270.0, -630.0])
def test_a_light_at_exactly_90_degrees_lies_on_the_horizon(phi):
    # radians(90) is not π/2 exactly: cos gave 6.1e-17 > 0, so a horizon light counted as above the
    # horizon and A jumped to ~1e16 between θ = 89.99° (A ~ 1e3) and 90.01° (A = 0).
    for vector in (direction(90.0, phi), world_direction(90.0, phi), np.asarray(Light.directional(90.0, phi).vector)):
        assert vector[2] == 0.0
        np.testing.assert_allclose(np.linalg.norm(vector), 1.0, rtol=1e-15)
    assert direction(180.0, phi)[2] == -1.0 and direction(0.0, phi)[2] == 1.0
    assert float(a_term(direction(90.0, phi), direction(0.0, 0.0))) == 0.0


def test_a_term_follows_the_exact_value_up_to_the_w_cutoff():
    # Forward mirror pair at θ: 1 + ωi·ωo = 2cos²θ, so A = (R/R0)² exactly. Computing 1 + ωi·ωo directly
    # cancels every digit but the last few near the horizon (relative error ~1e-16/cos²θ).
    for cos_theta in (1e-2, 1e-4, 1e-6, 5.01e-7):
        sin_theta = np.sqrt(1.0 - cos_theta**2)
        light, view = np.array([sin_theta, 0.0, cos_theta]), np.array([-sin_theta, 0.0, cos_theta])
        assert float(a_term(light, view, ior=None)) == pytest.approx(1.0, rel=1e-9)
        ratio = fresnel_dielectric(np.array(cos_theta), 1.5) / fresnel_dielectric(np.array(1.0), 1.5)
        assert float(a_term(light, view, ior=1.5)) == pytest.approx(float(ratio) ** 2, rel=1e-9)


@pytest.mark.parametrize("ior", [1e-200, 1e-20, 1e20, 1e200])
def test_extreme_ior_gives_a_finite_fresnel_ratio(ior):
    # ior² under/overflows; (1 − cos²)/ior² became 0/0 = NaN at normal incidence for tiny IOR.
    cosines = np.array([0.0, 1e-8, 0.5, 1.0])
    with np.errstate(invalid="raise", divide="raise"):
        reflectance = fresnel_dielectric(cosines, ior)
    assert np.all(np.isfinite(reflectance)) and np.all((reflectance >= 0.0) & (reflectance <= 1.0))
    light, view = direction(40.0, 0.0), direction(20.0, 180.0)
    assert np.isfinite(float(a_term(light, view, ior)))


@pytest.mark.parametrize("vector", [(1e308, 1e308, 0.0), (3e-320, 4e-320, 0.0), (-1e200, 0.0, 1e200)])
def test_directional_light_of_extreme_magnitude_is_normalised(vector):
    # |v| overflowed to inf (direction became 0: an unlit scene) or lost its digits as a denormal.
    light = Light("directional", vector)
    expected = np.asarray(vector) / np.max(np.abs(vector))
    np.testing.assert_allclose(light.vector, expected / np.linalg.norm(expected), rtol=1e-12)


# --------------------------------------------------------------------------------------------------
# GPU


@pytest.fixture(scope="module")
def scene(ctx) -> Iterator[object]:
    from viewer.scene import SceneRenderer

    # The texture path (the stress is in the key vectors and the A-term, not in the MLP; the baked path's
    # ~25 s first compile per program is covered by tests/runtime/test_golden.py).
    renderer = SceneRenderer(ctx, load_model(BLAZED), weights_path="texture")
    yield renderer
    renderer.release()


def assert_clean(*images: np.ndarray) -> None:
    for image in images:
        assert np.all(np.isfinite(image)), f"{np.count_nonzero(~np.isfinite(image))} non-finite values"
        assert np.all(image >= 0.0)


def test_brdf_slices_are_finite_for_every_light_exposure_and_ior(scene):
    network = scene.network
    size = 16
    outside = np.hypot(*np.meshgrid(np.arange(size) - 7.5, np.arange(size) - 7.5)) > size / 2
    for theta in (0.0, 1e-6, 45.0, 89.0, 89.99, 90.0, 90.01, 179.99, 180.0):
        for phi in (0.0, 90.0, 137.5, 359.99, -720.0):
            exposed, xyz = network.render_brdf_slice_layers(theta, phi, size, 1e6, 1.5)
            assert_clean(exposed, xyz)
            assert np.all(exposed[outside] == 0.0)
    for theta in (0.0, 89.99):
        for exposure in EXPOSURES:
            for ior in IORS:
                exposed, xyz = network.render_brdf_slice_layers(theta, 30.0, size, exposure, ior)
                assert_clean(exposed, xyz)
                assert exposed.max() > 0.0, (theta, exposure, ior)


def test_brdf_slice_radiance_is_continuous_up_to_the_horizon_and_zero_beyond(scene):
    network = scene.network
    size = 16
    previous = None
    # Steps of ≤ 0.009°: the key moves by < 2e-4 between neighbours (the blazed orders are sharp in u).
    for theta in (89.99, 89.999, 89.9999, 89.99999):
        exposed = network.render_brdf_slice_layers(theta, 0.0, size, 1.0, 1.5)[0].astype(np.float64)
        radiance = np.cos(np.radians(theta)) * exposed  # cosθi · A · XYZ: finite as θi → 90°
        assert_clean(radiance)
        if previous is not None:
            scale = max(previous.max(), radiance.max())
            assert np.max(np.abs(radiance - previous)) <= 0.02 * scale + 1e-30, theta
        previous = radiance
    assert previous.max() > 0.0
    for theta in (90.0, 90.0001, 135.0):
        exposed, xyz = network.render_brdf_slice_layers(theta, 0.0, size, 1e6, 1.5)
        assert np.all(exposed == 0.0), theta
        assert_clean(xyz)


def reference_a(light: np.ndarray, view: np.ndarray, ior: float | None) -> np.ndarray:
    """Eq. 5 in float64 with 1 + ωi·ωo = |ωi + ωo|²/2 (exact for unit vectors)."""
    k = light + view
    one_plus = 0.5 * np.sum(k * k, axis=-1)
    cos_i, cos_o = light[..., 2], view[..., 2]
    w = -(cos_i + cos_o)
    ratio = 1.0
    if ior:
        ratio = (fresnel_dielectric(np.sqrt(np.clip(0.5 * one_plus, 0, 1)), ior) / fresnel_dielectric(1.0, ior)) ** 2
    with np.errstate(divide="ignore", invalid="ignore"):  # masked below
        value = ratio * one_plus**2 / (cos_i * cos_o) / w**2
    return np.where((np.abs(w) > 1e-6) & (cos_i > 0) & (cos_o > 0), value, 0.0)


@pytest.mark.parametrize("ior", [1.5, None])
def test_gpu_a_term_follows_float64_up_to_the_w_cutoff(scene, ior):
    cosines = np.array([1e-1, 1e-2, 1e-3, 1e-4, 1e-5, 1e-6, 6e-7, 5.2e-7, 4.8e-7, 1e-7, 0.0])
    sines = np.sqrt(1.0 - cosines**2)
    forward = (np.stack([sines, 0 * sines, cosines], -1), np.stack([-sines, 0 * sines, cosines], -1))
    retro = (forward[0], forward[0])
    side = (forward[0], np.stack([0 * sines, sines, cosines], -1))
    for light, view in (forward, retro, side):
        light32, view32 = light.astype(np.float32).astype(np.float64), view.astype(np.float32).astype(np.float64)
        gpu = scene.network.a_term(light32, view32, ior).astype(np.float64)
        expected = reference_a(light32, view32, ior)
        assert_clean(gpu)
        np.testing.assert_allclose(gpu, expected, rtol=1e-3, atol=0.0)
    # The forward pair's jump at the cut-off is bounded by the analytic limit (R/R0)² → 1/R0².
    limit = 1.0 / fresnel_dielectric(1.0, 1.5) ** 2 if ior else 1.0
    assert scene.network.a_term(forward[0][6], forward[1][6], ior) <= limit * (1 + 1e-3)


def test_gpu_a_term_is_finite_for_adversarial_unit_pairs_and_iors(scene):
    rng = np.random.default_rng(5)
    theta = np.concatenate([rng.uniform(85.0, 90.0, 200), [0.0, 89.99, 89.999, 90.0, 90.0001]])
    phi = np.concatenate([rng.uniform(0.0, 360.0, 200), [0.0, 90.0, 180.0, 270.0, 359.99]])
    light = np.stack([direction(t, p) for t, p in zip(theta, phi, strict=True)])
    view = np.concatenate([light[1:], light[:1]])
    for ior in IORS:
        for pair in ((light, view), (light, light), (light, light * [-1, -1, 1])):
            assert_clean(scene.network.a_term(*pair, ior))


def test_gpu_network_is_finite_and_continuous_at_adversarial_keys(scene):
    angles = np.radians(np.arange(0.0, 360.0, 15.0))
    rim = []
    for gap in (0.0, 1e-7, 1e-5, 1e-3):
        radius = np.sqrt(4.0 - gap)
        rim.append(np.stack([radius * np.cos(angles), radius * np.sin(angles), -np.sqrt(gap) * np.ones_like(angles)],
                            -1))
    specials = np.array([[0.0, 0.0, w] for w in (0.0, -0.0, -1e-40, -1e-7, -1e-6, -1.0, -2.0, -2.0000002)]
                        + [[2.0000002, 0.0, 0.0], [1e-40, -1e-40, -1.0], [5.0, 5.0, 3.0], [-5.0, 0.0, -9.0]])
    keys = np.concatenate([*rim, specials])
    xyz = scene.network.evaluate_keys(keys[:, 0], keys[:, 1], keys[:, 2])
    outputs = scene.network.network_outputs(keys[:, 0], keys[:, 1], keys[:, 2])
    assert_clean(xyz, outputs)
    # Along physical paths the network's XYZ moves continuously: the rim at gap 1e-7 vs gap 0, and the
    # specular axis at w = −1e-7 vs w = 0 (keys 1e-7 apart; the top encoding frequency is 1571 rad per unit).
    count = angles.size
    np.testing.assert_allclose(xyz[count:2 * count], xyz[:count], rtol=2e-3, atol=1e-6 * xyz.max())
    np.testing.assert_allclose(xyz[4 * count + 3], xyz[4 * count], rtol=2e-3)


# --------------------------------------------------------------------------------------------------
# Meshes


def _bypass(mesh: Mesh, **arrays: np.ndarray) -> Mesh:
    """A copy of ``mesh`` with frame arrays the constructor would refuse (to test the shader's fallbacks)."""
    copy = Mesh(mesh.positions, mesh.normals, mesh.tangents, mesh.uvs, mesh.indices)
    for name, value in arrays.items():
        object.__setattr__(copy, name, np.ascontiguousarray(value, dtype=np.float32))
    return copy


def degenerate_meshes() -> dict[str, Mesh]:
    quad = plane(0.2)
    count = quad.vertex_count
    flipped = quad.normals * np.array([[1.0], [-1.0], [-1.0], [1.0]])  # interpolated normal crosses zero
    opposite_tangents = quad.tangents * np.array([[1.0], [-1.0], [-1.0], [1.0]])  # interpolated tangent crosses 0
    positions = np.array([[0, 0, 0], [0, 0, 0], [0, 0, 0], [0.1, 0, 0], [0.2, 0, 0], [-0.1, 0, 0]], np.float32)
    frame = np.broadcast_to([0.0, 0.0, 1.0], positions.shape)
    degenerate = Mesh(positions, frame, np.broadcast_to([1.0, 0.0, 0.0], positions.shape), np.zeros((6, 2)),
                      np.array([[0, 1, 2], [0, 3, 4], [3, 4, 5]]))  # a point, and collinear triangles
    return {
        "zero normals": _bypass(quad, normals=np.zeros((count, 3))),
        "zero tangents": _bypass(quad, tangents=np.zeros((count, 3))),
        "tangent = normal": _bypass(quad, tangents=quad.normals),
        "tangent = −normal": _bypass(quad, tangents=-quad.normals),
        "non-unit frame": _bypass(quad, normals=quad.normals * 1e-20, tangents=quad.tangents * 1e20),
        "normals cancel": Mesh(quad.positions, flipped, quad.tangents, quad.uvs, quad.indices),
        "tangents cancel": Mesh(quad.positions, quad.normals, opposite_tangents, quad.uvs, quad.indices),
        "zero-area triangles": degenerate,
        "sphere poles": sphere(0.05, 8, 4),
        "full disc": compact_disc(0.0, 0.06, 16, 2),
    }


@pytest.mark.parametrize("name", list(degenerate_meshes()))
def test_degenerate_meshes_render_finite(scene, name):
    mesh = degenerate_meshes()[name]
    camera = Camera(distance=0.3, azimuth_deg=30.0, elevation_deg=55.0)
    for light in (Light.directional(35.0, 210.0), Light.directional(89.99, 0.0), Light.point((0.0, 0.0, 0.0))):
        rgba = scene.render_rgba(mesh, camera, light, (16, 16), exposure=1e6, ior=1.5)
        assert_clean(rgba)
        assert set(np.unique(rgba[..., 3])) <= {0.0, 1.0}
        assert np.all(rgba[rgba[..., 3] == 0.0] == 0.0)


def test_mesh_renders_are_finite_for_adversarial_cameras_lights_exposures_and_iors(scene):
    meshes = {"plane": plane(1.0), "sphere": sphere(0.05, 16, 8), "disc": compact_disc(0.0075, 0.06, 32, 2)}
    cameras = [Camera(distance=0.3, azimuth_deg=a, elevation_deg=e)
               for a, e in ((0.0, 90.0), (45.0, -90.0), (10.0, 0.0), (-90.0, 89.99), (200.0, 0.01))]
    lights = [Light.directional(t, p) for t, p in ((0.0, 0.0), (89.99, 45.0), (90.0, 90.0), (179.99, 0.0))]
    lights += [Light.point((0.0, 0.0, 1e-7)), Light.point((0.0, 0.0, 1e6), 1e12)]
    for mesh in meshes.values():
        for camera in cameras:
            for light in lights:
                rgba = scene.render_rgba(mesh, camera, light, (12, 12), exposure=1e6, ior=1.5)
                assert_clean(rgba)
    for exposure in EXPOSURES:
        for ior in IORS:
            rgba = scene.render_rgba(meshes["plane"], Camera(distance=0.3, elevation_deg=55.0),
                                     Light.directional(35.0, 90.0), (12, 12), exposure=exposure, ior=ior)
            assert_clean(rgba)
            assert rgba[..., :3].max() > 0.0, (exposure, ior)
