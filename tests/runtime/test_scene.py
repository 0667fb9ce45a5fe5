"""Meshes, camera, the mesh renderer (shaders/surface.glsl) and ``gratnet render``.

GPU tests need an OpenGL 4.3 context through EGL (Mesa llvmpipe on a CPU-only machine) and skip with the
reason when there is none. Renders are tiny (≤ 64×64) with the shipped blazed model (28k MACs per pixel).
"""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np
import pytest

from gratnet.brdf import a_term
from gratnet.cli import main
from gratnet.errors import GratNetError
from gratnet.modelfile import evaluate_keys, load_model
from gratnet.precision import OWN_KEYS, assert_within, driver_bound
from tests.helpers import REPO, check_plane_against_numpy, plane_geometry
from viewer.camera import Camera, Light, world_direction
from viewer.meshes import Mesh, arbitrary_tangents, compact_disc, load_obj, plane, sphere

BLAZED = REPO / "assets" / "blazed" / "model.npz"
EXPOSURE = 5000.0  # the blazed slices' exposure: its diffraction orders are ~1e-3 of a mirror


# --------------------------------------------------------------------------------------------------
# Meshes (no GPU)


def assert_frame(mesh: Mesh) -> None:
    """Unit normals and tangents, orthogonal; triangles counter-clockwise seen from the normals' side."""
    assert mesh.positions.dtype == mesh.normals.dtype == mesh.tangents.dtype == mesh.uvs.dtype == np.float32
    assert mesh.indices.dtype == np.uint32 and mesh.indices.shape[1] == 3
    np.testing.assert_allclose(np.linalg.norm(mesh.normals, axis=1), 1.0, atol=1e-6)
    np.testing.assert_allclose(np.linalg.norm(mesh.tangents, axis=1), 1.0, atol=1e-6)
    np.testing.assert_allclose(np.sum(mesh.normals * mesh.tangents, axis=1), 0.0, atol=1e-6)
    np.testing.assert_allclose(np.linalg.norm(mesh.bitangents, axis=1), 1.0, atol=1e-6)
    p = mesh.positions.astype(np.float64)[mesh.indices]
    face = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    assert np.all(np.linalg.norm(face, axis=1) > 0.0)  # no degenerate triangles
    corner_normals = mesh.normals[mesh.indices].sum(axis=1)
    assert np.all(np.sum(face * corner_normals, axis=1) > 0.0)


def test_compact_disc_frame_and_tangent_along_the_tracks():
    mesh = compact_disc(inner_radius=0.0075, outer_radius=0.06, segments=64, rings=4)
    assert_frame(mesh)
    assert mesh.vertex_count == 5 * 65 and mesh.triangle_count == 2 * 4 * 64
    radius = np.linalg.norm(mesh.positions[:, :2], axis=1)
    np.testing.assert_allclose(mesh.positions[:, 2], 0.0)
    assert radius.min() == pytest.approx(0.0075, rel=1e-6) and radius.max() == pytest.approx(0.06, rel=1e-6)
    np.testing.assert_allclose(mesh.normals, np.broadcast_to([0.0, 0.0, 1.0], mesh.normals.shape))
    # Tangent = the azimuthal direction (counter-clockwise), i.e. along the tracks, ⟂ to the radius.
    azimuth = np.arctan2(mesh.positions[:, 1], mesh.positions[:, 0])
    expected = np.stack([-np.sin(azimuth), np.cos(azimuth), np.zeros_like(azimuth)], axis=1)
    np.testing.assert_allclose(mesh.tangents, expected, atol=1e-6)
    np.testing.assert_allclose(np.sum(mesh.tangents[:, :2] * mesh.positions[:, :2], axis=1), 0.0, atol=1e-8)
    # The bitangent points to the centre; the UVs follow the frame (u along t, v along b).
    inward = -mesh.positions[:, :2] / radius[:, None]
    np.testing.assert_allclose(mesh.bitangents[:, :2], inward, atol=1e-6)
    assert mesh.uvs[:, 1].min() == 0.0 and mesh.uvs[:, 1].max() == 1.0


def test_compact_disc_may_be_a_full_disc_and_rejects_bad_radii():
    full = compact_disc(inner_radius=0.0, segments=16, rings=2)
    assert_frame(full)
    assert full.triangle_count == 2 * 2 * 16 - 16
    with pytest.raises(GratNetError, match="inner_radius"):
        compact_disc(inner_radius=0.1, outer_radius=0.05)
    with pytest.raises(GratNetError, match="segments"):
        compact_disc(segments=2)


def test_sphere_frame_tangent_along_latitude_lines():
    mesh = sphere(radius=0.05, segments=24, rings=12)
    assert_frame(mesh)
    assert mesh.triangle_count == 2 * 24 * 12 - 2 * 24  # pole caps: one triangle per cell
    np.testing.assert_allclose(np.linalg.norm(mesh.positions, axis=1), 0.05, rtol=1e-6)
    np.testing.assert_allclose(mesh.normals, mesh.positions / 0.05, atol=1e-6)
    np.testing.assert_allclose(mesh.tangents[:, 2], 0.0, atol=1e-7)  # horizontal: along a parallel
    # Eastwards: tangent = z × position, normalised (away from the poles).
    away = np.linalg.norm(mesh.positions[:, :2], axis=1) > 1e-3
    east = np.cross([0.0, 0.0, 1.0], mesh.positions[away])
    np.testing.assert_allclose(mesh.tangents[away], east / np.linalg.norm(east, axis=1, keepdims=True), atol=1e-6)
    assert np.all(mesh.bitangents[away, 2] > 0.0)  # the bitangent points north


def test_plane_frame_is_the_world_frame():
    mesh = plane(0.2, subdivisions=3)
    assert_frame(mesh)
    assert mesh.triangle_count == 18
    np.testing.assert_allclose(mesh.tangents, np.broadcast_to([1.0, 0.0, 0.0], mesh.tangents.shape))
    np.testing.assert_allclose(mesh.bitangents, np.broadcast_to([0.0, 1.0, 0.0], mesh.tangents.shape))
    np.testing.assert_allclose(mesh.positions.min(axis=0), [-0.1, -0.1, 0.0], atol=1e-7)


def test_arbitrary_tangents_are_unit_and_orthogonal_everywhere():
    rng = np.random.default_rng(3)
    normals = rng.standard_normal((500, 3))
    normals = np.concatenate([normals, [[0, 0, 1], [0, 0, -1], [1, 0, 0], [0, -1e-9, -1]]])
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    tangents = arbitrary_tangents(normals)
    np.testing.assert_allclose(np.linalg.norm(tangents, axis=1), 1.0, atol=1e-12)
    np.testing.assert_allclose(np.sum(tangents * normals, axis=1), 0.0, atol=1e-12)


def test_mesh_rejects_a_bad_frame_and_bad_indices():
    good = plane(0.1)
    with pytest.raises(GratNetError, match="unit and orthogonal"):
        Mesh(good.positions, good.normals, good.normals, good.uvs, good.indices)
    with pytest.raises(GratNetError, match="indices"):
        Mesh(good.positions, good.normals, good.tangents, good.uvs, good.indices + 10)


CUBE_OBJ = """# a unit cube, one UV square per face, quads, metres
o cube
v 0 0 0
v 1 0 0
v 1 1 0
v 0 1 0
v 0 0 1
v 1 0 1
v 1 1 1
v 0 1 1
vt 0 0
vt 1 0
vt 1 1
vt 0 1
vn 0 0 -1
vn 0 0 1
vn 0 -1 0
vn 0 1 0
vn -1 0 0
vn 1 0 0
s off
f 1/1/1 4/2/1 3/3/1 2/4/1
f 5/1/2 6/2/2 7/3/2 8/4/2
f 1/1/3 2/2/3 6/3/3 5/4/3
f 4/1/4 8/2/4 7/3/4 3/4/4
f 1/1/5 5/2/5 8/3/5 4/4/5
f 2/1/6 3/2/6 7/3/6 6/4/6
"""


def test_obj_cube_round_trip(tmp_path):
    path = tmp_path / "cube.obj"
    path.write_text(CUBE_OBJ)
    mesh = load_obj(path)
    assert_frame(mesh)
    assert mesh.triangle_count == 12 and mesh.vertex_count == 24  # 4 corners per face, quads split in two
    # Every corner keeps its position, normal and UV; the tangent is ∂P/∂u of its face.
    positions = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]])
    np.testing.assert_array_equal(np.unique(mesh.positions, axis=0), np.unique(positions, axis=0))
    expected_tangents = {  # face normal -> direction of increasing u on that face
        (0, 0, -1): (0, 1, 0), (0, 0, 1): (1, 0, 0), (0, -1, 0): (1, 0, 0),
        (0, 1, 0): (0, 0, 1), (-1, 0, 0): (0, 0, 1), (1, 0, 0): (0, 1, 0),
    }
    for normal, tangent in expected_tangents.items():
        rows = np.all(np.isclose(mesh.normals, normal), axis=1)
        assert rows.sum() == 4
        np.testing.assert_allclose(mesh.tangents[rows], np.broadcast_to(tangent, (4, 3)), atol=1e-6)
    corners = {tuple(p) + tuple(n) + tuple(t) for p, n, t in zip(mesh.positions, mesh.normals, mesh.uvs, strict=True)}
    assert len(corners) == 24


def test_obj_without_uvs_or_normals_gets_a_stable_frame_and_skips_degenerate_faces(tmp_path):
    path = tmp_path / "bare.obj"
    # A counter-clockwise square (one quad), a collinear triangle, and a face with negative indices.
    path.write_text("v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 2 0 0\nf 1 2 3 4\nf 1 2 5\nf -4 -3 -2\n")
    mesh = load_obj(path)
    assert_frame(mesh)
    assert mesh.triangle_count == 3  # the collinear face 1 2 5 is skipped
    np.testing.assert_allclose(mesh.normals, np.broadcast_to([0.0, 0.0, 1.0], mesh.normals.shape), atol=1e-7)
    np.testing.assert_allclose(mesh.tangents, arbitrary_tangents(mesh.normals.astype(np.float64)), atol=1e-6)


def test_obj_winding_follows_the_given_normals(tmp_path):
    path = tmp_path / "cw.obj"
    path.write_text("v 0 0 0\nv 0 1 0\nv 1 0 0\nvn 0 0 1\nvt 0 0\nvt 0 1\nvt 1 0\nf 1/1/1 2/2/1 3/3/1\n")
    mesh = load_obj(path)
    assert_frame(mesh)  # flipped to counter-clockwise about +z
    np.testing.assert_allclose(mesh.tangents, np.broadcast_to([1.0, 0.0, 0.0], (3, 3)), atol=1e-6)


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("v 0 0 0\nv 1 0\n", "truncated"),
        ("v 0 0 0\nv 1 0 x\n", "non-numeric"),
        ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 4\n", "out of range"),
        ("v 0 0 0\nv 1 0 0\nf 1 2\n", "at least 3"),
        ("v 0 0 0\n", "no faces"),
        ("v 0 0 0\nv 1 0 0\nv 2 0 0\nf 1 2 3\n", "degenerate"),
        ("", "no faces"),
    ],
)
def test_bad_obj_raises_one_clear_error(tmp_path, text, message):
    path = tmp_path / "bad.obj"
    path.write_text(text)
    with pytest.raises(GratNetError, match=message):
        load_obj(path)


def test_missing_obj_raises(tmp_path):
    with pytest.raises(GratNetError, match="cannot read mesh"):
        load_obj(tmp_path / "nothing.obj")


# --------------------------------------------------------------------------------------------------
# Camera (no GPU)


def test_camera_projects_the_target_to_the_centre_and_rays_match_the_matrices():
    camera = Camera(distance=0.3, azimuth_deg=30.0, elevation_deg=55.0, fov_deg=30.0)
    np.testing.assert_allclose(np.linalg.norm(camera.eye()), 0.3)
    np.testing.assert_allclose(camera.eye() / 0.3, world_direction(35.0, 30.0), atol=1e-12)
    matrix = camera.view_projection(2.0).astype(np.float64)
    clip = np.array([0.0, 0.0, 0.0, 1.0]) @ matrix
    np.testing.assert_allclose(clip[:2] / clip[3], 0.0, atol=1e-6)
    # A point along the ray through pixel (row 3, column 40) of an 80×40 image lands on that pixel centre.
    eye, ray = camera.pixel_ray(3, 40, 80, 40)
    clip = np.append(eye + 0.25 * ray, 1.0) @ matrix
    ndc = clip[:2] / clip[3]
    np.testing.assert_allclose([(ndc[0] + 1) * 40 - 0.5, (1 - ndc[1]) * 20 - 0.5], [40, 3], atol=1e-3)
    for elevation in (90.0, -90.0):  # straight down / up: still a valid frame
        assert np.all(np.isfinite(Camera(0.2, 0.0, elevation).view_matrix()))
    with pytest.raises(GratNetError):
        Camera(distance=0.0)
    with pytest.raises(GratNetError):
        Camera(elevation_deg=91.0)


def test_lights():
    light = Light.directional(30.0, 90.0)
    np.testing.assert_allclose(light.vector, world_direction(30.0, 90.0))
    direction, irradiance = light.towards([1.0, 2.0, 3.0])
    assert irradiance == 1.0
    point = Light.point([0.0, 0.0, 2.0], intensity=8.0)
    direction, irradiance = point.towards([0.0, 0.0, 0.0])
    np.testing.assert_allclose(direction, [0.0, 0.0, 1.0])
    assert irradiance == pytest.approx(2.0)
    with pytest.raises(GratNetError):
        Light("directional", (0.0, 0.0, 0.0))


# --------------------------------------------------------------------------------------------------
# Rendering (GPU)


@pytest.fixture(scope="module")
def model():
    return load_model(BLAZED)


@pytest.fixture(scope="module")
def scene(ctx, model) -> Iterator[object]:
    from viewer.scene import SceneRenderer

    # The texture path: these tests are about the scene, and the baked path's first compile (~25 s per
    # program at this size on llvmpipe) is covered once by tests/runtime/test_golden.py and test_shipped_models.py.
    # The forward path (tests/runtime/test_deferred.py ties the deferred one to it).
    renderer = SceneRenderer(ctx, model, weights_path="texture", render_path="forward")
    yield renderer
    renderer.release()


@pytest.mark.parametrize("ior", [1.5, None])
def test_plane_renders_the_networks_specular_value_at_the_centre_pixel(scene, model, ior):
    # 33×33: the centre pixel's ray passes through the target exactly, so ωo there is eye/|eye|.
    camera = Camera(distance=0.3, azimuth_deg=30.0, elevation_deg=55.0, fov_deg=30.0)
    view = camera.eye() / np.linalg.norm(camera.eye())
    light_theta, light_phi = 35.0, 210.0  # the mirror direction of the view about the normal +z
    light = world_direction(light_theta, light_phi)
    np.testing.assert_allclose(light[:2], -view[:2], atol=1e-12)
    image, key_a = scene.render_layers(plane(1.0), camera, Light.directional(light_theta, light_phi), (33, 33),
                                       exposure=EXPOSURE, ior=ior)
    assert image.shape == (33, 33, 4) and image.dtype == np.float32
    assert np.all(np.isfinite(image)) and np.all(image[..., 3] == 1.0)  # the plane fills the frame
    # The plane's tangent frame is the world frame: the shader saw the numpy ωi, ωo up to float32 rounding.
    key = -(light + view)
    gpu_key = key_a[16, 16, :3].astype(np.float64)
    np.testing.assert_allclose(gpu_key, key, rtol=0.0, atol=1e-6)
    a = float(a_term(light, view, ior))
    assert key_a[16, 16, 3] == pytest.approx(a, rel=1e-5)
    # The value: network at the key the shader used × A(numpy ωi, ωo) × exposure.
    # Why the shader's float32 key: at the specular peak u = v = 0, and the simple-max scheme feeds the
    # network sign(u)·2·sqrt(|u|/2) (physics.md eq. 6), whose slope is infinite there. float32 rounding of
    # ωi + ωo leaves |u| ~ 1e-8, which alone moves this model's value by ~2 % (1e-10: 0.2 %); a float32
    # renderer cannot reproduce the float64 value at exactly u = v = 0 more closely than that.
    # The bound (docs/physics.md, "Float32 error budget") at the key the shader used: the encoding saw exactly
    # it, so only sin/cos and the MLP's rounding remain; at the float64 key, 1e-6 of key error on top.
    own = driver_bound(model, *gpu_key, OWN_KEYS)
    factor = EXPOSURE * a
    assert factor * own.xyz[1] > 1.0  # a bright specular peak, not a floor
    pixel = image[16, 16, :3].astype(np.float64)
    assert_within(pixel, factor * own.xyz, factor * own.bound + 1e-5 * factor * own.xyz, "centre pixel values")
    at_numpy_key = driver_bound(model, *key, key_error=1e-6)
    assert_within(pixel, factor * at_numpy_key.xyz, factor * at_numpy_key.bound, "centre pixel values (float64 key)")


def test_plane_with_a_rotated_tangent_renders_the_off_specular_value(scene, model):
    # Tangent +y: the tangent frame is (t, b, n) = (+y, −x, +z); light off the mirror direction.
    base = plane(1.0)
    mesh = Mesh(base.positions, base.normals, np.broadcast_to([0.0, 1.0, 0.0], base.tangents.shape).copy(),
                base.uvs, base.indices)
    camera = Camera(distance=0.3, azimuth_deg=30.0, elevation_deg=55.0, fov_deg=30.0)
    view_world = camera.eye() / np.linalg.norm(camera.eye())
    # Light at (30°, 186°): in the rotated frame the key (−0.235, −0.001, −1.685) lies on a diffraction
    # order of the blazed grating, where an accurate model is bright (elsewhere it may be exactly 0).
    light_world = world_direction(30.0, 186.0)
    to_tangent = np.array([[0.0, 1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    image, key_a = scene.render_layers(mesh, camera, Light.directional(30.0, 186.0), (33, 33), exposure=EXPOSURE,
                                       ior=1.5)
    light_tangent, view_tangent = to_tangent @ light_world, to_tangent @ view_world
    gpu_key = key_a[16, 16, :3].astype(np.float64)
    np.testing.assert_allclose(gpu_key, -(light_tangent + view_tangent), rtol=0.0, atol=1e-6)
    a = float(a_term(light_tangent, view_tangent, 1.5))
    assert key_a[16, 16, 3] == pytest.approx(a, rel=1e-5)
    own = driver_bound(model, *gpu_key, OWN_KEYS)
    assert own.xyz.max() > 1e-6 / EXPOSURE
    assert_within(image[16, 16, :3], EXPOSURE * a * own.xyz, EXPOSURE * a * own.bound + 1e-5 * EXPOSURE * a * own.xyz,
                  "off-specular values")


def plane_reference(model, camera: Camera, light: Light, size: tuple[int, int], exposure: float) -> np.ndarray:
    """exposure · irradiance · A · XYZ per pixel of an infinite plane z = 0 lit by a point light (numpy,
    float64, (H, W, 3)): each pixel's ray hits z = 0; its ωo and the light give the value (1/d² too)."""
    geometry = plane_geometry(camera, light, size)
    key = geometry["key"]
    return (exposure * geometry["irradiance"] * geometry["a"])[..., None] * evaluate_keys(model, key[..., 0],
                                                                                          key[..., 1], key[..., 2])


def test_plane_render_matches_numpy_at_every_pixel(scene, model):
    """Each pixel's ray hits z = 0; its ωo and the light give the numpy value (point light: 1/d² too)."""
    camera = Camera(distance=0.25, azimuth_deg=-70.0, elevation_deg=40.0, fov_deg=40.0)
    light = Light.point([0.0, 0.08, 0.1], intensity=0.02)
    size = (20, 16)
    image, key_a = scene.render_layers(plane(2.0), camera, light, size, exposure=EXPOSURE, ior=1.5)
    check_plane_against_numpy(image, key_a, model, camera, light, size, EXPOSURE)


@pytest.mark.parametrize("render_path", ["forward", "deferred"])
def test_a_shadowed_material_renders_smiths_term_at_every_pixel(ctx, model, render_path):
    """A model that records its relief's slopes (gratnet.shadowing) renders S · A · XYZ on both paths: a low
    point light and a steep relief, so S runs from ~1 to well below it across the plane."""
    import dataclasses

    from viewer.scene import SceneRenderer

    covariance = (0.45, 0.12, 0.3)
    volume = {**model.metadata.get("volume", {}), "slope_covariance": list(covariance)}
    shadowed = dataclasses.replace(model, metadata={**model.metadata, "volume": volume})
    camera = Camera(distance=0.25, azimuth_deg=-70.0, elevation_deg=40.0, fov_deg=40.0)
    light = Light.point([0.0, 0.15, 0.03], intensity=0.02)
    size = (20, 16)
    shadowing = plane_geometry(camera, light, size, covariance)["a"] / plane_geometry(camera, light, size)["a"]
    assert shadowing.min() < 0.6 and shadowing.max() > 0.85
    renderer = SceneRenderer(ctx, shadowed, weights_path="texture", render_path=render_path)
    try:
        image, key_a = renderer.render_layers(plane(2.0), camera, light, size, exposure=EXPOSURE, ior=1.5)
        check_plane_against_numpy(image, key_a, shadowed, camera, light, size, EXPOSURE, slope_covariance=covariance)
        if render_path == "deferred":  # the G-buffer's path: the same pixels as the forward layers' values
            rgba = renderer.render_rgba(plane(2.0), camera, light, size, exposure=EXPOSURE, ior=1.5)
            np.testing.assert_allclose(rgba, image, rtol=1e-5, atol=1e-6 * float(image[..., :3].max()))
    finally:
        renderer.release()


def test_compact_disc_render_is_finite_lit_on_the_disc_and_zero_outside(scene):
    import time

    camera = Camera(distance=0.25, azimuth_deg=-90.0, elevation_deg=45.0)
    mesh = compact_disc()
    buffers = scene.upload(mesh)
    try:
        scene.render_rgba(buffers, camera, Light.directional(45.0, 0.0), (64, 64), exposure=EXPOSURE)  # compile
        start = time.perf_counter()
        image = scene.render_rgba(buffers, camera, Light.directional(45.0, 0.0), (64, 64), exposure=EXPOSURE)
        elapsed = time.perf_counter() - start
    finally:
        buffers.release()
    print(f"64×64 CD render: {elapsed * 1000:.0f} ms")
    assert image.shape == (64, 64, 4)
    assert np.all(np.isfinite(image))
    coverage = image[..., 3]
    assert set(np.unique(coverage)) == {0.0, 1.0}
    disc = coverage == 1.0
    assert 0.1 < disc.mean() < 0.6
    assert np.all(image[~disc] == 0.0)  # background: zero XYZ and zero alpha
    xyz = image[..., :3]
    assert np.all(xyz >= 0.0)
    lit = disc & (xyz.max(axis=-1) > 0.0)
    assert lit.sum() > 0.5 * disc.sum()  # the network is > 0 almost everywhere on the disc
    assert np.count_nonzero(xyz[..., 1] > 0.01) >= 5  # and some diffraction order is visible
    # The corners and the centre hole are background.
    assert not disc[0, 0] and not disc[-1, -1] and not disc[32, 32]


@pytest.mark.parametrize("theta", [89.0, 89.99, 90.0, 95.0])
def test_sphere_render_is_finite_at_grazing_light(scene, theta):
    camera = Camera(distance=0.2, azimuth_deg=0.0, elevation_deg=10.0)
    image = scene.render_rgba(sphere(0.05, 32, 16), camera, Light.directional(theta, 180.0), (32, 32),
                              exposure=EXPOSURE, ior=1.5)
    assert np.all(np.isfinite(image))
    assert np.all(image[..., :3] >= 0.0)
    assert 0.1 < image[..., 3].mean() < 0.9
    assert np.all(image[image[..., 3] == 0.0] == 0.0)


def test_sphere_keys_match_the_analytic_sphere_and_vanish_at_the_mirror_point(scene):
    """The key layer against numpy on the exact sphere: outward normal, tangent eastwards along the parallels."""
    camera = Camera(distance=0.2, azimuth_deg=0.0, elevation_deg=20.0, fov_deg=40.0)
    light = Light.directional(30.0, 60.0)
    image, key_a = scene.render_layers(sphere(0.05, 64, 32), camera, light, (48, 48), exposure=EXPOSURE)
    rows, columns = np.mgrid[0:48, 0:48]
    expected = np.full((48, 48, 3), np.nan)
    latitude = np.full((48, 48), 90.0)
    facing = np.zeros((48, 48))  # cos θo: near the limb the faceted mesh is hit far from the sphere's point
    for row, column in zip(rows.ravel(), columns.ravel(), strict=True):
        eye, ray = camera.pixel_ray(row, column, 48, 48)
        b = float(np.dot(eye, ray))
        discriminant = b * b - (float(np.dot(eye, eye)) - 0.05**2)
        if discriminant < 0.0:
            continue
        normal = (eye - (b + np.sqrt(discriminant)) * ray) / 0.05
        latitude[row, column] = np.degrees(np.arcsin(normal[2]))
        facing[row, column] = -float(np.dot(normal, ray))
        east = np.cross([0.0, 0.0, 1.0], normal)
        tangent = east / np.linalg.norm(east)
        frame = np.stack([tangent, np.cross(normal, tangent), normal])  # rows t, b, n
        expected[row, column] = -(frame @ np.asarray(light.vector) + frame @ -ray)
    lit = (key_a[..., 3] > 0.0) & np.all(np.isfinite(expected), axis=-1)
    # Pixels well inside the silhouette and away from the pole, where the interpolated tangent turns
    # fast (the mesh is faceted: its normals are off by ~1e-3 inside a facet).
    inside = lit & (facing > 0.5) & (np.abs(latitude) < 60.0)
    assert inside.sum() > 200
    np.testing.assert_allclose(key_a[inside, :3], expected[inside], atol=0.02)
    # The pixel whose key is closest to the specular (u = v = 0) is the analytic mirror point.
    planar = np.where(inside, np.linalg.norm(key_a[..., :2], axis=-1), np.inf)
    analytic = np.where(inside, np.linalg.norm(expected[..., :2], axis=-1), np.inf)
    assert np.unravel_index(np.argmin(planar), planar.shape) == np.unravel_index(np.argmin(analytic), planar.shape)
    assert np.all(image[~lit & (image[..., 3] == 1.0), :3] == 0.0)


def test_back_faces_and_light_below_the_horizon_are_black(scene):
    camera_below = Camera(distance=0.3, azimuth_deg=0.0, elevation_deg=-60.0)
    image = scene.render_rgba(plane(1.0), camera_below, Light.directional(30.0, 0.0), (16, 16), exposure=EXPOSURE)
    assert np.all(image[..., 3] == 1.0) and np.all(image[..., :3] == 0.0)  # covered, unlit back face
    camera = Camera(distance=0.3, azimuth_deg=0.0, elevation_deg=60.0)
    image = scene.render_rgba(plane(1.0), camera, Light.directional(120.0, 0.0), (16, 16), exposure=EXPOSURE)
    assert np.all(image[..., 3] == 1.0) and np.all(image[..., :3] == 0.0)


def test_degenerate_tangent_is_replaced_in_the_shader(scene):
    base = plane(0.2)
    mesh = Mesh(base.positions, base.normals, base.tangents, base.uvs, base.indices)
    object.__setattr__(mesh, "tangents", np.zeros_like(base.tangents))  # bypass validation on purpose
    camera = Camera(distance=0.3, azimuth_deg=30.0, elevation_deg=55.0)
    image = scene.render(mesh, camera, Light.directional(35.0, 210.0), (9, 9), exposure=EXPOSURE)
    assert np.all(np.isfinite(image)) and image[4, 4, 1] > 0.0


def test_render_display_paths_agree(scene):
    from gratnet.display import xyz_to_display_srgb8

    xyz = np.random.default_rng(1).uniform(0.0, 1.2, (5, 6, 3)).astype(np.float32)
    np.testing.assert_array_equal(scene.display_srgb8(xyz), xyz_to_display_srgb8(xyz, 1.0))
    gpu = np.round(scene.network.display_srgb(xyz, 1.0) * 255.0)
    assert np.max(np.abs(gpu - scene.display_srgb8(xyz))) <= 1


# --------------------------------------------------------------------------------------------------
# gratnet render


def test_render_cli_writes_png_exr_and_config(ctx, tmp_path, capsys):
    import json

    import OpenEXR
    from PIL import Image

    png = tmp_path / "disc.png"
    common = ["render", "--material", "blazed", "--mesh", "cd", "--light", "45,0", "--camera", "0.25,-90,45",
              "--exposure", "5000", "--size", "40,24"]
    assert main([*common, "--out", str(png)]) == 0
    with Image.open(png) as image:
        assert image.size == (40, 24) and image.mode == "RGB"
        pixels = np.asarray(image)
    assert pixels.max() > 0
    config = json.loads((tmp_path / "disc.config.json").read_text())
    assert config["render"]["width"] == 40 and config["render"]["height"] == 24
    assert config["render"]["light_theta_degrees"] == 45.0 and config["render"]["mesh"] == "cd"
    assert config["model_file"].endswith("model.npz")

    exr = tmp_path / "disc_linear.exr"
    assert main([*common, "--no-fresnel", "--out", str(exr)]) == 0
    with OpenEXR.File(str(exr), separate_channels=True) as file:
        channels = {name: channel.pixels for name, channel in file.channels().items()}
    assert sorted(channels) == ["B", "G", "R"]
    assert channels["R"].shape == (24, 40) and channels["R"].dtype == np.float32
    rgb = np.stack([channels[c] for c in "RGB"], axis=-1)
    assert np.all(np.isfinite(rgb)) and rgb.max() > 0.0
    assert json.loads((tmp_path / "disc_linear.config.json").read_text())["render"]["fresnel"] is False

    slice_png = tmp_path / "slice.png"
    assert main(["render", "--material", str(BLAZED), "--slice", "--light", "30,0", "--size", "24,24",
                 "--exposure", "5000", "--out", str(slice_png)]) == 0
    with Image.open(slice_png) as image:
        assert image.size == (24, 24)
    assert "wrote" in capsys.readouterr().out


def test_render_cli_obj_mesh(ctx, tmp_path):
    obj = tmp_path / "cube.obj"
    obj.write_text(CUBE_OBJ)
    out = tmp_path / "cube.png"
    assert main(["render", "--mesh", str(obj), "--camera", "4,30,35", "--size", "16,16", "--out", str(out)]) == 0
    assert out.is_file()


@pytest.mark.parametrize(
    ("arguments", "message"),
    [
        (["--material", "no-such-material"], "unknown material"),
        (["--mesh", "torus"], "unknown mesh"),
        (["--mesh", "missing.obj"], "does not exist"),
        (["--size", "abc"], "--size"),
        (["--size", "0,10"], "--size"),
        (["--size", "10.5,10"], "--size"),
        (["--light", "30"], "--light"),
        (["--camera", "1,2"], "--camera"),
        (["--ior", "-1"], "ior"),  # 1 is accepted: the limit of R/R0 (physics.md)
        (["--slice", "--size", "10,20"], "square"),
        (["--exposure", "nan"], "exposure"),
    ],
)
def test_render_cli_bad_input_exits_2_with_one_line(tmp_path, capsys, arguments, message):
    out = tmp_path / "x.png"
    assert main(["render", *arguments, "--out", str(out)]) == 2
    captured = capsys.readouterr()
    lines = captured.err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("gratnet render: error:") and message in lines[0], captured.err
    assert not out.exists() and not (tmp_path / "x.config.json").exists()


def test_render_cli_bad_mesh_file_and_suffix(tmp_path, capsys):
    bad = tmp_path / "bad.obj"
    bad.write_text("v 0 0\n")
    assert main(["render", "--mesh", str(bad), "--out", str(tmp_path / "x.png")]) == 2
    assert "truncated" in capsys.readouterr().err
    assert main(["render", "--out", str(tmp_path / "x.jpg")]) == 2
    assert ".png" in capsys.readouterr().err


def test_render_cli_without_egl_says_so(tmp_path, capsys, monkeypatch):
    import viewer.context

    def no_egl():
        raise GratNetError("cannot create a headless OpenGL 4.3 context through EGL (test); install EGL and Mesa")

    monkeypatch.setattr(viewer.context, "create_headless_context", no_egl)
    assert main(["render", "--size", "8,8", "--out", str(tmp_path / "x.png")]) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and "EGL" in lines[0]
    assert not (tmp_path / "x.png").exists()
