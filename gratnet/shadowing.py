"""Shadowing and masking by the surface's own relief: Smith's term with the height field's slope statistics
(docs/physics.md, "Shadowing and masking").

Eq. 5's A-term grows as 1/cos θ towards either horizon and nothing in eq. 8 shadows it, so the integral of eq. 9
(environment light) diverges logarithmically at the horizon. A real relief hides itself from grazing light and
grazing views: the classical completion of the Kirchhoff approximation (Beckmann & Spizzichino 1963; He et al.
1991) multiplies it by Smith's (1967) shadowing–masking term for the surface's slope distribution. GratNet uses the
height-correlated form (Heitz 2014, eq. 99) with a Gaussian (Beckmann) slope distribution of the height field's
own slope covariance Σ (dimensionless, µm/µm):

    S(ωi, ωo) = 1 / (1 + Λ(ωi) + Λ(ωo)),    Λ(ω) = (erf(a) − 1)/2 + exp(−a²) / (2a√π),
    a = cos θ / sqrt(2 · ω_xyᵀ Σ ω_xy)      (ω_xy: the direction's tangent-plane part)

Σ = 0 along a direction (a flat field, or a grating seen along its lines) gives Λ = 0 there; normal incidence
gives Λ = 0 whatever Σ, so S = 1 and A = 1 exactly at normal light and view, as before. Towards the horizon
Λ grows as 1/a ∝ 1/cos θ, so S · A stays bounded and eq. 9 converges. BRDF slices (the paper's evaluation,
eq. 5) do not include S; rendered pixels do.

erf is evaluated by Abramowitz & Stegun 7.1.26 (absolute error ≤ 1.5·10⁻⁷) in the form
Λ = exp(−a²)/2 · (1/(a√π) − t·P(t)), t = 1/(1 + p·a): no cancellation for large a and no overflow. The GLSL
runtime (shaders/brdf.glsl, ``smith_shadowing``) evaluates the same expression; a parity test ties them and an
analytic test checks it against the exact erf.

The covariance is a property of the height field; the ground truth records it in the volume's metadata
(``slope_covariance``: ``[Σxx, Σxy, Σyy]``), so every model trained from it carries it under
``metadata["volume"]``. A model or volume without it renders unshadowed (S = 1: eq. 8 as the paper states it).

Runtime-side: numpy only.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence

import numpy as np

from gratnet.errors import GratNetError

__all__ = ["ERFC_COEFFICIENTS", "ERFC_P", "METADATA_KEY", "NO_SHADOWING", "check_slope_covariance",
           "model_slope_covariance", "slope_covariance_from_metadata", "smith_lambda", "smith_shadowing"]

#: Key of the slope covariance ``[Σxx, Σxy, Σyy]`` in a volume's metadata (and so in ``model.metadata["volume"]``).
METADATA_KEY = "slope_covariance"
#: The covariance of a surface that never shadows itself: S = 1 everywhere.
NO_SHADOWING = (0.0, 0.0, 0.0)

#: Abramowitz & Stegun 7.1.26 (the GLSL repeats these numbers): erfc(a) ≈ t·(A1 + t·(A2 + t·(A3 + t·(A4 + t·A5))))
#: · exp(−a²), t = 1/(1 + P·a), a ≥ 0.
ERFC_P = 0.3275911
ERFC_COEFFICIENTS = (0.254829592, -0.284496736, 1.421413741, -1.453152027, 1.061405429)
_INV_SQRT_PI = 1.0 / math.sqrt(math.pi)


def check_slope_covariance(value: object, where: str = "slope covariance") -> tuple[float, float, float]:
    """``(Σxx, Σxy, Σyy)`` as floats if ``value`` is three finite numbers forming a positive semi-definite matrix
    (Σxx, Σyy ≥ 0, Σxy² ≤ Σxx·Σyy up to rounding), else one GratNetError."""
    try:
        numbers = tuple(float(x) for x in value)  # type: ignore[attr-defined]
    except (TypeError, ValueError):
        raise GratNetError(f"{where} must be three numbers [Σxx, Σxy, Σyy], got {value!r}") from None
    if len(numbers) != 3 or not all(math.isfinite(x) for x in numbers):
        raise GratNetError(f"{where} must be three finite numbers [Σxx, Σxy, Σyy], got {value!r}")
    xx, xy, yy = numbers
    if xx < 0.0 or yy < 0.0 or xy * xy > xx * yy * (1.0 + 1e-9) + 1e-300:
        raise GratNetError(f"{where} must be a covariance (Σxx, Σyy ≥ 0 and Σxy² ≤ Σxx·Σyy), got {value!r}")
    return xx, xy, yy


def slope_covariance_from_metadata(metadata: Mapping[str, object]) -> tuple[float, float, float]:
    """The slope covariance a volume's metadata records (a model's: pass ``model.metadata.get("volume", {})``);
    :data:`NO_SHADOWING` when it records none."""
    value = metadata.get(METADATA_KEY) if isinstance(metadata, Mapping) else None
    if value is None:
        return NO_SHADOWING
    return check_slope_covariance(value, f"the metadata's {METADATA_KEY!r}")


def model_slope_covariance(model: object) -> tuple[float, float, float]:
    """The slope covariance a model file records under ``metadata["volume"]`` (every renderer of the model takes this
    one); :data:`NO_SHADOWING` when it records none."""
    metadata = getattr(model, "metadata", None)
    volume = metadata.get("volume") if isinstance(metadata, Mapping) else None
    return slope_covariance_from_metadata(volume if isinstance(volume, Mapping) else {})


def smith_lambda(direction: np.ndarray, covariance: Sequence[float]) -> np.ndarray:
    """Smith's Λ(ω) for unit directions ``(…, 3)`` in the tangent frame (z: the normal) and a slope covariance
    ``(Σxx, Σxy, Σyy)``; ``float64`` ``(…)``, ``inf`` at or below the horizon, 0 where the relief has no slope
    along the direction (or at normal incidence)."""
    xx, xy, yy = check_slope_covariance(covariance)
    d = np.asarray(direction, dtype=np.float64)
    x, y, cos_theta = d[..., 0], d[..., 1], d[..., 2]
    projected = np.maximum(x * x * xx + 2.0 * x * y * xy + y * y * yy, 0.0)  # ω_xyᵀ Σ ω_xy = sin²θ · σ_φ²
    spread = np.sqrt(2.0 * projected)  # cos θ / a
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        a = cos_theta / spread
        t = 1.0 / (1.0 + ERFC_P * a)
        c0, c1, c2, c3, c4 = ERFC_COEFFICIENTS
        polynomial = t * (c0 + t * (c1 + t * (c2 + t * (c3 + t * c4))))
        value = 0.5 * np.exp(-a * a) * (_INV_SQRT_PI / a - polynomial)
    value = np.where(spread > 0.0, value, 0.0)
    return np.where(cos_theta > 0.0, np.maximum(value, 0.0), np.inf)


def smith_shadowing(light: np.ndarray, view: np.ndarray, covariance: Sequence[float]) -> np.ndarray:
    """S(ωi, ωo) = 1 / (1 + Λ(ωi) + Λ(ωo)) for unit directions ``(…, 3)`` (broadcast), ``float64``; 0 with either
    direction at or below the horizon, 1 for :data:`NO_SHADOWING` above it."""
    light, view = np.broadcast_arrays(np.asarray(light, dtype=np.float64), np.asarray(view, dtype=np.float64))
    total = smith_lambda(light, covariance) + smith_lambda(view, covariance)
    with np.errstate(divide="ignore"):
        return np.where(np.isfinite(total), 1.0 / (1.0 + total), 0.0)
