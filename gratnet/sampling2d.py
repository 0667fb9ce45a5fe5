"""A piecewise-constant distribution over the unit square (issue 43): the one sampling contract that the
environment light (luminance × sin θ per texel) and the material's own importance table (its F-term over the
key's (u, v)) share, in numpy here and in GLSL in shaders/sampling.glsl (tied by tests/contract/test_sampling2d.py).

The distribution is a grid of ``rows × columns`` non-negative weights ``f[r, c]`` over cells of the unit square
(column c covers x ∈ [c/C, (c+1)/C), row r covers y ∈ [r/R, (r+1)/R)). Its density on the unit square is
``f[r, c] · R · C / Σf`` (:attr:`density`), constant within a cell. Sampling inverts two CDFs: the marginal over
rows (``R + 1`` values from 0 to 1) and, within the chosen row, the conditional over columns (``C + 1`` values per
row); both place the sample linearly within the cell, so a sample's density is exactly the cell's density.
A row of zero weight gets a uniform conditional CDF (it is never chosen; the numbers stay finite).

The GL runtime uploads both CDFs as one R32F texture (:meth:`PiecewiseConstant2D.packed`); there a cell's density is
the difference of its float32 CDF values, the exact density of the float32 sampler.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from gratnet.errors import GratNetError

__all__ = ["PiecewiseConstant2D"]


@dataclasses.dataclass(frozen=True)
class PiecewiseConstant2D:
    """A distribution over the unit square, constant over each cell of a grid (module docstring).

    Attributes:
        density: ``float64 (R, C)``, the density on the unit square in each cell (mean 1 over the square).
        marginal_cdf: ``float64 (R + 1,)``, the CDF over rows: 0 … 1, non-decreasing.
        conditional_cdf: ``float64 (R, C + 1)``, each row's CDF over its columns: 0 … 1, non-decreasing.
    """

    density: np.ndarray
    marginal_cdf: np.ndarray
    conditional_cdf: np.ndarray

    @classmethod
    def from_weights(cls, weights: object) -> PiecewiseConstant2D:
        """The distribution proportional to ``weights`` (``(R, C)``, finite, ≥ 0, not all 0), else GratNetError."""
        values = np.asarray(weights, dtype=np.float64)
        if values.ndim != 2 or min(values.shape) < 1:
            raise GratNetError(f"sampling weights must be a non-empty 2-D array, got shape {values.shape}")
        if not np.all(np.isfinite(values)) or np.any(values < 0.0):
            raise GratNetError("sampling weights must be finite and ≥ 0")
        total = float(values.sum())
        if not total > 0.0:
            raise GratNetError("sampling weights are all 0: nothing to sample")
        rows, columns = values.shape
        row_sums = values.sum(axis=1)
        marginal = np.concatenate([[0.0], np.cumsum(row_sums)]) / total
        marginal[-1] = 1.0
        cumulative = np.concatenate([np.zeros((rows, 1)), np.cumsum(values, axis=1)], axis=1)
        uniform = np.linspace(0.0, 1.0, columns + 1)
        with np.errstate(invalid="ignore", divide="ignore"):
            conditional = np.where(row_sums[:, None] > 0.0, cumulative / row_sums[:, None], uniform[None, :])
        conditional[:, -1] = 1.0
        density = values * (rows * columns / total)
        return cls(density=density, marginal_cdf=marginal, conditional_cdf=conditional)

    @property
    def shape(self) -> tuple[int, int]:
        """``(R, C)``: rows and columns of cells."""
        rows, columns = self.density.shape
        return int(rows), int(columns)

    def pdf(self, x: object, y: object) -> np.ndarray:
        """The density on the unit square at points ``(x, y)`` (broadcast; 0 outside [0, 1)²)."""
        xs, ys = np.broadcast_arrays(np.asarray(x, dtype=np.float64), np.asarray(y, dtype=np.float64))
        rows, columns = self.shape
        inside = (xs >= 0.0) & (xs < 1.0) & (ys >= 0.0) & (ys < 1.0)
        column = np.clip(np.floor(xs * columns), 0, columns - 1).astype(np.int64)
        row = np.clip(np.floor(ys * rows), 0, rows - 1).astype(np.int64)
        return np.where(inside, self.density[row, column], 0.0)

    def sample(self, xi_row: object, xi_column: object) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Points for uniform numbers ``xi_row``, ``xi_column`` in [0, 1) (broadcast): ``(x, y, density)``, the
        point on the unit square and its density there (:meth:`pdf`), as shaders/sampling.glsl computes them."""
        first, second = np.broadcast_arrays(np.asarray(xi_row, dtype=np.float64),
                                            np.asarray(xi_column, dtype=np.float64))
        rows, columns = self.shape
        row = np.clip(np.searchsorted(self.marginal_cdf, first, side="right") - 1, 0, rows - 1)
        low, high = self.marginal_cdf[row], self.marginal_cdf[row + 1]
        y = (row + _within(first, low, high)) / rows
        # Each row's CDF lifted by 2·row: one monotone array, so one searchsorted finds the column in its row.
        lifted = (self.conditional_cdf + 2.0 * np.arange(rows)[:, None]).reshape(-1)
        position = np.searchsorted(lifted, second + 2.0 * row, side="right") - 1
        column = np.clip(position - row * (columns + 1), 0, columns - 1)
        flat_row, flat_column = row.reshape(-1), column.reshape(-1)
        low = self.conditional_cdf[flat_row, flat_column].reshape(second.shape)
        high = self.conditional_cdf[flat_row, flat_column + 1].reshape(second.shape)
        x = (column + _within(second, low, high)) / columns
        return x, y, self.density[row, column]

    def packed(self) -> np.ndarray:
        """The ``float32`` texture shaders/sampling.glsl reads, ``(R + 1, max(C, R) + 1)``: row r < R holds row r's
        conditional CDF (``C + 1`` values), row R the marginal CDF (``R + 1`` values); the rest is 0."""
        rows, columns = self.shape
        table = np.zeros((rows + 1, max(columns, rows) + 1), dtype=np.float32)
        table[:rows, :columns + 1] = self.conditional_cdf
        table[rows, :rows + 1] = self.marginal_cdf
        return table


def _within(xi: np.ndarray, low: np.ndarray, high: np.ndarray) -> np.ndarray:
    """Where ``xi`` lies between a cell's CDF values, in [0, 1) (0 for an empty cell)."""
    width = high - low
    with np.errstate(invalid="ignore", divide="ignore"):
        fraction = np.where(width > 0.0, (xi - low) / width, 0.0)
    return np.clip(fraction, 0.0, np.nextafter(1.0, 0.0))
