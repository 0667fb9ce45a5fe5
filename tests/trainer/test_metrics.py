"""Image metrics (PSNR, SSIM, FLIP) and evaluation reports on small synthetic images."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from PIL import Image

from gratnet.display import xyz_to_display_srgb8
from gratnet.errors import GratNetError
from trainer.metrics import (
    flip,
    image_metrics,
    psnr_xyz,
    show_pair,
    ssim_srgb,
    ssim_ycbcr,
    to_display_srgb,
)
from trainer.report import comparison_figure, metrics_table_markdown, write_report

# XYZ of the D65 white with Y = 1: linear sRGB (1, 1, 1).
WHITE_XYZ = np.array([0.95047, 1.0, 1.08883])


def textured(size: int = 48, seed: int = 0) -> np.ndarray:
    """A smooth, structured exposed-XYZ image in roughly [0, 0.9] with a specular peak above 1."""
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[0:size, 0:size] / size
    base = 0.45 + 0.35 * np.sin(2 * np.pi * 3 * x)[..., None] * np.cos(2 * np.pi * 2 * y)[..., None]
    tint = np.array([0.9, 1.0, 0.8]) + 0.1 * rng.random(3)
    image = base * tint
    image[size // 2 - 2 : size // 2 + 2, size // 2 - 2 : size // 2 + 2] = 3.0  # clipped highlight
    return image


def noisy(image: np.ndarray, sigma: float, seed: int = 1) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return np.clip(image + rng.normal(0.0, sigma, image.shape), 0.0, None)


def test_to_display_srgb_matches_8bit_pipeline() -> None:
    image = textured(32)
    srgb = to_display_srgb(image)
    assert srgb.shape == image.shape and srgb.dtype == np.float64
    assert srgb.min() >= 0.0 and srgb.max() <= 1.0
    np.testing.assert_array_equal(np.round(srgb * 255).astype(np.uint8), xyz_to_display_srgb8(image))
    white = to_display_srgb(np.broadcast_to(WHITE_XYZ, (4, 4, 3)).copy())
    np.testing.assert_allclose(white, 1.0, atol=1e-3)


def test_identical_images() -> None:
    image = textured()
    assert psnr_xyz(image, image) == math.inf
    assert ssim_srgb(image, image) == pytest.approx(1.0)
    assert ssim_ycbcr(image, image) == pytest.approx(1.0)
    mean, error_map = flip(image, image)
    assert mean == pytest.approx(0.0, abs=1e-6)
    assert error_map.shape == image.shape[:2]
    assert np.all(error_map == 0.0)
    metrics = image_metrics(image, image)
    assert set(metrics) == {"psnr_xyz", "ssim_srgb", "ssim_ycbcr", "flip"}
    assert metrics["psnr_xyz"] == math.inf and metrics["flip"] == pytest.approx(0.0, abs=1e-6)


def test_psnr_uniform_offset() -> None:
    reference = np.full((16, 16, 3), 0.4)
    test = reference + 0.05
    expected = 10.0 * math.log10(1.0 / 0.05**2)
    assert psnr_xyz(reference, test) == pytest.approx(expected)
    assert psnr_xyz(test, reference) == pytest.approx(expected)


def test_psnr_clips_to_displayable_range() -> None:
    reference = np.full((8, 8, 3), 2.0)
    test = np.full((8, 8, 3), 5.0)
    assert psnr_xyz(reference, test) == math.inf  # both clip to 1
    test = np.full((8, 8, 3), 0.9)  # differs by 0.1 after clipping
    assert psnr_xyz(reference, test) == pytest.approx(20.0)


def test_mask_restricts_psnr() -> None:
    reference = np.full((16, 16, 3), 0.5)
    test = reference.copy()
    test[:, 8:] += 0.2  # error only in the right half
    mask = np.zeros((16, 16), dtype=bool)
    mask[:, :8] = True
    assert psnr_xyz(reference, test) == pytest.approx(10 * math.log10(1 / (0.5 * 0.2**2)))
    assert psnr_xyz(reference, test, mask) == math.inf
    assert image_metrics(reference, test, mask)["psnr_xyz"] == math.inf
    mask[:, :] = False
    mask[0, 15] = True
    assert image_metrics(reference, test, mask)["psnr_xyz"] == pytest.approx(10 * math.log10(1 / 0.2**2))
    # SSIM and FLIP ignore the mask.
    full = image_metrics(reference, test)
    masked = image_metrics(reference, test, mask)
    assert masked["ssim_srgb"] == full["ssim_srgb"] and masked["flip"] == full["flip"]


def test_bad_masks() -> None:
    image = textured(16)
    with pytest.raises(GratNetError):
        image_metrics(image, image, np.ones((16, 15), dtype=bool))
    with pytest.raises(GratNetError):
        image_metrics(image, image, np.ones((16, 16), dtype=np.float32))
    with pytest.raises(GratNetError):
        image_metrics(image, image, np.zeros((16, 16), dtype=bool))


def test_ssim_drops_for_shifted_and_noisy_images() -> None:
    image = textured()
    shifted = np.roll(image, 3, axis=1)
    for metric in (ssim_srgb, ssim_ycbcr):
        same = metric(image, image)
        assert metric(image, shifted) < same - 0.05
        low, high = metric(image, noisy(image, 0.02)), metric(image, noisy(image, 0.1))
        assert high < low < same


def test_flip_black_vs_white_and_noise_monotonic() -> None:
    black = np.zeros((32, 32, 3))
    white = np.broadcast_to(WHITE_XYZ, (32, 32, 3)).copy()
    mean, error_map = flip(black, white)
    assert mean > 0.5
    assert error_map.min() >= 0.0 and error_map.max() <= 1.0
    image = textured()
    errors = [flip(image, noisy(image, sigma))[0] for sigma in (0.01, 0.05, 0.2)]
    assert 0.0 < errors[0] < errors[1] < errors[2]


def test_flip_ppd_is_used() -> None:
    image = textured(32)
    test = noisy(image, 0.05)
    default, _ = flip(image, test)
    assert flip(image, test, ppd=67.02064514160156)[0] == pytest.approx(default)
    assert flip(image, test, ppd=10.0)[0] != pytest.approx(default)
    with pytest.raises(GratNetError):
        flip(image, test, ppd=0.0)


@pytest.mark.parametrize(
    ("reference", "test"),
    [
        (np.zeros((8, 8, 3)), np.zeros((8, 9, 3))),  # different shapes
        (np.zeros((8, 8, 4)), np.zeros((8, 8, 4))),  # not three channels
        (np.zeros((8, 8)), np.zeros((8, 8))),  # no channel axis
        (np.zeros((8, 8, 3)), np.full((8, 8, 3), np.nan)),  # not finite
        (np.full((8, 8, 3), np.inf), np.zeros((8, 8, 3))),  # not finite
    ],
)
def test_bad_shapes_raise(reference: np.ndarray, test: np.ndarray) -> None:
    for metric in (psnr_xyz, ssim_srgb, ssim_ycbcr, flip, image_metrics):
        with pytest.raises(GratNetError):
            metric(reference, test)


def test_small_images_still_work() -> None:
    image = textured(5)
    assert ssim_srgb(image, image) == pytest.approx(1.0)
    with pytest.raises(GratNetError):
        ssim_srgb(np.zeros((2, 8, 3)), np.zeros((2, 8, 3)))


def test_show_pair_agrees_with_flip_and_psnr() -> None:
    """The comparison figure's numbers (show_pair) are flip's and psnr_xyz's, computed once."""
    reference, test = textured(24), noisy(textured(24), 0.05)
    shown = show_pair(reference, test)
    mean_flip, flip_map = flip(reference, test)
    assert shown.mean_flip == mean_flip and np.array_equal(shown.flip_map, flip_map)
    assert shown.psnr_db == psnr_xyz(reference, test)
    assert np.array_equal(shown.reference_srgb, to_display_srgb(reference))
    with pytest.raises(GratNetError, match="shapes differ"):
        show_pair(reference, test[:-1])


def test_comparison_figure_writes_png(tmp_path) -> None:
    image = textured(32)
    path = tmp_path / "compare.png"
    comparison_figure(
        path,
        [("view 1", image, noisy(image, 0.05)), ("view 2", image, image)],
        title="test figure",
    )
    with Image.open(path) as png:
        png.load()
        assert png.format == "PNG"
        width, height = png.size
    # Two rows of square panels under three columns (+ colour bars): taller than one row, ~ 1.4 : 1.
    assert 1.0 < width / height < 2.0
    comparison_figure(tmp_path / "one.png", [("only", image, image)])
    with Image.open(tmp_path / "one.png") as png:
        single_width, single_height = png.size
    assert single_width == width and single_height < height
    assert single_width / single_height > 2.5
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]  # no temporary files left
    with pytest.raises(GratNetError):
        comparison_figure(tmp_path / "none.png", [])


def test_metrics_table_markdown_formats() -> None:
    table = metrics_table_markdown(
        [
            {"name": "a|b", "psnr_xyz": math.inf, "flip": 0.0123456, "count": 3},
            {"name": "c", "psnr_xyz": np.float32(31.234567), "flip": 1234567.0},
        ],
        ["name", "psnr_xyz", "flip", "count"],
    )
    lines = table.strip().splitlines()
    assert lines[0] == "| name | psnr_xyz | flip | count |"
    assert set(lines[1].replace("|", "").split()) == {"---"}
    assert lines[2] == "| a\\|b | ∞ | 0.01235 | 3 |"
    assert lines[3] == "| c | 31.23 | 1.235e+06 | — |"


def test_write_report(tmp_path) -> None:
    image = textured(16)
    comparison_figure(tmp_path / "figure one.png", [("x", image, image)])
    metrics = {"mean": {"psnr_xyz": math.inf, "flip": np.float64(0.25)}, "count": np.int64(2), "per_view": [1.5]}
    rows = [{"view": "front", "psnr_xyz": 35.123456, "flip": 0.05}]
    write_report(tmp_path / "out", metrics, rows, ["view", "psnr_xyz", "flip"], "Evaluation")
    text = (tmp_path / "out" / "metrics.json").read_text()
    loaded = json.loads(text, parse_constant=lambda name: pytest.fail(f"non-standard JSON constant {name}"))
    assert loaded == {"mean": {"psnr_xyz": "inf", "flip": 0.25}, "count": 2, "per_view": [1.5]}
    assert text.startswith("{\n  ")
    report = (tmp_path / "out" / "report.md").read_text()
    assert report.startswith("# Evaluation\n")
    assert "| view | psnr_xyz | flip |" in report
    assert "| front | 35.12 | 0.05 |" in report
    assert ".png" not in report  # no figures in that folder

    write_report(tmp_path, metrics, rows, ["view", "psnr_xyz", "flip"], "With figures")
    report = (tmp_path / "report.md").read_text()
    assert "![figure one.png](figure%20one.png)" in report
