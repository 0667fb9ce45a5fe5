"""CIE XYZ → display sRGB for previews and renders (runtime-side: no torch).

XYZ (D65 white, Y = 1 for a perfect mirror at the specular peak) → linear sRGB (IEC 61966-2-1
primaries, D65 white, no chromatic adaptation needed) → × exposure → clipped to [0, 1] → display
sRGB (the sRGB transfer function) → 8-bit. colour-science provides both steps.
"""

from __future__ import annotations

import math

import numpy as np

from gratnet.errors import GratNetError

#: FLIP's default pixels per degree (0.7 m viewing distance, 3840 px over 0.7 m); used unless overridden.
FLIP_DEFAULT_PPD = 67.02064514160156


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


def ldr_flip(reference_srgb: np.ndarray, test_srgb: np.ndarray, ppd: float | None = None) -> tuple[float, np.ndarray]:
    """Mean LDR-FLIP and its per-pixel map ``(H, W)`` float64 in [0, 1] of two display-sRGB images ``(H, W, 3)`` in
    [0, 1] (NVIDIA's ``flip_evaluator``, ``inputsRGB``), at ``ppd`` pixels per degree (default
    :data:`FLIP_DEFAULT_PPD`). The one FLIP of the project: evaluation reports, ``gratnet compare``, the viewer."""
    import flip_evaluator

    used_ppd = FLIP_DEFAULT_PPD if ppd is None else float(ppd)
    if not (math.isfinite(used_ppd) and used_ppd > 0.0):
        # flip_evaluator would call sys.exit() on a bad PPD: check here instead.
        raise GratNetError(f"FLIP pixels per degree must be a positive number, got {ppd}")
    error_map, mean_error, _ = flip_evaluator.evaluate(
        np.ascontiguousarray(reference_srgb, dtype=np.float32),
        np.ascontiguousarray(test_srgb, dtype=np.float32),
        "LDR",
        inputsRGB=True,
        applyMagma=False,
        computeMeanError=True,
        parameters={"ppd": used_ppd},
    )
    error = np.asarray(error_map, dtype=np.float64).reshape(np.shape(reference_srgb)[:2])
    return float(mean_error), error
