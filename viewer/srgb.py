"""The viewer's display conversion in numpy alone: exposed CIE XYZ to 8-bit display sRGB, as ``gratnet.display``.

``gratnet.display`` converts with colour-science, whose import takes 1.2–5.7 s on a busy 2-core machine
(issue 35: the window waited for it before it showed). The window converts every preview, band and sample
here instead, with the very operations colour-science performs for ``XYZ_to_RGB(xyz, "sRGB")`` and the sRGB
``cctf_encoding`` (its chromatic adaptation from the sRGB white point to itself, a matrix within 3e-17 of the
identity, then ``matrix_XYZ_to_RGB``, each applied as ``np.matmul``; then clipping, the sRGB transfer function
and rounding), so the bytes are the same as ``gratnet render``'s: tests/runtime/test_viewer_display.py compares them
bit for bit. No GL, no colour-science.
"""

from __future__ import annotations

import numpy as np

__all__ = ["XYZ_TO_LINEAR_SRGB", "display_srgb8", "linear_srgb"]

#: colour-science's CAT02 adaptation from the sRGB white point (D65) to itself: the identity up to rounding.
_SELF_ADAPTATION = np.array([
    [1.0, -2.925337592710602e-17, -2.0424934209769367e-17],
    [1.865516512262643e-17, 1.0, -6.012863655103287e-19],
    [-1.1925326645651568e-18, -6.805220268068795e-19, 1.0],
], dtype=np.float64)
#: IEC 61966-2-1's XYZ → linear sRGB matrix (colour-science's ``RGB_COLOURSPACES["sRGB"].matrix_XYZ_to_RGB``).
XYZ_TO_LINEAR_SRGB = np.array([
    [3.2406, -1.5372, -0.4986],
    [-0.9689, 1.8758, 0.0415],
    [0.0557, -0.204, 1.057],
], dtype=np.float64)


def _apply(matrix: np.ndarray, vectors: np.ndarray) -> np.ndarray:
    return np.matmul(matrix, vectors[..., None]).squeeze(-1)


def linear_srgb(xyz: np.ndarray) -> np.ndarray:
    """CIE XYZ ``(…, 3)`` → linear sRGB ``(…, 3)`` float64, unclipped (``gratnet.display.xyz_to_linear_srgb``)."""
    return _apply(XYZ_TO_LINEAR_SRGB, _apply(_SELF_ADAPTATION, np.asarray(xyz, dtype=np.float64)))


def display_srgb8(xyz: np.ndarray, exposure: float = 1.0) -> np.ndarray:
    """CIE XYZ ``(…, 3)`` → 8-bit display sRGB ``(…, 3)`` after multiplying by ``exposure`` and clipping
    (``gratnet.display.xyz_to_display_srgb8``, byte for byte)."""
    linear = np.clip(linear_srgb(xyz) * float(exposure), 0.0, 1.0)
    with np.errstate(invalid="ignore"):  # NaN stays NaN, as in colour-science
        encoded = np.where(linear <= 0.0031308, linear * 12.92,
                           1.055 * (np.sign(linear) * np.abs(linear) ** (1 / 2.4)) - 0.055)
    return np.round(np.clip(encoded, 0.0, 1.0) * 255.0).astype(np.uint8)
