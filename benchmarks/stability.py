"""Stability study: our F-term against the paper's Taylor series, as the height field grows taller.

    python benchmarks/stability.py [--plot docs/images/stability.png]

A Gaussian-correlated rough field is scaled to peak-to-valley spans of 0.1…4 µm; at w = −2 and
λ = 380 nm, both methods are compared with a brute-force float64 sum of eq. 1 on an 11×11 (u, v) grid.
"""

from __future__ import annotations

import argparse
import json

import numpy as np
from scipy import ndimage

from trainer.fourier import FTerm, OpticsConfig, prepare_surface
from trainer.heightfield import HeightField
from trainer.reference import brute_force_amplitude, taylor_amplitude
from trainer.spectral import monochromatic


def main() -> None:
    """Print one JSON line per height span; plot relative L2 errors against span."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--plot", help="PNG of relative error against peak-to-valley height")
    arguments = parser.parse_args()
    rng = np.random.default_rng(1)
    base = ndimage.gaussian_filter(rng.standard_normal((300, 300)), 10, mode="wrap")
    base = (base - base.min()) / np.ptp(base)
    u = np.linspace(-2, 2, 11)
    u_grid, v_grid = np.meshgrid(u, u)
    spans = [0.1, 0.25, 0.5, 1.0, 1.5, 2.0, 3.0, 4.0]
    ours, paper = [], []
    for span in spans:
        surface = prepare_surface(HeightField(base * span, 0.02, f"rough {span} µm"),
                                  OpticsConfig(sigma_s_um=1.0, window_extent_sigmas=6.0))
        w = np.full_like(u_grid, -2.0)
        reference = np.abs(brute_force_amplitude(surface, u_grid, v_grid, w, 0.38)) ** 2
        direct = FTerm(surface, monochromatic(380.0)).xyz_grid(u, u, [-2.0])[0, ..., 1].ravel()
        taylor = np.abs(taylor_amplitude(surface, u_grid, v_grid, w, 0.38)) ** 2
        ours.append(float(np.linalg.norm(direct - reference) / np.linalg.norm(reference)))
        paper.append(float(np.linalg.norm(taylor - reference) / np.linalg.norm(reference)))
        print(json.dumps({"span_um": span, "k_w_hmax_rad": round(2 * np.pi / 0.38 * 2 * span / 2, 1),
                          "ours_relative_l2": ours[-1], "taylor_relative_l2": paper[-1]}))
    if arguments.plot:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        from gratnet.figures import save_figure

        figure, axes = plt.subplots(figsize=(6, 3.6), dpi=130)
        axes.semilogy(spans, paper, "o-", label="paper's Taylor series (float64)")
        axes.semilogy(spans, ours, "s-", label="GratNet (zoom DFT, float32)")
        axes.axhline(0.01, color="grey", lw=0.8, ls="--")
        axes.set_xlabel("peak-to-valley height (µm)")
        axes.set_ylabel("relative L2 error of F vs brute force")
        axes.set_title("w = −2, λ = 380 nm")
        axes.legend()
        figure.tight_layout()
        save_figure(figure, arguments.plot)


if __name__ == "__main__":
    main()
