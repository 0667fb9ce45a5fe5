"""A-term and BRDF-slice geometry: analytic values, limits, and a flat mirror's specular pixel."""

from __future__ import annotations

import numpy as np
import pytest

from gratnet.brdf import a_term, direction, fresnel_dielectric, slice_view_directions
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
