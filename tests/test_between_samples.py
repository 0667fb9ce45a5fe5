"""benchmarks/between_samples.py: the on-sample, mid-cell and corner-spread figures on analytic lattices."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pytest

from benchmarks.between_samples import slice_errors

RESOLUTION = 5


def _lattice(values: Callable[[np.ndarray, np.ndarray], np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """Network coordinates of a 5² lattice at c_t = 0.3 and targets ``values(c_u, c_v)`` in 3 channels."""
    nodes = np.linspace(-1.0, 1.0, RESOLUTION)
    c_u, c_v = (axis.ravel() for axis in np.meshgrid(nodes, nodes, indexing="xy"))
    coordinates = np.stack([c_u, c_v, np.full_like(c_u, 0.3)], axis=1)
    return coordinates, np.stack([values(c_u, c_v)] * 3, axis=1)


def test_a_linear_field_is_interpolated_exactly_and_its_spread_is_the_gradient():
    a, b = 0.2, -0.1
    coordinates, targets = _lattice(lambda u, v: a * u + b * v + 0.5)
    exact = slice_errors(lambda points: np.stack([a * points[:, 0] + b * points[:, 1] + 0.5] * 3, axis=1),
                         coordinates, targets, RESOLUTION)
    assert exact["on_sample_rms"] == pytest.approx(0.0, abs=1e-12)
    assert exact["mid_cell_rms"] == pytest.approx(0.0, abs=1e-12)
    half = 1.0 / (RESOLUTION - 1)  # half a cell in network coordinates
    assert exact["corner_spread_rms"] == pytest.approx(np.hypot(a * half, b * half))
    offset = slice_errors(lambda points: np.stack([a * points[:, 0] + b * points[:, 1] + 0.53] * 3, axis=1),
                          coordinates, targets, RESOLUTION)
    assert offset["on_sample_rms"] == pytest.approx(0.03) and offset["mid_cell_rms"] == pytest.approx(0.03)


def _index(c: np.ndarray) -> np.ndarray:
    return (c + 1.0) * (RESOLUTION - 1) / 2  # lattice index along an axis, fractional between nodes


def test_at_the_sampling_limit_the_samples_do_not_fix_what_lies_between():
    """A checkerboard of ±1 (the finest pattern a lattice holds): the bilinear centre is 0 and the corners are 1
    from it. Two networks hit every sample; one is 0 at the cell centres, the other ±1 there."""
    coordinates, targets = _lattice(lambda u, v: np.cos(np.pi * _index(u)) * np.cos(np.pi * _index(v)))

    def separable(points: np.ndarray) -> np.ndarray:
        return np.stack([np.cos(np.pi * _index(points[:, 0])) * np.cos(np.pi * _index(points[:, 1]))] * 3, axis=1)

    def diagonal(points: np.ndarray) -> np.ndarray:
        return np.stack([np.cos(np.pi * (_index(points[:, 0]) + _index(points[:, 1])))] * 3, axis=1)

    for network, between in ((separable, 0.0), (diagonal, 1.0)):
        result = slice_errors(network, coordinates, targets, RESOLUTION)
        assert result["on_sample_rms"] == pytest.approx(0.0, abs=1e-12)
        assert result["corner_spread_rms"] == pytest.approx(1.0)
        assert result["mid_cell_rms"] == pytest.approx(between, abs=1e-12)
