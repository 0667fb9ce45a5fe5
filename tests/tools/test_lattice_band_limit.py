"""analysis.lattice_band_limit: F is band-limited by the integration width, and the lattice spacings."""

from __future__ import annotations

import numpy as np
import pytest

from analysis.lattice_band_limit import f_patch, lattice_spacing, power_spectrum, share_beyond
from trainer.fourier import OpticsConfig, prepare_surface
from trainer.heightfield import HeightField


def test_lattice_spacing_follows_the_scheme():
    assert lattice_spacing(1001, "regular", 0.3) == pytest.approx(0.004)
    # simple: u = 2·sign(u*)·(u*/2)², so du/du* = |u*|; u = 0.5 ↔ u* = 1, u = 1.125 ↔ u* = 1.5
    assert lattice_spacing(1001, "simple-max", 0.5) == pytest.approx(0.004, rel=5e-3)
    assert lattice_spacing(1001, "simple-max", 1.125) == pytest.approx(1.5 * 0.004, rel=5e-3)
    assert lattice_spacing(2001, "simple-max", 1.125) == pytest.approx(1.5 * 0.002, rel=5e-3)
    assert lattice_spacing(1001, "simple", 0.0) == pytest.approx(2 * (0.004 / 2) ** 2)  # the first node off 0


def test_a_cosine_has_all_its_power_at_its_frequency():
    points, spacing, frequency = 256, 1 / 256, 40.0  # a patch of side 1, patch Nyquist 128 cycles per unit
    u = np.arange(points) * spacing
    power, f_u, f_v = power_spectrum(np.cos(2 * np.pi * frequency * u)[None, :].repeat(points, axis=0), spacing)
    assert share_beyond(power, f_u, f_v, 30.0, 1.0) == pytest.approx(1.0, abs=1e-6)
    assert share_beyond(power, f_u, f_v, 45.0, 1.0) < 1e-4  # Hann: little leakage five bins away


def test_f_has_no_power_beyond_the_integration_width_and_plenty_below_it():
    """F's spectrum over u is the autocorrelation of the windowed field (physics.md, "How finely to sample u and
    v"): nothing at offsets beyond the integration width, whatever the surface. A rough random field (σs = 2 µm,
    a 12 µm patch) still has much of its speckle power at offsets above σs."""
    rng = np.random.default_rng(3)
    heights = 0.3 * rng.standard_normal((160, 160))
    field = HeightField(np.ascontiguousarray(heights, dtype=np.float64), 0.08, "test:random")
    optics = OpticsConfig(sigma_s_um=2.0)
    surface = prepare_surface(field, optics)
    wavelength_nm = 500.0
    values, spacing = f_patch(surface, wavelength_nm, (0.3, -0.2), -1.0, span=1.0, points=128)
    power, f_u, f_v = power_spectrum(values, spacing)
    cycles_per_um = 1.0 / (wavelength_nm / 1e3)  # a surface offset of 1 µm is this many cycles per unit of u
    assert share_beyond(power, f_u, f_v, *(2 * [1.05 * optics.extent_um * cycles_per_um])) < 1e-6
    assert share_beyond(power, f_u, f_v, *(2 * [optics.sigma_s_um * cycles_per_um])) > 0.05
