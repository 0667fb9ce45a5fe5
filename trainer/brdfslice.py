"""Ground-truth BRDF slices: fix ωi, look at every view direction of the hemisphere.

colour = exposure · A(ωi, ωo) · XYZ(−(ωi + ωo))  (physics.md, "BRDF slices"), with XYZ evaluated at
the exact key vectors (no lookup in a volume). For a fixed ωi the slice's u and v are regular
grids (u = −(sinθi cosφi + x), v = −(sinθi sinφi + y)), so the F-term engine's grid path applies,
with w = −(cosθi + cosθo) varying per pixel (Chebyshev interpolation in w).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from gratnet.brdf import a_term, direction, slice_view_directions
from gratnet.config import config_field
from gratnet.errors import GratNetError
from trainer.fourier import FTerm, OpticsConfig, PreparedSurface
from trainer.spectral import spectral_weights


@dataclasses.dataclass(frozen=True)
class SliceConfig:
    """A BRDF slice: light direction, image size, exposure and Fresnel."""

    light_theta_degrees: float = config_field(30.0, "light polar angle θi (degrees from the normal)", cli=False)
    light_phi_degrees: float = config_field(0.0, "light azimuth φi (degrees from +x)", cli=False)
    size: int = config_field(256, "image width and height (pixels)")
    exposure: float = config_field(5000.0, "multiplies A·XYZ before display (the paper's 'RU')")
    ior: float = config_field(1.5, "refractive index for the Fresnel term; 0 turns Fresnel off")

    def __post_init__(self) -> None:
        if not 0.0 <= self.light_theta_degrees < 90.0:
            raise GratNetError(f"light θ must lie in [0, 90) degrees, got {self.light_theta_degrees}")
        if self.size < 2:
            raise GratNetError(f"--size must be at least 2 pixels, got {self.size}")
        if not (np.isfinite(self.exposure) and self.exposure > 0):
            raise GratNetError(f"--exposure must be positive, got {self.exposure}")
        if self.ior < 0:
            raise GratNetError(f"--ior must be ≥ 0 (0: Fresnel off), got {self.ior}")


def slice_geometry(config: SliceConfig) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The slice's light direction (3,), view directions (size, size, 3) and unit-disc mask (size, size)."""
    light = direction(config.light_theta_degrees, config.light_phi_degrees)
    views, inside = slice_view_directions(config.size)
    return light, views, inside


def expose_slice(config: SliceConfig, light: np.ndarray, views: np.ndarray, inside: np.ndarray,
                 xyz: np.ndarray) -> np.ndarray:
    """exposure · A(ωi, ωo) · XYZ per pixel, 0 outside the disc: shared by ground-truth and network slices."""
    attenuation = a_term(light, views, ior=config.ior or None)
    return np.where(inside[..., None], config.exposure * attenuation[..., None] * xyz, 0.0)


def brdf_slice_xyz(surface: PreparedSurface, config: SliceConfig, optics: OpticsConfig,
                   progress: bool = True, device: str | None = None) -> np.ndarray:
    """exposure · A · XYZ for every pixel, shape (size, size, 3); 0 outside the unit disc. ``device``: as
    :class:`trainer.fourier.FTerm`'s (None: numpy)."""
    light, views, inside = slice_geometry(config)
    x_axis, y_axis = views[0, :, 0], views[:, 0, 1]
    u_axis = -(light[0] + x_axis)
    v_axis = -(light[1] + y_axis)
    # Outside the disc w is irrelevant: give it an in-range value so it does not widen the interpolation.
    w = np.where(inside, -(light[2] + views[..., 2]), -light[2] - 0.5)
    spectral = spectral_weights(optics.wavelength_start_nm, optics.wavelength_end_nm, optics.wavelength_step_nm)
    xyz = FTerm(surface, spectral, optics.tolerance, device=device).xyz_grid(
        u_axis, v_axis, [w], progress="BRDF slice" if progress else False
    )[0]
    return expose_slice(config, light, views, inside, xyz)
