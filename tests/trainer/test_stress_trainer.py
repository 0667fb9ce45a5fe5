"""Numerical stability on the trainer side (issue 5): property tests of the network contract's transforms
(gratnet/encoding.py, numpy and torch), log of zero / denormals / empty data in training, and the
ground truth of tall and rough height fields against the brute-force integral.

Tolerances of the range round trip (eq. 7), x = XYZ / white:
- power-log / log: y = r^n with r = 1 + log2(x)/B. Inverting loses a few ulps of r, and x = 2^(B(r − 1))
  turns an error Δr into a relative error B·ln2·Δr ≤ 33·Δr: ~1e-14 in float64 (we allow 1e-12) and
  ~1e-5 in float32 (we allow 3e-5). Below x = 2^-48 the transform maps to 0 by design (physics.md), so
  the absolute floor of the round trip is 2^-48; above x = 1 it clips to 1 (a perfect mirror).
- log1p: log1p and expm1 are each accurate to an ulp or two: 1e-12 (float64), 1e-5 (float32).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import ndimage

from gratnet.brdf import direction
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
from gratnet.errors import GratNetError
from gratnet.volume import Volume
from trainer.fourier import FTerm, OpticsConfig, prepare_surface, required_spacing_um
from trainer.heightfield import HeightField
from trainer.model import log_cosh_loss
from trainer.reference import brute_force_amplitude, brute_force_xyz
from trainer.sampling import grid_to_key
from trainer.spectral import monochromatic, spectral_weights
from trainer.train import split_samples, train, volume_samples
from trainer.train_config import TrainConfig

KINDS = ("power-log", "log", "log1p")
SCHEMES = ("regular", "simple", "simple-max")
FLOOR = 2.0**-48  # eq. 7: x ≤ 2^-48 maps to y = 0
# Derandomized: CI runs the same 60 examples each time (reproducible); set derandomize=False to explore more.
PROPERTY = settings(max_examples=60, deadline=None, derandomize=True)

ratios = st.one_of(
    st.floats(min_value=0.0, max_value=4.0, allow_nan=False),
    st.floats(min_value=2.0**-60, max_value=2.0**-40),  # around the floor
    st.sampled_from([0.0, 5e-324, 2.2e-308, FLOOR, FLOOR * (1 + 2**-40), 1.0, 1e300]),
)


def expected_round_trip(x: np.ndarray, kind: str) -> np.ndarray:
    return x if kind == "log1p" else np.minimum(x, 1.0)


def as_xyz(x: float, spec: RangeSpec) -> np.ndarray:
    return np.asarray(spec.white) * x


# --------------------------------------------------------------------------------------------------
# Range transform (eq. 7)


@PROPERTY
@given(x=ratios, kind=st.sampled_from(KINDS))
def test_range_round_trip_float64(x, kind):
    spec = RangeSpec(kind)
    xyz = as_xyz(x, spec)
    with np.errstate(over="ignore"):
        back = range_inverse(range_forward(xyz, spec), spec)
    expected = as_xyz(expected_round_trip(np.float64(x), kind), spec)
    if kind == "log1p" and x > 1e200:  # 2^y − 1 overflows exactly where x·white does; both are huge
        assert np.all(back > 1e200)
        return
    floor = 0.0 if kind == "log1p" else FLOOR * max(spec.white)
    assert np.all(np.abs(back - expected) <= 1e-12 * expected + floor + 1e-300), (back, expected)


@PROPERTY
@given(x=st.floats(min_value=0.0, max_value=4.0), kind=st.sampled_from(KINDS))
def test_range_round_trip_float32_torch_matches_its_tolerance(x, kind):
    spec = RangeSpec(kind)
    xyz = torch.tensor(as_xyz(x, spec), dtype=torch.float32)
    back = range_inverse(range_forward(xyz, spec), spec).double().numpy()
    expected = as_xyz(expected_round_trip(np.float64(np.float32(x)), kind), spec)
    floor = 0.0 if kind == "log1p" else FLOOR * max(spec.white)
    assert np.all(np.abs(back - expected) <= 3e-5 * expected + floor + 1e-37), (back, expected)


@PROPERTY
@given(a=ratios, b=ratios, kind=st.sampled_from(KINDS))
def test_range_transforms_are_monotone(a, b, kind):
    spec = RangeSpec(kind)
    low, high = sorted((a, b))
    forward = range_forward(np.array([[low] * 3, [high] * 3]), spec)
    assert np.all(forward[0] <= forward[1])
    y = np.sort(np.array([a, b]) / 4.0)  # network outputs, mostly in [0, 1]
    with np.errstate(over="ignore"):
        inverse = range_inverse(np.stack([np.full(3, y[0]), np.full(3, y[1])]), spec)
    assert np.all(inverse[0] <= inverse[1])


@pytest.mark.parametrize("kind", KINDS)
@pytest.mark.parametrize("library", ["numpy", "torch"])
def test_range_forward_at_zero_denormals_negatives_and_infinity(kind, library):
    spec = RangeSpec(kind)
    values = [0.0, -0.0, 5e-324, 1e-310, 1e-45, -1.0, -1e300, math.inf, -math.inf, math.nan]
    array = np.repeat(np.array(values)[:, None], 3, axis=1)
    if library == "torch":
        result = range_forward(torch.tensor(array, dtype=torch.float32), spec).double().numpy()
    else:
        with np.errstate(divide="raise", invalid="raise", over="raise", under="ignore"):
            result = range_forward(array, spec)
    # log of zero, denormals and negatives: 0 exactly for the log kinds (no −inf, no NaN).
    assert np.all(result[:7] >= 0.0) and np.all(np.isfinite(result[:7]))
    if kind != "log1p":
        assert np.all(result[:7] == 0.0) and np.all(result[7] == 1.0) and np.all(result[8] == 0.0)
    else:
        assert np.all(result[:5] <= 1e-44) and np.all(result[5:7] == 0.0) and np.all(np.isinf(result[7]))
    assert np.all(np.isnan(result[9]))  # NaN propagates: a corrupt target is not turned into a valid one


@pytest.mark.parametrize("kind", KINDS)
@pytest.mark.parametrize("library", ["numpy", "torch"])
def test_range_inverse_maps_nonpositive_and_nan_outputs_to_zero(kind, library):
    # Documented "y ≤ 0 → 0"; a NaN network output is not > 0 either, and the shader (range.glsl) gives 0.
    spec = RangeSpec(kind)
    y = np.repeat(np.array([0.0, -0.0, -1.0, -math.inf, math.nan, 5e-324])[:, None], 3, axis=1)
    if library == "torch":
        result = range_inverse(torch.tensor(y, dtype=torch.float64), spec).numpy()
    else:
        result = range_inverse(y, spec)
    assert np.all(result[:5] == 0.0)
    assert np.all(np.isfinite(result[5])) and np.all(result[5] >= 0.0)


@pytest.mark.parametrize("bits, power", [(math.inf, 8.0), (48.0, math.inf), (math.nan, 8.0), (-1.0, 8.0)])
def test_range_spec_refuses_non_finite_parameters(bits, power):
    # B = inf made every x > 0 map to y = 1: the training ran to the end and only then failed to save.
    with pytest.raises(GratNetError, match="B > 0"):
        RangeSpec("power-log", bits, power)
    with pytest.raises(GratNetError):
        TrainConfig(range_bits=bits, range_power=power).range_spec()


# --------------------------------------------------------------------------------------------------
# Key vector → network coordinates → key (eq. 6)

angles = st.floats(min_value=0.0, max_value=90.0)
azimuths = st.floats(min_value=-360.0, max_value=720.0)


@PROPERTY
@given(theta_i=angles, phi_i=azimuths, theta_o=angles, phi_o=azimuths, scheme=st.sampled_from(SCHEMES))
def test_network_coordinates_invert_to_the_key_for_every_direction_pair(theta_i, phi_i, theta_o, phi_o, scheme):
    u, v, w = -(direction(theta_i, phi_i) + direction(theta_o, phi_o))
    with np.errstate(all="raise", under="ignore"):
        c = network_coordinates(np.array([u]), np.array([v]), np.array([w]), scheme)[0]
    assert np.all(np.abs(c) <= 1.0 + 1e-12)
    # Back: u = grid_to_key(2·c_u) (the volume's domain transform), w from t = (c_t + 1)/2.
    np.testing.assert_allclose(grid_to_key(2.0 * c[:2], scheme), [u, v], rtol=1e-12, atol=1e-15)
    t = (c[2] + 1.0) / 2.0
    depth = np.sqrt(max(4.0 - u * u - v * v, 0.0)) if scheme == "simple-max" else 2.0
    assert -t * depth == pytest.approx(w, rel=1e-12, abs=1e-12)


@PROPERTY
@given(key=st.floats(min_value=-1e300, max_value=1e300, allow_subnormal=True), scheme=st.sampled_from(SCHEMES))
def test_key_to_grid_is_odd_monotone_and_free_of_floating_point_errors(key, scheme):
    keys = np.array([key, np.nextafter(key, np.inf), -key])
    with np.errstate(all="raise", under="ignore"):  # underflow to a denormal or 0 is the right answer
        grid = key_to_grid(keys, scheme)
    assert grid[0] <= grid[1] and grid[2] == -grid[0]
    # The sign is kept, except where a subnormal key's image underflows to 0 (5e-324 · ½ is 0: found by Hypothesis).
    underflow = grid[0] == 0.0 and abs(key) < np.finfo(np.float64).tiny
    assert np.sign(grid[0]) == np.sign(key) or underflow


@PROPERTY
@given(u=st.floats(-1e6, 1e6), v=st.floats(-1e6, 1e6), w=st.floats(-1e6, 1e6), scheme=st.sampled_from(SCHEMES))
def test_t_is_in_the_unit_interval_for_any_finite_key(u, v, w, scheme):
    arrays = [np.array([value]) for value in (u, v, w)]
    with np.errstate(all="raise", under="ignore"):
        t = key_to_t(*arrays, scheme)
    assert 0.0 <= t[0] <= 1.0


@PROPERTY
@given(coordinates=st.lists(st.floats(-1e4, 1e4), min_size=3, max_size=3), scheme=st.sampled_from(SCHEMES),
       frequencies=st.integers(1, 24), t_frequencies=st.integers(0, 6))
def test_encoding_is_finite_and_numpy_equals_torch(coordinates, scheme, frequencies, t_frequencies):
    spec = EncodingSpec.for_grid(1001, 11, frequencies, t_frequencies)
    u, v, w = (np.array([c]) for c in coordinates)
    numpy_result = encode(network_coordinates(u, v, w, scheme), spec)
    torch_result = encode(network_coordinates(*(torch.tensor(a) for a in (u, v, w)), scheme), spec).numpy()
    assert numpy_result.shape == (1, spec.features) and np.all(np.isfinite(numpy_result))
    # sin/cos of a phase φ agree between two libms to about 1e-16·|φ|; the phases here reach ~1e7 rad for
    # keys far outside the physical range (|u|, |v| ≤ 2), so the tolerance scales with the largest phase.
    largest_coordinate = 2.0 * float(np.max(np.abs(network_coordinates(u, v, w, scheme))))  # c_u + c_v doubles it
    largest_phase = largest_coordinate * np.pi * spec.scale ** (frequencies - 1)
    np.testing.assert_allclose(torch_result, numpy_result, rtol=1e-12, atol=1e-12 + 1e-15 * largest_phase)
    assert np.all(np.abs(numpy_result[0, 3:]) <= 1.0)


# --------------------------------------------------------------------------------------------------
# Training data: log of zero, denormals, empty data


def small_volume(values: np.ndarray, scheme: str = "simple-max") -> Volume:
    slices = values.shape[0]
    return Volume(values.astype(np.float32), {"scheme": scheme, "resolution": values.shape[1], "slices": slices,
                                              "slice_t": list(np.linspace(0.0, 1.0, slices))})


@pytest.mark.parametrize("kind", KINDS)
def test_samples_of_zero_and_denormal_volumes_are_finite_zeros(kind):
    values = np.zeros((3, 9, 9, 3))
    values[1] = 1e-42  # float32 denormal
    values[2, ..., 1] = -0.0
    with np.errstate(divide="raise", invalid="raise", over="raise", under="ignore"):
        coordinates, targets, _ = volume_samples(small_volume(values), RangeSpec(kind))
    assert np.all(np.isfinite(coordinates)) and np.all(np.abs(coordinates) <= 1.0)
    assert np.all(np.isfinite(targets)) and np.all(targets >= 0.0) and targets.max() <= 1e-40


def test_log_cosh_loss_stays_finite_with_finite_gradients_at_extremes():
    difference = torch.tensor([0.0, 1e-45, 1e-30, 20.0, 1e10, 1e30, -1e30], requires_grad=True)
    loss = log_cosh_loss(difference, torch.zeros(7))
    loss.backward()
    assert torch.isfinite(loss) and torch.all(torch.isfinite(difference.grad))


@pytest.mark.parametrize(
    ("values", "config"),
    [
        (np.ones((1, 9, 9, 3)), TrainConfig(test_slices="0", preset="tiny")),  # every slice held out
        (np.ones((3, 9, 9, 3)), TrainConfig(test_slices="0,1,2", preset="tiny")),
        (np.ones((2, 2, 2, 3)), TrainConfig(split="all", preset="tiny")),  # R = 2: only u² + v² = 8 > 4
    ],
    ids=["one-slice-held-out", "all-slices-held-out", "no-reachable-sample"],
)
def test_training_without_samples_is_one_clear_error_and_writes_nothing(tmp_path, values, config):
    # Before: the trainer "trained" 0 steps and wrote a model.npz of random weights.
    volume = small_volume(values)
    with pytest.raises(GratNetError, match="no training samples"):
        split_samples(volume, config)
    with pytest.raises(GratNetError, match="no training samples"):
        train(volume, config, tmp_path / "run", progress=False)
    assert not (tmp_path / "run" / "model.npz").exists()


# --------------------------------------------------------------------------------------------------
# Ground truth of tall and rough height fields


def tall_rough_field(span_um: float, dx_um: float, side: int, seed: int) -> HeightField:
    """A broad relief `span_um` tall (correlation ~0.6 µm) plus a fine roughness (~0.1 µm correlation)."""
    rng = np.random.default_rng(seed)
    broad = ndimage.gaussian_filter(rng.standard_normal((side, side)), 0.6 / dx_um, mode="wrap")
    fine = ndimage.gaussian_filter(rng.standard_normal((side, side)), 0.1 / dx_um, mode="wrap")
    broad = (broad - broad.min()) / np.ptp(broad) * span_um
    return HeightField(broad + 0.03 * fine / fine.std(), dx_um, f"tall rough {span_um} µm")


@pytest.mark.parametrize("span_um", [4.0, 8.0])
def test_tall_rough_field_matches_brute_force_at_every_w(span_um):
    optics = OpticsConfig(sigma_s_um=0.5, window_extent_sigmas=6.0)
    field = tall_rough_field(span_um, 0.02, 150, seed=int(span_um))
    surface = prepare_surface(field, optics)
    assert surface.half_span_um >= 0.45 * span_um  # really tall: k·|w|·hmax up to ~130 rad at 380 nm
    assert surface.dx_um <= required_spacing_um(field, 0.38) * (1 + 1e-9)
    u = np.linspace(-2.0, 2.0, 9)
    u_grid, v_grid = np.meshgrid(u, u)
    depth = np.sqrt(np.clip(4 - u_grid**2 - v_grid**2, 0, None))
    w_slices = [-2.0, -1e-9, 0.0, -0.999 * depth, -1e-7 * depth]  # constant and varying w, down to w → 0
    engine = FTerm(surface, monochromatic(380.0))
    power = engine.xyz_grid(u, u, w_slices)[..., 1]
    assert np.all(np.isfinite(power)) and np.all(power >= 0.0)
    assert power.max() <= 1.0 + 1e-5  # |P| ≤ ∫g: F ≤ 1 for any surface (triangle inequality)
    for index, w in enumerate(w_slices):
        w_grid = np.broadcast_to(w, u_grid.shape)
        reference = np.abs(brute_force_amplitude(surface, u_grid, v_grid, w_grid, 0.38)).reshape(u_grid.shape) ** 2
        error = np.linalg.norm(power[index] - reference) / np.linalg.norm(reference)
        assert error < 1e-4, (index, error)


def test_tall_rough_scattered_points_and_spectrum_stay_finite_and_match_brute_force():
    field = tall_rough_field(5.0, 0.02, 150, seed=3)
    surface = prepare_surface(field, OpticsConfig(sigma_s_um=0.5, window_extent_sigmas=6.0))
    spectrum = spectral_weights(380.0, 780.0, 100.0)
    rng = np.random.default_rng(11)
    u, v = rng.uniform(-1.4, 1.4, (2, 24))
    w = -rng.uniform(0.0, 1.0, 24) * np.sqrt(4 - u**2 - v**2)
    w[0], w[1], w[2] = 0.0, -1e-12, -np.sqrt(4 - u[2] ** 2 - v[2] ** 2)  # w → 0 and the deepest reachable w
    got = FTerm(surface, spectrum).xyz_points(u, v, w, chunk=8)
    reference = brute_force_xyz(surface, u, v, w, spectrum)
    assert np.all(np.isfinite(got)) and np.all(got >= 0.0)
    assert np.all(got[:, 1] <= spectrum.xyz_weights[:, 1].sum() * (1 + 1e-5))
    assert np.linalg.norm(got - reference) / np.linalg.norm(reference) < 1e-4
