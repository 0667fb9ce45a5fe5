"""Smith's shadowing–masking (gratnet.shadowing): analytic checks first.

- Λ against its closed form with the exact erf (the runtime's A&S 7.1.26 is within 1e-7);
- Λ is Smith's for the Gaussian slope distribution of covariance Σ: (1 + Λ(ω)) cos θ is the projected area of the
  relief, E[max(0, ω · (−∂h/∂x, −∂h/∂y, 1))] (Heitz 2014, eq. 25 in slope space), checked by quadrature;
- limits: S = 1 at normal light and view and for no slopes, 0 at the horizon, anisotropy follows Σ;
- what it is for: eq. 9's integral of A over the hemisphere diverges without S and converges with it.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from gratnet.brdf import a_term, direction
from gratnet.errors import GratNetError
from gratnet.shadowing import (
    NO_SHADOWING,
    check_slope_covariance,
    model_slope_covariance,
    slope_covariance_from_metadata,
    smith_lambda,
    smith_shadowing,
)


def exact_lambda(a: float) -> float:
    return (math.erf(a) - 1.0) / 2.0 + math.exp(-a * a) / (2.0 * a * math.sqrt(math.pi))


@pytest.mark.parametrize("sigma", [0.02, 0.17, 0.9, 3.0])
def test_lambda_matches_the_closed_form_with_the_exact_erf(sigma):
    thetas = np.radians(np.linspace(0.5, 89.99, 400))
    for phi in (0.0, 0.7, 2.0):
        directions = np.stack([np.sin(thetas) * np.cos(phi), np.sin(thetas) * np.sin(phi), np.cos(thetas)], -1)
        actual = smith_lambda(directions, (sigma**2, 0.0, sigma**2))
        a = np.cos(thetas) / (math.sqrt(2.0) * sigma * np.sin(thetas))
        expected = np.array([exact_lambda(float(x)) for x in a])
        np.testing.assert_allclose(actual, expected, rtol=0, atol=1e-7)


@pytest.mark.parametrize("covariance", [(0.03, 0.0, 0.01), (0.5, 0.2, 0.3), (0.8, -0.5, 0.9)])
@pytest.mark.parametrize("theta, phi", [(20.0, 10.0), (60.0, 135.0), (80.0, 250.0), (88.0, 300.0)])
def test_lambda_is_smiths_for_the_gaussian_slopes_of_the_covariance(covariance, theta, phi):
    """(1 + Λ) cos θ = E[max(0, cos θ − ω_xy · ∇h)] over ∇h ~ N(0, Σ): the relief's projected area towards ω."""
    omega = direction(theta, phi)
    xx, xy, yy = covariance
    # ω_xy · ∇h ~ N(0, q), q = ω_xyᵀ Σ ω_xy: E[max(0, c − s)] = c Φ(c/√q) + √q φ(c/√q), with the exact erf.
    c, root = float(omega[2]), math.sqrt(omega[0] ** 2 * xx + 2.0 * omega[0] * omega[1] * xy + omega[1] ** 2 * yy)
    ratio = c / root
    projected = c * 0.5 * (1.0 + math.erf(ratio / math.sqrt(2.0))) + root * math.exp(-0.5 * ratio**2) / math.sqrt(
        2.0 * math.pi)
    expected = projected / c - 1.0
    # ... and by sampling the slopes themselves (3 standard errors of a million draws).
    slopes = np.random.default_rng(0).multivariate_normal([0.0, 0.0], [[xx, xy], [xy, yy]], size=1_000_000)
    drawn = np.maximum(0.0, c - slopes @ omega[:2]) / c - 1.0
    assert abs(float(drawn.mean()) - expected) < 3.0 * float(drawn.std()) / 1000.0 + 1e-12
    assert float(smith_lambda(omega, covariance)) == pytest.approx(expected, rel=1e-5, abs=2e-7)


def test_limits_normal_incidence_no_slopes_horizon_and_anisotropy():
    normal = np.array([0.0, 0.0, 1.0])
    grazing = direction(85.0, 0.0)
    assert smith_shadowing(normal, normal, (0.5, 0.1, 0.4)) == 1.0
    assert smith_shadowing(grazing, direction(70.0, 90.0), NO_SHADOWING) == 1.0
    assert smith_shadowing(direction(90.0, 0.0), normal, (0.1, 0.0, 0.1)) == 0.0
    assert smith_shadowing(normal, direction(95.0, 30.0), (0.1, 0.0, 0.1)) == 0.0
    # A grating with slopes along x only: light along its lines (y) is never shadowed, across them it is.
    grating = (0.15, 0.0, 0.0)
    assert smith_lambda(direction(85.0, 90.0), grating) == 0.0
    assert smith_lambda(direction(85.0, 0.0), grating) > 0.5
    # Λ grows monotonically towards the horizon and as 1/a there (S · A stays bounded).
    thetas = np.radians(np.linspace(1.0, 89.999, 500))
    values = smith_lambda(np.stack([np.sin(thetas), 0 * thetas, np.cos(thetas)], -1), (0.04, 0.0, 0.04))
    assert np.all(np.diff(values) >= 0.0)
    a = np.cos(thetas[-1]) / (math.sqrt(2.0 * 0.04) * np.sin(thetas[-1]))
    assert values[-1] * a == pytest.approx(1.0 / (2.0 * math.sqrt(math.pi)), rel=1e-3)


def test_eq9_converges_at_the_horizon_with_shadowing_and_not_without():
    """∫ A dω over θi < θ_max for one view: each decade of cos θ_max adds a constant without S (a log
    divergence, physics.md), and nearly nothing with it."""
    view = direction(30.0, 0.0)
    covariance = (0.0069, 0.0, 0.030)  # paper-cd's order of magnitude (σ = 0.08, 0.17)

    def integral(cos_low: float, cos_high: float, shadowed: bool) -> float:
        # Gauss–Legendre in log(cos θ) and in φ: the integrand varies like 1/cos θ.
        nodes, weights = np.polynomial.legendre.leggauss(64)
        low, high = math.log(cos_low), math.log(cos_high)
        logs = 0.5 * (high - low) * nodes + 0.5 * (high + low)
        cosines = np.exp(logs)
        phis = math.pi * (nodes + 1.0)
        c, p = np.meshgrid(cosines, phis, indexing="ij")
        s = np.sqrt(1.0 - c * c)
        light = np.stack([s * np.cos(p), s * np.sin(p), c], -1)
        value = a_term(light, np.broadcast_to(view, light.shape), 1.5)
        if shadowed:
            value = value * smith_shadowing(light, np.broadcast_to(view, light.shape), covariance)
        # dω = sin θ dθ dφ = d(cos θ) dφ = cos θ d(log cos θ) dφ
        jacobian = c * 0.5 * (high - low) * math.pi
        return float(np.sum(np.outer(weights, weights) * value * jacobian))

    decades = [integral(10.0 ** -(k + 1), 10.0**-k, shadowed) for shadowed in (False, True) for k in (1, 3, 5)]
    unshadowed, shadowed = decades[:3], decades[3:]
    assert unshadowed[2] == pytest.approx(unshadowed[1], rel=0.01)  # the same amount per decade: diverges
    assert shadowed[1] < 0.01 * unshadowed[1] and shadowed[2] < 1e-4 * unshadowed[2]  # falls ~10× per decade


@pytest.mark.parametrize("bad", [(1.0, 0.0), (1.0, 0.0, float("nan")), (-0.1, 0.0, 0.1), (0.1, 0.2, 0.1), "abc",
                                 None])
def test_a_bad_covariance_is_one_clear_error(bad):
    with pytest.raises(GratNetError, match="covariance|three"):
        check_slope_covariance(bad)


def test_metadata_without_a_covariance_means_unshadowed():
    assert slope_covariance_from_metadata({}) == NO_SHADOWING
    assert slope_covariance_from_metadata({"slope_covariance": [0.1, 0.0, 0.2]}) == (0.1, 0.0, 0.2)
    with pytest.raises(GratNetError, match="slope_covariance"):
        slope_covariance_from_metadata({"slope_covariance": [0.1, 0.0, -0.2]})
    # A model's: under metadata["volume"]; a model without one, or with another kind of entry there, is unshadowed.
    from types import SimpleNamespace

    assert model_slope_covariance(SimpleNamespace(metadata={"volume": {"slope_covariance": [0.1, 0.0, 0.2]}})) == (
        0.1, 0.0, 0.2)
    for metadata in ({}, {"volume": None}, {"volume": "text"}):
        assert model_slope_covariance(SimpleNamespace(metadata=metadata)) == NO_SHADOWING
