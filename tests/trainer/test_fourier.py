"""The F-term: analytic checks first (flat mirror, grating equation, blaze, symmetry), then the
fast engine against a brute-force sum of the integral, then stability on tall fields."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import ndimage
from scipy.special import jv

from gratnet.errors import GratNetError
from trainer.fourier import FTerm, OpticsConfig, chebyshev_node_count, prepare_surface, required_spacing_um
from trainer.heightfield import HeightField
from trainer.reference import brute_force_amplitude, brute_force_xyz, taylor_amplitude
from trainer.spectral import monochromatic

SMALL = OpticsConfig(sigma_s_um=2.0, window_extent_sigmas=6.0)


def stripes(profile_um: np.ndarray, dx_um: float, rows: int | None = None) -> HeightField:
    """A field constant along y with the given profile along x."""
    return HeightField(np.tile(profile_um, (rows or profile_um.size, 1)), dx_um, "test stripes")


def test_flat_mirror_peak_is_one_and_white(coarse_spectrum):
    field = HeightField(np.zeros((64, 64)), 0.1, "flat")
    engine = FTerm(prepare_surface(field, SMALL), coarse_spectrum)
    xyz = engine.xyz_grid(np.array([0.0]), np.array([0.0]), [0.0, -1.0, -2.0])
    # F = 1 at every λ at u = v = 0: XYZ is the normalised D65 white point, Y = 1 exactly.
    np.testing.assert_allclose(xyz[:, 0, 0, 1], 1.0, rtol=1e-6)
    np.testing.assert_allclose(xyz[:, 0, 0], np.tile(coarse_spectrum.xyz_weights.sum(0), (3, 1)), rtol=1e-6)


def test_flat_mirror_lobe_is_the_windows_gaussian():
    # |FT of a Gaussian window|²/(∫g)² = exp(−k² σs² (u² + v²)) for the continuous integral.
    wavelength_nm, sigma_um = 500.0, 2.0
    field = HeightField(np.zeros((8, 8)), 0.05, "flat")
    surface = prepare_surface(field, OpticsConfig(sigma_s_um=sigma_um, window_extent_sigmas=10.0))
    u = np.linspace(-0.06, 0.06, 13)
    power = FTerm(surface, monochromatic(wavelength_nm)).xyz_grid(u, np.array([0.01]), [-1.0])[0, 0, :, 1]
    wavenumber = 2 * np.pi / (wavelength_nm / 1000)
    expected = np.exp(-(wavenumber * sigma_um) ** 2 * (u**2 + 0.01**2))
    np.testing.assert_allclose(power, expected, rtol=1e-4, atol=1e-9)


@pytest.mark.parametrize("w", [-0.7, -2.0])
def test_sinusoidal_grating_orders_obey_grating_equation_and_bessel_powers(w):
    # h = A sin(2πx/Λ): order m leaves at u = −mλ/Λ with power J_m(k w A)² (Jacobi–Anger).
    period_um, amplitude_um, wavelength_nm, dx = 1.0 / 0.6, 0.12, 550.0, 0.05
    side = int(round(6 * 2.0 / dx))
    x = np.arange(side) * dx
    field = stripes(amplitude_um * np.sin(2 * np.pi * x / period_um), dx)
    surface = prepare_surface(field, SMALL)
    engine = FTerm(surface, monochromatic(wavelength_nm))
    wavelength_um = wavelength_nm / 1000
    u = np.linspace(-2, 2, 4001)
    power = engine.xyz_grid(u, np.array([0.0]), [w])[0, 0, :, 1]
    wavenumber = 2 * np.pi / wavelength_um
    for order in range(-3, 4):
        centre = -order * wavelength_um / period_um
        near = np.abs(u - centre) < 0.5 * wavelength_um / period_um
        peak_u = u[near][np.argmax(power[near])]
        assert abs(peak_u - centre) <= 2e-3, (order, peak_u, centre)
        expected = jv(order, wavenumber * w * amplitude_um) ** 2
        assert power[near].max() == pytest.approx(expected, rel=0.02, abs=2e-4), order


def test_blazed_grating_sends_energy_to_positive_u():
    # A sawtooth rising along +x: the facet normal tilts towards −x, the mirror direction has u > 0.
    dx, period = 0.04, 2.5
    x = np.arange(int(12 / dx)) * dx
    field = stripes(0.25 * (x % period) / period, dx)
    engine = FTerm(prepare_surface(field, SMALL), monochromatic(500.0))
    u = np.linspace(-2, 2, 801)
    power = engine.xyz_grid(u, np.array([0.0]), [-1.5])[0, 0, :, 1]
    assert power[u > 0.02].sum() > 5 * power[u < -0.02].sum()
    # And the blaze peak sits where the facet slope sends it: u ≈ −w · slope.
    slope = 0.25 / period
    assert abs(u[np.argmax(power)] - 1.5 * slope) < 0.5 / period


def test_point_symmetric_field_gives_point_symmetric_lobe(coarse_spectrum):
    rng = np.random.default_rng(3)
    side = int(np.ceil(SMALL.extent_um / 0.08))
    heights = ndimage.gaussian_filter(rng.standard_normal((side, side)), 4) * 0.3
    heights = heights + heights[::-1, ::-1]  # h(−x, −y) = h(x, y) about the window centre
    field = HeightField(heights, 0.08, "symmetric")
    engine = FTerm(prepare_surface(field, SMALL), coarse_spectrum)
    u = np.linspace(-1.5, 1.5, 31)
    xyz = engine.xyz_grid(u, u, [-1.2])[0]
    np.testing.assert_allclose(xyz, xyz[::-1, ::-1], rtol=1e-4, atol=1e-7 * xyz.max())
    # A mirror-symmetric profile h(−x) = h(x) (stripes) gives F(u) = F(−u) at v = 0 as well.
    x = (np.arange(side) - (side - 1) / 2) * 0.08
    stripe_engine = FTerm(prepare_surface(stripes(0.2 * np.cos(2 * np.pi * x / 1.3) ** 3, 0.08), SMALL),
                          coarse_spectrum)
    line = stripe_engine.xyz_grid(u, np.array([0.0]), [-0.8])[0, 0]
    np.testing.assert_allclose(line, line[::-1], rtol=1e-4, atol=1e-7 * line.max())


def _rough_field(span_um: float, dx: float, side: int, seed: int = 0, smooth: float = 6.0) -> HeightField:
    rng = np.random.default_rng(seed)
    heights = ndimage.gaussian_filter(rng.standard_normal((side, side)), smooth, mode="wrap")
    heights = (heights - heights.min()) / np.ptp(heights) * span_um
    return HeightField(heights, dx, f"rough {span_um} µm")


def test_engine_matches_brute_force_on_scattered_grids(coarse_spectrum):
    field = _rough_field(0.6, 0.05, 160)
    surface = prepare_surface(field, OpticsConfig(sigma_s_um=1.2, window_extent_sigmas=6.0))
    u = np.sort(np.random.default_rng(1).uniform(-2, 2, 17))  # non-uniform axes are fine too
    v = np.linspace(-2, 2, 15)
    u_grid, v_grid = np.meshgrid(u, v)
    varying_w = -0.9 * np.sqrt(np.clip(4 - u_grid**2 - v_grid**2, 0, None))
    engine = FTerm(surface, coarse_spectrum)
    xyz = engine.xyz_grid(u, v, [-0.4, varying_w])
    assert engine.last_node_count >= 2
    for index, w in enumerate([np.full_like(u_grid, -0.4), varying_w]):
        reference = brute_force_xyz(surface, u_grid, v_grid, w, coarse_spectrum).reshape(xyz[index].shape)
        error = np.linalg.norm(xyz[index] - reference) / np.linalg.norm(reference)
        assert error < 1e-5, (index, error)


def test_tall_field_is_stable_where_the_papers_taylor_series_fails():
    # 3 µm peak-to-valley at w = −2, λ = 380 nm: k·|w|·hmax ≈ 50 rad.
    field = _rough_field(3.0, 0.02, 300, seed=1, smooth=10.0)
    surface = prepare_surface(field, OpticsConfig(sigma_s_um=1.0, window_extent_sigmas=6.0))
    u = np.linspace(-2, 2, 11)
    u_grid, v_grid = np.meshgrid(u, u)
    w = np.full_like(u_grid, -2.0)
    reference = np.abs(brute_force_amplitude(surface, u_grid, v_grid, w, 0.38)) ** 2
    engine = FTerm(surface, monochromatic(380.0))
    direct = engine.xyz_grid(u, u, [-2.0])[0, ..., 1].ravel()
    assert np.linalg.norm(direct - reference) / np.linalg.norm(reference) < 1e-4
    varying = -2.0 * np.sqrt(np.clip(1 - (u_grid**2 + v_grid**2) / 8, 0, None))  # spans [−2, −1.41]
    interpolated = engine.xyz_grid(u, u, [varying])[0, ..., 1].ravel()
    reference_varying = np.abs(brute_force_amplitude(surface, u_grid, v_grid, varying, 0.38)) ** 2
    assert np.linalg.norm(interpolated - reference_varying) / np.linalg.norm(reference_varying) < 1e-4
    # The paper's series in float64 is useless here: this case really needs the stable method.
    taylor = np.abs(taylor_amplitude(surface, u_grid, v_grid, w, 0.38)) ** 2
    assert np.linalg.norm(taylor - reference) / np.linalg.norm(reference) > 1.0


def test_chebyshev_node_count_grows_with_phase_range():
    counts = [chebyshev_node_count(a, 1e-9) for a in (0.1, 1.0, 10.0, 50.0)]
    assert counts == sorted(counts) and counts[0] >= 2 and counts[-1] > 50


def test_coarse_field_is_resampled_with_a_message():
    field = _rough_field(0.2, 0.3, 40)
    messages: list[str] = []
    surface = prepare_surface(field, SMALL, messages.append)
    assert any("resampled" in message for message in messages)
    assert surface.dx_um <= required_spacing_um(field, 0.38) * (1 + 1e-9)
    assert surface.dx_um < 0.3


def test_small_patch_is_repeated_with_a_message_and_huge_grids_are_refused():
    messages: list[str] = []
    surface = prepare_surface(_rough_field(0.1, 0.05, 40), SMALL, messages.append)
    assert any("repeated" in message for message in messages)
    assert surface.heights_um.shape == (240, 240)
    with pytest.raises(GratNetError, match="integration grid"):
        prepare_surface(_rough_field(0.1, 0.05, 40), OpticsConfig(sigma_s_um=100.0))


def test_scattered_points_match_brute_force(coarse_spectrum):
    field = _rough_field(0.8, 0.05, 120, seed=4)
    surface = prepare_surface(field, OpticsConfig(sigma_s_um=1.0, window_extent_sigmas=6.0))
    rng = np.random.default_rng(7)
    u, v = rng.uniform(-1.4, 1.4, (2, 37))
    w = -rng.uniform(0, 1, 37) * np.sqrt(4 - u**2 - v**2)
    got = FTerm(surface, coarse_spectrum).xyz_points(u, v, w, chunk=16)
    reference = brute_force_xyz(surface, u, v, w, coarse_spectrum)
    assert got.shape == (37, 3)
    assert np.linalg.norm(got - reference) / np.linalg.norm(reference) < 1e-5


@pytest.mark.parametrize("mode", ["periodic", "mirror"])
def test_cover_window_keeps_the_patch_centred(mode):
    from trainer.heightfield import cover_window

    patch = np.random.default_rng(2).uniform(0, 1, (10, 14))
    covered = cover_window(HeightField(patch, 0.1, "patch"), 40, mode).heights_um
    assert covered.shape == (40, 40)
    np.testing.assert_array_equal(covered[15:25, 13:27], patch)  # original patch at the centre
    neighbour = covered[15:25, 27:41] if mode == "periodic" else covered[15:25, 27:40][:, ::-1]
    expected = patch if mode == "periodic" else patch[:, 1:]
    np.testing.assert_array_equal(neighbour, expected[:, : neighbour.shape[1]])
    cropped = cover_window(HeightField(covered, 0.1, "big"), 20, mode).heights_um
    np.testing.assert_array_equal(cropped, covered[10:30, 10:30])


@pytest.mark.parametrize("device", ["cpu", pytest.param("cuda", marks=pytest.mark.skipif(
    not __import__("torch").cuda.is_available(), reason="no CUDA device"))])
def test_torch_engine_equals_numpy_engine(coarse_spectrum, device):
    # The GPU path (--device cuda) is the numpy engine's loop with torch arrays: constant-w slices and
    # per-sample w (Chebyshev interpolation, as simple-max volumes and BRDF slices use) agree to float32
    # rounding, relative to the peak, on a tall rough field.
    rng = np.random.default_rng(3)
    field = HeightField(ndimage.gaussian_filter(rng.standard_normal((96, 96)), 3) * 0.6, 0.06, "rough")
    surface = prepare_surface(field, SMALL)
    u = np.linspace(-1.2, 1.1, 37)
    v = np.linspace(-0.9, 1.3, 29)
    w_varying = -1.0 - 0.8 * np.hypot(*np.meshgrid(u, v)) / 2
    slices = [-1.3, w_varying, -2.0]
    numpy_engine = FTerm(surface, coarse_spectrum)
    expected = numpy_engine.xyz_grid(u, v, slices)
    torch_engine = FTerm(surface, coarse_spectrum, device=device)
    got = torch_engine.xyz_grid(u, v, slices)
    assert numpy_engine.last_node_count > 2 and torch_engine.last_node_count == numpy_engine.last_node_count
    assert got.dtype == np.float64 and got.shape == expected.shape
    np.testing.assert_allclose(got, expected, rtol=0, atol=2e-6 * expected.max())
    # And a wavelength block alone (sweep parts) on the torch path.
    part = torch_engine.xyz_grid(u, v, slices, wavelengths=range(0, 3))
    np.testing.assert_allclose(part, numpy_engine.xyz_grid(u, v, slices, wavelengths=range(0, 3)),
                               rtol=0, atol=2e-6 * expected.max())
