"""What several test modules share: the repository's paths, random models and key sets, the plane's numpy
reference, small meshes and the viewer's fake clock. Test modules import from here (and take fixtures from
conftest.py), never from one another: tests/contract/test_architecture.py checks that.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from gratnet.brdf import a_term, direction
from gratnet.encoding import EncodingSpec, RangeSpec
from gratnet.environment import Environment
from gratnet.modelfile import ModelFile, evaluate_keys
from gratnet.precision import (
    OWN_KEYS,
    UNIT_ROUNDOFF,
    DriverErrors,
    assert_within,
    driver_bound,
    exceeding,
    raster_key_error,
)
from gratnet.shadowing import NO_SHADOWING, model_slope_covariance, smith_shadowing
from viewer.renderer import xyz_to_linear_srgb_matrix
from viewer.state import ViewerState

if TYPE_CHECKING:
    import pytest

    from viewer.camera import Camera, Light

#: The repository's root (tests/ is one below it).
REPO = Path(__file__).resolve().parents[1]
#: The shipped models and their files.
ASSETS = REPO / "assets"
#: Data shared between checkouts (height-field scans), beside the repository; tests skip without it.
SHARED_DATA = REPO.parent / "shared" / "data"


# --------------------------------------------------------------------------------------------------
# Random models and keys (the GLSL parity tests, the deferred and tiled paths, the precision bound)


#: random_model's encoding.
SPEC = EncodingSpec.for_grid(101, 5)  # 163 features, s ≈ 1.24, top frequency 50π
#: The GLSL parity tests' relative tolerance (assert_relative).
RELATIVE = 1e-4


def random_model(
    sizes: list[int],
    activation: str = "silu",
    output_activation: str = "clamp",
    scheme: str = "regular",
    range_kind: str = "power-log",
    spec: EncodingSpec = SPEC,
    seed: int = 0,
) -> ModelFile:
    """A random funnel whose outputs mostly land inside (0, 1), where eq. 7 is well conditioned."""
    rng = np.random.default_rng(seed)
    weights, biases = [], []
    for inputs, outputs in zip(sizes[:-1], sizes[1:], strict=False):
        weights.append((rng.standard_normal((outputs, inputs)) / np.sqrt(inputs)).astype(np.float32))
        biases.append((0.1 * rng.standard_normal(outputs)).astype(np.float32))
    weights[-1] = (0.3 * weights[-1]).astype(np.float32)
    biases[-1] = np.array([0.55, 0.6, 0.65], dtype=np.float32)
    return ModelFile(list(sizes), weights, biases, activation, output_activation, spec, RangeSpec(kind=range_kind),
                     scheme)


def random_grid_model(features: int, levels: int, dtype: str, interpolation: str = "linear",
                      seed: int = 5, diagonals: bool = True) -> ModelFile:
    """A random feature-grid model: 2 hidden layers of 21, outputs mostly inside (0, 1); levels of 7, 13 and 25
    nodes a side (odd widths) and 5, 3, 2 along t (levels differ along t too, down to the fewest a level may
    have). ``diagonals``: eq. 6's c_u ± c_v groups (False: eq. 6a)."""
    rng = np.random.default_rng(seed)
    spec = EncodingSpec.for_grid(101, 5, 4, 2, diagonals)
    grids = [(0.5 * rng.standard_normal((t_nodes, nodes, nodes, features))).astype(dtype)
             for nodes, t_nodes in list(zip((7, 13, 25), (5, 3, 2), strict=True))[:levels]]
    sizes = [levels * features + spec.features, 21, 21, 3]
    weights = [(rng.standard_normal((b, a)) / np.sqrt(a)).astype(np.float32)
               for a, b in zip(sizes[:-1], sizes[1:], strict=True)]
    weights[-1] = (0.3 * weights[-1]).astype(np.float32)
    biases = [(0.1 * rng.standard_normal(b)).astype(np.float32) for b in sizes[1:]]
    biases[-1] = np.array([0.55, 0.6, 0.65], dtype=np.float32)
    model = ModelFile(sizes, weights, biases, "silu", "clamp", spec, RangeSpec(), "simple-max", grids=grids)
    model.grid_interpolation = interpolation
    return model



def top_sine_columns(model: ModelFile) -> list[int]:
    """The first-layer columns of the top frequency's sine of every spatial group and of t: eq. 6's layout, typed
    here apart from trainer.unseen (which finds them by evaluating the encoding on the lattice)."""
    spec, grid = model.encoding, model.grid_feature_count
    L, Lt = spec.frequencies, spec.t_frequencies
    return [grid + 3 + 2 * L * g + L - 1 for g in range(spec.groups)] + [grid + 3 + 2 * spec.groups * L + Lt - 1]


def parity_keys() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """~270 key vectors: random direction pairs plus normal incidence, |w| → 0 and u² + v² → 4."""
    rng = np.random.default_rng(7)
    count = 220
    theta = np.degrees(np.arccos(rng.uniform(0.0, 1.0, (2, count))))  # uniform over the hemisphere
    phi = rng.uniform(0.0, 360.0, (2, count))
    light = np.stack([direction(t, p) for t, p in zip(theta[0], phi[0], strict=True)])
    view = np.stack([direction(t, p) for t, p in zip(theta[1], phi[1], strict=True)])
    keys = [-(light + view)]
    keys.append(np.array([[0.0, 0.0, w] for w in (0.0, -1e-7, -1e-3, -0.5, -1.0, -1.999, -2.0)]))
    angles = np.radians(np.arange(0.0, 360.0, 30.0))
    for gap in (1e-2, 1e-3, 1e-5):  # u² + v² = 4 − gap, with w inside the physical ball and just at its edge
        radius = np.sqrt(4.0 - gap)
        for w in (0.0, -0.5 * np.sqrt(gap), -np.sqrt(gap)):
            keys.append(np.stack([radius * np.cos(angles), radius * np.sin(angles), np.full_like(angles, w)], -1))
    keys.append(np.array([[2.0, 0.0, 0.0], [0.0, -2.0, 0.0], [1.0, 1.0, -1e-6], [-0.3, 0.2, -2.0]]))
    stacked = np.concatenate(keys)
    # The GPU receives float32 keys; the reference is evaluated at exactly those values.
    stacked = stacked.astype(np.float32).astype(np.float64)
    return stacked[:, 0], stacked[:, 1], stacked[:, 2]


def assert_relative(actual: np.ndarray, expected: np.ndarray, relative: float, floor: float) -> None:
    error = np.abs(np.asarray(actual, dtype=np.float64) - expected)
    allowed = relative * np.maximum(np.abs(expected), floor)
    worst = int(np.argmax(error / allowed))
    assert np.all(error <= allowed), (
        f"max error {error.flat[worst]:.3g} at {np.unravel_index(worst, error.shape)} "
        f"(value {expected.flat[worst]:.6g}), allowed {allowed.flat[worst]:.3g}"
    )


# --------------------------------------------------------------------------------------------------
# GLSL sources written to a folder (the preprocessor's error messages: the parity and the baked path's tests)


def write_shaders(root: Path, files: dict[str, str]) -> Path:
    for name, text in files.items():
        (root / name).write_text(text, encoding="utf-8")
    return root


PROGRAM = """// a test program
#include "fullscreen_test.glsl"
#ifdef FRAGMENT_SHADER
#include "broken.glsl"
layout(location = 0) out vec4 colour;
void main() { colour = vec4(helper()); }
#endif
"""
FULLSCREEN = """#ifdef VERTEX_SHADER
void main() { gl_Position = vec4(0.0, 0.0, 0.0, 1.0); }
#endif
"""


# --------------------------------------------------------------------------------------------------
# Model files


def flip_in_member(path: Path, name: str, offset: int | None = None, mask: int = 0x40) -> bytes:
    """The bytes of the archive at ``path`` with one byte of member ``name``'s stored (deflated or not) data XORed
    with ``mask``: ``offset`` bytes into that data (its middle by default), never in a zip header, whose spare
    fields (times, extras) no reader checks."""
    import zipfile

    data = bytearray(path.read_bytes())
    with zipfile.ZipFile(path) as archive:
        member = archive.getinfo(name)
    header = member.header_offset  # local header: 30 bytes, then the name and the extra field (lengths at 26, 28)
    start = header + 30 + int.from_bytes(data[header + 26:header + 28], "little") + int.from_bytes(
        data[header + 28:header + 30], "little")
    offset = member.compress_size // 2 if offset is None else offset
    assert 0 <= offset < member.compress_size
    data[start + offset] ^= mask
    return bytes(data)


# --------------------------------------------------------------------------------------------------
# The plane render's numpy reference (the forward and deferred paths, the precision bound)


def plane_geometry(camera: Camera, light: Light, size: tuple[int, int],
                   slope_covariance: tuple[float, float, float] = NO_SHADOWING) -> dict[str, np.ndarray]:
    """Each pixel's ray hitting the infinite plane z = 0 (float64, ``(H, W, …)``): the surface ``point``, the
    ``key`` −(ωi + ωo), ``a`` = A(ωi, ωo) (ior 1.5) times Smith's shadowing for ``slope_covariance`` and the
    point light's ``irradiance`` there (1/d²)."""
    width, height = size
    points, views = [], []
    for row in range(height):
        for column in range(width):
            eye, ray = camera.pixel_ray(row, column, width, height)
            points.append(eye - eye[2] / ray[2] * ray)
            views.append(-ray)
    points, views = np.array(points), np.array(views)
    offsets = np.asarray(light.vector) - points
    distances = np.linalg.norm(offsets, axis=1, keepdims=True)
    lights = offsets / distances
    return {"point": points.reshape(height, width, 3), "key": (-(lights + views)).reshape(height, width, 3),
            "a": (a_term(lights, views, 1.5) * smith_shadowing(lights, views, slope_covariance)).reshape(height, width),
            "irradiance": (light.intensity / distances[:, 0] ** 2).reshape(height, width)}


def point_of_key(points: np.ndarray, key: np.ndarray, eye: np.ndarray, light: np.ndarray) -> np.ndarray:
    """The points of z = 0 (float64, ``(…, 3)``) whose key −(ωi + ωo) for a point light at ``light`` and the eye
    at ``eye`` is ``key``, by Gauss–Newton from ``points`` (the rays' points: within a sub-pixel step)."""

    def key_at(p: np.ndarray) -> np.ndarray:
        to_light, to_eye = light - p, eye - p
        return -(to_light / np.linalg.norm(to_light, axis=-1, keepdims=True)
                 + to_eye / np.linalg.norm(to_eye, axis=-1, keepdims=True))

    p = np.array(points, dtype=np.float64)
    step = 1e-6  # metres: the finite-difference Jacobian's step (the key is smooth at this scale)
    for _ in range(4):
        residual = key_at(p) - key
        columns = []
        for axis in (0, 1):
            moved = p.copy()
            moved[..., axis] += step
            columns.append((key_at(moved) - key_at(p)) / step)
        jacobian = np.stack(columns, axis=-1)  # (…, 3, 2)
        normal = np.swapaxes(jacobian, -1, -2) @ jacobian
        delta = np.linalg.solve(normal, (np.swapaxes(jacobian, -1, -2) @ residual[..., None]))[..., 0]
        p[..., :2] -= delta
    return p


def check_plane_against_numpy(image: np.ndarray, key_a: np.ndarray, model, camera: Camera, light: Light,
                              size: tuple[int, int], exposure: float, errors: DriverErrors = OWN_KEYS,
                              slope_covariance: tuple[float, float, float] | None = None) -> None:
    """A plane render against numpy in two well-conditioned steps (docs/physics.md, "Float32 error budget").

    1. Geometry: the key layer against float64 rays, within what a rasterizer's sub-pixel snapping moves
       (``raster_key_error``); A likewise (times Smith's shadowing for ``slope_covariance``; None: the model's).
    2. Shading: ``image`` against exposure · irradiance · A · XYZ(key) at the key and A the shader used
       (``key_a``: the forward path's key layer), within ``driver_bound``; the irradiance at the surface point
       whose key is the shader's (``point_of_key``: the sub-pixel move taken out, so a 0.1 % error in the
       value is not hidden behind the 1/d² of a point 2⁻⁸ pixel away).
    Comparing the values through the float64 key instead would let a key error of 1e-5 move this model's
    specular peak (pixel (10, 13): 716.6, v = 0.004, on eq. 6's sqrt) by 3 %: ill-conditioned.
    """
    if slope_covariance is None:  # the model's own (gratnet.shadowing), as the renderer takes it
        slope_covariance = model_slope_covariance(model)
    geometry = plane_geometry(camera, light, size, slope_covariance)
    covered = np.ones(image.shape[:2], dtype=bool)
    assert np.all(image[..., 3] == 1.0)
    key_error = raster_key_error(geometry["key"], covered)
    assert_within(key_a[..., :3], geometry["key"], key_error[..., None], "key components")
    a_error = raster_key_error(geometry["a"][..., None], covered) - 16.0 * UNIT_ROUNDOFF + 1e-5 * geometry["a"]
    assert_within(key_a[..., 3], geometry["a"], a_error, "A values")
    key = key_a[..., :3].astype(np.float64)
    bound = driver_bound(model, key[..., 0], key[..., 1], key[..., 2], errors)
    point = point_of_key(geometry["point"], key, camera.eye(), np.asarray(light.vector))
    irradiance = light.intensity / np.sum((np.asarray(light.vector) - point) ** 2, axis=-1)
    factor = exposure * irradiance * key_a[..., 3].astype(np.float64)
    expected = factor[..., None] * bound.xyz
    # The float32 products exposure · irradiance · A · XYZ and the key's own rounding through the 1/d² fit.
    tolerance = factor[..., None] * bound.bound + 64.0 * UNIT_ROUNDOFF * expected
    assert expected.max() > 1e-3
    assert_within(image[..., :3], expected, tolerance, "exposed XYZ values")


# --------------------------------------------------------------------------------------------------
# Meshes and the viewer


def two_planes():
    """Two overlapping squares facing +z, the far one (z = 0) drawn first: overdraw without a pre-pass."""
    from viewer.meshes import Mesh, plane

    far, near = plane(0.1), plane(0.06)
    positions = np.concatenate([far.positions, near.positions + np.float32([0.0, 0.0, 0.01])])
    indices = np.concatenate([far.indices, near.indices + np.uint32(far.positions.shape[0])])
    return Mesh(positions, np.concatenate([far.normals, near.normals]),
                np.concatenate([far.tangents, near.tangents]), np.concatenate([far.uvs, near.uvs]),
                indices.astype(np.uint32))


#: A view of the plane that shows the blazed grating's diffraction streak (the viewer's tests).
PLANE = ViewerState(mesh="plane", camera_distance=0.15, camera_elevation=50.0, light_theta=30.0, light_phi=90.0,
                    exposure=5000.0)


class FakeClock:
    """A clock the test advances by hand."""

    def __init__(self) -> None:
        self.now = 1000.0

    def __call__(self) -> float:
        return self.now

    def advance(self, seconds: float) -> None:
        self.now += seconds


# --------------------------------------------------------------------------------------------------
# Materials with quality points (gratnet.quality, viewer.catalog)


def write_material(assets: Path, name: str, points: dict[str, ModelFile]) -> dict[str, Path]:
    """A shipped material ``assets/NAME`` with one model file per quality point (``points``: quality name →
    model, each saved where gratnet.quality's folders put it). Returns quality → model file."""
    from gratnet.modelfile import save_model
    from gratnet.quality import POINT_FOLDERS

    paths = {}
    for quality, model in points.items():
        path = assets / name / POINT_FOLDERS[quality] / "model.npz"
        path.parent.mkdir(parents=True, exist_ok=True)
        save_model(path, model)
        paths[quality] = path
    return paths


def two_point_material(assets: Path, name: str = "duo", fast: bool = True) -> dict[str, Path]:
    """A material of random models at ``assets/NAME``: the accurate point a wider net (hidden 16) than the fast
    one (hidden 8; left out without ``fast``), both claiming the shipped cd material's surface and display
    analysis (its ``metadata``), so that its ground-truth volumes and default views are cd's."""
    import dataclasses

    from gratnet.modelfile import load_model

    metadata = {key: value for key, value in load_model(ASSETS / "cd" / "model.npz").metadata.items()
                if key in ("volume", "display")}
    points = {"accurate": dataclasses.replace(random_model([SPEC.features, 16, 3], seed=1), metadata=metadata)}
    if fast:
        points["fast"] = dataclasses.replace(random_model([SPEC.features, 8, 3], seed=2), metadata=metadata)
    return write_material(assets, name, points)


# --------------------------------------------------------------------------------------------------
# Bad input (tests/contract/test_bad_input*.py)


def run_cli(argv: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str]:
    """``gratnet ARGV``'s exit status and stderr."""
    from gratnet.cli import main

    code = main(argv)
    return code, capsys.readouterr().err


def shown_lines(stderr: str) -> list[str]:
    """``stderr`` as a terminal leaves it: each line's text after its last carriage return (a progress bar that
    cleared itself, tqdm's ``leave=False``, leaves nothing), blank lines dropped."""
    return [shown for line in stderr.split("\n") if (shown := line.rsplit("\r", 1)[-1].strip())]


def assert_one_clear_error(code: int, stderr: str, command: str, *needles: str) -> None:
    lines = shown_lines(stderr)
    assert code == 2, (code, stderr)
    assert len(lines) == 1, stderr
    assert lines[0].startswith(f"gratnet {command}: error: "), stderr
    assert "Traceback" not in stderr
    for needle in needles:
        assert needle in lines[0], stderr


def assert_nothing_written(folder: Path, before: set[str]) -> None:
    """No new file in ``folder`` (atomic writers leave no ``.NAME.*.tmp*`` behind either)."""
    after = {path.name for path in folder.iterdir()} if folder.is_dir() else set()
    assert after <= before, sorted(after - before)


# --------------------------------------------------------------------------------------------------
# Sampling (χ² of directions against their density)


def solid_angle_chi2(directions: np.ndarray, density: Callable[[np.ndarray], np.ndarray], count: int,
                     bins: tuple[int, int], sub: int) -> tuple[float, float]:
    """A χ² test of sampled unit ``directions`` (the valid ones of ``count`` draws) against ``density`` (sr⁻¹ of
    ``(N, 3)`` directions) over a (cos θ, φ) histogram of ``bins``; each bin's expectation by the midpoint rule on
    ``sub`` × ``sub`` points (d(solid angle) = d cos θ · dφ), bins expected to hold fewer than 5 samples pooled, as
    Mitsuba's ChiSquareTest does. Returns ``(p-value, expected total)``: the density's integral times ``count``."""
    import math

    from scipy import stats

    bins_cos, bins_phi = bins
    histogram, _, _ = np.histogram2d(directions[:, 2], np.arctan2(directions[:, 1], directions[:, 0]),
                                     bins=[bins_cos, bins_phi], range=[[0.0, 1.0], [-math.pi, math.pi]])
    c = (np.arange(bins_cos * sub) + 0.5) / (bins_cos * sub)
    p = -math.pi + 2.0 * math.pi * (np.arange(bins_phi * sub) + 0.5) / (bins_phi * sub)
    cc, pp = np.meshgrid(c, p, indexing="ij")
    s = np.sqrt(1.0 - cc * cc)
    grid = np.stack([s * np.cos(pp), s * np.sin(pp), cc], -1).reshape(-1, 3)
    values = np.asarray(density(grid)).reshape(bins_cos * sub, bins_phi * sub)
    cell = (1.0 / (bins_cos * sub)) * (2.0 * math.pi / (bins_phi * sub))
    expected = values.reshape(bins_cos, sub, bins_phi, sub).sum(axis=(1, 3)) * cell * count
    order = np.argsort(expected.ravel())
    e, observed = expected.ravel()[order], histogram.ravel()[order]
    keep = e >= 5.0
    pooled_e, pooled_h = np.append(e[keep], e[~keep].sum()), np.append(observed[keep], observed[~keep].sum())
    pooled_e *= pooled_h.sum() / pooled_e.sum()
    return float(stats.chisquare(pooled_h, pooled_e).pvalue), float(expected.sum())


def covered_mean(rgba: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Mean and standard error of the exposed XYZ over the pixels a render covers with every sample (sampled-light
    tests: each pixel an independent estimate of the same integral)."""
    import math

    values = rgba[..., :3][rgba[..., 3] == 1.0].astype(np.float64)
    assert len(values) > 100
    return values.mean(axis=0), values.std(axis=0) / math.sqrt(len(values))


def smooth_random_model(seed: int = 4) -> ModelFile:
    """A random network of low frequencies only (top frequency 2π): A · XYZ barely changes across a small light."""
    spec = EncodingSpec(frequencies=2, t_frequencies=1, scale=2.0, t_scale=2.0)
    return random_model([spec.features, 16, 3], spec=spec, seed=seed)


# ------------------------------------------------------------------------------------------------
# Exported shaders at grazing angles (tests/tools/test_export_shaders.py, test_export_wgsl.py)

#: How far the shader's Smith shadowing may be from gratnet.shadowing's (float64 at the float32 directions):
#: tests/runtime/test_shader_parity.py's test_gpu_shadowing_matches_numpy holds the runtime's brdf.glsl to this.
SHADOWING_RTOL = 2e-5
SHADOWING_ATOL = 1e-6
#: Shipped materials with steep reliefs (rms slopes 0.93 and 0.73): S is far below 1 towards the horizon.
STEEP = ("paper-corner-cubes", "paper-pits")


def model_shadowing(model, wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
    """gratnet.shadowing's S (float64) at the float32 directions, for the model's slope covariance as the runtime
    takes it (gratnet.shadowing.model_slope_covariance; none recorded: S = 1 above the horizon)."""
    return smith_shadowing(wi.astype(np.float64), wo.astype(np.float64), model_slope_covariance(model))


def shade_expectations(model, wi: np.ndarray, wo: np.ndarray, xyz: np.ndarray, xyz_bound: np.ndarray,
                       exposure: float = 3.0, ior: float = 1.5) -> dict[str, np.ndarray]:
    """numpy's gratnet_shade (exposure · A · S · XYZ) and gratnet_shade_unshadowed (exposure · A · XYZ) with their
    bounds: the XYZ within ``xyz_bound``, A as the runtime's own A-term test allows it (RELATIVE), S as its shadowing
    test does (SHADOWING_RTOL, SHADOWING_ATOL)."""
    a = a_term(wi.astype(np.float64), wo.astype(np.float64), ior)[:, None]
    s = model_shadowing(model, wi, wo)[:, None]
    unshadowed = exposure * a * xyz
    unshadowed_bound = exposure * (a * xyz_bound + RELATIVE * a * np.abs(xyz))
    return {"a": a[:, 0], "s": s[:, 0], "unshadowed": unshadowed, "unshadowed_bound": unshadowed_bound,
            "shade": s * unshadowed,
            "shade_bound": s * unshadowed_bound + (SHADOWING_RTOL * s + SHADOWING_ATOL) * np.abs(unshadowed)}


def grazing_directions(count: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Unit direction pairs (float32) towards the horizon, where Smith's S of a steep relief is far below 1: a
    quarter mirror pairs (the specular peak) at 60°…89.5°, a quarter with the light at 75°…89.9° and the view
    anywhere above the horizon, a quarter the other way round, a quarter both at 75°…89.9°; azimuths at random."""
    rng = np.random.default_rng(seed)
    quarter = count // 4

    def at(theta_degrees: np.ndarray, phi_degrees: np.ndarray) -> np.ndarray:
        theta, phi = np.radians(theta_degrees), np.radians(phi_degrees)
        return np.stack([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)], axis=-1)

    def azimuths(n: int = quarter) -> np.ndarray:
        return rng.uniform(0.0, 360.0, n)

    def grazing(n: int = quarter) -> np.ndarray:
        return rng.uniform(75.0, 89.9, n)

    def anywhere(n: int = quarter) -> np.ndarray:
        return np.degrees(np.arccos(rng.uniform(0.02, 1.0, n)))

    mirror_theta, mirror_phi = rng.uniform(60.0, 89.5, quarter), azimuths()
    wi = np.concatenate([at(mirror_theta, mirror_phi), at(grazing(), azimuths()), at(anywhere(), azimuths()),
                         at(grazing(), azimuths())])
    wo = np.concatenate([at(mirror_theta, mirror_phi + 180.0), at(anywhere(), azimuths()), at(grazing(), azimuths()),
                         at(grazing(), azimuths())])
    assert wi.shape == (count, 3)
    return wi.astype(np.float32), wo.astype(np.float32)


def check_grazing_shadowing(name: str, model, results: list[np.ndarray], wi: np.ndarray, wo: np.ndarray,
                            errors=OWN_KEYS) -> dict[str, float]:
    """gratnet_shade against numpy's exposure · A · S · XYZ and gratnet_shade_unshadowed against exposure · A · XYZ
    at :func:`grazing_directions`; the ratio of the two against S. ``results``: (shade, unshadowed). Returns the
    largest relative difference of the shade from numpy (over values above 10⁻³ of its peak) and of the ratio
    from S."""
    shade, unshadowed = results
    key = -(wi + wo)
    u, v, w = (key[:, i].astype(np.float64) for i in range(3))
    xyz = evaluate_keys(model, u, v, w)
    expected = shade_expectations(model, wi, wo, xyz, driver_bound(model, u, v, w, errors).bound)
    s = expected["s"]
    # The test can see S: a shader without it (or with S = 1) would be off by 1/S, far beyond the bounds.
    assert np.all(expected["a"] > 0) and np.median(s) < 0.6 and s.min() < 0.1, (name, np.median(s), s.min())
    assert_within(shade, expected["shade"], expected["shade_bound"], f"{name}: gratnet_shade at grazing angles",
                  floor=1e-30)
    assert_within(unshadowed, expected["unshadowed"], expected["unshadowed_bound"],
                  f"{name}: gratnet_shade_unshadowed at grazing angles", floor=1e-30)
    # ...and a shader without S would not pass: the unshadowed value is outside the shadowed bound almost everywhere.
    assert np.mean(exceeding(unshadowed, expected["shade"], expected["shade_bound"], floor=1e-30).any(axis=1)) > 0.9
    # The same network value in both: their ratio is the shader's S alone, free of the network's error.
    lit = np.abs(unshadowed) > 1e-30
    assert np.count_nonzero(lit.all(axis=1)) > 0.9 * len(s), f"{name}: {np.count_nonzero(lit.all(axis=1))} pairs lit"
    ratio = np.where(lit, shade / np.where(lit, unshadowed, 1.0), np.nan)
    ratio_error = np.abs(ratio - s[:, None])
    assert np.nanmax(ratio_error / (SHADOWING_RTOL * s[:, None] + SHADOWING_ATOL)) <= 1.0, (
        f"{name}: gratnet_shade / gratnet_shade_unshadowed is not S: off by {np.nanmax(ratio_error):.3g}")
    bright = np.abs(expected["shade"]) > 1e-3 * np.abs(expected["shade"]).max()
    return {"shade": float((np.abs(shade - expected["shade"])[bright] / np.abs(expected["shade"])[bright]).max()),
            "ratio": float(np.nanmax(ratio_error / s[:, None]))}


def structured_map(height: int = 64) -> np.ndarray:
    """Linear sRGB radiance with colour, azimuthal structure and a bright blob, dark within 20° of the horizon
    and below it (A · XYZ grows as 1/cos θi at grazing light: a dark horizon keeps the integral's variance finite)."""
    width = 2 * height
    theta = np.pi * (np.arange(height) + 0.5) / height
    phi = 2 * np.pi * (np.arange(width) + 0.5) / width
    t, p = np.meshgrid(theta, phi, indexing="ij")
    radiance = np.stack([1.0 + 0.5 * np.cos(p), 0.8 + 0.3 * np.sin(2 * p), 0.6 + 0.4 * np.cos(t)], axis=-1)
    blob = np.exp(-((t - 0.6) ** 2 + np.angle(np.exp(1j * (p - 2.0))) ** 2) / 0.02)
    radiance = radiance + 20.0 * blob[..., None] * np.array([1.0, 0.9, 0.7])
    radiance[t > math.radians(70.0)] = 0.0
    return radiance.astype(np.float32)


def hemisphere_integral(model, environment: Environment, wo: np.ndarray, ior: float = 1.5,
                        steps: int = 600) -> np.ndarray:
    """∫ A(ωi, ωo) · XYZ(−(ωi + ωo)) ⊙ L(ωi) dωi over the upper hemisphere (plane: tangent frame = world), CIE XYZ,
    midpoint rule in (θ, φ) with ``steps`` × 2·``steps`` cells; the colour product in linear sRGB."""
    theta = (np.arange(steps) + 0.5) / steps * (np.pi / 2)
    phi = (np.arange(2 * steps) + 0.5) / (2 * steps) * (2 * np.pi)
    t, p = np.meshgrid(theta, phi, indexing="ij")
    wi = np.stack([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)], axis=-1)
    key = -(wi + wo)
    xyz = evaluate_keys(model, key[..., 0], key[..., 1], key[..., 2])
    a = a_term(wi.reshape(-1, 3), np.broadcast_to(wo, (wi.size // 3, 3)), ior).reshape(t.shape)
    to_rgb = xyz_to_linear_srgb_matrix()
    rgb = np.einsum("ij,...j->...i", to_rgb, xyz) * environment.radiance(wi.reshape(-1, 3)).reshape(wi.shape)
    cell = (np.pi / 2 / steps) * (np.pi / steps) * np.sin(t)
    return np.linalg.inv(to_rgb) @ np.einsum("ijc,ij->c", rgb * a[..., None], cell)
