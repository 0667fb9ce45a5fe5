"""The Mitsuba 3 plugin (mitsuba_plugin/): the contract's value, the mesh's tangent frame, sampling, and
agreement with the GL renderer.

- eval parity: the plugin's ``eval`` equals evaluate_keys × a_term × smith_shadowing → linear sRGB (computed here
  from the contract's own functions) at random directions, in ``scalar_rgb`` (one lookup per call) and ``llvm_ad_rgb``;
- tangent frame: on the CD, rays hit the disc and ``eval`` equals the contract in the frame whose x is the
  interpolated vertex tangent, as the GL rasterizer's (along the tracks: viewer.meshes.compact_disc);
- sampling: χ² of the sampled directions against ``pdf`` (Mitsuba's own ChiSquareTest, as its BSDF tests do,
  and a scipy version on the numpy sampler), and sample weights = eval / pdf;
- renders: Mitsuba (llvm_ad_rgb, or scalar_rgb without LLVM ≥ 18; direct lighting, directional light,
  orthographic camera) against ``gratnet render``'s SceneRenderer (a camera 200 m away with a 0.037° field
  of view: orthographic to 1e-4 rad) on the CD; mean FLIP below a stated threshold, and far above it for a
  wrong cosine or a mirrored image;
- ``gratnet mitsuba-render``: writes image + config, refuses bad input with one line.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

mi_module = pytest.importorskip("mitsuba", reason="the mitsuba extra is not installed")

from gratnet.brdf import a_term  # noqa: E402
from gratnet.modelfile import evaluate_keys, load_model  # noqa: E402
from gratnet.shadowing import slope_covariance_from_metadata, smith_shadowing  # noqa: E402
from mitsuba_plugin import shading  # noqa: E402
from mitsuba_plugin.runtime import llvm_usable, set_variant  # noqa: E402
from tests.helpers import solid_angle_chi2  # noqa: E402
from viewer.catalog import ASSETS  # noqa: E402

MATERIAL = ASSETS / "cd" / "model.npz"
needs_llvm = pytest.mark.skipif(not llvm_usable(),
                                reason="Dr.Jit finds no LLVM ≥ 18 (Debian: apt-get install libllvm19)")


def _contract_rgb(model_path: object, light: np.ndarray, view: np.ndarray, ior: float | None) -> np.ndarray:
    """S · A · XYZ(−(ωl + ωv)) → linear sRGB straight from the contract's functions (colour-science matrix; S with
    the model's slope covariance)."""
    import colour

    model = load_model(model_path)
    covariance = slope_covariance_from_metadata(model.metadata["volume"])
    assert covariance != (0.0, 0.0, 0.0)  # the shipped model records its relief's slopes: S is checked too
    key = -(light + view)
    factor = a_term(light, view, ior) * smith_shadowing(light, view, covariance)
    xyz = evaluate_keys(model, key[:, 0], key[:, 1], key[:, 2]) * factor[:, None]
    return np.asarray(colour.XYZ_to_RGB(xyz, "sRGB"))


def _random_hemisphere(rng: np.random.Generator, count: int, min_cos: float = 0.05) -> np.ndarray:
    directions = rng.normal(size=(count, 3))
    directions[:, 2] = np.abs(directions[:, 2])
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    directions[:, 2] = np.maximum(directions[:, 2], min_cos)
    return directions / np.linalg.norm(directions, axis=1, keepdims=True)


def _bsdf(mi: object, **extra: object) -> object:
    return mi.load_dict({"type": "gratnet", "filename": str(MATERIAL), **extra})


# ------------------------------------------------------------------------------------------------
# eval parity


def test_eval_matches_the_contract_one_lookup_at_a_time_in_scalar_rgb() -> None:
    mi = set_variant("scalar_rgb")
    rng = np.random.default_rng(1)
    view, light = _random_hemisphere(rng, 40), _random_hemisphere(rng, 40)
    light[:10] = shading.mirror(view[:10]) + 0.01 * rng.normal(size=(10, 3))  # near the specular peak
    light /= np.linalg.norm(light, axis=1, keepdims=True)
    view, light = (d.astype(np.float32).astype(np.float64) for d in (view, light))  # what Mitsuba holds
    expected = _contract_rgb(MATERIAL, light, view, 1.5)
    bsdf = _bsdf(mi, ior=1.5)
    ctx = mi.BSDFContext()
    got = []
    for v, l in zip(view, light, strict=True):
        si = mi.SurfaceInteraction3f()
        si.wi = mi.Vector3f(*v)
        got.append(np.array(bsdf.eval(ctx, si, mi.Vector3f(*l)), dtype=np.float64))
    got = np.array(got)
    assert np.max(expected) > 0.0
    np.testing.assert_allclose(got, expected, rtol=1e-5, atol=1e-6 * np.max(np.abs(expected)))
    # Below the horizon: 0, as the GL runtime.
    si = mi.SurfaceInteraction3f()
    si.wi = mi.Vector3f(0.3, 0.0, -0.95)
    assert np.all(np.array(bsdf.eval(ctx, si, mi.Vector3f(0.0, 0.0, 1.0))) == 0.0)


@needs_llvm
def test_eval_matches_the_contract_wide_in_llvm_and_importance_mode_swaps_the_cosine() -> None:
    mi = set_variant("llvm_ad_rgb")
    import drjit as dr

    rng = np.random.default_rng(2)
    count = 5000
    view, light = (_random_hemisphere(rng, count).astype(np.float32).astype(np.float64) for _ in range(2))
    for ior in (1.5, None):
        expected = _contract_rgb(MATERIAL, light, view, ior)
        bsdf = _bsdf(mi, ior=0.0 if ior is None else ior)
        si = dr.zeros(mi.SurfaceInteraction3f, count)
        si.wi = mi.Vector3f(*(mi.Float(view[:, k].astype(np.float32)) for k in range(3)))
        wo = mi.Vector3f(*(mi.Float(light[:, k].astype(np.float32)) for k in range(3)))
        got = np.array(bsdf.eval(mi.BSDFContext(), si, wo), dtype=np.float64).reshape(3, -1).T
        # The same float32 directions on both sides: only the float32 colour output differs.
        np.testing.assert_allclose(got, expected, rtol=1e-5, atol=1e-6 * np.max(np.abs(expected)))
    # Importance transport: si.wi is the light side; eval = A·XYZ · cos θ_view / cos θ_light.
    bsdf = _bsdf(mi, ior=1.5)
    ctx = mi.BSDFContext(mi.TransportMode.Importance)
    si = dr.zeros(mi.SurfaceInteraction3f, count)
    si.wi = mi.Vector3f(*(mi.Float(light[:, k].astype(np.float32)) for k in range(3)))
    wo = mi.Vector3f(*(mi.Float(view[:, k].astype(np.float32)) for k in range(3)))
    got = np.array(bsdf.eval(ctx, si, wo), dtype=np.float64).reshape(3, -1).T
    expected = _contract_rgb(MATERIAL, light, view, 1.5) * (view[:, 2] / light[:, 2])[:, None]
    np.testing.assert_allclose(got, expected, rtol=1e-5, atol=1e-6 * np.max(np.abs(expected)))


# ------------------------------------------------------------------------------------------------
# the tangent frame comes from the mesh


@needs_llvm
def test_cd_frame_runs_along_the_tracks() -> None:
    """Rays hitting the CD: eval equals the contract in the frame x = (−sin φ, cos φ, 0) (along the tracks),
    and differs from it when the frame is turned by 90° (so the check can fail)."""
    mi = set_variant("llvm_ad_rgb")
    from mitsuba_plugin import scene as mitsuba_scene
    from viewer import meshes

    rng = np.random.default_rng(3)
    count = 2000
    radius = rng.uniform(0.012, 0.058, count)
    phi = rng.uniform(0.0, 2.0 * math.pi, count)
    points = np.stack([radius * np.cos(phi), radius * np.sin(phi), np.zeros(count)], axis=-1)
    view_world, light_world = _random_hemisphere(rng, count, 0.3), _random_hemisphere(rng, count, 0.3)
    shape = mitsuba_scene.mitsuba_mesh(mi, meshes.compact_disc(), _bsdf(mi, tangent_attribute="vertex_tangent"))
    scene = mi.load_dict({"type": "scene", "disc": shape})
    origins = points + view_world  # 1 m back along the view direction
    ray = mi.Ray3f(mi.Point3f(*(mi.Float(origins[:, k].astype(np.float32)) for k in range(3))),
                   mi.Vector3f(*(mi.Float(-view_world[:, k].astype(np.float32)) for k in range(3))))
    si = scene.ray_intersect(ray)
    assert bool(np.all(np.array(si.is_valid())))
    wo_local = si.to_local(mi.Vector3f(*(mi.Float(light_world[:, k].astype(np.float32)) for k in range(3))))
    got = np.array(si.bsdf().eval(mi.BSDFContext(), si, wo_local), dtype=np.float64).reshape(3, -1).T

    # The GL rasterizer's tangent at the hit: the barycentric mix of the triangle's vertex tangents (the disc is
    # planar, normal +z, so Gram–Schmidt is dropping z), normalised.
    disc = meshes.compact_disc()
    corners = disc.indices[np.array(si.prim_index)]
    hit = np.array(si.p, dtype=np.float64).reshape(3, -1).T
    a, b, c = (disc.positions[corners[:, k], :2].astype(np.float64) for k in range(3))
    matrix = np.stack([b - a, c - a], axis=-1)
    beta_gamma = np.linalg.solve(matrix, (hit[:, :2] - a)[..., None])[..., 0]
    weights = np.concatenate([1.0 - beta_gamma.sum(-1, keepdims=True), beta_gamma], axis=-1)
    tangent = np.einsum("nk,nkd->nd", weights, disc.tangents[corners].astype(np.float64))
    angle = np.arctan2(-tangent[:, 0], tangent[:, 1])  # tangent = (−sin angle, cos angle, 0)
    assert np.max(np.abs(np.angle(np.exp(1j * (angle - phi))))) < 0.01  # along the tracks, to the mesh's resolution

    def in_frame(vectors: np.ndarray, angle: np.ndarray) -> np.ndarray:
        tangent = np.stack([-np.sin(angle), np.cos(angle), np.zeros_like(angle)], -1)
        bitangent = np.cross([0.0, 0.0, 1.0], tangent)
        return np.stack([np.sum(vectors * tangent, -1), np.sum(vectors * bitangent, -1), vectors[:, 2]], -1)

    view_world = np.array(-ray.d, dtype=np.float64).reshape(3, -1).T  # the float32 directions Mitsuba used
    expected = _contract_rgb(MATERIAL, in_frame(light_world, angle), in_frame(view_world, angle), 1.5)
    turned = _contract_rgb(MATERIAL, in_frame(light_world, angle + math.pi / 2),
                           in_frame(view_world, angle + math.pi / 2), 1.5)
    floor = 1e-3 * np.mean(np.abs(expected))

    def relative(values: np.ndarray) -> np.ndarray:
        return np.abs(values - expected) / (np.abs(expected) + floor)

    print(f"CD frame: relative error median {np.median(relative(got)):.2e}, 99th percentile "
          f"{np.percentile(relative(got), 99):.2e}")
    assert np.mean(relative(got) > 1e-3) < 0.01, np.max(relative(got))
    assert np.mean(relative(turned) > 0.1) > 0.15  # measured 0.29: the frame matters


# ------------------------------------------------------------------------------------------------
# sampling


def _numpy_chi2_p_value(theta: float, probability: float, lobe: float, pdf_lobe: float | None = None) -> float:
    """scipy χ² p-value of a (cos θ, φ) histogram of :func:`shading.sample_mixture` against the integrated
    :func:`shading.mixture_pdf` (invalid samples land in no bin; the pdf integrates to the valid share).
    ``pdf_lobe``: a different lobe width for the pdf (a deliberately wrong pdf)."""
    rng = np.random.default_rng(4)
    count = 400_000
    kappa = shading.kappa_for_lobe(lobe)
    pdf_kappa = kappa if pdf_lobe is None else shading.kappa_for_lobe(pdf_lobe)
    view = np.array([[math.sin(math.radians(theta)), 0.0, math.cos(math.radians(theta))]])
    directions, valid = shading.sample_mixture(view, rng.random(count), rng.random(count), rng.random(count),
                                               probability, kappa)
    p_value, expected = solid_angle_chi2(directions[valid],
                                         lambda grid: shading.mixture_pdf(view, grid, probability, pdf_kappa),
                                         count, (40, 80), 6)
    if pdf_lobe is None:
        assert abs(expected - valid.sum()) < 4.0 * math.sqrt(count) + 1e-3 * count
    return p_value


@pytest.mark.parametrize(("theta", "probability", "lobe"), [(0.0, 0.5, 10.0), (50.0, 0.5, 6.0), (75.0, 0.7, 10.0),
                                                             (30.0, 0.0, 2.0)])
def test_numpy_sampler_matches_its_pdf_chi2(theta: float, probability: float, lobe: float) -> None:
    p_value = _numpy_chi2_p_value(theta, probability, lobe)
    print(f"numpy sampler θ={theta}° p={probability} lobe={lobe}°: χ² p-value {p_value:.3f}")
    assert p_value > 0.001


def test_the_chi2_check_rejects_a_pdf_that_is_slightly_off() -> None:
    """The same check with the pdf's lobe 10 % wider than the sampler's rejects it (the check can fail)."""
    assert _numpy_chi2_p_value(50.0, 0.5, 6.0, pdf_lobe=6.6) < 1e-6


def _mitsuba_chi2(mi: object, bsdf: object, theta: float) -> object:
    """Mitsuba's ChiSquareTest (as in its own BSDF tests) of ``bsdf.sample()`` against its ``pdf()`` for the view
    at ``theta`` (degrees, φ = 0); validity is pdf > 0 (the adapter's weight-based one would drop directions where
    the network is 0). Returns the test, run at significance 0.01 (``passed`` set on it)."""
    import drjit as dr
    from mitsuba.chi2 import ChiSquareTest, SphericalDomain

    wi = [math.sin(math.radians(theta)), 0.0, math.cos(math.radians(theta))]
    ctx = mi.BSDFContext()

    def interaction(count: int) -> object:
        si = dr.zeros(mi.SurfaceInteraction3f, count)
        si.wi = mi.Vector3f(*wi)
        return si

    def sample_functor(sample: object, *args: object) -> tuple[object, object]:
        count = dr.width(sample)
        result, weight = bsdf.sample(ctx, interaction(count), sample[0], mi.Point2f(sample[1], sample[2]))
        return result.wo, dr.select(result.pdf > 0.0, mi.Float(1.0), mi.Float(0.0))

    def pdf_functor(wo: object, *args: object) -> object:
        return bsdf.pdf(ctx, interaction(dr.width(wo)), wo)

    test = ChiSquareTest(domain=SphericalDomain(), sample_func=sample_functor, pdf_func=pdf_functor,
                         sample_dim=3, sample_count=200_000, res=101, ires=8)
    test.passed = test.run(significance_level=0.01, quiet=True)
    return test


@needs_llvm
@pytest.mark.parametrize(("theta", "lobe"), [(0.0, 8.0), (45.0, 8.0), (70.0, 4.0), (30.0, 2.0)])
def test_plugin_sampling_passes_mitsubas_chi2_test(theta: float, lobe: float) -> None:
    """The mixture sampler (``sampler`` = mixture) against its pdf, by Mitsuba's ChiSquareTest."""
    mi = set_variant("llvm_ad_rgb")
    test = _mitsuba_chi2(mi, _bsdf(mi, sampler="mixture", lobe_degrees=lobe, specular_probability=0.5), theta)
    print(f"Mitsuba χ² mixture θ={theta}° lobe={lobe}°: p-value {float(test.p_value):.3f}")
    assert test.passed, test.messages


@pytest.fixture(scope="module")
def contrasted_material(tmp_path_factory: pytest.TempPathFactory) -> str:
    """A random network whose luminance varies ~200:1 over (u, v), smoothly at the table's cell scale: the CD's
    peaks (a few table cells wide) defeat ChiSquareTest's own quadrature of the pdf (ires = 8 points per bin), not
    the sampler (tests/contract/test_importance.py checks sharp peaks cell by cell)."""
    from gratnet.modelfile import save_model
    from tests.helpers import random_model

    model = random_model([163, 32, 16, 3], scheme="simple-max", seed=0)
    model.weights[-1] = (3.0 * model.weights[-1]).astype(np.float32)
    path = tmp_path_factory.mktemp("importance") / "contrasted.npz"
    save_model(path, model)
    return str(path)


@needs_llvm
@pytest.mark.parametrize("theta", [0.0, 45.0, 75.0])
def test_plugin_table_sampling_passes_mitsubas_chi2_test(contrasted_material: str, theta: float) -> None:
    """The table sampler (``sampler`` = table, the default: gratnet.importance) against its pdf, by Mitsuba's
    ChiSquareTest."""
    mi = set_variant("llvm_ad_rgb")
    bsdf = mi.load_dict({"type": "gratnet", "filename": contrasted_material})
    test = _mitsuba_chi2(mi, bsdf, theta)
    print(f"Mitsuba χ² table θ={theta}°: p-value {float(test.p_value):.3f}")
    assert test.passed, test.messages


def test_tangent_frame_turns_the_tangent_onto_x_and_back() -> None:
    """The table samples in the tangent frame: the mesh tangent (cos α, sin α, 0) in Mitsuba's shading frame is
    the table's x, and from_tangent_frame undoes to_tangent_frame."""
    rng = np.random.default_rng(6)
    alpha = rng.uniform(-math.pi, math.pi, 50)
    rotation = np.stack([np.cos(alpha), np.sin(alpha)], axis=-1)
    tangent = np.stack([np.cos(alpha), np.sin(alpha), np.zeros(50)], axis=-1)
    np.testing.assert_allclose(shading.to_tangent_frame(tangent, rotation), np.tile([1.0, 0.0, 0.0], (50, 1)),
                               atol=1e-12)
    directions = _random_hemisphere(rng, 50)
    np.testing.assert_allclose(shading.from_tangent_frame(shading.to_tangent_frame(directions, rotation), rotation),
                               directions, atol=1e-12)
    assert shading.to_tangent_frame(directions, None) is directions


def test_the_default_sampler_is_the_table_and_a_bad_one_is_one_line() -> None:
    from gratnet.errors import GratNetError
    from mitsuba_plugin.runtime import plugin_errors

    mi = set_variant("scalar_rgb")
    assert "sampler='table'" in str(_bsdf(mi))
    with pytest.raises(GratNetError, match=r"^gratnet BSDF: property 'sampler' must be one of table, mixture, got "
                                           r"'magic'$"), plugin_errors():
        _bsdf(mi, sampler="magic")


@needs_llvm
@pytest.mark.parametrize("sampler", ["table", "mixture"])
def test_sample_weight_is_eval_over_pdf(sampler: str) -> None:
    mi = set_variant("llvm_ad_rgb")
    import drjit as dr

    bsdf = _bsdf(mi, sampler=sampler)
    count = 4000
    rng = np.random.default_rng(5)
    si = dr.zeros(mi.SurfaceInteraction3f, count)
    view = _random_hemisphere(rng, count, 0.2)
    si.wi = mi.Vector3f(*(mi.Float(view[:, k].astype(np.float32)) for k in range(3)))
    ctx = mi.BSDFContext()
    sample, weight = bsdf.sample(ctx, si, mi.Float(rng.random(count).astype(np.float32)),
                                 mi.Point2f(*(mi.Float(rng.random(count).astype(np.float32)) for _ in range(2))))
    value, density = bsdf.eval_pdf(ctx, si, sample.wo)
    pdf = np.array(sample.pdf)
    valid = pdf > 0
    assert valid.mean() > 0.8
    np.testing.assert_allclose(np.array(density)[valid], pdf[valid], rtol=1e-4)
    weight, value = (np.array(a, dtype=np.float64).reshape(3, -1).T for a in (weight, value))
    np.testing.assert_allclose(weight[valid] * pdf[valid, None], value[valid], rtol=1e-3,
                               atol=1e-6 * np.abs(value).max())
    assert np.all(weight[~valid] == 0.0)


# ------------------------------------------------------------------------------------------------
# Mitsuba against the GL renderer

#: The comparison's exposure (the CD's network output is ~1e-4 of a mirror's away from the peak).
EXPOSURE = 1e4
#: Mean FLIP allowed between the two renders. Measured at 16 spp: 0.037 (llvm_ad_rgb, 64²), 0.047 (scalar_rgb,
#: 32², the fallback where Dr.Jit finds no LLVM ≥ 18); a cos θ_light mistake gives 0.12, a mirrored image 0.30.
FLIP_THRESHOLD = 0.06


def test_mitsuba_render_agrees_with_gratnet_render() -> None:
    variant = "llvm_ad_rgb" if llvm_usable() else "scalar_rgb"
    mi = set_variant(variant)
    from mitsuba_plugin import scene as mitsuba_scene
    from trainer.metrics import flip
    from viewer import meshes
    from viewer.camera import Camera, Light
    from viewer.context import create_headless_context
    from viewer.scene import SceneRenderer

    # scalar_rgb calls the BSDF once per lookup (≈ 20 s for 32² × 16 spp here): a smaller image there.
    size = 64 if variant == "llvm_ad_rgb" else 32
    spp, supersample, half_height = 16, 4, 0.065
    azimuth, elevation = -70.0, 55.0
    light = Light.directional(40.0, 60.0)  # azimuth off the symmetry axes: a mirrored image fails
    mesh = meshes.compact_disc()
    scene = mitsuba_scene.build_scene(
        mi, mesh, mitsuba_scene.bsdf_dict(MATERIAL, 1.5),
        mitsuba_scene.sensor(mi, Camera(1.0, azimuth, elevation), size, size, spp,
                             orthographic_half_height=half_height),
        mitsuba_scene.emitters(light), integrator="direct")
    mitsuba_rgb = mitsuba_scene.render_passes(mi, scene, spp).astype(np.float64)

    distance = 200.0
    camera = Camera(distance, azimuth, elevation, fov_deg=2.0 * math.degrees(math.atan(half_height / distance)))
    ctx = create_headless_context()
    try:
        with SceneRenderer(ctx, load_model(MATERIAL), weights_path="texture") as renderer:
            xyz = renderer.render(mesh, camera, light, (size * supersample,) * 2, 1.0, 1.5)
    finally:
        ctx.release()
    gl_xyz = xyz.astype(np.float64).reshape(size, supersample, size, supersample, 3).mean(axis=(1, 3))

    to_xyz = np.linalg.inv(shading.xyz_to_linear_srgb_matrix())
    mitsuba_xyz = mitsuba_rgb @ to_xyz
    covered = np.mean(np.any(gl_xyz > 0, axis=-1))
    assert covered > 0.3
    mean_flip, _ = flip(gl_xyz * EXPOSURE, mitsuba_xyz * EXPOSURE)
    wrong_cosine, _ = flip(gl_xyz * EXPOSURE, mitsuba_xyz * EXPOSURE * math.cos(math.radians(40.0)))
    mirrored, _ = flip(gl_xyz * EXPOSURE, mitsuba_xyz[:, ::-1] * EXPOSURE)
    print(f"Mitsuba ({variant}, {size}², {spp} spp) vs GL: mean FLIP {mean_flip:.4f} (threshold {FLIP_THRESHOLD}); "
          f"with a cos θ_light factor {wrong_cosine:.4f}; mirrored {mirrored:.4f}")
    assert mean_flip < FLIP_THRESHOLD
    assert wrong_cosine > FLIP_THRESHOLD and mirrored > FLIP_THRESHOLD
    np.testing.assert_allclose(mitsuba_rgb.mean(axis=(0, 1)), (gl_xyz @ shading.xyz_to_linear_srgb_matrix()).mean(
        axis=(0, 1)), rtol=0.05)


# ------------------------------------------------------------------------------------------------
# the command


def test_mitsuba_render_command_writes_image_and_config(tmp_path: object, capsys: pytest.CaptureFixture) -> None:
    import json

    from PIL import Image

    from gratnet.cli import main

    out = tmp_path / "cd.png"
    status = main(["mitsuba-render", "--material", "cd", "--mesh", "plane", "--light", "30,0", "--size", "12,10",
                   "--spp", "2", "--exposure", "3000", "--environment", "1e-4", "--integrator", "path",
                   "--max-depth", "3", "--quiet", "--out", str(out)])
    assert status == 0
    image = np.asarray(Image.open(out))
    assert image.shape == (10, 12, 3) and image.max() > 0
    config = json.loads((tmp_path / "cd.config.json").read_text())
    assert config["mitsuba_render"]["spp"] == 2 and config["mitsuba_render"]["light_theta_degrees"] == 30.0
    assert "wrote" in capsys.readouterr().out


@pytest.mark.parametrize(("flags", "message"), [
    (["--spp", "0"], "--spp"),
    (["--environment", "missing.exr"], "does not exist"),
    (["--environment", "-1"], "--environment"),
    (["--ior", "nan"], "ior"),
    (["--light", "45"], "--light"),
    (["--mesh", "nothing.obj"], "does not exist"),
    (["--material", "no-such-material"], "unknown material"),
    (["--variant", "llvm_ad_rgb", "--lobe-degrees", "0"], "--lobe-degrees"),
])
def test_mitsuba_render_refuses_bad_input_with_one_line(tmp_path: object, capsys: pytest.CaptureFixture,
                                                        flags: list[str], message: str) -> None:
    from gratnet.cli import main

    out = tmp_path / "x.png"
    status = main(["mitsuba-render", "--quiet", "--size", "8,8", "--out", str(out), *flags])
    error = capsys.readouterr().err.strip()
    assert status == 2
    assert len(error.splitlines()) == 1 and message in error, error
    assert not out.exists()


def test_mitsuba_render_refuses_a_bad_output_before_work(tmp_path: object, capsys: pytest.CaptureFixture) -> None:
    from gratnet.cli import main

    blocker = tmp_path / "file"
    blocker.write_text("x")
    for out, message in ((tmp_path / "x.jpg", ".png"), (blocker / "x.png", "is a file, not a folder"),
                         (tmp_path, ".png")):
        assert main(["mitsuba-render", "--quiet", "--out", str(out)]) == 2
        assert message in capsys.readouterr().err


def _write_sky_exr(path: object) -> None:
    """A 16×8 lat-long map: upper half red, lower half blue (linear sRGB)."""
    import OpenEXR

    image = np.zeros((8, 16, 3), np.float32)
    image[:4] = (1.0, 0.0, 0.0)
    image[4:] = (0.0, 0.0, 1.0)
    with OpenEXR.File({"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage},
                      {"RGB": image}) as exr:
        exr.write(str(path))


def test_environment_map_up_is_plus_z(tmp_path: object) -> None:
    """The lat-long map's top rows are seen looking along +z (GratNet's up), its bottom rows along −z."""
    mi = set_variant("scalar_rgb")
    from mitsuba_plugin import scene as mitsuba_scene

    _write_sky_exr(tmp_path / "sky.exr")
    environment = mitsuba_scene.emitters(None, tmp_path / "sky.exr")["environment"]
    seen = {}
    for name, target, up in (("up", [0, 0, 1], [1, 0, 0]), ("down", [0, 0, -1], [1, 0, 0])):
        scene = mi.load_dict({"type": "scene", "environment": environment, "integrator": {"type": "direct"},
                              "sensor": {"type": "perspective", "fov": 1.0, "film": {"type": "hdrfilm", "width": 1,
                                                                                     "height": 1},
                                         "to_world": mi.ScalarTransform4f().look_at(origin=[0, 0, 0], target=target,
                                                                                   up=up)}})
        seen[name] = np.asarray(mi.render(scene, spp=4)).ravel()
    np.testing.assert_allclose(seen["up"], [1.0, 0.0, 0.0], atol=1e-3)
    np.testing.assert_allclose(seen["down"], [0.0, 0.0, 1.0], atol=1e-3)


def test_mitsuba_render_command_takes_an_obj_a_point_light_and_an_exr_environment(
        tmp_path: object, capsys: pytest.CaptureFixture) -> None:
    from gratnet.cli import main

    obj = tmp_path / "quad.obj"
    obj.write_text("v -0.05 -0.05 0\nv 0.05 -0.05 0\nv 0.05 0.05 0\nv -0.05 0.05 0\n"
                   "vt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nvn 0 0 1\nf 1/1/1 2/2/1 3/3/1 4/4/1\n")
    _write_sky_exr(tmp_path / "sky.exr")
    out = tmp_path / "quad.exr"
    status = main(["mitsuba-render", "--material", "blazed", "--mesh", str(obj), "--point-light", "0,-0.1,0.2",
                   "--environment", str(tmp_path / "sky.exr"), "--environment-scale", "0.01", "--camera",
                   "0.3,-90,60", "--exposure", "1", "--size", "16,12", "--spp", "2", "--quiet", "--out", str(out)])
    assert status == 0, capsys.readouterr().err
    import OpenEXR

    with OpenEXR.File(str(out)) as exr:
        pixels = next(iter(exr.channels().values())).pixels
    assert pixels.shape == (12, 16, 3) and np.all(np.isfinite(pixels))
    # The camera looks down 60°: the top corners miss the quad and show black, as gratnet render's background (the
    # environment is hidden from camera rays); the quad is lit by the point light (given, so on beside the map).
    np.testing.assert_array_equal(pixels[0, 0], [0.0, 0.0, 0.0])
    assert float(pixels[6, 8].max()) > 0.0
    import json

    config = json.loads((tmp_path / "quad.config.json").read_text())["mitsuba_render"]
    assert config["light_intensity"] == 1.0 and config["point_light"] == [0.0, -0.1, 0.2]


def test_without_mitsuba_the_command_says_how_to_install_it(tmp_path: object, capsys: pytest.CaptureFixture,
                                                            monkeypatch: pytest.MonkeyPatch) -> None:
    import sys

    from gratnet.cli import main

    monkeypatch.setitem(sys.modules, "mitsuba", None)  # `import mitsuba` raises ImportError
    assert main(["mitsuba-render", "--quiet", "--out", str(tmp_path / "x.png")]) == 2
    error = capsys.readouterr().err.strip()
    assert len(error.splitlines()) == 1 and "[mitsuba]" in error, error


SCENE_FIELDS = ("light_theta_degrees", "light_phi_degrees", "point_light", "camera_distance", "camera_azimuth_degrees",
                "camera_elevation_degrees", "exposure")


@pytest.mark.parametrize("flags", [[], ["--point-light", "0,-0.1,0.2"], ["--light", "30,0", "--camera", "0.3,-80,60",
                                                                         "--exposure", "700"]],
                         ids=["all defaults", "point light", "all given"])
def test_mitsuba_render_and_render_resolve_the_same_light_camera_and_exposure(
        tmp_path: object, capsys: pytest.CaptureFixture, flags: list[str]) -> None:
    # Both commands end to end, on one material and mesh: the scene their configs record must be the same,
    # and be the defaults of viewer.defaults (or the flags, where given).
    import json

    from gratnet.cli import main
    from viewer.defaults import resolve_defaults

    material, mesh = "cd", "sphere"
    scenes = {}
    for command, extra in (("render", ["--weights-path", "texture"]), ("mitsuba-render", ["--spp", "1"])):
        out = tmp_path / f"{command}.png"
        status = main([command, "--material", material, "--mesh", mesh, "--size", "8,8", "--quiet", *extra, *flags,
                       "--out", str(out)])
        assert status == 0, capsys.readouterr().err
        recorded = json.loads((tmp_path / f"{command}.config.json").read_text())[command.replace("-", "_")]
        scenes[command] = {name: recorded[name] for name in SCENE_FIELDS}
    assert scenes["mitsuba-render"] == scenes["render"]
    scene = scenes["render"]
    if not flags:
        defaults = resolve_defaults(material, mesh)
        assert (scene["light_theta_degrees"], scene["light_phi_degrees"], scene["camera_distance"],
                scene["camera_elevation_degrees"], scene["exposure"]) == (
            defaults.light_theta_degrees, defaults.light_phi_degrees, defaults.camera_distance,
            defaults.camera_elevation_degrees, defaults.exposure)
    elif flags[0] == "--point-light":
        assert scene["point_light"] == [0.0, -0.1, 0.2]
        assert scene["exposure"] == pytest.approx(resolve_defaults(material, mesh).exposure * 0.05)  # × |p|² (m²)
    else:
        assert (scene["light_theta_degrees"], scene["light_phi_degrees"], scene["camera_distance"],
                scene["camera_azimuth_degrees"], scene["camera_elevation_degrees"], scene["exposure"]) == (
            30.0, 0.0, 0.3, -80.0, 60.0, 700.0)
