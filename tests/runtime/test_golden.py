"""Golden images: small renders of the shipped blazed model compared with stored references.

Each case renders 96×96 display sRGB (``SceneRenderer`` → ``display_srgb8``, the path of every GratNet PNG)
and compares it with ``tests/runtime/golden/NAME.png``. It passes when both hold:

- mean LDR-FLIP (``flip_evaluator`` on display sRGB in [0, 1], default 67 pixels per degree) ≤ 0.01;
- at least 99.9 % of the pixels differ by ≤ 8/255 in every channel, plus, when the picture is compared on a
  GPU, what two correct float32 drivers may differ by at that pixel (``gratnet.precision.driver_bound`` at the
  pixel's key, the key moved by a rasterizer's sub-pixel snapping; docs/physics.md, "Float32 error budget"),
  in display levels.

A failure writes ``NAME.actual.png``, ``NAME.expected.png`` and ``NAME.diff.png`` (per-pixel largest
channel difference ×8, grey) to ``tests/_failures/`` (gitignored) and names them. ``pytest
--regenerate-golden`` rewrites the references from the current renderer (those cases then report as
skipped, saying what was written). GPU tests skip when no OpenGL 4.3 context can be made through EGL.
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from gratnet.modelfile import load_model
from tests.helpers import REPO
from viewer.camera import Camera, Light
from viewer.meshes import compact_disc, plane, sphere

BLAZED = REPO / "assets" / "blazed" / "model.npz"
GOLDEN = Path(__file__).resolve().parent / "golden"
FAILURES = REPO / "tests" / "_failures"  # gitignored; scripts/gpu_check.sh collects it
SIZE = 96

#: Largest mean FLIP allowed.
MAX_MEAN_FLIP = 0.01
#: A pixel "differs" when a channel differs by more than this many 8-bit levels …
MAX_LEVELS = 8
#: … and at most this fraction of the pixels may differ.
MAX_DIFFERING_FRACTION = 0.001

#: name → (mesh builder or None for the BRDF slice, camera (distance, azimuth, elevation), light (θ, φ),
#: exposure). Views chosen so that each picture shows the grating's colours, not just black.
CASES = {
    "cd": (compact_disc, (0.18, -90.0, 50.0), (20.0, 90.0), 5000.0),
    "sphere": (sphere, (0.2, -90.0, 30.0), (50.0, -60.0), 2000.0),
    "plane": (plane, (0.15, -90.0, 50.0), (30.0, 90.0), 5000.0),
    "slice": (None, None, (30.0, 0.0), 5000.0),
}


# --------------------------------------------------------------------------------------------------
# Comparison


def compare(actual: np.ndarray, expected: np.ndarray,
            allowed_levels: np.ndarray | int = MAX_LEVELS) -> tuple[list[str], dict[str, float]]:
    """``(problems, measures)`` for two ``uint8`` ``(H, W, 3)`` display-sRGB images; no problems = pass.
    ``allowed_levels``: the largest channel difference per pixel that does not count as differing (``(H, W)``
    or one number)."""
    import flip_evaluator

    if actual.shape != expected.shape:
        return [f"shape {actual.shape} differs from the reference's {expected.shape}"], {}
    _, mean_flip, _ = flip_evaluator.evaluate(
        np.ascontiguousarray(expected, dtype=np.float32) / 255.0,
        np.ascontiguousarray(actual, dtype=np.float32) / 255.0,
        "LDR", inputsRGB=True, applyMagma=False, computeMeanError=True,
    )
    levels = np.abs(actual.astype(np.int16) - expected.astype(np.int16)).max(axis=2)
    differing = float(np.mean(levels > allowed_levels))
    measures = {"mean_flip": float(mean_flip), "differing_fraction": differing, "max_levels": float(levels.max())}
    problems = []
    if not mean_flip <= MAX_MEAN_FLIP:
        problems.append(f"mean FLIP {mean_flip:.4f} > {MAX_MEAN_FLIP}")
    if differing > MAX_DIFFERING_FRACTION:
        allowed = f"{MAX_LEVELS}/255" if np.ndim(allowed_levels) == 0 else \
            f"{MAX_LEVELS}/255 + the float32 driver bound (up to {int(np.max(allowed_levels))}/255)"
        problems.append(f"{differing:.2%} of the pixels differ by more than {allowed} "
                        f"(allowed {MAX_DIFFERING_FRACTION:.1%}; largest difference {levels.max()}/255)")
    return problems, measures


def write_failure(name: str, actual: np.ndarray, expected: np.ndarray, folder: Path = FAILURES) -> list[Path]:
    """Write the actual, expected and difference images of a failed case; return their paths."""
    folder.mkdir(parents=True, exist_ok=True)
    paths = [folder / f"{name}.actual.png", folder / f"{name}.expected.png", folder / f"{name}.diff.png"]
    Image.fromarray(actual).save(paths[0])
    Image.fromarray(expected).save(paths[1])
    if actual.shape == expected.shape:
        levels = np.abs(actual.astype(np.int16) - expected.astype(np.int16)).max(axis=2)
        Image.fromarray(np.minimum(255, levels * 8).astype(np.uint8)).save(paths[2])
    else:
        paths.pop()
    return paths


def check_golden(name: str, actual: np.ndarray, regenerate: bool, golden: Path = GOLDEN,
                 failures: Path = FAILURES, allowed_levels: np.ndarray | int = MAX_LEVELS) -> dict[str, float]:
    """Compare with (or, regenerating, rewrite) ``golden/NAME.png``; fail with the failure images' paths."""
    reference = golden / f"{name}.png"
    if regenerate:
        golden.mkdir(parents=True, exist_ok=True)
        Image.fromarray(actual).save(reference)
        pytest.skip(f"regenerated {reference.relative_to(REPO) if reference.is_relative_to(REPO) else reference}")
    if not reference.is_file():
        pytest.fail(f"no golden image {reference}; create it with: python -m pytest tests/runtime/test_golden.py "
                    "--regenerate-golden")
    expected = np.asarray(Image.open(reference).convert("RGB"))
    problems, measures = compare(actual, expected, allowed_levels)
    if problems:
        paths = write_failure(name, actual, expected, failures)
        pytest.fail(f"golden image {name}: {'; '.join(problems)}. Wrote {', '.join(str(p) for p in paths)}")
    return measures


# --------------------------------------------------------------------------------------------------
# Rendering


@pytest.fixture(scope="module")
def scene(ctx: object) -> Iterator[object]:
    from viewer.scene import SceneRenderer

    renderer = SceneRenderer(ctx, load_model(BLAZED), render_path="forward")  # the golden images are forward's
    yield renderer
    renderer.release()


@pytest.fixture(scope="module")
def deferred_scene(ctx: object) -> Iterator[object]:
    from viewer.scene import SceneRenderer

    renderer = SceneRenderer(ctx, load_model(BLAZED), render_path="deferred")
    yield renderer
    renderer.release()


def render_case(scene, name: str) -> np.ndarray:
    build, camera, (theta, phi), exposure = CASES[name]
    if build is None:
        xyz = scene.render_brdf_slice(theta, phi, SIZE, exposure)
    else:
        xyz = scene.render(build(), Camera(*camera), Light.directional(theta, phi), (SIZE, SIZE), exposure)
    assert np.all(np.isfinite(xyz))
    return scene.display_srgb8(xyz)


#: Largest share of a case's pixels whose driver allowance may exceed MAX_LEVELS: beyond it the scene is too
#: ill-conditioned (too many pixels where a sub-pixel move of the key changes the display) for the pixel rule
#: to say much, and the case should change.
MAX_LOOSE_FRACTION = 0.1
_ALLOWANCES: dict[str, np.ndarray] = {}


def driver_allowance(scene, name: str) -> np.ndarray:
    """:func:`driver_levels` of case ``name`` once per test session (the forward and deferred tests share it),
    checked against :data:`MAX_LOOSE_FRACTION`."""
    if name not in _ALLOWANCES:
        allowance = driver_levels(scene, name)
        loose = float(np.mean(allowance > MAX_LEVELS))
        assert loose <= MAX_LOOSE_FRACTION, f"{name}: {loose:.1%} of the pixels are ill-conditioned"
        _ALLOWANCES[name] = allowance
    return _ALLOWANCES[name]


def driver_levels(scene, name: str) -> np.ndarray:
    """Display levels ``(H, W)`` that another correct float32 driver may move each pixel of case ``name`` by,
    beyond :data:`MAX_LEVELS` (docs/physics.md, "Float32 error budget"): ``driver_bound`` at the forward
    path's key layer (the BRDF slice: the numpy keys of its pixels), the key moved by sub-pixel snapping
    (``raster_key_error``), times exposure · A; the XYZ box's 8 corners through the display transform."""
    from gratnet.brdf import a_term, direction, slice_view_directions
    from gratnet.precision import driver_bound, raster_key_error

    build, camera, (theta, phi), exposure = CASES[name]
    if build is None:
        views, inside = slice_view_directions(SIZE)
        light = direction(theta, phi)
        key = -(light + views)
        factor = exposure * a_term(light, views, 1.5) * inside
        key_error = None  # DriverErrors' 16 u: the slice's key is computed per pixel, no rasterized geometry
    else:
        _, key_a = scene.render_layers(build(), Camera(*camera), Light.directional(theta, phi), (SIZE, SIZE),
                                       exposure)
        key = key_a[..., :3].astype(np.float64)
        factor = exposure * key_a[..., 3].astype(np.float64)
        key_error = raster_key_error(key, key_a[..., 3] > 0)
    lit = factor > 0  # A = 0 or background: black on every driver, nothing to evaluate
    value, tolerance = np.zeros((SIZE, SIZE, 3)), np.zeros((SIZE, SIZE, 3))
    bound = driver_bound(scene.model, key[lit, 0], key[lit, 1], key[lit, 2],
                         key_error=None if key_error is None else key_error[lit])
    value[lit], tolerance[lit] = factor[lit, None] * bound.xyz, factor[lit, None] * bound.bound
    shown = scene.display_srgb8(value).astype(np.int16)
    levels = np.zeros(shown.shape[:2], dtype=np.int16)
    for corner in np.ndindex(2, 2, 2):
        moved = scene.display_srgb8(np.maximum(value + (2 * np.array(corner) - 1) * tolerance, 0.0))
        levels = np.maximum(levels, np.abs(moved.astype(np.int16) - shown).max(axis=2))
    return MAX_LEVELS + levels


@pytest.mark.parametrize("name", list(CASES))
def test_render_matches_golden_image(scene, name, request):
    actual = render_case(scene, name)
    assert np.count_nonzero(actual.max(axis=2) > 16) >= 20, f"{name}: the render is (nearly) black"
    check_golden(name, actual, request.config.getoption("--regenerate-golden"),
                 allowed_levels=driver_allowance(scene, name))


@pytest.mark.parametrize("name", [name for name, case in CASES.items() if case[0] is not None])
def test_deferred_render_matches_the_same_golden_image(scene, deferred_scene, name):
    """The deferred path (viewer/deferred.py) must give the forward path's pictures: the same references."""
    assert deferred_scene.render_path == "deferred"
    check_golden(name, render_case(deferred_scene, name), False, allowed_levels=driver_allowance(scene, name))


# --------------------------------------------------------------------------------------------------
# The comparison itself can fail (no GPU needed)


def golden_image(name: str) -> np.ndarray:
    path = GOLDEN / f"{name}.png"
    if not path.is_file():
        pytest.skip(f"no golden image {path} yet (python -m pytest tests/runtime/test_golden.py --regenerate-golden)")
    return np.asarray(Image.open(path).convert("RGB"))


def test_identical_images_pass():
    image = golden_image("cd")
    problems, measures = compare(image, image.copy())
    assert problems == [] and measures["mean_flip"] == 0.0 and measures["differing_fraction"] == 0.0


def test_a_small_bright_patch_fails_on_the_pixel_tolerance():
    expected = golden_image("plane")
    actual = expected.copy()
    actual[10:14, 10:14] = 255  # 16 pixels: 0.17 % of 96², over the 0.1 % allowed
    problems, measures = compare(actual, expected)
    assert any("differ by more than" in problem for problem in problems), measures
    assert measures["mean_flip"] <= MAX_MEAN_FLIP  # the patch is too small for the mean FLIP alone


def test_a_shifted_image_fails_on_flip():
    expected = golden_image("slice")
    actual = np.roll(expected, 3, axis=1)  # the whole picture three pixels to the right
    problems, measures = compare(actual, expected)
    assert any("mean FLIP" in problem for problem in problems), measures


def test_a_dimmed_image_fails_on_both():
    expected = golden_image("cd")
    actual = (expected.astype(np.float64) * 0.5).round().astype(np.uint8)  # one stop darker
    problems, measures = compare(actual, expected)
    assert len(problems) == 2, measures


def test_a_failure_writes_actual_expected_and_diff_and_says_where(tmp_path):
    expected = golden_image("plane")
    actual = expected.copy()
    actual[:, :] = 0
    golden = tmp_path / "golden"
    golden.mkdir()
    Image.fromarray(expected).save(golden / "case.png")
    with pytest.raises(pytest.fail.Exception) as failure:
        check_golden("case", actual, False, golden=golden, failures=tmp_path / "failures")
    message = str(failure.value)
    for suffix in ("actual", "expected", "diff"):
        path = tmp_path / "failures" / f"case.{suffix}.png"
        assert path.is_file() and str(path) in message
    diff = np.asarray(Image.open(tmp_path / "failures" / "case.diff.png"))
    assert diff.max() > 0


def test_wrong_size_fails():
    expected = golden_image("plane")
    problems, _ = compare(expected[:-1], expected)
    assert problems and "shape" in problems[0]
