"""Learned feature grids: trilinear interpolation of dense 3D feature grids over the network coordinates.

docs/physics.md "Feature-grid network". A grid network's input is, per level ``l`` (coarse to fine), the
``C`` features of a dense grid ``G_l`` of shape ``(T_l, R_l, R_l, C)`` (axes: c_t, c_v, c_u, feature)
interpolated trilinearly at the network coordinates ``(c_u, c_v, c_t) ∈ [−1, 1]³``, followed by the
sinusoidal encoding (gratnet/encoding.py). Grid node ``i`` of an axis of ``N`` nodes sits at
``c = −1 + 2i/(N − 1)``: both ends of [−1, 1] are nodes (torch's ``grid_sample(align_corners=True)``; in
GL texture coordinates, node ``i`` is the texel centre ``(i + 0.5)/N``), so the volume's 1001 u* samples
fall on grid nodes whenever ``(N − 1)`` divides 1000. Coordinates outside [−1, 1] are clamped.

One implementation for numpy arrays and torch tensors alike (array-api-compat picks the namespace), used
by the trainer (torch, with autograd into the grids) and the runtime's numpy evaluator; the GLSL shader
implements the same formula and a parity test ties them together.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import array_api_compat

from gratnet.errors import GratNetError

#: Most features per level: the shader packs a level's C features into ceil(C/4) RGBA textures ("chunks"),
#: so 16 costs a level four textures (shaders/featuregrid.glsl). Whether levels × chunks textures fit a given
#: OpenGL context is checked when a renderer loads the model (viewer.renderer.check_grid_texture_units): three
#: levels of 16 features need 12 grid samplers beside 4 others, GL 4.3's minimum of 16 per shader stage.
MAX_FEATURES = 16
#: Features per texture (RGBA) in the shader: chunk k of a level holds features 4k … 4k + 3.
CHUNK_FEATURES = 4
#: How features are interpolated between nodes: ``linear`` (trilinear, C⁰: its kinks at the cell faces show
#: as a lattice of lines in slices) or ``smoothstep`` (trilinear with each axis' cell fraction f replaced by
#: f²(3 − 2f): C¹, the same eight nodes, and on a GPU still one hardware-filtered fetch).
INTERPOLATIONS = ("linear", "smoothstep")


def check_interpolation(interpolation: str) -> str:
    """``interpolation`` itself if it is one of :data:`INTERPOLATIONS`, else a one-line error."""
    if interpolation not in INTERPOLATIONS:
        raise GratNetError(f"grid interpolation must be one of {', '.join(INTERPOLATIONS)}, got {interpolation!r}")
    return interpolation


def grid_chunks(features: int) -> int:
    """Textures per level in the shader for ``features`` features per level: ``ceil(features / 4)``."""
    return -(-int(features) // CHUNK_FEATURES)


def _cell(xp: Any, c: Any, nodes: int) -> tuple[Any, Any]:
    """(lower node i₀, fraction f) of coordinates ``c`` on an axis of ``nodes`` nodes (eq. 6g): p = (clamp(c, −1, 1)
    + 1)·(N − 1)/2, i₀ = clamp(⌊p⌋, 0, N − 2) (the last cell includes its far end), f = p − i₀."""
    position = (xp.clip(c, -1.0, 1.0) + 1.0) * (0.5 * (nodes - 1))
    lower = xp.clip(xp.floor(position), 0.0, float(nodes - 2))
    return lower, position - lower


def _smoothstep(fraction: Any) -> Any:
    return fraction * fraction * (3.0 - 2.0 * fraction)


def smoothstep_coordinates(coordinates: Any, nodes_uvt: Sequence[int]) -> Any:
    """Network coordinates ``(…, 3)`` moved within their grid cell so that *linear* interpolation at the result
    is smoothstep interpolation at the input (eq. 6g with f → f²(3 − 2f) per axis), for a level of
    ``nodes_uvt = (R_u, R_v, T)`` nodes: for lookups that only interpolate linearly (the trainer's
    ``grid_sample``). Clamped to [−1, 1] like the grid lookup itself."""
    xp = array_api_compat.array_namespace(coordinates)
    axes = []
    for axis, nodes in enumerate(nodes_uvt):
        lower, fraction = _cell(xp, coordinates[..., axis], int(nodes))
        axes.append((lower + _smoothstep(fraction)) / (0.5 * (int(nodes) - 1)) - 1.0)
    return xp.stack(axes, axis=-1)


def level_resolutions(levels: int, finest: int, t_resolution: int | Sequence[int],
                      step: int = 2) -> list[tuple[int, int]]:
    """(R_l, T_l) per level, coarse to fine: the finest has ``finest`` nodes per u*/v* axis and each
    coarser level 1/``step`` of the intervals of the next (``R_l − 1 = (finest − 1)/step^(levels−1−l)``, at least
    2 nodes); ``t_resolution`` nodes along t on every level, or one count per level (coarse to fine)."""
    per_level = [t_resolution] * levels if isinstance(t_resolution, int) else [int(t) for t in t_resolution]
    if levels < 1 or finest < 2 or step < 2 or len(per_level) != levels or min(per_level) < 2:
        raise GratNetError(f"a feature grid needs ≥ 1 level, ≥ 2 nodes per u*/v* axis, a level step ≥ 2 and ≥ 2 "
                           f"nodes along t on each of its levels, got {levels} levels, {finest} nodes, step {step} "
                           f"and t {t_resolution}")
    return [(max(2, round((finest - 1) / step ** (levels - 1 - level)) + 1), per_level[level])
            for level in range(levels)]


def grid_features(grids: Sequence[Any], coordinates: Any, interpolation: str = "linear") -> Any:
    """Features of every level at network coordinates ``(…, 3)`` → ``(…, Σ C_l)``, level 0 first.

    Each grid is ``(T, R_v, R_u, C)``; the result has the coordinates' dtype (float16 grids are widened).
    ``interpolation``: one of :data:`INTERPOLATIONS`.
    """
    xp = array_api_compat.array_namespace(coordinates)
    check_interpolation(interpolation)
    batch = tuple(coordinates.shape[:-1])
    points = xp.reshape(coordinates, (-1, 3))
    parts = []
    for grid in grids:
        t_nodes, v_nodes, u_nodes, channels = (int(size) for size in grid.shape)
        flat = xp.reshape(xp.astype(grid, coordinates.dtype), (-1, channels))
        index, fraction = [], []
        for axis, nodes in enumerate((u_nodes, v_nodes, t_nodes)):
            lower, f = _cell(xp, points[:, axis], nodes)
            index.append(xp.astype(lower, xp.int64))
            fraction.append(_smoothstep(f) if interpolation == "smoothstep" else f)
        (iu, iv, it), (fu, fv, ft) = index, fraction
        base = (it * v_nodes + iv) * u_nodes + iu
        corners, weights = [], []
        for dt in (0, 1):  # the 8 corners in one gather: autograd then scatters into the grid once, not 8 times
            for dv in (0, 1):
                for du in (0, 1):
                    corners.append(base + (dt * v_nodes + dv) * u_nodes + du)
                    weights.append((ft if dt else 1.0 - ft) * (fv if dv else 1.0 - fv) * (fu if du else 1.0 - fu))
        values = xp.take(flat, xp.reshape(xp.stack(corners, axis=1), (-1,)), axis=0)
        values = xp.reshape(values, (-1, 8, channels))
        total = xp.sum(xp.stack(weights, axis=1)[:, :, None] * values, axis=1)
        parts.append(total)
    features = xp.concat(parts, axis=-1)
    return xp.reshape(features, (*batch, int(features.shape[-1])))
