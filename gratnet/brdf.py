"""Geometry of a BRDF slice and the A-term (docs/physics.md, "BRDF slices" and "The A-term").

Conventions: directions are unit vectors in the surface frame (x, y tangent, z = normal) pointing
away from the surface; a direction at polar angle θ and azimuth φ (degrees) is
(sinθ cosφ, sinθ sinφ, cosθ). The key vector is (u, v, w) = −(ωi + ωo), so w ∈ [−2, 0].

    A(ωi, ωo) = R(ωi, ωo)² · G / (R0² · w²),  G = (1 + ωi·ωo)² / (cosθi · cosθo)   for |w| > 1e-6, else 0

with R the unpolarised Fresnel reflectance (intensity) of a dielectric of refractive
index ``ior`` at the half-vector angle and R0 its value at normal incidence (``ior=None``: R/R0 = 1).
Runtime-side (numpy only); the GLSL runtime implements the same formula and a parity test ties them.
"""

from __future__ import annotations

import math

import numpy as np

W_EPSILON = 1e-6  # |w| below this: A = 0 (grazing: the 1/w² factor is meaningless there)


def cos_sin_degrees(angle_degrees: float) -> tuple[float, float]:
    """(cos, sin) of an angle in degrees, exact at multiples of 90°.

    radians(90) is not π/2 exactly, so cos(radians(90)) = 6.1e-17: a light at θ = 90° would sit *above*
    the horizon and get A ~ 1e16 (physics.md eq. 5 wants 0 there).
    """
    quadrant = float(angle_degrees) % 360.0  # 360.0 itself for tiny negative angles (rounding)
    if quadrant % 90.0 == 0.0:
        return {0.0: (1.0, 0.0), 90.0: (0.0, 1.0), 180.0: (-1.0, 0.0), 270.0: (0.0, -1.0), 360.0: (1.0, 0.0)}[quadrant]
    radians = math.radians(angle_degrees)
    return math.cos(radians), math.sin(radians)


def direction(theta_degrees: float, phi_degrees: float) -> np.ndarray:
    """Unit vector at polar angle θ and azimuth φ (degrees) in the surface frame."""
    cos_theta, sin_theta = cos_sin_degrees(theta_degrees)
    cos_phi, sin_phi = cos_sin_degrees(phi_degrees)
    return np.array([sin_theta * cos_phi, sin_theta * sin_phi, cos_theta])


def slice_view_directions(size: int) -> tuple[np.ndarray, np.ndarray]:
    """View directions ωo of a size×size BRDF-slice image and the mask of pixels inside the unit disc.

    Pixel centres map orthographically onto the base plane: column j → x = −1 + (2j + 1)/size
    (left to right), row i → y = 1 − (2i + 1)/size (top to bottom, so +y is up), and
    ωo = (x, y, sqrt(1 − x² − y²)). Returns (directions (size, size, 3), inside (size, size)).
    """
    centres = -1.0 + (2.0 * np.arange(size) + 1.0) / size
    x, y = np.meshgrid(centres, -centres, indexing="xy")
    radius_squared = x * x + y * y
    inside = radius_squared < 1.0
    z = np.sqrt(np.clip(1.0 - radius_squared, 0.0, None))
    return np.stack([x, y, z], axis=-1), inside


def fresnel_dielectric(cos_incidence: np.ndarray, ior: float) -> np.ndarray:
    """Unpolarised Fresnel reflectance of a dielectric (real refractive index ``ior``) at cos θ."""
    cos_i = np.clip(np.asarray(cos_incidence, dtype=np.float64), 0.0, 1.0)
    with np.errstate(over="ignore"):  # two divisions: ior² under/overflows for extreme IORs (0/0 = NaN)
        sin_t_squared = (1.0 - cos_i * cos_i) / ior / ior
    cos_t = np.sqrt(np.clip(1.0 - sin_t_squared, 0.0, None))
    perpendicular = (cos_i - ior * cos_t) / np.maximum(cos_i + ior * cos_t, 1e-300)
    parallel = (ior * cos_i - cos_t) / np.maximum(ior * cos_i + cos_t, 1e-300)
    reflectance = 0.5 * (perpendicular**2 + parallel**2)
    return np.where(sin_t_squared >= 1.0, 1.0, reflectance)


def a_term(light: np.ndarray, view: np.ndarray, ior: float | None = 1.5) -> np.ndarray:
    """A(ωi, ωo) for directions of shape (…, 3) (broadcast); 0 where |w| ≤ 1e-6 or below the horizon."""
    light, view = np.broadcast_arrays(np.asarray(light, dtype=np.float64), np.asarray(view, dtype=np.float64))
    cos_light, cos_view = light[..., 2], view[..., 2]
    w = -(cos_light + cos_view)
    # 1 + ωi·ωo = |ωi + ωo|²/2 for unit vectors: no cancellation near grazing, where ωi·ωo → −1 (as the shader).
    key = light + view
    one_plus_cosine = 0.5 * np.sum(key * key, axis=-1)
    geometry = np.square(one_plus_cosine) / np.maximum(cos_light * cos_view, 1e-300)
    if ior is None:
        fresnel_ratio = 1.0
    else:
        # Half-vector angle: cos θh = ωi·h = sqrt((1 + ωi·ωo)/2).
        cos_half = np.sqrt(np.clip(0.5 * one_plus_cosine, 0.0, 1.0))
        fresnel_ratio = np.square(fresnel_dielectric(cos_half, ior) / fresnel_dielectric(np.ones(1), ior)[0])
    valid = (np.abs(w) > W_EPSILON) & (cos_light > 0.0) & (cos_view > 0.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        value = fresnel_ratio * geometry / np.square(w)
    return np.where(valid, value, 0.0)
