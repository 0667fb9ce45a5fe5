"""The GratNet BSDF's arithmetic in numpy: its value (the GL runtime's contract) and its sampling density.

Nothing here imports Mitsuba, so the numbers can be checked where Mitsuba is absent; ``mitsuba_plugin.bsdf``
moves Mitsuba's arrays in and out. Directions are unit vectors in the surface's tangent frame (x = tangent,
y = bitangent = normal × tangent, z = normal; docs/physics.md "Units and frames"), pointing away from the
surface, ``float64`` ``(N, 3)``.

Value (docs/physics.md "Path tracing: Mitsuba 3"): for light direction ωl and view direction ωv,

    eval = S(ωl, ωv) · A(ωl, ωv) · M · XYZ(−(ωl + ωv))   (linear sRGB; M = CIE XYZ → linear sRGB; S: Smith's
                                                      shadowing, gratnet.shadowing)

which is Mitsuba's ``eval`` (the BSDF times the cosine of the light-side direction) in radiance transport,
and exactly what the GLSL runtime shades per unit light. The network runs only where A > 0.

Sampling (:data:`SAMPLERS`, the plugin's ``sampler`` property):

- ``table`` (the default): the material's own diffraction, :mod:`gratnet.importance` — its luminance over the
  key's (u, v), so the light direction follows every diffraction order, with a cosine-weighted share. The
  table is anisotropic: directions enter and leave it in the tangent frame (:func:`to_tangent_frame`,
  :func:`from_tangent_frame`).
- ``mixture`` (the earlier sampler, kept for comparison): a von Mises–Fisher lobe around the mirror direction
  of ωv (probability ``p``, concentration κ) and the cosine-weighted hemisphere (probability 1 − p). Samples
  below the horizon are invalid (weight 0); :func:`mixture_pdf` is their exact density in solid angle (sr⁻¹),
  0 below the horizon, so it integrates to the fraction of valid samples.
"""

from __future__ import annotations

import math

import numpy as np

from gratnet.brdf import a_term
from gratnet.display import xyz_to_linear_srgb
from gratnet.modelfile import ModelFile, evaluate_keys
from gratnet.shadowing import model_slope_covariance, smith_shadowing
from viewer.meshes import arbitrary_tangents

__all__ = [
    "CHUNK",
    "DEFAULT_SAMPLER",
    "SAMPLERS",
    "cosine_hemisphere",
    "eval_linear_srgb",
    "from_tangent_frame",
    "kappa_for_lobe",
    "mirror",
    "mixture_pdf",
    "sample_mixture",
    "vmf_pdf",
    "to_tangent_frame",
    "vmf_sample",
    "xyz_to_linear_srgb_matrix",
]

#: Network evaluations per numpy batch: bounds the float64 hidden activations (≈ 0.1 GB for the shipped size).
CHUNK = 1 << 16
#: The BSDF's samplers: the material's own importance table (gratnet.importance), or the lobe + cosine mixture.
SAMPLERS = ("table", "mixture")
#: The sampler a ``gratnet`` BSDF uses unless told otherwise.
DEFAULT_SAMPLER = "table"


def to_tangent_frame(directions: np.ndarray, rotation: np.ndarray | None) -> np.ndarray:
    """Shading-frame directions ``(N, 3)`` in the tangent frame turned by α about the normal, ``rotation`` =
    ``(cos α, sin α)`` per row (``(N, 2)``; None: the frames are one): ``(x c + y s, −x s + y c, z)``."""
    if rotation is None:
        return directions
    c, s = rotation[:, 0], rotation[:, 1]
    x, y = directions[:, 0], directions[:, 1]
    return np.stack([x * c + y * s, -x * s + y * c, directions[:, 2]], axis=-1)


def from_tangent_frame(directions: np.ndarray, rotation: np.ndarray | None) -> np.ndarray:
    """The inverse of :func:`to_tangent_frame`: ``(x c − y s, x s + y c, z)``."""
    if rotation is None:
        return directions
    c, s = rotation[:, 0], rotation[:, 1]
    x, y = directions[:, 0], directions[:, 1]
    return np.stack([x * c - y * s, x * s + y * c, directions[:, 2]], axis=-1)


def xyz_to_linear_srgb_matrix() -> np.ndarray:
    """``(3, 3)`` matrix ``R`` with ``linear_srgb = xyz @ R`` (gratnet.display's conversion is linear: its
    rows are the images of the unit XYZ vectors), so the colour-science call is made once, not per lookup."""
    return np.asarray(xyz_to_linear_srgb(np.eye(3)), dtype=np.float64)


def eval_linear_srgb(model: ModelFile, light: np.ndarray, view: np.ndarray, ior: float | None,
                     matrix: np.ndarray | None = None) -> np.ndarray:
    """``S(ωl, ωv) · A(ωl, ωv) · XYZ(−(ωl + ωv))`` in linear sRGB, ``float64`` ``(N, 3)``, for tangent-frame
    directions ``(N, 3)`` (broadcast); 0 where A is 0 (either direction at or below the horizon, |w| ≤ 1e-6).
    ``ior``: the Fresnel index of the A-term (``None``: no Fresnel); S: Smith's shadowing with the slope covariance
    the model records (gratnet.shadowing; none recorded: S = 1)."""
    light, view = np.broadcast_arrays(np.asarray(light, dtype=np.float64).reshape(-1, 3),
                                      np.asarray(view, dtype=np.float64).reshape(-1, 3))
    matrix = xyz_to_linear_srgb_matrix() if matrix is None else matrix
    a = a_term(light, view, ior) * smith_shadowing(light, view, model_slope_covariance(model))
    result = np.zeros(light.shape, dtype=np.float64)
    lit = np.flatnonzero(np.isfinite(a) & (a > 0.0))
    for start in range(0, lit.size, CHUNK):
        rows = lit[start:start + CHUNK]
        key = -(light[rows] + view[rows])  # physics.md "Key vector"
        xyz = evaluate_keys(model, key[:, 0], key[:, 1], key[:, 2])
        result[rows] = (a[rows, None] * xyz) @ matrix
    return result


def mirror(view: np.ndarray) -> np.ndarray:
    """Mirror directions about the normal (z): ``(−x, −y, z)``."""
    view = np.asarray(view, dtype=np.float64)
    return view * np.array([-1.0, -1.0, 1.0])


def kappa_for_lobe(lobe_degrees: float) -> float:
    """The vMF concentration κ whose angular standard deviation (per axis, small angles) is ``lobe_degrees``."""
    sigma = math.radians(lobe_degrees)
    return 1.0 / (sigma * sigma)


def _vmf_normalisation(kappa: float) -> float:
    """κ / (2π (1 − e^{−2κ})): the vMF density at its mean direction, sr⁻¹."""
    return kappa / (2.0 * math.pi * -math.expm1(-2.0 * kappa))


def vmf_pdf(mean: np.ndarray, directions: np.ndarray, kappa: float) -> np.ndarray:
    """von Mises–Fisher density on the sphere, sr⁻¹: C(κ) exp(κ (μ·ω − 1)), with μ·ω − 1 = −|ω − μ|²/2
    (no cancellation near the mean, where the density matters most)."""
    difference = np.asarray(directions, dtype=np.float64) - np.asarray(mean, dtype=np.float64)
    return _vmf_normalisation(kappa) * np.exp(-0.5 * kappa * np.sum(difference * difference, axis=-1))


def vmf_sample(mean: np.ndarray, xi1: np.ndarray, xi2: np.ndarray, kappa: float) -> np.ndarray:
    """Directions distributed by the vMF density around unit ``mean`` (N, 3) from uniform ``xi1, xi2`` (N,).

    Inverse CDF of the cosine to the mean: ``1 − c = −log(ξ + (1 − ξ) e^{−2κ}) / κ``; the sine comes from
    ``(1 − c)(1 + c)`` so that it keeps its digits near the mean.
    """
    mean = np.asarray(mean, dtype=np.float64)
    xi1, xi2 = np.asarray(xi1, dtype=np.float64), np.asarray(xi2, dtype=np.float64)
    with np.errstate(divide="ignore"):
        one_minus = -np.log(xi1 + (1.0 - xi1) * math.exp(-2.0 * kappa)) / kappa
    one_minus = np.clip(one_minus, 0.0, 2.0)
    cosine = 1.0 - one_minus
    sine = np.sqrt(np.clip(one_minus * (2.0 - one_minus), 0.0, None))
    phi = 2.0 * math.pi * xi2
    first = arbitrary_tangents(mean)
    second = np.cross(mean, first)
    return (cosine[:, None] * mean + (sine * np.cos(phi))[:, None] * first
            + (sine * np.sin(phi))[:, None] * second)


def cosine_hemisphere(xi1: np.ndarray, xi2: np.ndarray) -> np.ndarray:
    """Cosine-weighted directions on the upper hemisphere (density cos θ / π) from uniform ``xi1, xi2``."""
    xi1, xi2 = np.asarray(xi1, dtype=np.float64), np.asarray(xi2, dtype=np.float64)
    radius = np.sqrt(np.clip(xi1, 0.0, 1.0))
    phi = 2.0 * math.pi * xi2
    return np.stack([radius * np.cos(phi), radius * np.sin(phi), np.sqrt(np.clip(1.0 - xi1, 0.0, 1.0))], axis=-1)


def mixture_pdf(view: np.ndarray, directions: np.ndarray, probability: float, kappa: float) -> np.ndarray:
    """Density (sr⁻¹) of :func:`sample_mixture`'s valid samples: ``p · vMF(mirror(ωv), ω) + (1 − p) · cos θ / π``
    for ω above the horizon and ωv above it, else 0."""
    view, directions = np.broadcast_arrays(np.asarray(view, dtype=np.float64).reshape(-1, 3),
                                           np.asarray(directions, dtype=np.float64).reshape(-1, 3))
    cosine = directions[:, 2]
    density = probability * vmf_pdf(mirror(view), directions, kappa) + (1.0 - probability) * cosine / math.pi
    return np.where((cosine > 0.0) & (view[:, 2] > 0.0), density, 0.0)


def sample_mixture(view: np.ndarray, xi0: np.ndarray, xi1: np.ndarray, xi2: np.ndarray, probability: float,
                   kappa: float) -> tuple[np.ndarray, np.ndarray]:
    """``(directions (N, 3), valid (N,))``: the lobe where ``xi0 < probability``, else the cosine hemisphere;
    ``valid`` is False below the horizon (or for a view direction below it)."""
    view = np.asarray(view, dtype=np.float64).reshape(-1, 3)
    xi0, xi1, xi2 = (np.asarray(xi, dtype=np.float64).reshape(-1) for xi in (xi0, xi1, xi2))
    count = max(view.shape[0], xi0.size, xi1.size, xi2.size)
    view = np.broadcast_to(view, (count, 3))
    xi0, xi1, xi2 = (np.broadcast_to(xi, (count,)) for xi in (xi0, xi1, xi2))
    lobe = xi0 < probability
    directions = cosine_hemisphere(xi1, xi2)
    if np.any(lobe):
        directions[lobe] = vmf_sample(mirror(view[lobe]), xi1[lobe], xi2[lobe], kappa)
    valid = (directions[:, 2] > 0.0) & (view[:, 2] > 0.0)
    return directions, valid
