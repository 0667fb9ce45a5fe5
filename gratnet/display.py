"""CIE XYZ → display sRGB for previews and renders (runtime-side: no torch).

XYZ (D65 white, Y = 1 for a perfect mirror at the specular peak) → linear sRGB (IEC 61966-2-1
primaries, D65 white, no chromatic adaptation needed) → × exposure → clipped to [0, 1] → display
sRGB (the sRGB transfer function) → 8-bit. colour-science provides both steps.
"""

from __future__ import annotations

import numpy as np


def xyz_to_linear_srgb(xyz: np.ndarray) -> np.ndarray:
    """CIE XYZ (…, 3) → linear sRGB (…, 3), unclipped (may be negative out of gamut)."""
    import colour

    return np.asarray(colour.XYZ_to_RGB(np.asarray(xyz, dtype=np.float64), "sRGB"), dtype=np.float64)


def xyz_to_display_srgb8(xyz: np.ndarray, exposure: float = 1.0) -> np.ndarray:
    """CIE XYZ (…, 3) → 8-bit display sRGB (…, 3) after multiplying by ``exposure`` and clipping."""
    import colour

    linear = np.clip(xyz_to_linear_srgb(xyz) * float(exposure), 0.0, 1.0)
    encoded = np.asarray(colour.cctf_encoding(linear, function="sRGB"), dtype=np.float64)
    return np.round(np.clip(encoded, 0.0, 1.0) * 255.0).astype(np.uint8)
