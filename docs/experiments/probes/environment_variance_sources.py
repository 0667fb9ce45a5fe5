"""Probe (issue 43): where the variance of the environment estimator comes from, sample by sample, in numpy.

For paper-cd's network on a flat patch (tangent frame = world frame) under the shipped sky, at several views and
map turns (a turn of the map is a turn of the CD's tracks, i.e. another place on the disc), draws the GL runtime's
two strategies (docs/physics.md "Environment light": light sampling from the map's luminance, material sampling
from the model's importance table with its cosine share) and scores each sample of the one-sample MIS estimator
(pass k uses strategy k mod 2, weight 2 · w_s · f / p_s, power heuristic) by its share of the second moment E[X²],
grouped by strategy and by where the light comes from: the sun (within 2° of the map's brightest direction), near
the horizon (θi > 75°), elsewhere. f = S · A · Y(−(ωi + ωo)) · L_Y(ωi) (luminance; S with the model's slope
covariance).

    python docs/experiments/probes/environment_variance_sources.py        # ~2 min on two CPU cores
"""

from __future__ import annotations

import math

import numpy as np

from gratnet.brdf import a_term, direction
from gratnet.environment import LUMINANCE_WEIGHTS, Environment, load_environment
from gratnet.importance import cached_material_table
from gratnet.modelfile import ModelFile, evaluate_keys, load_model
from gratnet.shadowing import slope_covariance_from_metadata, smith_shadowing
from viewer.catalog import resolve_material

SAMPLES = 100_000


def integrand(model: ModelFile, covariance: tuple[float, float, float], environment: Environment, wi: np.ndarray,
              wo: np.ndarray) -> np.ndarray:
    """S · A · Y · L_Y at light directions ``wi`` (N, 3) for one view ``wo``; 0 below the horizon."""
    view = np.broadcast_to(wo, wi.shape)
    factor = a_term(wi, view, 1.5) * smith_shadowing(wi, view, covariance)
    value = np.zeros(len(wi))
    lit = factor > 0.0
    key = -(wi[lit] + view[lit])
    y = evaluate_keys(model, key[:, 0], key[:, 1], key[:, 2])[:, 1]
    luminance = environment.radiance(wi[lit]) @ np.asarray(LUMINANCE_WEIGHTS)
    value[lit] = factor[lit] * y * luminance
    return value


def main() -> None:
    model = load_model(resolve_material("paper-cd"))
    covariance = slope_covariance_from_metadata(model.metadata["volume"])
    table = cached_material_table(model)
    rng = np.random.default_rng(0)
    totals: dict[str, float] = {}
    print("view θo, φo   map turn   mean   sqrt(E[X²])/mean   share of E[X²]: light sun / horizon / other, "
          "material sun / horizon / other")
    for theta_o, phi_o in ((20.0, 0.0), (45.0, 200.0), (60.0, 90.0)):
        wo = direction(theta_o, phi_o)
        for turn in (0.0, 60.0, 150.0, 250.0):
            environment = load_environment("sky", rotation_degrees=turn)
            luminance_map = environment.radiance_map.astype(np.float64) @ np.asarray(LUMINANCE_WEIGHTS)
            row, column = np.unravel_index(np.argmax(luminance_map), luminance_map.shape)
            height, width = luminance_map.shape
            sun = environment.directions(np.asarray([(column + 0.5) / width]), np.asarray([row / (height - 1)]))[0]
            light_dirs, light_pdf = environment.sample(rng.random(SAMPLES), rng.random(SAMPLES))
            material_dirs, material_pdf, valid = table.sample(wo, rng.random(SAMPLES), rng.random(SAMPLES),
                                                              rng.random(SAMPLES))
            groups = {}
            for name, dirs, own in (("light", light_dirs, light_pdf), ("material", material_dirs, material_pdf)):
                f = integrand(model, covariance, environment, dirs, wo)
                p_light = environment.pdf(dirs)
                p_material = table.pdf(wo, dirs)
                with np.errstate(divide="ignore", invalid="ignore"):
                    weight = np.where(own > 0.0, own**2 / (p_light**2 + p_material**2), 0.0)
                    x = np.where(own > 0.0, 2.0 * weight * f / own, 0.0)
                near_sun = dirs @ sun > math.cos(math.radians(2.0))
                horizon = dirs[:, 2] < math.cos(math.radians(75.0))
                groups[name] = (x, near_sun, horizon & ~near_sun, ~near_sun & ~horizon)
            # One-sample MIS: half the passes per strategy; mean = (E_L[x] + E_M[x]) / 2.
            mean = 0.5 * (groups["light"][0].mean() + groups["material"][0].mean())
            second = 0.5 * (np.mean(groups["light"][0] ** 2) + np.mean(groups["material"][0] ** 2))
            shares = []
            for name in ("light", "material"):
                x, *masks = groups[name]
                for mask in masks:
                    share = 0.5 * np.sum(x[mask] ** 2) / len(x) / second
                    shares.append(share)
                    key = f"{name} {('sun', 'horizon', 'other')[len(shares) - 1 - (3 if name == 'material' else 0)]}"
                    totals[key] = totals.get(key, 0.0) + share
            print(f"{theta_o:5.0f}, {phi_o:4.0f}   {turn:6.0f}   {mean:9.3e}   {math.sqrt(second) / mean:8.2f}   "
                  + "  ".join(f"{s:5.3f}" for s in shares), flush=True)
    count = 12
    print("mean shares over the 12 cases: " + ", ".join(f"{k} {v / count:.3f}" for k, v in totals.items()))


if __name__ == "__main__":
    main()
