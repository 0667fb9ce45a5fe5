"""Height fields: heights in micrometres on a regular square grid.

Conventions (docs/physics.md): ``heights_um[iy, ix]`` is the height (µm) at
x = ix · dx_um, y = iy · dx_um; x runs along columns, y along rows. Pixels are square.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Literal

import numpy as np

from gratnet.errors import GratNetError

RepeatMode = Literal["periodic", "mirror"]


@dataclasses.dataclass(frozen=True, eq=False)
class HeightField:
    """A height field: ``heights_um[iy, ix]`` in µm, sample spacing ``dx_um`` (µm) along x and y.

    ``source`` says where it came from (a generator with its parameters, or a file); it is recorded
    in every output made from the field.
    """

    heights_um: np.ndarray
    dx_um: float
    source: str = "array"

    def __post_init__(self) -> None:
        heights = np.asarray(self.heights_um)
        if heights.ndim != 2:
            raise GratNetError(f"height field must be a 2-D array, got shape {heights.shape} ({self.source})")
        if heights.size == 0 or min(heights.shape) < 2:
            raise GratNetError(f"height field is empty or degenerate: shape {heights.shape} ({self.source})")
        if not np.issubdtype(heights.dtype, np.number) or np.iscomplexobj(heights):
            raise GratNetError(f"height field must hold real numbers, got dtype {heights.dtype} ({self.source})")
        heights = heights.astype(np.float64)
        if not np.all(np.isfinite(heights)):
            bad = int(np.size(heights) - np.count_nonzero(np.isfinite(heights)))
            raise GratNetError(f"height field has {bad} NaN/inf samples ({self.source})")
        try:
            dx = float(self.dx_um)
        except (TypeError, ValueError):
            raise GratNetError(f"sample spacing dx must be a number in µm, got {self.dx_um!r}") from None
        if not math.isfinite(dx) or dx <= 0:
            raise GratNetError(f"sample spacing dx must be a positive number of µm, got {self.dx_um!r}")
        heights.setflags(write=False)
        object.__setattr__(self, "heights_um", heights)
        object.__setattr__(self, "dx_um", dx)

    @property
    def shape(self) -> tuple[int, int]:
        """(rows, columns) = (ny, nx)."""
        return self.heights_um.shape  # type: ignore[return-value]

    @property
    def size_um(self) -> tuple[float, float]:
        """Lateral size (width along x, height along y) in µm: samples × dx."""
        rows, columns = self.shape
        return columns * self.dx_um, rows * self.dx_um

    @property
    def span_um(self) -> float:
        """Peak-to-valley height (µm)."""
        return float(self.heights_um.max() - self.heights_um.min())

    def slope_percentile(self, percentile: float = 99.0) -> float:
        """A robust maximum surface slope |∇h| (dimensionless): the given percentile over samples.

        Discontinuities (a blazed grating's step) give arbitrarily large slopes at a few samples;
        a percentile ignores them, the bulk of the surface sets the sampling it needs.
        """
        gradient_y, gradient_x = np.gradient(self.heights_um, self.dx_um)
        return float(np.percentile(np.hypot(gradient_x, gradient_y), percentile))


def tile_to_cover(field: HeightField, width_um: float, mode: RepeatMode = "periodic") -> HeightField:
    """Repeat ``field`` (periodically or mirrored) until it is at least ``width_um`` wide on both axes.

    The paper repeats a patch narrower than the coherence window to cover it. A field already wide
    enough is returned unchanged.
    """
    if mode not in ("periodic", "mirror"):
        raise GratNetError(f"repeat mode must be 'periodic' or 'mirror', got {mode!r}")
    needed = math.ceil(width_um / field.dx_um - 1e-9)
    rows, columns = field.shape
    if rows >= needed and columns >= needed:
        return field
    tile = field.heights_um
    if mode == "mirror":
        # Mirrored repeat: no height jump at the seams (a slope reversal instead).
        tile = np.concatenate([tile, tile[::-1, :]], axis=0)
        tile = np.concatenate([tile, tile[:, ::-1]], axis=1)
    repeats = (max(1, math.ceil(needed / tile.shape[0])), max(1, math.ceil(needed / tile.shape[1])))
    tiled = np.tile(tile, repeats)[: max(rows, needed), : max(columns, needed)]
    return HeightField(tiled, field.dx_um, f"{field.source} [repeated {mode} to {width_um:.4g} µm]")


def resample(field: HeightField, dx_um: float, mode: RepeatMode | Literal["edge"] = "edge") -> HeightField:
    """Resample ``field`` to spacing ``dx_um`` (µm) with cubic splines, keeping its lateral size (±dx).

    ``mode`` says how the spline sees beyond the edges: 'periodic' for a field that will be tiled
    periodically (no seam artefacts), 'mirror' for mirrored tiling, 'edge' otherwise.
    """
    from scipy import ndimage

    if dx_um <= 0:
        raise GratNetError(f"resampling spacing must be positive, got {dx_um} µm")
    width_um, height_um = field.size_um
    columns = max(2, round(width_um / dx_um))
    rows = max(2, round(height_um / dx_um))
    spline_mode = {"periodic": "grid-wrap", "mirror": "mirror", "edge": "nearest"}[mode]
    # Sample centres of the new grid (spacing exactly dx_um, centred on the old extent), in old-sample units.
    new_x = ((np.arange(columns) - (columns - 1) / 2) * dx_um + width_um / 2) / field.dx_um - 0.5
    new_y = ((np.arange(rows) - (rows - 1) / 2) * dx_um + height_um / 2) / field.dx_um - 0.5
    grid_y, grid_x = np.meshgrid(new_y, new_x, indexing="ij")
    heights = ndimage.map_coordinates(field.heights_um, [grid_y, grid_x], order=3, mode=spline_mode)
    return HeightField(heights, dx_um, f"{field.source} [resampled to dx={dx_um:.4g} µm]")
