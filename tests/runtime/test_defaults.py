"""The shared defaults (viewer.defaults) and the display analysis and black-picture hint (gratnet.showcase).

Analytic checks first (light aiming, sampling, framing, the hint's arithmetic), then cross-checks of the
analysis against the grating equation, then renders of every shipped material on every built-in mesh at
the defaults, the black-picture warning of ``gratnet render``, and ``render`` and ``view`` agreeing.
"""

from __future__ import annotations

import argparse
import colorsys
import math
import re
from pathlib import Path

import numpy as np
import pytest

from gratnet.bounds import DISPLAY_SKIP_THRESHOLD
from gratnet.cli import build_parser, main
from gratnet.display import xyz_to_linear_srgb
from gratnet.modelfile import load_model
from gratnet.showcase import (
    BLACK_FRACTION_WARNING,
    DISPLAY_KEY,
    MaterialDisplay,
    analyse_model,
    black_fraction,
    black_image_hint,
    material_display,
    suggest_exposure,
)
from viewer import defaults
from viewer.catalog import ASSETS, MESHES, shipped_materials
from viewer.meshes import plane, sphere

MATERIALS = shipped_materials()


def _xyz_of_linear_srgb(rgb: np.ndarray) -> np.ndarray:
    """CIE XYZ whose linear sRGB is ``rgb`` (inverse of gratnet.display's matrix)."""
    matrix = xyz_to_linear_srgb(np.eye(3))  # row k: linear sRGB of the k-th XYZ unit vector
    return np.asarray(rgb, dtype=np.float64) @ np.linalg.inv(matrix)


# --------------------------------------------------------------------------------------------------
# Analytic


def test_aimed_light_makes_the_requested_key_vector():
    frame = {"tangents": np.array([[1.0, 0.0, 0.0]]), "bitangents": np.array([[0.0, 1.0, 0.0]]),
             "normals": np.array([[0.0, 0.0, 1.0]])}
    view = np.array([0.0, -math.sin(math.radians(45)), math.cos(math.radians(45))])
    for key in [(0.181, 0.0), (0.0, 0.3), (-0.5, 0.2)]:
        light = defaults.aim_light(key, view, frame, 0)
        assert light is not None and abs(np.linalg.norm(light) - 1.0) < 1e-12
        np.testing.assert_allclose(-(light + view)[:2], key, atol=1e-12)  # K = −(ωi + ωo), physics.md
    # Unreachable: the light would have to be 90° or more from the normal.
    assert defaults.aim_light((0.0, -1.8), view, frame, 0) is None


def test_surface_samples_are_uniform_and_carry_the_frame():
    samples = defaults.surface_samples(sphere(radius=0.05), count=4000)
    np.testing.assert_allclose(np.linalg.norm(samples["positions"], axis=1), 0.05, rtol=5e-3)  # inside: flat facets
    np.testing.assert_allclose(np.sum(samples["normals"] * samples["positions"], axis=1) / 0.05, 1.0, atol=5e-3)
    for a, b in [("normals", "tangents"), ("normals", "bitangents"), ("tangents", "bitangents")]:
        assert np.max(np.abs(np.sum(samples[a] * samples[b], axis=1))) < 1e-9
    # Uniform by area: the upper hemisphere holds half the points (binomial std 0.008 for 4000).
    assert abs(np.mean(samples["positions"][:, 2] > 0) - 0.5) < 0.03
    flat = defaults.surface_samples(plane(size=0.1), count=4000)["positions"]
    assert np.all(np.abs(flat[:, :2]) <= 0.05) and abs(np.mean(flat[:, 0] > 0.025) - 0.25) < 0.03


def test_framing_distance_fits_the_mesh_into_the_field_of_view():
    distance = defaults.framing_distance(sphere(radius=0.05), 40.0)
    assert distance == pytest.approx(0.05 / (defaults.FRAMING * math.sin(math.radians(20.0))), rel=1e-6)


def test_scene_defaults_aim_a_peak_at_the_plane_centre():
    """A material whose only peak is at K = (0.3, 0): on the plane (tangent frame = world frame), the light
    is the one that puts that key vector at the aimed point, the point seen nearest the image centre."""
    model = load_model(ASSETS / "sinusoidal" / "model.npz")
    display = MaterialDisplay(exposure=10.0, peak_keys_uv=((0.3, 0.0),), peak_brightness=(0.1,),
                              specular_brightness=0.5, specular_radius=0.08)
    result = defaults.scene_defaults(model, plane(), display=display)
    from viewer.camera import Camera, Light

    camera = Camera(result.camera_distance, result.camera_azimuth_degrees, result.camera_elevation_degrees)
    light = Light.directional(result.light_theta_degrees, result.light_phi_degrees).vector
    view = camera.eye() / np.linalg.norm(camera.eye())  # towards the eye from the centre (the aimed point is near it)
    key = -(np.asarray(light) + view)
    # The peak itself or a fraction of it towards the specular direction (module docstring, step 2).
    assert result.aimed_key_uv in {(round(f * 0.3, 4), 0.0) for f in defaults.AIM_FRACTIONS}
    np.testing.assert_allclose(key[:2], result.aimed_key_uv, atol=0.03)  # the aimed point: a sample near the centre
    assert 0 < result.exposure <= defaults.MAX_VISIBLE_RATIO * 10.0


def test_display_analysis_round_trips_and_rejects_malformed_entries():
    display = MaterialDisplay(exposure=12.5, peak_keys_uv=((0.25, -0.125),), peak_brightness=(0.08,),
                              specular_brightness=0.5, specular_radius=0.08)
    back = MaterialDisplay.from_json(display.to_json())
    assert back is not None and back.stored and dataclass_fields(back) == dataclass_fields(display)
    for broken in [None, {}, {**display.to_json(), "version": 99}, {**display.to_json(), "exposure": -1},
                   {**display.to_json(), "peak_keys_uv": []}, {**display.to_json(), "exposure": "x"}]:
        assert MaterialDisplay.from_json(broken) is None


def dataclass_fields(display: MaterialDisplay) -> tuple[object, ...]:
    return (display.exposure, display.peak_keys_uv, display.peak_brightness, display.specular_brightness,
            display.specular_radius, display.analysis_w)


def test_black_fraction_counts_pixels_the_display_shows_black():
    image = np.zeros((10, 10, 3))
    image[0, :7] = _xyz_of_linear_srgb([0.5, 0.5, 0.5])
    image[1, 0] = _xyz_of_linear_srgb([0.3 * DISPLAY_SKIP_THRESHOLD] * 3)  # below the display's step: black
    assert black_fraction(image) == pytest.approx(0.93)


def test_suggested_exposure_maps_the_lit_pixels_to_white_and_shows_the_picture():
    image = np.zeros((100, 100, 3))
    image[:10, :10] = _xyz_of_linear_srgb([1e-6, 4e-6, 2e-6])  # 1 % lit, brightness 4e-6 at exposure 2
    suggestion = suggest_exposure(image, exposure=2.0)
    assert suggestion == pytest.approx(2.0 / 4e-6, rel=5e-3)  # the 99th percentile of the lit pixels → white
    assert black_fraction(image * suggestion / 2.0) <= 0.99
    # Bright pixels over a dim lit area: the percentile alone (→ 1) would leave the dim 2 % black; the
    # visibility floor raises the suggestion to 8 display steps on them: 8 · 1.52e-4 / 1e-7 ≈ 1.2e4.
    image = np.zeros((100, 100, 3))
    image[:2] = _xyz_of_linear_srgb([1e-7, 1e-7, 1e-7])
    image[2, :50] = _xyz_of_linear_srgb([1.0, 1.0, 1.0])
    suggestion = suggest_exposure(image, exposure=1.0)
    assert suggestion == pytest.approx(8 * DISPLAY_SKIP_THRESHOLD / 1e-7, rel=5e-3)
    assert black_fraction(image * suggestion) == pytest.approx(0.975)
    assert suggest_exposure(np.zeros((4, 4, 3)), 1.0) is None and suggest_exposure(image, 0.0) is None


def test_black_image_hint_only_for_black_pictures():
    image = np.zeros((100, 100, 3))
    image[:2, :] = _xyz_of_linear_srgb([1e-5, 1e-5, 1e-5])  # lit but below the display's step: all black
    hint = black_image_hint(image, 0.5)
    assert hint is not None and "100.0 % of the image is black" in hint and "--exposure" in hint
    assert black_image_hint(image * 1e4, 5e3) is None  # 2 % visible: 98 % black < 99 %
    assert "no pixel is lit" in (black_image_hint(np.zeros((8, 8, 3)), 1.0) or "")
    assert BLACK_FRACTION_WARNING == 0.99


# --------------------------------------------------------------------------------------------------
# Cross-checks of the analysis


def test_analysis_finds_the_grating_orders():
    """The brightest off-specular peaks of the sinusoidal (600 lines/mm) and blazed (2.5 µm period) gratings
    lie on their first orders: u = ±λ/Λ for λ in 380…780 nm, v ≈ 0 (physics.md, "Grating equation");
    the blazed one on the +u side (its heights rise along +x)."""
    for name, period_um, sides in [("sinusoidal", 1000.0 / 600.0, {-1, 1}), ("blazed", 2.5, {1})]:
        display = material_display(load_model(ASSETS / name / "model.npz"))
        u, v = display.peak_keys_uv[0]
        assert 0.380 / period_um - 0.01 <= abs(u) <= 0.780 / period_um + 0.01 and abs(v) < 0.01
        assert int(np.sign(u)) in sides
        assert display.exposure == pytest.approx(1.0 / display.peak_brightness[0], rel=1e-5)


@pytest.mark.parametrize("name", ["cd", "blazed"])
def test_stored_analysis_matches_a_fresh_one(name):
    """The shipped files carry the analysis (scripts/store_display_analysis.py) and it is what the analysis
    computes now, so older files (computed at load time) and new ones (stored) get the same defaults."""
    model = load_model(ASSETS / name / "model.npz")
    stored = material_display(model)
    assert stored.stored and DISPLAY_KEY in model.metadata
    fresh = analyse_model(model)
    assert fresh.peak_keys_uv == stored.peak_keys_uv
    assert fresh.exposure == pytest.approx(stored.exposure, rel=1e-4)


def _network(bias: float | None = None, seed: int = 0) -> object:
    """A small network standing for a material never seen: random weights (``bias`` None), or one whose
    output is the constant ``clamp(bias)`` (all weights 0)."""
    from gratnet.encoding import EncodingSpec, RangeSpec
    from gratnet.modelfile import ModelFile

    sizes = [163, 16, 3]
    rng = np.random.default_rng(seed)
    weights = [rng.normal(0.0, math.sqrt(2.0 / a), (b, a)).astype(np.float32)
               for a, b in zip(sizes, sizes[1:], strict=False)]
    biases = [rng.normal(0.0, 0.3, b).astype(np.float32) for b in sizes[1:]]
    if bias is not None:
        weights = [np.zeros_like(w) for w in weights]
        biases = [np.zeros_like(biases[0]), np.full(3, bias, dtype=np.float32)]
    return ModelFile(sizes, weights, biases, "relu", "clamp", EncodingSpec.for_grid(1001, 11), RangeSpec(),
                     "simple-max", {})


@pytest.mark.parametrize("kind", ["random", "black", "uniform"])
def test_materials_never_seen_get_finite_defaults_on_every_mesh(kind):
    """Generalisation: an arbitrary network, one that is black everywhere (no peak: the specular fallback,
    exposure 1) and one that is uniformly grey (every key a peak) give usable defaults on every mesh."""
    model = _network(seed=3) if kind == "random" else _network(bias=-5.0 if kind == "black" else 0.9)
    display = analyse_model(model)
    assert display.exposure > 0 and math.isfinite(display.exposure) and display.peak_keys_uv
    if kind == "black":
        assert display.peak_keys_uv == ((0.0, 0.0),) and display.exposure == 1.0
    for mesh in (plane(), sphere(), defaults_mesh("cd")):
        result = defaults.scene_defaults(model, mesh, display=display)
        assert 0.0 <= result.light_theta_degrees <= defaults.MAX_LIGHT_DEGREES
        assert result.camera_elevation_degrees in defaults.CAMERA_ELEVATIONS_DEGREES
        assert 0 < result.exposure <= defaults.MAX_VISIBLE_RATIO * display.exposure
    assert defaults.slice_defaults(model, display).exposure > 0


def defaults_mesh(name: str) -> object:
    from viewer.catalog import build_mesh

    return build_mesh(name)


# --------------------------------------------------------------------------------------------------
# Renders at the defaults


def _shows_diffraction(display_srgb8: np.ndarray) -> tuple[bool, str]:
    """The criterion for "shows its diffraction" (8-bit display sRGB, H × W × 3):

    - not black: under ``BLACK_FRACTION_WARNING`` (99 %) of the pixels black, i.e. the picture does not draw
      ``gratnet render``'s warning (measured at 96×72: 1.9 % non-black for the thinnest, a grating's order
      line on the plane, up to 52 %);
    - coloured: at least 10 pixels with chroma (max − min channel) ≥ 32/255 that are not white, spread over
      at least 3 of the 6 hue sextants: dispersion, not a tinted highlight (measured ≥ 21 pixels, 5–6
      sextants);
    - not a saturated blob: at most 5 % of the pixels have a channel at 255 (measured ≤ 0.9 %).
    """
    pixels = display_srgb8.reshape(-1, 3).astype(int)
    black = float(np.mean(~np.any(pixels > 0, axis=1)))
    coloured, sextants = _dispersion(display_srgb8)
    saturated = float(np.mean(np.any(pixels >= 255, axis=1)))
    ok = black < BLACK_FRACTION_WARNING and coloured >= 10 and sextants >= 3 and saturated <= 0.05
    return ok, f"black {black:.3f}, {coloured} coloured pixels in {sextants} hue sextants, saturated {saturated:.3f}"


def _dispersion(display_srgb8: np.ndarray) -> tuple[int, int]:
    """(pixels with chroma (max − min channel) ≥ 32/255 that are not white, hue sextants among them)."""
    pixels = display_srgb8.reshape(-1, 3).astype(int)
    chroma = pixels.max(axis=1) - pixels.min(axis=1)
    coloured = pixels[(chroma >= 32) & ~np.all(pixels >= 250, axis=1)]
    return len(coloured), len({int(colorsys.rgb_to_hsv(*(p / 255.0))[0] * 6) % 6 for p in coloured})


#: (material, mesh) pairs whose default picture is a thin order ring on black, by their physics: the paper's
#: 100 µm blazed grating under a 65 µm window has orders a few 10⁻³ wide in u, so a directional light on the
#: sphere lights a one-pixel ring (99.5 % of a 96×72 picture black at the defaults, the exposure already at
#: MAX_VISIBLE_RATIO × the material's); the 20 µm `blazed` tile passes only by its repetition's faint
#: speckle. For these the ring must still show the dispersion (coloured pixels in ≥ 3 hue sextants).
THIN_RING = {("paper-blazed", "sphere")}


@pytest.mark.parametrize("material", MATERIALS)
def test_every_shipped_material_shows_its_diffraction_on_every_mesh_at_the_defaults(ctx, material):
    from viewer.camera import Camera, Light
    from viewer.catalog import build_mesh
    from viewer.scene import SceneRenderer

    failures = []
    # The texture path: the same pixels as the baked one, without a ~25 s compile per model on llvmpipe.
    with SceneRenderer(ctx, load_model(ASSETS / material / "model.npz"), weights_path="texture") as renderer:
        for mesh in MESHES:
            d = defaults.resolve_defaults(material, mesh)
            camera = Camera(d.camera_distance, d.camera_azimuth_degrees, d.camera_elevation_degrees,
                            fov_deg=defaults.FOV_DEGREES)
            light = Light.directional(d.light_theta_degrees, d.light_phi_degrees)
            pixels = SceneRenderer.display_srgb8(renderer.render(build_mesh(mesh), camera, light, (96, 72),
                                                                 d.exposure, 1.5))
            ok, summary = _shows_diffraction(pixels)
            if (material, mesh) in THIN_RING:
                coloured, sextants = _dispersion(pixels)
                ok = coloured >= 10 and sextants >= 3
            if not ok:
                failures.append(f"{material} on {mesh} ({d.light_text}, exposure {d.exposure:g}): {summary}")
        if material == "cd":  # the criterion can fail: the old fixed defaults of `gratnet render` show nothing
            old = renderer.render(build_mesh("cd"), Camera(0.25, -90.0, 45.0), Light.directional(45.0, 90.0),
                                  (96, 72), 1.0, 1.5)
            assert not _shows_diffraction(SceneRenderer.display_srgb8(old))[0]
    assert not failures, "; ".join(failures)


def test_render_warns_about_a_black_picture_and_its_suggestion_shows_it(ctx, tmp_path, capsys):
    from PIL import Image

    common = ["render", "--material", "cd", "--mesh", "plane", "--size", "64,48", "--weights-path", "texture"]
    dark = tmp_path / "dark.png"
    assert main([*common, "--exposure", "1e-4", "--out", str(dark)]) == 0  # the exit status is unchanged
    error = capsys.readouterr().err
    match = re.search(r"warning: .*black on the display at exposure 0\.0001; try --exposure (\S+)", error)
    assert match, error
    suggestion = float(match.group(1))
    assert suggestion > 1e-4
    shown = tmp_path / "shown.png"
    assert main([*common, "--exposure", f"{suggestion:g}", "--out", str(shown)]) == 0
    assert "warning" not in capsys.readouterr().err
    with Image.open(shown) as image:
        pixels = np.asarray(image)
    assert np.mean(~np.any(pixels > 0, axis=-1)) < BLACK_FRACTION_WARNING


# --------------------------------------------------------------------------------------------------
# One set of defaults for render and view


def _filled(argv: list[str]) -> argparse.Namespace:
    from viewer.scene_config import fill_scene_defaults

    arguments = build_parser().parse_args(argv)
    fill_scene_defaults(arguments)
    return arguments


@pytest.mark.parametrize("material", MATERIALS)
def test_render_and_view_resolve_identical_defaults(material):
    for mesh in MESHES:
        rendered = _filled(["render", "--material", material, "--mesh", mesh, "--out", "x.png"])
        viewed = _filled(["view", "--material", material, "--mesh", mesh])
        assert (rendered.light_text, rendered.camera_text, rendered.exposure) == \
            (viewed.light_text, viewed.camera_text, viewed.exposure)
    rendered = _filled(["render", "--material", material, "--slice", "--out", "x.png"])
    viewed = _filled(["view", "--material", material, "--slice"])
    assert (rendered.light_text, rendered.exposure) == (viewed.light_text, viewed.exposure)


def test_view_starting_state_and_render_config_use_the_defaults_and_flags_override(ctx, tmp_path):
    import json

    from viewer.default_view import state_defaults
    from viewer.view_cli import starting_state

    state = starting_state(build_parser().parse_args(["view", "--material", "pits", "--mesh", "sphere"]))
    d = defaults.resolve_defaults("pits", "sphere")
    assert (state.light_theta, state.light_phi, state.camera_distance, state.camera_azimuth, state.camera_elevation,
            state.exposure) == (d.light_theta_degrees, d.light_phi_degrees, d.camera_distance,
                                d.camera_azimuth_degrees, d.camera_elevation_degrees, d.exposure)
    assert state_defaults("pits", "sphere") == {
        "light_theta": state.light_theta, "light_phi": state.light_phi, "camera_distance": state.camera_distance,
        "camera_azimuth": state.camera_azimuth, "camera_elevation": state.camera_elevation, "exposure": state.exposure}
    out = tmp_path / "pits.png"
    assert main(["render", "--material", "pits", "--mesh", "sphere", "--size", "16,12", "--weights-path", "texture",
                 "--exposure", "7", "--out", str(out)]) == 0
    config = json.loads(Path(str(out).replace(".png", ".config.json")).read_text())["render"]
    assert config["exposure"] == 7.0  # an explicit flag wins
    assert (config["light_theta_degrees"], config["light_phi_degrees"], config["camera_distance"]) == \
        (d.light_theta_degrees, d.light_phi_degrees, d.camera_distance)
