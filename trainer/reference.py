"""Reference evaluations of the F-term, for tests and the stability study only (slow, float64).

- :func:`brute_force_xyz`: the integral (physics.md eq. 1) summed term by term at arbitrary key
  vectors, with no separation, no interpolation and no Taylor series.
- :func:`taylor_xyz`: the paper's route (Appendix A: P = Σₙ (i k w)ⁿ/n! · FT[g·hⁿ]), kept to show
  where it breaks down (tall height fields).
"""

from __future__ import annotations

import math

import numpy as np

from trainer.fourier import PreparedSurface
from trainer.spectral import SpectralWeights, spectral_weights


def _points(u: np.ndarray, v: np.ndarray, w: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    u, v, w = np.broadcast_arrays(*(np.asarray(a, dtype=np.float64) for a in (u, v, w)))
    return u.ravel(), v.ravel(), w.ravel()


def brute_force_amplitude(
    surface: PreparedSurface, u: np.ndarray, v: np.ndarray, w: np.ndarray, wavelength_um: float
) -> np.ndarray:
    """P/∫g at each point (u, v, w) for one wavelength (µm), float64, summed over every sample."""
    wavenumber = 2.0 * np.pi / wavelength_um
    x_grid, y_grid = np.meshgrid(surface.x_um, surface.y_um, indexing="xy")
    heights = surface.heights_um.astype(np.float64).ravel()
    window = np.outer(surface.window_y, surface.window_x).ravel()
    x_flat, y_flat = x_grid.ravel(), y_grid.ravel()
    u, v, w = _points(u, v, w)
    amplitude = np.empty(u.size, dtype=np.complex128)
    chunk = max(1, 2_000_000 // heights.size)
    for start in range(0, u.size, chunk):
        stop = start + chunk
        phase = wavenumber * (
            np.outer(u[start:stop], x_flat) + np.outer(v[start:stop], y_flat) + np.outer(w[start:stop], heights)
        )
        amplitude[start:stop] = np.exp(1j * phase) @ window
    return amplitude


def brute_force_xyz(
    surface: PreparedSurface, u: np.ndarray, v: np.ndarray, w: np.ndarray, spectral: SpectralWeights | None = None
) -> np.ndarray:
    """CIE XYZ (eq. 3) at each point (u, v, w) by brute force; shape (points, 3)."""
    spectral = spectral or spectral_weights()
    size = _points(u, v, w)[0].size
    xyz = np.zeros((size, 3))
    for wavelength, weights in zip(spectral.wavelengths_um, spectral.xyz_weights, strict=True):
        power = np.abs(brute_force_amplitude(surface, u, v, w, wavelength)) ** 2
        xyz += power[:, None] * weights
    return xyz


def taylor_amplitude(
    surface: PreparedSurface, u: np.ndarray, v: np.ndarray, w: np.ndarray, wavelength_um: float,
    terms: int | None = None,
) -> np.ndarray:
    """P/∫g by the paper's Taylor series in (i k w h)ⁿ/n!, in float64 (Appendix A).

    The moments FT[g·hⁿ] are computed exactly (brute force); only the series itself is the paper's.
    Without ``terms``, as many terms as the series needs to converge in exact arithmetic.
    """
    wavenumber = 2.0 * np.pi / wavelength_um
    u, v, w = _points(u, v, w)
    x_grid, y_grid = np.meshgrid(surface.x_um, surface.y_um, indexing="xy")
    window = np.outer(surface.window_y, surface.window_x).ravel()
    heights = surface.heights_um.astype(np.float64).ravel()
    plane_wave = np.exp(1j * wavenumber * (np.outer(u, x_grid.ravel()) + np.outer(v, y_grid.ravel())))
    largest = wavenumber * float(np.max(np.abs(w))) * surface.half_span_um
    count = terms or int(math.ceil(math.e * largest + 40))
    total = np.zeros(u.size, dtype=np.complex128)
    power_of_h = np.ones_like(heights)
    factor = np.ones(u.size, dtype=np.complex128)  # (i k w)ⁿ / n!
    for order in range(count):
        total += factor * (plane_wave @ (window * power_of_h))
        power_of_h = power_of_h * heights
        factor = factor * (1j * wavenumber * w) / (order + 1)
    return total
