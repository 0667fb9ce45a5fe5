"""Spectral integration weights: D65 illuminant × CIE 1931 2° colour matching functions (colour-science).

XYZ(u,v,w) = Σλ F(u,v,w,λ) · D65(λ) · cmf(λ) / Σλ D65(λ) · ȳ(λ)      (docs/physics.md, "Colour")

so a perfectly reflecting flat mirror (F = 1 at every λ) has Y = 1 and the chromaticity of D65.
"""

from __future__ import annotations

import dataclasses
import functools

import numpy as np

from gratnet.errors import GratNetError

OBSERVER = "CIE 1931 2 Degree Standard Observer"
ILLUMINANT = "D65"


@dataclasses.dataclass(frozen=True)
class SpectralWeights:
    """Wavelength samples (nm) and the per-wavelength CIE XYZ weights (D65 × cmf, normalised so Σ ȳ-weights = 1)."""

    wavelengths_nm: np.ndarray  # shape (L,)
    xyz_weights: np.ndarray  # shape (L, 3): columns X, Y, Z

    @property
    def wavelengths_um(self) -> np.ndarray:
        """Wavelengths in µm."""
        return self.wavelengths_nm / 1000.0


@functools.lru_cache(maxsize=8)
def spectral_weights(start_nm: float = 380.0, end_nm: float = 780.0, step_nm: float = 5.0) -> SpectralWeights:
    """D65-weighted CIE 1931 2° colour matching functions on start…end (both included) every step (nm)."""
    import colour

    if not (step_nm > 0 and 360.0 <= start_nm <= end_nm <= 830.0):
        raise GratNetError(
            f"wavelength range must lie within 360–830 nm with a positive step, got {start_nm}–{end_nm} nm "
            f"every {step_nm} nm"
        )
    count = int(round((end_nm - start_nm) / step_nm)) + 1
    wavelengths = start_nm + step_nm * np.arange(count, dtype=np.float64)
    wavelengths = wavelengths[wavelengths <= end_nm + 1e-9]
    # Sampled (interpolated where needed) on the tables' own 1 nm / 5 nm domains.
    cmfs = np.asarray(colour.MSDS_CMFS[OBSERVER][wavelengths], dtype=np.float64)
    illuminant = np.asarray(colour.SDS_ILLUMINANTS[ILLUMINANT][wavelengths], dtype=np.float64)
    weights = cmfs * illuminant[:, None]
    weights /= weights[:, 1].sum()
    wavelengths.setflags(write=False)
    weights.setflags(write=False)
    return SpectralWeights(wavelengths, weights)


def monochromatic(wavelength_nm: float) -> SpectralWeights:
    """One wavelength whose Y weight is 1 (X = Z = 0): XYZ[..., 1] is then F itself (studies, tests)."""
    return SpectralWeights(np.array([float(wavelength_nm)]), np.array([[0.0, 1.0, 0.0]]))
