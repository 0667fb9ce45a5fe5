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
        return self.heights_um.shape

    @property
    def size_um(self) -> tuple[float, float]:
        """Lateral size (width along x, height along y) in µm: samples × dx."""
        rows, columns = self.shape
        return columns * self.dx_um, rows * self.dx_um

    @property
    def span_um(self) -> float:
        """Peak-to-valley height (µm)."""
        return float(self.heights_um.max() - self.heights_um.min())

    def slope_covariance(self) -> tuple[float, float, float]:
        """``(Σxx, Σxy, Σyy)``: the covariance of the surface slopes (∂h/∂x, ∂h/∂y) (dimensionless, µm/µm) over its
        samples, central differences at ``dx_um`` (one-sided at the edges), mean slope removed: the statistics of
        Smith's shadowing–masking term (gratnet.shadowing; physics.md, "Shadowing and masking")."""
        gradient_y, gradient_x = np.gradient(self.heights_um, self.dx_um)
        covariance = np.cov(np.stack([gradient_x.ravel(), gradient_y.ravel()]), bias=True)
        return float(covariance[0, 0]), float(covariance[0, 1]), float(covariance[1, 1])

    def slope_percentile(self, percentile: float = 99.0) -> float:
        """A robust maximum surface slope |∇h| (dimensionless): the given percentile over samples.

        Discontinuities (a blazed grating's step) give arbitrarily large slopes at a few samples;
        a percentile ignores them, the bulk of the surface sets the sampling it needs.
        """
        gradient_y, gradient_x = np.gradient(self.heights_um, self.dx_um)
        return float(np.percentile(np.hypot(gradient_x, gradient_y), percentile))


def cover_window(field: HeightField, samples: int, mode: RepeatMode = "periodic") -> HeightField:
    """A ``samples``×``samples`` field centred on ``field``'s centre: repeated around it where it is
    narrower (periodically, or mirrored: no height jump at the seams), cropped where it is wider.

    The paper repeats a patch narrower than the coherence window to cover it; repeating around the
    patch keeps the original patch at the window centre.
    """
    if mode not in ("periodic", "mirror"):
        raise GratNetError(f"repeat mode must be 'periodic' or 'mirror', got {mode!r}")
    heights = field.heights_um
    pad_rows = max(0, samples - heights.shape[0])
    pad_columns = max(0, samples - heights.shape[1])
    pad = ((pad_rows // 2, pad_rows - pad_rows // 2), (pad_columns // 2, pad_columns - pad_columns // 2))
    padded = np.pad(heights, pad, mode="wrap" if mode == "periodic" else "symmetric")
    top = (padded.shape[0] - samples) // 2
    left = (padded.shape[1] - samples) // 2
    covered = padded[top : top + samples, left : left + samples]
    if covered.shape == heights.shape:
        return field
    action = f"repeated {mode}" if pad_rows or pad_columns else "cropped"
    return HeightField(covered, field.dx_um, f"{field.source} [{action} to {samples * field.dx_um:.4g} µm]")


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
