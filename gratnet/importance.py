"""Sampling light directions from the material's own diffraction (issue 43): the numpy contract.

GratNet's BRDF (docs/physics.md eq. 8) is ``f(ωi, ωo) = A(ωi, ωo) · XYZ(key) / cos θi`` with the key
``(u, v, w) = −(ωi + ωo)`` in the tangent frame. With the view ``ωo`` fixed, ``ωi.xy = −(u, v) − ωo.xy``, so a
distribution over ``(u, v)`` is a distribution over light directions, with ``du dv = cos θi dωi``. A diffraction
order sits at a fixed ``(u, v)`` whatever the view (the grating equation), so one 2-D table per material — its
luminance over ``(u, v)`` — follows every order under every view. The GLSL side (shaders/sampling.glsl's
piecewise-constant distribution, :mod:`gratnet.sampling2d`) is to reproduce the formulas below exactly.

**Directions** are unit vectors in the tangent frame (x = tangent, y = bitangent, z = normal), pointing away from
the surface: ``wo`` towards the viewer (Mitsuba's ``si.wi`` in radiance transport), ``wi`` towards the light
(the sampled direction; Mitsuba's ``wo``). Densities are per steradian of ``wi``.

**The table** (:class:`MaterialTable`): a :class:`~gratnet.sampling2d.PiecewiseConstant2D` over the square
``(u, v) ∈ [key_min, key_max]²`` (``[−2, 2]²``, the volume's own axes), column ↔ u, row ↔ v::

    x = (u − key_min) / (key_max − key_min),   y = (v − key_min) / (key_max − key_min)
    pdf_uv(u, v) = distribution.pdf(x, y) / (key_max − key_min)²                       (per unit u · unit v)

**The density** of a light direction ``wi`` for the view ``wo`` (sr⁻¹), with ``d =`` :data:`DEFENSIVE_SHARE`::

    pdf(wo, wi) = (1 − d) · pdf_uv(−(wi.x + wo.x), −(wi.y + wo.y)) · wi.z  +  d · wi.z / π
                  for wi.z > 0 and wo.z > 0, else 0

**Sampling** from three uniform numbers ``ξc, ξr, ξk`` ∈ [0, 1) (``xi_choice, xi_row, xi_column``; Mitsuba's
``sample1, sample2.x, sample2.y``). ``ξc`` only chooses the branch (it is not reused)::

    ξc < d  (cosine branch, sqrt-radius mapping):
        r = sqrt(ξr),  φ = 2π ξk,  wi = (r cos φ, r sin φ, sqrt(1 − ξr))
    ξc ≥ d  (table branch):
        (x, y) = distribution.sample(ξr, ξk)            (ξr picks the row, i.e. v; ξk the column, i.e. u)
        u = key_min + x (key_max − key_min),  v = key_min + y (key_max − key_min)
        wi.x = −u − wo.x,  wi.y = −v − wo.y,  s = wi.x² + wi.y²
        valid only when s < 1;  wi.z = sqrt(1 − s)

Every sample also needs ``wo.z > 0``. A valid sample's density is ``pdf(wo, wi)`` above (the mixture's, whichever
branch drew it: one-sample multiple importance sampling); an invalid one has pdf 0 and ``wi = (0, 0, 1)``. The
density of valid samples integrates to 1 minus the table mass that falls outside the unit disc around
``−wo.xy`` in ``(u, v)`` (those samples are the invalid ones). The estimator's weight is ``eval / pdf``.

**The weights** of cell ``(row r, column c)``: the material's luminance (CIE Y) over the cell, the maximum over
``subsamples × subsamples`` points per cell (the centres of a regular sub-grid; a diffraction peak narrower than a
cell still lights its cell), averaged over the w fractions ``t`` in ``w_range`` of the deepest reachable ``w``,
``w = −t · sqrt(4 − u² − v²)`` (simple-max's own ``t``: every ``w`` a pair of directions meets at ``(u, v)`` has
``t ∈ [0, 1]``; a peak's position does not depend on w, only its height); plus a floor of :data:`FLOOR_SHARE` ×
the mean over the cells that meet the disc ``u² + v² < 4``, so that every reachable cell has weight > 0. Cells
wholly outside that disc (no pair of directions reaches them) weigh 0.

**Choices** (measured on cd, paper-cd and paper-snake, 2 CPU cores shared with a training run): the error of the
16-sample estimate of ``∫ A · Y dωi`` (the integral a constant environment needs, Fresnel 1.5), median over
2048 estimates, relative, mean over ten views (θo 0°, 30°, 60°, 75° × φo 0°, 45°, 90°):

    sampler                           cd     paper-cd  paper-snake   build (512²: cd / paper-cd / paper-snake)
    mixture (vMF 2°, p = 0.5)         0.85   0.59      0.88
    128², 4² points, 4 fractions      0.76   0.46      0.78
    256², 2² points, 4 fractions      0.37   0.23      0.38
    512², 1 point, 4 fractions        0.21   0.16      0.21
    512², 1 point, t = 0.375, 0.75    0.21   0.16      0.21          4.0 s / 4.3 s / 6.9 s
    512², 1 point, t = 0.5 only       0.21   0.17      0.22

So the cells' size matters (a CD's peaks are ~0.004 wide in u: std λ/(2√2 π σs)), the number of w slices hardly
(max or mean alike): the default is 512², the cell centre, the mean of t = 0.375 and 0.75. At 512² a cell is
0.0078 wide, so a peak between centres is at most 1.4 (its std) from one: it keeps ≥ e⁻¹ of its height there.

**Grazing light** is what is left: eq. 8's ``f · cos θi = A · XYZ`` grows like ``1/cos θi`` as the light grazes
(``G = (1 + ωi·ωo)²/(cos θi cos θo)``), while any density over ``(u, v)`` (or the cosine) gives ``wi`` a density
∝ ``cos θi`` there; so rare samples at ``cos θi`` ~ 0.01 weigh ~10³ × the mean (``∫ A · Y dωi`` itself diverges
logarithmically at the horizon unless Y vanishes there). A uniform instead of a cosine-weighted defensive share
(5–20 %) did not reduce the error above, nor the largest weights; 10 % cosine-weighted is as good as 5 or 20 %.

**The colour table** (:attr:`MaterialTable.colour`, resampled sampling's control variate, docs/physics.md
"Environment light"): the material's CIE XYZ over the same cells (the mean over each cell's points) at the w fractions
:data:`COLOUR_W_FRACTIONS`, evaluated with the luminance in one pass over the union of the fractions (five at the
defaults). Measured (paper-cd, CD, sky, 64², 64 passes; docs/experiments/2026-11-28-environment-agreement.md): its
average over t = 0.375, 0.75 took FLIP from 0.0277 to 0.0246, four slices read linearly in t to 0.0230, eight the
same 0.0230, 1024² cells 0.0220: four slices at the table's 512² it is.

**Cost and cache.** A shipped model's table takes a few seconds on two CPU cores (float32 network evaluations:
paper-cd's 5 slices in ~5 s with a training beside it), so tables are cached in-process and on disk as
``$XDG_CACHE_HOME/gratnet/importance/<hash>.npz`` (else ``~/.cache/gratnet/importance/``; 15 MB each at 512² with
the colour table), keyed by a hash of the material's content and the table's parameters.

numpy only (no torch, no GL).
"""

from __future__ import annotations

import dataclasses
import functools
import hashlib
import json
import math
import sys
import threading
import time
from collections.abc import Callable, Iterable
from pathlib import Path

import numpy as np

from gratnet.atomic import atomic_path, cache_folder
from gratnet.encoding import network_coordinates, range_inverse
from gratnet.errors import GratNetError
from gratnet.modelfile import ModelFile, content_digest, network_inputs, validated
from gratnet.network import activate_hidden, activate_output
from gratnet.sampling2d import PiecewiseConstant2D

__all__ = [
    "DEFAULT_RESOLUTION",
    "DEFAULT_SUBSAMPLES",
    "DEFAULT_W_FRACTIONS",
    "DEFENSIVE_SHARE",
    "FLOOR_SHARE",
    "KEY_LIMIT",
    "RESAMPLING_CANDIDATES",
    "RESAMPLING_MATERIAL_CANDIDATES",
    "COLOUR_SLICES",
    "COLOUR_W_FRACTIONS",
    "Colour",
    "MAX_RESOLUTION",
    "MIN_RESOLUTION",
    "Luminance",
    "MaterialTable",
    "clear_memory_cache",
    "cosine_hemisphere",
    "FLAT_RESOLUTION",
    "cached_material_table",
    "flat_table",
    "importance_cache_folder",
    "luminance_table",
    "luminance_weights",
    "material_table",
    "material_weights",
    "model_luminance",
    "model_xyz",
    "volume_luminance",
    "volume_xyz",
    "volume_table",
]

#: Cells per axis of :func:`flat_table` (its density is flat: more cells would only cost texture memory).
FLAT_RESOLUTION = 64
#: Share of samples drawn cosine-weighted over the upper hemisphere: every direction above the horizon keeps a
#: density ≥ DEFENSIVE_SHARE · cos θ / π, so the estimator's weight is bounded where the table is too low.
DEFENSIVE_SHARE = 0.1
#: Resampled sampling (gratnet.codes.ENVIRONMENT_SAMPLING ``resampled``, shaders/environment.glsl): candidates per
#: pass, and how many of them material sampling draws (the rest the environment's luminance): a share of 0.25.
RESAMPLING_CANDIDATES = 32
RESAMPLING_MATERIAL_CANDIDATES = 8
#: The table's square is [−KEY_LIMIT, KEY_LIMIT]² in (u, v): the volume's axes (gratnet.volume.AXIS_LIMIT).
KEY_LIMIT = 2.0
#: Cells per axis of the default table.
DEFAULT_RESOLUTION = 512
#: Luminance points per cell and axis (their maximum is the cell's value). One (the cell's centre) at 512²: the
#: same evaluations as 2² points per cell at 256² and half the 16-sample error (module docstring, "Choices").
DEFAULT_SUBSAMPLES = 1
#: The w slices averaged, as fractions t of the deepest reachable w: w = −t · sqrt(4 − u² − v²).
DEFAULT_W_FRACTIONS: tuple[float, ...] = (0.375, 0.75)
#: The control variate's colour table (shaders/environment.glsl, resampled sampling; docs/physics.md "Environment
#: light"): the material's CIE XYZ over the same (u, v) cells (the mean over each cell's points) at the w fractions
#: ``t_j = (j + 0.5) / COLOUR_SLICES``, read linearly in t between them (held at the end ones beyond).
COLOUR_SLICES = 4
COLOUR_W_FRACTIONS: tuple[float, ...] = tuple((j + 0.5) / COLOUR_SLICES for j in range(COLOUR_SLICES))
#: Floor on every reachable cell's weight, relative to the mean over reachable cells.
FLOOR_SHARE = 1e-3
#: Resolutions accepted: powers of two in this range.
MIN_RESOLUTION, MAX_RESOLUTION = 16, 2048
#: Luminance evaluations per numpy batch (bounds the float32 activations, ≈ 50 MB for the shipped size).
CHUNK = 1 << 15
#: Seconds before a build shows a progress bar (tqdm's ``delay``): builds under it stay silent.
PROGRESS_DELAY = 1.0
_COMBINES = ("mean", "max")
_FORMAT = "gratnet-importance-table"
_FORMAT_VERSION = 2  # 2: with the colour table
_MEMORY_ENTRIES = 8

#: ``luminance(u, v, w) -> Y`` over broadcast ``float64`` arrays: a material's CIE Y (dimensionless).
Luminance = Callable[[np.ndarray, np.ndarray, np.ndarray], np.ndarray]
#: ``xyz(u, v, w) -> (N, 3)``: a material's CIE XYZ (dimensionless) at ``N`` key vectors.
Colour = Callable[[np.ndarray, np.ndarray, np.ndarray], np.ndarray]


# ------------------------------------------------------------------------------------------------
# The table and its sampler


@dataclasses.dataclass(frozen=True, eq=False)
class MaterialTable:
    """A material's luminance over the key's ``(u, v)`` as a sampling distribution (module docstring).

    Attributes:
        distribution: over the unit square: ``x = (u − key_min)/(key_max − key_min)`` (columns), ``y`` likewise
            with ``v`` (rows).
        key_min, key_max: the square's extent in ``u`` and ``v`` (dimensionless; −2 and 2).
        w_range: the w slices combined, as fractions ``t`` of the deepest reachable w at each ``(u, v)``:
            ``w = −t · sqrt(4 − u² − v²)``.
        source: what it was built from: ``model``, ``volume`` or ``luminance`` (a function).
        digest: hash of the material's content and the table's parameters (the cache key).
        resolution: cells per axis.
        subsamples: luminance points per cell and axis.
        combine: how the w slices were combined: ``mean`` or ``max``.
        build_seconds: wall time of the build (s), as first built (a cached table keeps it).
        colour: the control variate's table, CIE XYZ ``float32 (COLOUR_SLICES, R, R, 3)`` (slice j at
            ``COLOUR_W_FRACTIONS[j]``; row ↔ v, column ↔ u, as the distribution), or None (a flat table, or one of a
            luminance function alone: no control variate).
    """

    distribution: PiecewiseConstant2D
    key_min: float
    key_max: float
    w_range: tuple[float, ...]
    source: str
    digest: str
    resolution: int
    subsamples: int
    combine: str
    build_seconds: float
    colour: np.ndarray | None = None

    @property
    def span(self) -> float:
        """``key_max − key_min``: the square's side in u (and v)."""
        return self.key_max - self.key_min

    def pdf_uv(self, u: object, v: object) -> np.ndarray:
        """The table's density at ``(u, v)`` (broadcast), per unit u · unit v: the unit-square density /
        ``span²``; 0 outside the square."""
        span = self.span
        us, vs = np.broadcast_arrays(np.asarray(u, dtype=np.float64), np.asarray(v, dtype=np.float64))
        return self.distribution.pdf((us - self.key_min) / span, (vs - self.key_min) / span) / (span * span)

    def pdf(self, wo: object, wi: object) -> np.ndarray:
        """Solid-angle density (sr⁻¹) of light directions ``wi`` ``(N, 3)`` for views ``wo`` ``(N, 3)`` or ``(3,)``:
        ``(1 − d) · pdf_uv(−(wi + wo).xy) · cos θi + d · cos θi / π`` above the horizon (both), else 0."""
        light = _directions(wi, "wi")
        view = _directions(wo, "wo", light.shape[0])
        cosine = light[:, 2]
        table = self.pdf_uv(-(light[:, 0] + view[:, 0]), -(light[:, 1] + view[:, 1]))
        density = ((1.0 - DEFENSIVE_SHARE) * table + DEFENSIVE_SHARE / math.pi) * cosine
        return np.where((cosine > 0.0) & (view[:, 2] > 0.0), density, 0.0)

    def sample(self, wo: object, xi_choice: object, xi_row: object, xi_column: object
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Light directions for views ``wo`` ``(N, 3)`` or ``(3,)`` from uniform numbers in [0, 1) ``(N,)``
        (module docstring): ``(wi (N, 3), pdf (N,), valid (N,))``; ``pdf`` = :meth:`pdf` for valid samples,
        0 for invalid ones (``wi = (0, 0, 1)``)."""
        numbers = [_uniform(xi, name) for xi, name in ((xi_choice, "xi_choice"), (xi_row, "xi_row"),
                                                        (xi_column, "xi_column"))]
        count = max(number.size for number in numbers)
        view = np.asarray(wo, dtype=np.float64)
        if view.ndim == 2:
            count = max(count, view.shape[0])
        view = _directions(wo, "wo", count)
        try:
            choice, row, column = (np.broadcast_to(number, (count,)) for number in numbers)
        except ValueError:
            raise GratNetError(f"xi_choice, xi_row and xi_column must have one length (or 1), got "
                               f"{', '.join(str(number.size) for number in numbers)}") from None
        x, y, _ = self.distribution.sample(row, column)
        light = np.empty((count, 3))
        light[:, 0] = -(self.key_min + x * self.span) - view[:, 0]
        light[:, 1] = -(self.key_min + y * self.span) - view[:, 1]
        squared = light[:, 0] ** 2 + light[:, 1] ** 2
        light[:, 2] = np.sqrt(np.clip(1.0 - squared, 0.0, None))
        valid = squared < 1.0
        cosine = choice < DEFENSIVE_SHARE
        if np.any(cosine):
            light[cosine] = cosine_hemisphere(row[cosine], column[cosine])
            valid[cosine] = light[cosine, 2] > 0.0
        valid &= view[:, 2] > 0.0
        density = np.where(valid, self.pdf(view, light), 0.0)
        valid &= density > 0.0
        light[~valid] = (0.0, 0.0, 1.0)
        return light, np.where(valid, density, 0.0), valid


def cosine_hemisphere(xi_row: object, xi_column: object) -> np.ndarray:
    """Cosine-weighted directions (density cos θ / π) by the sqrt-radius mapping: ``r = sqrt(ξr)``,
    ``φ = 2π ξk``, ``(r cos φ, r sin φ, sqrt(1 − ξr))``, ``(N, 3)``."""
    first, second = np.broadcast_arrays(np.asarray(xi_row, dtype=np.float64), np.asarray(xi_column, dtype=np.float64))
    radius = np.sqrt(np.clip(first, 0.0, 1.0))
    phi = 2.0 * math.pi * second
    return np.stack([radius * np.cos(phi), radius * np.sin(phi), np.sqrt(np.clip(1.0 - first, 0.0, 1.0))], axis=-1)


def _directions(value: object, name: str, count: int | None = None) -> np.ndarray:
    """``value`` as ``float64 (N, 3)`` (a ``(3,)`` vector broadcast to ``count`` rows), else one GratNetError."""
    array = np.asarray(value, dtype=np.float64)
    if array.ndim == 1 and array.shape[0] == 3:
        array = array[None, :]
    if array.ndim != 2 or array.shape[1] != 3:
        raise GratNetError(f"{name} must be directions of shape (N, 3) or (3,), got shape {array.shape}")
    if count is not None and array.shape[0] != count:
        if array.shape[0] != 1:
            raise GratNetError(f"{name} has {array.shape[0]} directions where {count} (or 1) are needed")
        array = np.broadcast_to(array, (count, 3))
    return array


def _uniform(value: object, name: str) -> np.ndarray:
    array = np.asarray(value, dtype=np.float64)
    if array.ndim > 1:
        raise GratNetError(f"{name} must be a number or a 1-D array of uniform numbers, got shape {array.shape}")
    return array.reshape(-1)


# ------------------------------------------------------------------------------------------------
# Building: luminance over (u, v) → weights → table


def _check_resolution(resolution: object) -> int:
    if isinstance(resolution, bool) or not isinstance(resolution, (int, np.integer)) or not (
            MIN_RESOLUTION <= int(resolution) <= MAX_RESOLUTION) or int(resolution) & (int(resolution) - 1):
        raise GratNetError(f"importance table resolution must be a power of two from {MIN_RESOLUTION} to "
                           f"{MAX_RESOLUTION}, got {resolution!r}")
    return int(resolution)


def _check_parameters(resolution: object, subsamples: object, w_range: Iterable[float], combine: object
                      ) -> tuple[int, int, tuple[float, ...], str]:
    size = _check_resolution(resolution)
    if isinstance(subsamples, bool) or not isinstance(subsamples, (int, np.integer)) or not 1 <= int(subsamples) <= 8:
        raise GratNetError(f"importance table subsamples must be an integer from 1 to 8, got {subsamples!r}")
    fractions = tuple(float(t) for t in w_range)
    if not fractions or not all(math.isfinite(t) and 0.0 <= t <= 1.0 for t in fractions):
        raise GratNetError(f"importance table w fractions must be numbers in [0, 1], got {fractions!r}")
    if combine not in _COMBINES:
        raise GratNetError(f"importance table combine must be one of {', '.join(_COMBINES)}, got {combine!r}")
    return size, int(subsamples), fractions, str(combine)


def _slice_values(function: Colour, channels: int, size: int, sub: int, fractions: tuple[float, ...],
                  progress: bool, description: str) -> np.ndarray:
    """``function(u, v, w)`` (``channels`` values per point) at the ``size·sub`` × ``size·sub`` points of the square
    (the centres of a regular grid, never on a cell edge) for each w fraction: ``float64 (F, points², channels)``,
    row-major (v, u); 0 outside the disc u² + v² < 4 (no pair of directions reaches it) and where not finite."""
    points = size * sub
    axis = -KEY_LIMIT + (np.arange(points) + 0.5) * (2.0 * KEY_LIMIT / points)
    u, v = np.meshgrid(axis, axis)  # (rows ↔ v, columns ↔ u)
    radius_squared = u * u + v * v
    inside = np.flatnonzero(radius_squared < 4.0)
    depth = np.sqrt(np.clip(4.0 - radius_squared.reshape(-1)[inside], 0.0, None))
    u_in, v_in = u.reshape(-1)[inside], v.reshape(-1)[inside]
    per_slice = np.zeros((len(fractions), points * points, channels))
    batches = [(k, start) for k in range(len(fractions)) for start in range(0, inside.size, CHUNK)]
    iterator: Iterable[tuple[int, int]] = batches
    if progress:
        from tqdm import tqdm

        iterator = tqdm(batches, desc=description, unit="batch", leave=False, delay=PROGRESS_DELAY, file=sys.stderr)
    for k, start in iterator:
        rows = slice(start, start + CHUNK)
        values = np.asarray(function(u_in[rows], v_in[rows], -fractions[k] * depth[rows]), dtype=np.float64)
        per_slice[k, inside[rows]] = np.where(np.isfinite(values), values, 0.0).reshape(-1, channels)
    return per_slice


def _weights(luminance: np.ndarray, size: int, sub: int, how: str) -> np.ndarray:
    """The cell weights of per-slice luminance ``(F, points²)`` (module docstring, "The weights")."""
    cells = np.clip(luminance, 0.0, None).reshape(-1, size, sub, size, sub).max(axis=(2, 4))
    weights = cells.mean(axis=0) if how == "mean" else cells.max(axis=0)
    reachable = _reachable_cells(size)
    mean = float(weights[reachable].mean())
    floor = FLOOR_SHARE * mean if mean > 0.0 else 1.0  # a black material: sample the disc uniformly
    return np.where(reachable, np.maximum(weights, floor), 0.0)


def luminance_weights(luminance: Luminance, resolution: int = DEFAULT_RESOLUTION, *,
                      subsamples: int = DEFAULT_SUBSAMPLES, w_range: Iterable[float] = DEFAULT_W_FRACTIONS,
                      combine: str = "mean", progress: bool = True, description: str = "importance table"
                      ) -> np.ndarray:
    """The table's cell weights ``float64 (R, R)`` (row ↔ v, column ↔ u) for ``luminance(u, v, w)`` (module
    docstring, "The weights"): per w fraction the maximum over each cell's ``subsamples²`` points, then the
    ``combine`` over the fractions, then the floor on reachable cells; 0 on cells wholly outside u² + v² < 4."""
    size, sub, fractions, how = _check_parameters(resolution, subsamples, w_range, combine)
    values = _slice_values(luminance, 1, size, sub, fractions, progress, description)
    return _weights(values[..., 0], size, sub, how)


def material_weights(xyz: Colour, resolution: int = DEFAULT_RESOLUTION, *, subsamples: int = DEFAULT_SUBSAMPLES,
                     w_range: Iterable[float] = DEFAULT_W_FRACTIONS, combine: str = "mean", progress: bool = True,
                     description: str = "importance table") -> tuple[np.ndarray, np.ndarray]:
    """:func:`luminance_weights` of ``xyz``'s Y and the colour table (:attr:`MaterialTable.colour`: the mean XYZ over
    each cell's points at :data:`COLOUR_W_FRACTIONS`), from one evaluation of ``xyz`` per point and fraction of
    either."""
    size, sub, fractions, how = _check_parameters(resolution, subsamples, w_range, combine)
    union = tuple(sorted(set(fractions) | set(COLOUR_W_FRACTIONS)))
    values = _slice_values(xyz, 3, size, sub, union, progress, description)
    weights = _weights(values[[union.index(t) for t in fractions], :, 1], size, sub, how)
    colour = values[[union.index(t) for t in COLOUR_W_FRACTIONS]].reshape(COLOUR_SLICES, size, sub, size, sub, 3)
    return weights, colour.mean(axis=(2, 4)).astype(np.float32)


def _reachable_cells(size: int) -> np.ndarray:
    """``bool (R, R)``: the cells whose nearest point to the origin lies inside the disc u² + v² < 4 (the keys a pair
    of directions reaches)."""
    edges = -KEY_LIMIT + np.arange(size + 1) * (2.0 * KEY_LIMIT / size)
    nearest = np.where(edges[:-1] > 0.0, edges[:-1], np.where(edges[1:] < 0.0, edges[1:], 0.0))
    return nearest[:, None] ** 2 + nearest[None, :] ** 2 < 4.0


@functools.lru_cache(maxsize=4)  # immutable, asked for once per environment pass
def flat_table(resolution: int = FLAT_RESOLUTION) -> MaterialTable:
    """A table that knows no material: every reachable cell weighs the same (uniform in ``(u, v)`` over the disc
    u² + v² < 4, so the table branch draws light directions with density ∝ cos θi around each view). Any table gives
    an unbiased estimate; this one only a noisier one. The viewer samples with it while the material's own table is
    being built (seconds of numpy), so that the first picture under an environment does not wait for it."""
    size = _check_resolution(resolution)
    return _table(_reachable_cells(size).astype(np.float64), "flat", f"flat-{size}", 1, DEFAULT_W_FRACTIONS, "mean",
                  0.0)


def luminance_table(luminance: Luminance, resolution: int = DEFAULT_RESOLUTION, *,
                    subsamples: int = DEFAULT_SUBSAMPLES, w_range: Iterable[float] = DEFAULT_W_FRACTIONS,
                    combine: str = "mean", source: str = "luminance", digest: str = "", progress: bool = True
                    ) -> MaterialTable:
    """The table of any luminance function ``luminance(u, v, w) -> Y`` (no cache; :func:`material_table` and
    :func:`volume_table` cache theirs)."""
    size, sub, fractions, how = _check_parameters(resolution, subsamples, w_range, combine)
    started = time.perf_counter()
    weights = luminance_weights(luminance, size, subsamples=sub, w_range=fractions, combine=how, progress=progress)
    return _table(weights, source, digest, sub, fractions, how, time.perf_counter() - started)


def _table(weights: np.ndarray, source: str, digest: str, subsamples: int, fractions: tuple[float, ...],
           combine: str, seconds: float, colour: np.ndarray | None = None) -> MaterialTable:
    return MaterialTable(distribution=PiecewiseConstant2D.from_weights(weights), key_min=-KEY_LIMIT,
                         key_max=KEY_LIMIT, w_range=fractions, source=source, digest=digest,
                         resolution=int(weights.shape[0]), subsamples=subsamples, combine=combine,
                         build_seconds=float(seconds), colour=colour)


# ------------------------------------------------------------------------------------------------
# Materials: a model file, a ground-truth volume


def model_xyz(model: ModelFile) -> Colour:
    """The network's CIE XYZ ``(N, 3)`` at key vectors, evaluated in float32 (the table needs a few digits, and float32
    halves the cost of the float64 contract evaluator, gratnet.modelfile.evaluate_keys; relative difference
    ≤ 2e-3 on the shipped models)."""
    valid = validated(model)
    weights = [np.ascontiguousarray(weight.astype(np.float32).T) for weight in valid.weights]
    biases = [bias.astype(np.float32) for bias in valid.biases]
    last = len(weights) - 1

    def xyz(u: np.ndarray, v: np.ndarray, w: np.ndarray) -> np.ndarray:
        coordinates = network_coordinates(np.asarray(u, dtype=np.float32), np.asarray(v, dtype=np.float32),
                                          np.asarray(w, dtype=np.float32), valid.scheme)
        x = np.asarray(network_inputs(valid, coordinates.astype(np.float32)), dtype=np.float32)
        for layer, (weight, bias) in enumerate(zip(weights, biases, strict=True)):
            x = x @ weight + bias
            x = activate_output(x, valid.output_activation) if layer == last else activate_hidden(x, valid.activation)
        return np.asarray(range_inverse(x.astype(np.float64), valid.range), dtype=np.float64)

    return xyz


def model_luminance(model: ModelFile) -> Luminance:
    """The network's CIE Y at key vectors (:func:`model_xyz`'s second channel)."""
    xyz = model_xyz(model)
    return lambda u, v, w: xyz(u, v, w)[..., 1]


def volume_xyz(xyz: np.ndarray, scheme: str) -> Colour:
    """The ground-truth volume's CIE XYZ ``(N, 3)`` at key vectors: the reference look-up
    (gratnet.reference.reference_xyz, trilinear in the volume's own coordinates)."""
    from gratnet.reference import reference_xyz

    values = np.asarray(xyz, dtype=np.float32)

    def colour(u: np.ndarray, v: np.ndarray, w: np.ndarray) -> np.ndarray:
        return np.asarray(reference_xyz(values, scheme, u, v, w), dtype=np.float64)

    return colour


def volume_luminance(xyz: np.ndarray, scheme: str) -> Luminance:
    """The ground-truth volume's CIE Y at key vectors: the reference look-up (gratnet.reference.reference_xyz,
    trilinear in the volume's own coordinates), on the Y channel alone."""
    luminance = volume_xyz(np.asarray(xyz)[..., 1:2], scheme)  # the Y channel alone, converted once
    return lambda u, v, w: luminance(u, v, w)[..., 0]


def _volume_digest(xyz: np.ndarray, scheme: str) -> str:
    digest = hashlib.sha256(np.ascontiguousarray(xyz, dtype=np.float32).tobytes())
    digest.update(json.dumps({"shape": list(np.shape(xyz)), "scheme": scheme}).encode("utf-8"))
    return digest.hexdigest()


def importance_cache_folder() -> Path:
    """``$XDG_CACHE_HOME/gratnet/importance`` (else ``~/.cache/gratnet/importance``): the on-disk tables."""
    return cache_folder("importance")


_MEMORY: dict[str, MaterialTable] = {}
_MEMORY_LOCK = threading.Lock()


def clear_memory_cache() -> None:
    """Forget the tables kept in this process (the on-disk cache stays): the next call reads or builds again."""
    with _MEMORY_LOCK:
        _MEMORY.clear()


def _cached_table(material: str, source: str, colour: Callable[[], Colour], resolution: int, subsamples: int,
                  w_range: Iterable[float], combine: str, cache: bool, progress: bool, build: bool = True
                  ) -> MaterialTable | None:
    """The table for ``material`` (a content hash) and the parameters: from memory, else from disk, else built
    (then kept in both; with ``build`` False: None instead)."""
    size, sub, fractions, how = _check_parameters(resolution, subsamples, w_range, combine)
    parameters = {"format": _FORMAT, "version": _FORMAT_VERSION, "material": material, "source": source,
                  "resolution": size, "subsamples": sub, "w_range": list(fractions), "combine": how,
                  "floor_share": FLOOR_SHARE, "key_limit": KEY_LIMIT, "colour_w_range": list(COLOUR_W_FRACTIONS)}
    digest = hashlib.sha256(json.dumps(parameters, sort_keys=True).encode("utf-8")).hexdigest()[:32]
    if cache:
        with _MEMORY_LOCK:
            found = _MEMORY.get(digest)
        if found is not None:
            return found
    path = importance_cache_folder() / f"{digest}.npz"
    table = _read_cached(path, parameters, digest) if cache else None
    if table is None and not build:
        return None
    if table is None:
        started = time.perf_counter()
        weights, colours = material_weights(colour(), size, subsamples=sub, w_range=fractions, combine=how,
                                            progress=progress, description=f"importance table ({source})")
        table = _table(weights, source, digest, sub, fractions, how, time.perf_counter() - started, colours)
        if cache:
            _write_cached(path, parameters, weights, colours, table.build_seconds)
    if cache:
        with _MEMORY_LOCK:
            while len(_MEMORY) >= _MEMORY_ENTRIES:
                _MEMORY.pop(next(iter(_MEMORY)))
            _MEMORY[digest] = table
    return table


def _read_cached(path: Path, parameters: dict[str, object], digest: str) -> MaterialTable | None:
    try:
        with np.load(path, allow_pickle=False) as archive:
            header = json.loads(str(archive["header"]))
            weights = np.asarray(archive["weights"], dtype=np.float64)
            colour = np.asarray(archive["colour"], dtype=np.float32)
    except (OSError, ValueError, KeyError):
        return None  # missing or unreadable: rebuild
    size = int(parameters["resolution"])  # type: ignore[call-overload]
    if (header.get("parameters") != parameters or weights.shape != (size, size)
            or colour.shape != (COLOUR_SLICES, size, size, 3) or not np.all(np.isfinite(colour))):
        return None
    try:
        return _table(weights, str(parameters["source"]), digest, int(parameters["subsamples"]),  # type: ignore[call-overload]
                      tuple(parameters["w_range"]), str(parameters["combine"]),  # type: ignore[arg-type]
                      float(header.get("build_seconds", 0.0)), colour)
    except GratNetError:
        return None  # corrupt weights: rebuild


def _write_cached(path: Path, parameters: dict[str, object], weights: np.ndarray, colour: np.ndarray,
                  seconds: float) -> None:
    header = json.dumps({"parameters": parameters, "build_seconds": round(seconds, 3)})
    try:
        with atomic_path(path, output=False) as temporary, open(temporary, "wb") as handle:
            np.savez(handle, header=np.array(header), weights=weights.astype(np.float64),
                     colour=colour.astype(np.float32))
    except (OSError, GratNetError) as error:  # a read-only cache only costs a rebuild
        print(f"note: could not cache the importance table at {path}: {error}", file=sys.stderr)


def material_table(model: ModelFile, resolution: int = DEFAULT_RESOLUTION, *, subsamples: int = DEFAULT_SUBSAMPLES,
                   w_range: Iterable[float] = DEFAULT_W_FRACTIONS, combine: str = "mean", cache: bool = True,
                   progress: bool = True) -> MaterialTable:
    """The importance table of a trained network (its CIE Y in float32) with its colour table, cached in memory and
    on disk (:func:`importance_cache_folder`) by the model's content hash and the parameters."""
    table = _cached_table(content_digest(validated(model)), "model", lambda: model_xyz(model), resolution,
                          subsamples, w_range, combine, cache, progress)
    assert table is not None  # built when not cached
    return table


def cached_material_table(model: ModelFile, resolution: int = DEFAULT_RESOLUTION, *,
                          subsamples: int = DEFAULT_SUBSAMPLES, w_range: Iterable[float] = DEFAULT_W_FRACTIONS,
                          combine: str = "mean") -> MaterialTable | None:
    """:func:`material_table` if it is in memory or in the disk cache (milliseconds), else None: never builds."""
    return _cached_table(content_digest(validated(model)), "model", lambda: model_xyz(model), resolution,
                         subsamples, w_range, combine, True, False, build=False)


def volume_table(volume: object, resolution: int = DEFAULT_RESOLUTION, *, subsamples: int = DEFAULT_SUBSAMPLES,
                 w_range: Iterable[float] = DEFAULT_W_FRACTIONS, combine: str = "mean", cache: bool = True,
                 progress: bool = True) -> MaterialTable:
    """The importance table of a ground-truth volume (gratnet.volume.Volume, for ``--reference`` renders): its
    reference look-up's CIE Y, cached like :func:`material_table` by the volume's content hash."""
    from gratnet.codes import SCHEME

    xyz = getattr(volume, "xyz", None)
    metadata = getattr(volume, "metadata", None)
    if not isinstance(xyz, np.ndarray) or xyz.ndim != 4 or xyz.shape[-1] != 3 or not isinstance(metadata, dict):
        raise GratNetError("volume_table needs a gratnet.volume.Volume (xyz of shape (S, R, R, 3) and metadata)")
    scheme = metadata.get("scheme")
    if scheme not in SCHEME:
        raise GratNetError(f"the volume's metadata names no sampling scheme ({', '.join(SCHEME.names)}), got "
                           f"{scheme!r}")
    table = _cached_table(_volume_digest(xyz, str(scheme)), "volume", lambda: volume_xyz(xyz, str(scheme)),
                          resolution, subsamples, w_range, combine, cache, progress)
    assert table is not None  # built when not cached
    return table
