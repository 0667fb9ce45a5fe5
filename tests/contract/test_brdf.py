"""A-term and BRDF-slice geometry: analytic values, limits, and a flat mirror's specular pixel."""

from __future__ import annotations

import numpy as np
import pytest

from gratnet.brdf import A_MAX, a_term, direction, fresnel_dielectric, fresnel_ratio, slice_view_directions
from trainer.brdfslice import SliceConfig, brdf_slice_xyz
from trainer.fourier import OpticsConfig, prepare_surface
from trainer.heightfield import HeightField


def test_a_term_is_one_at_normal_incidence_and_view():
    # G = (1+1)²/(1·1) = 4, w = −2, R = R0: A = 4/4 = 1, with or without Fresnel.
    normal = direction(0, 0)
    assert a_term(normal, normal, ior=1.5) == pytest.approx(1.0)
    assert a_term(normal, normal, ior=None) == pytest.approx(1.0)


def test_a_term_matches_its_formula_and_vanishes_where_it_must():
    light, view = direction(40, 10), direction(25, 200)
    cosine = light @ view
    w = -(light[2] + view[2])
    geometry = (1 + cosine) ** 2 / (light[2] * view[2])
    assert a_term(light, view, ior=None) == pytest.approx(geometry / w**2)
    ratio = fresnel_dielectric(np.sqrt((1 + cosine) / 2), 1.5) / fresnel_dielectric(1.0, 1.5)
    assert a_term(light, view, ior=1.5) == pytest.approx(ratio**2 * geometry / w**2)
    grazing = direction(90, 0)
    assert a_term(grazing, direction(90, 180), ior=1.5) == 0.0  # |w| < 1e-6
    below = np.array([0.0, 0.6, -0.8])
    assert a_term(light, below, ior=1.5) == 0.0


def test_fresnel_limits():
    assert fresnel_dielectric(1.0, 1.5) == pytest.approx(0.04)
    assert fresnel_dielectric(0.0, 1.5) == pytest.approx(1.0)
    brewster = np.arctan(1.5)
    # At Brewster's angle only the perpendicular part reflects: R = Rs/2.
    cos_b = np.cos(brewster)
    cos_t = np.sqrt(1 - (np.sin(brewster) / 1.5) ** 2)
    perpendicular = ((cos_b - 1.5 * cos_t) / (cos_b + 1.5 * cos_t)) ** 2
    assert fresnel_dielectric(cos_b, 1.5) == pytest.approx(perpendicular / 2)


@pytest.mark.parametrize("ior", [1.5, 1.33, 2.4, 0.7, 0.51, 1e3])
def test_fresnel_ratio_equals_the_direct_ratio_away_from_one(ior):
    # Away from n = 1 the direct R/R0 loses nothing in float64: the cancelled form must agree with it.
    cosines = np.concatenate([np.linspace(0.0, 1.0, 41), [1e-3, 1e-6]])
    direct = fresnel_dielectric(cosines, ior) / fresnel_dielectric(1.0, ior)
    np.testing.assert_allclose(fresnel_ratio(cosines[cosines > 0], ior), direct[cosines > 0], rtol=1e-12)


def test_fresnel_ratio_is_continuous_through_one_and_has_the_stated_limit():
    # physics.md: at n = 1, R/R0 = (1 + cos²2θ)/(2cos⁴θ); either side of 1 tends to it.
    cosines = np.array([1.0, 0.9, 0.5, 0.2, 0.05])
    theta = np.arccos(cosines)
    limit = (1 + np.cos(2 * theta) ** 2) / (2 * cosines**4)
    np.testing.assert_allclose(fresnel_ratio(cosines, 1.0), limit, rtol=1e-12)
    for offset in (1e-4, 1e-6, 1e-8):
        for ior in (1 + offset, 1 - offset):
            relative = np.abs(fresnel_ratio(cosines, ior) / limit - 1.0)
            assert np.all(relative <= 50 * offset / cosines**2), (ior, relative)
    # Total internal reflection (n < 1 past the critical angle): R = 1, so R/R0 = 1/R0.
    assert fresnel_ratio(0.1, 0.7) == pytest.approx(1.0 / fresnel_dielectric(1.0, 0.7), rel=1e-12)


def test_a_term_is_capped_where_ior_one_diverges_at_grazing():
    # Forward mirror pair at cos θ = 1e-6: G/w² = 1 and R/R0 at n = 1 is ~1/cos⁴θ, so (R/R0)² ~ 1e48.
    cos_theta = 1e-6
    sin_theta = np.sqrt(1 - cos_theta**2)
    light, view = np.array([sin_theta, 0.0, cos_theta]), np.array([-sin_theta, 0.0, cos_theta])
    assert float(a_term(light, view, ior=1.0)) == A_MAX
    assert float(a_term(light, view, ior=1.5)) == pytest.approx(1 / fresnel_dielectric(1.0, 1.5) ** 2, rel=1e-4)


def test_slice_view_directions_orientation():
    views, inside = slice_view_directions(5)
    np.testing.assert_allclose(views[2, 2], [0, 0, 1])
    assert views[0, 2, 1] > 0 and views[4, 2, 1] < 0  # +y is up
    assert views[2, 0, 0] < 0 and views[2, 4, 0] > 0  # +x is right
    assert not inside[0, 0] and inside[2, 2]
    np.testing.assert_allclose(np.linalg.norm(views[inside], axis=-1), 1.0)


@pytest.mark.parametrize("theta, phi", [(30.0, 0.0), (45.0, 135.0)])
def test_flat_mirror_slice_peaks_at_the_mirror_direction(theta, phi):
    field = HeightField(np.zeros((8, 8)), 0.1, "flat")
    optics = OpticsConfig(sigma_s_um=3.0, wavelength_step_nm=100.0)
    size = 64
    xyz = brdf_slice_xyz(prepare_surface(field, optics),
                         SliceConfig(theta, phi, size=size, exposure=1.0), optics, progress=False)
    row, column = np.unravel_index(np.argmax(xyz[..., 1]), xyz.shape[:2])
    views, _ = slice_view_directions(size)
    mirror = direction(theta, phi) * np.array([-1, -1, 1])
    assert np.hypot(*(views[row, column, :2] - mirror[:2])) <= 2.0 / size
