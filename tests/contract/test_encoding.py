"""The network contract (gratnet/encoding.py): transforms, their inverses, the encoding's layout."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from gratnet.encoding import (
    EncodingSpec,
    RangeSpec,
    encode,
    key_to_grid,
    key_to_t,
    network_coordinates,
    range_forward,
    range_inverse,
)
from trainer.sampling import grid_to_key

finite_positive = st.floats(min_value=2.0**-40, max_value=1.0, allow_nan=False)


@settings(max_examples=200, deadline=None, derandomize=True)
@given(x=finite_positive, kind=st.sampled_from(["power-log", "log", "log1p"]))
def test_range_inverse_undoes_forward(x, kind):
    spec = RangeSpec(kind)
    xyz = np.array([x * spec.white[0], x, x * spec.white[2]])
    np.testing.assert_allclose(range_inverse(range_forward(xyz, spec), spec), xyz, rtol=1e-9)


@settings(max_examples=100, deadline=None, derandomize=True)
@given(y=st.floats(min_value=1e-6, max_value=1.0))
def test_range_forward_undoes_inverse(y):
    spec = RangeSpec()
    values = np.full(3, y)
    np.testing.assert_allclose(range_forward(range_inverse(values, spec), spec), values, rtol=1e-9)


def test_range_transform_edges():
    spec = RangeSpec()
    white = np.array(spec.white)
    assert np.array_equal(range_forward(white, spec), np.ones(3))  # a perfect mirror maps to 1, Z unclipped
    assert np.array_equal(range_forward(np.zeros(3), spec), np.zeros(3))  # log of zero: 0, no NaN
    assert np.array_equal(range_inverse(np.zeros(3), spec), np.zeros(3))
    tiny = range_forward(np.full(3, 2.0**-48), spec)  # 1 + log2(x)/48 = 0 exactly at x = 2^-48 (Y)
    assert tiny[1] == 0.0
    with np.errstate(divide="raise", invalid="raise", over="raise"):
        range_forward(np.array([5e-324, 0.0, 1e-300]), spec)  # denormals and zeros: no floating-point error


@pytest.mark.parametrize("scheme", ["regular", "simple", "simple-max"])
def test_key_to_grid_inverts_the_volume_domain_transform(scheme):
    grid = np.linspace(-2, 2, 41)
    np.testing.assert_allclose(key_to_grid(grid_to_key(grid, scheme), scheme), grid, atol=1e-12)


def test_t_remap():
    u, v = np.array([0.3, 1.2, 2.0]), np.array([0.4, 0.0, 0.0])
    depth = np.sqrt(np.clip(4 - u**2 - v**2, 0, None))
    np.testing.assert_allclose(key_to_t(u, v, -0.5 * depth, "simple-max"), [0.5, 0.5, 0.0])
    np.testing.assert_allclose(key_to_t(u, v, np.array([-2.0, -1.0, 0.0]), "regular"), [1.0, 0.5, 0.0])


def test_encoding_layout_and_frequencies():
    spec = EncodingSpec.for_grid(1001, 11)
    assert spec.features == 163
    assert spec.scale == pytest.approx(500 ** (1 / 18)) and spec.scale == pytest.approx(1.412, abs=1e-3)
    # The top frequency sits at the grid's Nyquist rate: π·s^(L−1) = π / Δc with Δc = 2/(R − 1).
    assert math.pi * spec.scale ** (spec.frequencies - 1) == pytest.approx(math.pi / (2 / 1000))
    coordinates = np.array([[0.25, -0.5, 0.1]])
    encoded = encode(coordinates, spec)[0]
    assert encoded.shape == (163,)
    np.testing.assert_array_equal(encoded[:3], coordinates[0])
    L = spec.frequencies
    omega = math.pi * spec.scale ** np.arange(L)
    np.testing.assert_allclose(encoded[3:3 + L], np.sin(omega * 0.25))
    np.testing.assert_allclose(encoded[3 + L:3 + 2 * L], np.cos(omega * 0.25))
    np.testing.assert_allclose(encoded[3 + 4 * L:3 + 5 * L], np.sin(omega * (0.25 - 0.5)))  # c_u + c_v
    np.testing.assert_allclose(encoded[3 + 6 * L:3 + 7 * L], np.sin(omega * 0.75))  # c_u − c_v
    omega_t = math.pi * spec.t_scale ** np.arange(spec.t_frequencies)
    np.testing.assert_allclose(encoded[-2 * spec.t_frequencies:-spec.t_frequencies], np.sin(omega_t * 0.1))


def test_eq_6a_is_eq_6_without_the_diagonal_groups():
    """Without the diagonals (eq. 6a) the encoding is eq. 6's coordinates, c_u and c_v blocks and c_t block, in
    that order: 3 + 2·(2·L + L_t) features, at the same frequencies."""
    full = EncodingSpec.for_grid(1001, 11, 19, 2)
    axes = EncodingSpec.for_grid(1001, 11, 19, 2, diagonals=False)
    assert (full.groups, axes.groups) == (4, 2) and axes.features == 3 + 2 * (2 * 19 + 2) == 83
    assert axes.angular_frequencies()[0].tolist() == full.angular_frequencies()[0].tolist()
    coordinates = np.random.default_rng(3).uniform(-1.0, 1.0, (50, 3))
    a, f, L = encode(coordinates, axes), encode(coordinates, full), full.frequencies
    np.testing.assert_array_equal(a[:, :3 + 4 * L], f[:, :3 + 4 * L])
    np.testing.assert_array_equal(a[:, 3 + 4 * L:], f[:, 3 + 8 * L:])
    np.testing.assert_allclose(encode(torch.from_numpy(coordinates), axes).numpy(), a, rtol=0, atol=1e-12)


def test_numpy_and_torch_give_the_same_encoding():
    spec = EncodingSpec.for_grid(101, 5)
    rng = np.random.default_rng(0)
    u, v = rng.uniform(-1.4, 1.4, (2, 50))
    w = -rng.uniform(0, 1, 50) * np.sqrt(4 - u**2 - v**2)
    numpy_result = encode(network_coordinates(u, v, w, "simple-max"), spec)
    torch_result = encode(network_coordinates(*(torch.tensor(a) for a in (u, v, w)), "simple-max"), spec)
    np.testing.assert_allclose(torch_result.numpy(), numpy_result, rtol=1e-12, atol=1e-12)
    assert np.all(np.abs(network_coordinates(u, v, w, "simple-max")) <= 1.0)
