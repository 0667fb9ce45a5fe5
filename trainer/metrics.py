"""Image metrics comparing a ground-truth render with a network prediction.

Both inputs are *exposed* CIE XYZ images (H, W, 3): float, ≥ 0, already multiplied by the exposure
and the A-term, so values may exceed 1 at specular peaks. The display pipeline is the one of
:mod:`gratnet.display`: XYZ → linear sRGB → clip to [0, 1] → sRGB transfer function.

* ``psnr_xyz``: PSNR of the XYZ values clipped to [0, 1] (the displayable range), peak 1.
* ``ssim_srgb``: SSIM (scikit-image, default 7 × 7 uniform window, ``data_range=1``) on display sRGB.
* ``ssim_ycbcr``: the same SSIM on full-range ITU-R BT.601 YCbCr computed from display sRGB
  (Y ∈ [0, 1], Cb and Cr shifted from [−½, ½] to [0, 1]), mean over the three channels.
* ``flip``: LDR-FLIP (NVIDIA ``flip_evaluator``) on display sRGB in [0, 1] at 67.02 pixels per
  degree (FLIP's default: a 0.7 m wide 3840-pixel display seen from 0.7 m).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from gratnet.display import ldr_flip, xyz_to_linear_srgb
from gratnet.errors import GratNetError

#: SSIM window side used by scikit-image by default; reduced (odd, ≥ 3) for smaller images.
_SSIM_WINDOW = 7

METRIC_NAMES = ("psnr_xyz", "ssim_srgb", "ssim_ycbcr", "flip")


def _check_image(image: np.ndarray, name: str) -> np.ndarray:
    array = np.asarray(image)
    if array.ndim != 3 or array.shape[-1] != 3:
        raise GratNetError(f"{name} must be an (H, W, 3) XYZ image, got shape {array.shape}")
    if array.shape[0] < 1 or array.shape[1] < 1:
        raise GratNetError(f"{name} is empty (shape {array.shape})")
    if not np.issubdtype(array.dtype, np.number) or np.iscomplexobj(array):
        raise GratNetError(f"{name} must hold real numbers, got dtype {array.dtype}")
    array = array.astype(np.float64, copy=False)
    if not np.all(np.isfinite(array)):
        raise GratNetError(f"{name} contains NaN or infinite values")
    return array


def _check_pair(reference_xyz: np.ndarray, test_xyz: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    reference = _check_image(reference_xyz, "the reference image")
    test = _check_image(test_xyz, "the test image")
    if reference.shape != test.shape:
        raise GratNetError(f"image shapes differ: reference {reference.shape}, test {test.shape}")
    return reference, test


def _display_srgb(xyz: np.ndarray) -> np.ndarray:
    import colour

    linear = np.clip(xyz_to_linear_srgb(xyz), 0.0, 1.0)
    encoded = np.asarray(colour.cctf_encoding(linear, function="sRGB"), dtype=np.float64)
    return np.clip(encoded, 0.0, 1.0)


def to_display_srgb(xyz: np.ndarray) -> np.ndarray:
    """Exposed CIE XYZ (H, W, 3) → display sRGB float64 in [0, 1] (clipped linear sRGB, sRGB curve)."""
    return _display_srgb(_check_image(xyz, "the image"))


def _ycbcr_bt601(srgb: np.ndarray) -> np.ndarray:
    """Display sRGB in [0, 1] → full-range BT.601 YCbCr with every channel in [0, 1]."""
    import colour

    ycbcr = np.asarray(
        colour.RGB_to_YCbCr(srgb, K=colour.WEIGHTS_YCBCR["ITU-R BT.601"], out_legal=False, out_int=False),
        dtype=np.float64,
    )
    ycbcr[..., 1:] += 0.5
    return np.clip(ycbcr, 0.0, 1.0)


def _ssim(reference: np.ndarray, test: np.ndarray) -> float:
    """Mean SSIM over the channels of two (H, W, C) images with values in [0, 1]."""
    from skimage.metrics import structural_similarity

    side = min(reference.shape[0], reference.shape[1])
    window = min(_SSIM_WINDOW, side if side % 2 == 1 else side - 1)
    if window < 3:
        raise GratNetError(f"SSIM needs images at least 3 × 3 pixels, got {reference.shape[0]} × {reference.shape[1]}")
    value = structural_similarity(reference, test, win_size=window, data_range=1.0, channel_axis=-1)
    return float(value)


def _psnr(reference: np.ndarray, test: np.ndarray, mask: np.ndarray | None) -> float:
    difference = np.clip(reference, 0.0, 1.0) - np.clip(test, 0.0, 1.0)
    if mask is not None:
        difference = difference[mask]
    mse = float(np.mean(difference * difference))
    if mse == 0.0:
        return math.inf
    return 10.0 * math.log10(1.0 / mse)


def _check_mask(mask: np.ndarray | None, shape: tuple[int, ...]) -> np.ndarray | None:
    if mask is None:
        return None
    array = np.asarray(mask)
    if array.shape != tuple(shape[:2]):
        raise GratNetError(f"the mask must have shape {tuple(shape[:2])} (H, W), got {array.shape}")
    if array.dtype != np.bool_:
        raise GratNetError(f"the mask must be boolean, got dtype {array.dtype}")
    if not array.any():
        raise GratNetError("the mask selects no pixels: PSNR is undefined")
    return array


def psnr_xyz(reference_xyz: np.ndarray, test_xyz: np.ndarray, mask: np.ndarray | None = None) -> float:
    """PSNR (dB) of the exposed XYZ images clipped to [0, 1], peak 1, MSE over all pixels and channels.

    ``mask`` (H, W) bool restricts the MSE to the selected pixels. Returns ``inf`` when the clipped
    images are identical (there).
    """
    reference, test = _check_pair(reference_xyz, test_xyz)
    return _psnr(reference, test, _check_mask(mask, reference.shape))


def ssim_srgb(reference_xyz: np.ndarray, test_xyz: np.ndarray) -> float:
    """SSIM on display sRGB: ``structural_similarity(channel_axis=-1, data_range=1)``, 7 × 7 window.

    The window shrinks to the largest odd size that fits for images smaller than 7 pixels.
    """
    reference, test = _check_pair(reference_xyz, test_xyz)
    return _ssim(_display_srgb(reference), _display_srgb(test))


def ssim_ycbcr(reference_xyz: np.ndarray, test_xyz: np.ndarray) -> float:
    """SSIM on full-range ITU-R BT.601 YCbCr (from display sRGB, channels in [0, 1]), channel mean."""
    reference, test = _check_pair(reference_xyz, test_xyz)
    return _ssim(_ycbcr_bt601(_display_srgb(reference)), _ycbcr_bt601(_display_srgb(test)))


def flip(reference_xyz: np.ndarray, test_xyz: np.ndarray, ppd: float | None = None) -> tuple[float, np.ndarray]:
    """Mean LDR-FLIP and the per-pixel FLIP error map (H, W) float64 in [0, 1].

    Both images go through the display pipeline and are handed to ``flip_evaluator.evaluate`` as
    float32 display sRGB in [0, 1] (``"LDR"``, ``inputsRGB=True``). ``ppd`` defaults to FLIP's own
    default, 67.02 pixels per degree (:data:`gratnet.display.FLIP_DEFAULT_PPD`).
    """
    reference, test = _check_pair(reference_xyz, test_xyz)
    return ldr_flip(_display_srgb(reference), _display_srgb(test), ppd)


@dataclasses.dataclass(frozen=True)
class ShownPair:
    """One image pair as a comparison figure shows it (trainer/report.py): both images in display sRGB, float64
    (H, W, 3) in [0, 1]; the LDR-FLIP error map (H, W) in [0, 1] and its mean; PSNR (dB) of the whole image."""

    reference_srgb: np.ndarray
    test_srgb: np.ndarray
    flip_map: np.ndarray
    mean_flip: float
    psnr_db: float


def show_pair(reference_xyz: np.ndarray, test_xyz: np.ndarray) -> ShownPair:
    """The display images, FLIP map and PSNR of one exposed XYZ pair, each computed once: the same numbers as
    :func:`flip` and :func:`psnr_xyz` (no mask), which would each convert both images again."""
    reference, test = _check_pair(reference_xyz, test_xyz)
    reference_srgb, test_srgb = _display_srgb(reference), _display_srgb(test)
    mean_flip, flip_map = ldr_flip(reference_srgb, test_srgb, None)
    return ShownPair(reference_srgb, test_srgb, flip_map, mean_flip, _psnr(reference, test, None))


def image_metrics(reference_xyz: np.ndarray, test_xyz: np.ndarray, mask: np.ndarray | None = None) -> dict[str, float]:
    """``{"psnr_xyz", "ssim_srgb", "ssim_ycbcr", "flip"}`` for one image pair.

    ``mask`` (H, W) bool restricts PSNR to the selected pixels (e.g. inside the BRDF disc); SSIM
    and FLIP always use the whole image (they are neighbourhood-based).
    """
    reference, test = _check_pair(reference_xyz, test_xyz)
    selected = _check_mask(mask, reference.shape)
    reference_srgb = _display_srgb(reference)
    test_srgb = _display_srgb(test)
    mean_flip, _ = ldr_flip(reference_srgb, test_srgb, None)
    return {
        "psnr_xyz": _psnr(reference, test, selected),
        "ssim_srgb": _ssim(reference_srgb, test_srgb),
        "ssim_ycbcr": _ssim(_ycbcr_bt601(reference_srgb), _ycbcr_bt601(test_srgb)),
        "flip": mean_flip,
    }
