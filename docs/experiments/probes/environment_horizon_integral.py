"""Probe (issue 43): does eq. 9's integral converge at the horizon? For paper-cd's network at one view, the
integral of A · Y(−(ωi + ωo)) · L(ωi) over ωi with θi < θ_max, for θ_max → 90°, under the shipped sky and under a
constant environment. A grows as 1/cos θi (eq. 5's G), so if the integrand's other factors stay positive at the
horizon the integral grows like log(1/cos θ_max) without bound. With Smith's shadowing (gratnet.shadowing, the model's
slope covariance; physics.md "Shadowing and masking") it converges: both columns are printed.

    python docs/experiments/probes/environment_horizon_integral.py     # ~1 min on two CPU cores

Quadrature: θ in bands [θ_k, θ_k+1] with cos θ_k = 10^(−k/8) (equal steps of log(1/cos θ)), 16 Gauss–Legendre
points in cos θ per band, 720 azimuths; the model by gratnet.modelfile.evaluate_keys (float64).
"""

from __future__ import annotations

import math

import numpy as np

from gratnet.brdf import a_term
from gratnet.environment import load_environment
from gratnet.modelfile import evaluate_keys, load_model
from gratnet.shadowing import slope_covariance_from_metadata, smith_shadowing
from viewer.camera import world_direction
from viewer.catalog import resolve_material


def main() -> None:
    model = load_model(resolve_material("paper-cd"))
    wo = world_direction(30.0, 200.0)  # a view 30° from the normal
    sky = load_environment("sky")
    covariance = slope_covariance_from_metadata(model.metadata.get("volume") or {})
    nodes, weights = np.polynomial.legendre.leggauss(16)
    azimuths = (np.arange(720) + 0.5) / 720 * 2 * math.pi
    edges = [1.0] + [10 ** (-k / 8) for k in range(1, 41)]  # cos θ from 1 down to 1e-5
    totals = {"sky": 0.0, "constant 1": 0.0, "sky, S": 0.0, "constant 1, S": 0.0}
    print(f"paper-cd, slope covariance {covariance}")
    print("cos θ_max   θ_max (°)   ∫ under sky   ∫ under constant 1   with S: sky   constant 1   "
          "(A · Y · L, θi < θ_max)")
    for upper, lower in zip(edges[:-1], edges[1:], strict=True):
        mu = 0.5 * (upper + lower) + 0.5 * (upper - lower) * nodes  # cos θ in the band
        weight_mu = 0.5 * (upper - lower) * weights
        m, p = np.meshgrid(mu, azimuths, indexing="ij")
        s = np.sqrt(1 - m**2)
        wi = np.stack([s * np.cos(p), s * np.sin(p), m], axis=-1).reshape(-1, 3)
        key = -(wi + wo)
        y = evaluate_keys(model, key[:, 0], key[:, 1], key[:, 2])[:, 1]
        a = a_term(wi, np.broadcast_to(wo, wi.shape), 1.5)
        cell = (weight_mu[:, None] * np.full(p.shape, 2 * math.pi / len(azimuths))).ravel()
        luminance = sky.radiance(wi) @ np.array([0.2126, 0.7152, 0.0722])
        totals["sky"] += float(np.sum(a * y * luminance * cell))
        totals["constant 1"] += float(np.sum(a * y * cell))
        shadowing = smith_shadowing(wi, np.broadcast_to(wo, wi.shape), covariance)
        totals["sky, S"] += float(np.sum(shadowing * a * y * luminance * cell))
        totals["constant 1, S"] += float(np.sum(shadowing * a * y * cell))
        print(f"{lower:9.1e}   {math.degrees(math.acos(lower)):9.5f}   {totals['sky']:11.5e}   "
              f"{totals['constant 1']:11.5e}          {totals['sky, S']:11.5e}   {totals['constant 1, S']:11.5e}",
              flush=True)


if __name__ == "__main__":
    main()
