"""Geometry of a BRDF slice and the A-term (docs/physics.md, "BRDF slices" and "The A-term").

Conventions: directions are unit vectors in the surface frame (x, y tangent, z = normal) pointing
away from the surface; a direction at polar angle θ and azimuth φ (degrees) is
(sinθ cosφ, sinθ sinφ, cosθ). The key vector is (u, v, w) = −(ωi + ωo), so w ∈ [−2, 0].

    A(ωi, ωo) = R(ωi, ωo)² · G / (R0² · w²),  G = (1 + ωi·ωo)² / (cosθi · cosθo)   for |w| > 1e-6, else 0

with R the unpolarised Fresnel reflectance (intensity) of a dielectric of refractive
index ``ior`` at the half-vector angle and R0 its value at normal incidence (``ior=None``: R/R0 = 1).
R/R0 is computed in a form where the factor (n² − 1)² of both R and R0 cancels analytically
(:func:`fresnel_ratio`), so it stays exact in float32 as n → 1 and has a limit at n = 1. A is capped
at :data:`A_MAX` so that exposure · A · XYZ cannot overflow float32 (physics.md, "The A-term").
Runtime-side (numpy only); the GLSL runtime implements the same formula and a parity test ties them.
"""

from __future__ import annotations

import math

import numpy as np

#: The paper's evaluation slices: (θi, φi) in degrees and exposure ("RU"). `gratnet evaluate` scores these
#: first, then any further --views, and metrics.json lists them in this order.
STANDARD_SLICES: tuple[tuple[float, float, float], ...] = (
    (0.0, 0.0, 2000.0),
    (30.0, 135.0, 5000.0),
    (30.0, 0.0, 5000.0),
    (72.0, 30.0, 5000.0),
    (72.0, 270.0, 5000.0),
)

W_EPSILON = 1e-6  # |w| below this: A = 0 (grazing: the 1/w² factor is meaningless there)
#: Cap on A: above the largest value it takes within the |w| cut-off for IOR ≥ 1 + 1e-6 or off (retro-
#: reflection at |w| = 1e-6 gives 1/cos⁴θ = 1.6e25); reached only for IOR within 1e-6 of 1 at grazing
#: half-vectors, or for degenerate mesh normals. With exposure ≤ 1e10 the product stays in float32.
A_MAX = 1e26


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


#: Largest exposure the command line takes (physics.md, "The A-term": exposure · A_MAX · XYZ in float32).
EXPOSURE_MAX = 1e10
#: IOR range accepted (0 or None: Fresnel off). R/R0 is exact in float32 over all of it; beyond, n or
#: 1/n leaves float32's normal range.
IOR_RANGE = (1e-30, 1e30)


def check_exposure(exposure: float, flag: str = "--exposure") -> float:
    """``exposure`` if it is a number in [0, EXPOSURE_MAX], else one GratNetError naming ``flag``."""
    from gratnet.errors import GratNetError

    value = float(exposure)
    if not (math.isfinite(value) and 0.0 <= value <= EXPOSURE_MAX):
        raise GratNetError(f"{flag} must be a number from 0 to {EXPOSURE_MAX:.0e} (typical: 1 to 1e4), "
                           f"got {exposure!r}")
    return value + 0.0


def check_ior(ior: float | None, flag: str = "--ior") -> float | None:
    """``ior`` checked: None/0 (Fresnel off) or a number in IOR_RANGE (1 included: the limit of R/R0)."""
    from gratnet.errors import GratNetError

    if ior is None or ior == 0:
        return None
    value = float(ior)
    low, high = IOR_RANGE
    if not (math.isfinite(value) and low <= value <= high):
        raise GratNetError(f"{flag} must be 0 (no Fresnel) or a refractive index from {low:g} to {high:g} "
                           f"(typical: 1.3 to 2.5), got {ior!r}")
    return value


def fresnel_ratio(cos_incidence: np.ndarray, ior: float) -> np.ndarray:
    """R(θ)/R0: the unpolarised Fresnel reflectance at cos θ over its value at normal incidence.

    With cos θt = sqrt(1 − sin²θ/n²), the amplitudes are rs = (1 − n²)/(cosθ + n cosθt)² (from
    cosθ − n cosθt = (cos²θ − n²cos²θt)/(cosθ + n cosθt) and cos²θ − n²cos²θt = 1 − n²) and
    rp = (n² − 1)·q/(n cosθ + cosθt)² with q = cos²θ − sin²θt; at normal incidence both are
    ±(n² − 1)/(n + 1)². So, with s = (n + 1)/(cosθ + n cosθt) and p = (n + 1)/(n cosθ + cosθt),

        R/R0 = (s⁴ + q²·p⁴) / 2,

    free of the (n² − 1)² that cancels catastrophically in float32 as n → 1. At n = 1 it is the limit
    (1 + cos²2θ)/(2cos⁴θ). Under total internal reflection (n < 1) R = 1, so R/R0 = ((n + 1)/(n − 1))².
    Near n = 1, cos²θt is taken as (cos²θ + (n − 1)(n + 1))/n², which does not cancel at grazing θ.
    """
    cos_i = np.clip(np.asarray(cos_incidence, dtype=np.float64), 0.0, 1.0)
    n = float(ior)
    with np.errstate(over="ignore", divide="ignore", invalid="ignore"):
        sin_t_squared = (1.0 - cos_i * cos_i) / n / n  # two divisions: n² under/overflows for extreme n
        cos_t_squared = 1.0 - sin_t_squared
        if abs(n - 1.0) < 0.5:  # 1 − sin²θt cancels at grazing angles near n = 1; n − 1 is exact
            cos_t_squared = (cos_i * cos_i + (n - 1.0) * (n + 1.0)) / (n * n)
        cos_t = np.sqrt(np.clip(cos_t_squared, 0.0, None))
        s = (n + 1.0) / (cos_i + n * cos_t)
        p = (n + 1.0) / (n * cos_i + cos_t)
        q = cos_i * cos_i - sin_t_squared
        ratio = 0.5 * (s**4 + (q * q) * p**4)
        total = ((n + 1.0) / (n - 1.0)) ** 2 if n != 1.0 else np.inf
    return np.where(cos_t_squared <= 0.0, total, ratio)


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
        ratio_squared = 1.0
    else:
        # Half-vector angle: cos θh = ωi·h = sqrt((1 + ωi·ωo)/2).
        cos_half = np.sqrt(np.clip(0.5 * one_plus_cosine, 0.0, 1.0))
        ratio_squared = np.square(fresnel_ratio(cos_half, ior))
    valid = (np.abs(w) > W_EPSILON) & (cos_light > 0.0) & (cos_view > 0.0)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        value = np.minimum(ratio_squared * geometry / np.square(w), A_MAX)
    return np.where(valid, value, 0.0)
