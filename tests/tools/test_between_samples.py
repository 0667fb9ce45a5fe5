"""analysis.between_samples: the on-sample, mid-cell and corner-spread figures on analytic lattices."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pytest

from analysis.between_samples import centre_truth, slice_errors

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


def _fine_lattice(values: Callable[[np.ndarray, np.ndarray], np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """The same as ``_lattice`` on the (2R − 1)² lattice: every other node is one of the R² lattice's."""
    nodes = np.linspace(-1.0, 1.0, 2 * RESOLUTION - 1)
    c_u, c_v = (axis.ravel() for axis in np.meshgrid(nodes, nodes, indexing="xy"))
    coordinates = np.stack([c_u, c_v, np.full_like(c_u, 0.3)], axis=1)
    return coordinates, np.stack([values(c_u, c_v)] * 3, axis=1)


def test_the_fine_lattice_gives_the_truth_at_the_cell_centres():
    """A curved field f = a·c_u²: bilinear at a cell centre exceeds f by a·h²/4 (h the cell width), and a network
    equal to f errs by 0 against the truth there while it errs by a·h²/4 against bilinear."""
    a = 0.7
    field = lambda u, v: a * u**2 + 0.1 * v  # noqa: E731
    coordinates, targets = _lattice(field)
    truth = centre_truth(*_fine_lattice(field), RESOLUTION)
    assert truth.shape == (RESOLUTION - 1, RESOLUTION - 1, 3)
    centres = -1.0 + (2 * np.arange(RESOLUTION - 1) + 1) / (RESOLUTION - 1)
    np.testing.assert_allclose(truth[:, :, 0], field(centres[None, :], centres[:, None]))

    def exact(points: np.ndarray) -> np.ndarray:
        return np.stack([field(points[:, 0], points[:, 1])] * 3, axis=1)

    h = 2.0 / (RESOLUTION - 1)
    result = slice_errors(exact, coordinates, targets, RESOLUTION, truth)
    assert result["mid_cell_truth_rms"] == pytest.approx(0.0, abs=1e-12)
    assert result["bilinear_truth_rms"] == pytest.approx(a * h**2 / 4)
    assert result["mid_cell_rms"] == pytest.approx(a * h**2 / 4)
    assert "mid_cell_truth_rms" not in slice_errors(exact, coordinates, targets, RESOLUTION)


def test_unreachable_centres_are_left_out_of_the_truth_figures():
    coordinates, targets = _lattice(lambda u, v: u + v)
    fine_coordinates, fine_targets = _fine_lattice(lambda u, v: u + v)
    reachable = np.hypot(fine_coordinates[:, 0], fine_coordinates[:, 1]) <= 0.8  # volumes hold no sample beyond
    truth = centre_truth(fine_coordinates[reachable], fine_targets[reachable], RESOLUTION)
    assert np.isnan(truth[0, 0]).all() and not np.isnan(truth[1, 1]).any()
    result = slice_errors(lambda points: np.stack([points[:, 0] + points[:, 1] + 0.01] * 3, axis=1),
                          coordinates, targets, RESOLUTION, truth)
    assert result["mid_cell_truth_rms"] == pytest.approx(0.01)
    assert result["bilinear_truth_rms"] == pytest.approx(0.0, abs=1e-12)
