"""How much truncating the Gaussian window changes F (decides the default window extent).

    python benchmarks/window_truncation.py [--material cd] [--plot docs/images/window_truncation.png]

For extents of 4, 6, 8 σs, compares one w-slice of Y (R = 201, λ every 40 nm) with a 10 σs
reference: relative L2 and the median / 95th percentile of |Δlog10 Y| where the reference Y > 1e-12.
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np

from trainer.fourier import FTerm, OpticsConfig, prepare_surface
from trainer.loaders import load_heightfield
from trainer.spectral import spectral_weights


def main() -> None:
    """Print one JSON line per extent and optionally plot the slices' log-ratio."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--material", default="cd")
    parser.add_argument("--plot", help="PNG of log10 Y(extent)/Y(reference) along v = 0")
    arguments = parser.parse_args()
    field = load_heightfield(arguments.material)
    spectrum = spectral_weights(380.0, 780.0, 40.0)
    u = np.linspace(-2, 2, 201)
    slices: dict[float, tuple[np.ndarray, float, int]] = {}  # luminance, seconds, grid side
    for extent in (4.0, 6.0, 8.0, 10.0):
        surface = prepare_surface(field, OpticsConfig(window_extent_sigmas=extent))
        started = time.perf_counter()
        luminance = FTerm(surface, spectrum).xyz_grid(u, u, [-1.0])[0, ..., 1]
        seconds = time.perf_counter() - started
        slices[extent] = (luminance, seconds, surface.heights_um.shape[0])
    reference = slices.pop(10.0)[0]
    mask = reference > 1e-12
    for extent, (luminance, seconds, side) in slices.items():
        log_error = np.abs(np.log10(np.maximum(luminance[mask], 1e-30)) - np.log10(reference[mask]))
        print(json.dumps({
            "material": arguments.material, "extent_sigmas": extent, "grid": side, "seconds": round(seconds, 2),
            "relative_l2": float(np.linalg.norm(luminance - reference) / np.linalg.norm(reference)),
            "median_abs_dlog10": round(float(np.median(log_error)), 5),
            "p95_abs_dlog10": round(float(np.percentile(log_error, 95)), 5),
        }))
    if arguments.plot:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        from gratnet.figures import save_figure

        figure, axes = plt.subplots(figsize=(7, 3.5), dpi=130)
        centre = len(u) // 2
        for extent, (luminance, _, _) in slices.items():
            axes.plot(u, np.log10(np.maximum(luminance[centre], 1e-30) / reference[centre]),
                      label=f"±{extent / 2:g} σs")
        axes.set_xlabel("u (v = 0, w = −1)")
        axes.set_ylabel("log10 Y / Y(±5 σs)")
        axes.set_title(f"Window truncation error, {arguments.material}")
        axes.legend()
        figure.tight_layout()
        save_figure(figure, arguments.plot)


if __name__ == "__main__":
    main()
