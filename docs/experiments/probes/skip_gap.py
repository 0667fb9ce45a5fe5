"""Where the output bound leaves work on the table: dark pixels that the bound does not skip.

For each model and standard BRDF slice (256², numpy, no GL): the network's displayed peak (exposure · A ·
max_r M_r·XYZ, linear sRGB) and the bound's (gratnet.bounds, cached default parameters) at every in-disc
pixel, against the display's smallest step (DISPLAY_SKIP_THRESHOLD). Prints one JSON line per slice: the
fraction the bound skips, the fraction the network leaves dark, and for the dark pixels that are not
skipped the 10/50/90 % quantiles of network/step and bound/step. A bound/step just above 1 there means a
tighter bound would skip them; a network/step near 1 means the network's own faint floor is in the way.

    OMP_NUM_THREADS=1 python docs/experiments/probes/skip_gap.py assets/blazed/model.npz assets/sinusoidal/model.npz
"""

from __future__ import annotations

import argparse
import json

import numpy as np

from gratnet.bounds import DISPLAY_SKIP_THRESHOLD, BoundParameters, display_skip_matrix, output_bounds
from gratnet.encoding import network_coordinates
from gratnet.modelfile import evaluate_keys, load_model


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("models", nargs="+", help="model files (.npz)")
    parser.add_argument("--size", type=int, default=256, help="slice size, pixels per side")
    arguments = parser.parse_args(argv)

    from trainer.brdfslice import SliceConfig, expose_slice, slice_geometry
    from trainer.evaluate import STANDARD_SLICES

    matrix = display_skip_matrix()
    for path in arguments.models:
        model = load_model(path)
        bounds = output_bounds(model, BoundParameters())
        for theta, phi, exposure in STANDARD_SLICES:
            config = SliceConfig(theta, phi, arguments.size, exposure, ior=1.5)
            light, views, inside = slice_geometry(config)
            keys = -(light + views[inside])
            u, v, w = (keys[:, k].astype(np.float32) for k in range(3))
            xyz = evaluate_keys(model, u, v, w).astype(np.float64)
            ones = np.zeros((*views.shape[:-1], 3))
            ones[inside] = 1.0
            scale = expose_slice(config, light, views, inside, ones)[inside][:, 0]  # exposure · A
            network = scale * (xyz @ matrix.T).max(axis=-1) / DISPLAY_SKIP_THRESHOLD
            coordinates = network_coordinates(keys[:, 0], keys[:, 1], keys[:, 2], model.scheme)
            bound = scale * (bounds.lookup(coordinates) @ matrix.T).max(axis=-1) / DISPLAY_SKIP_THRESHOLD
            gap = (network < 1.0) & (bound >= 1.0)
            quantiles = [0.1, 0.5, 0.9]
            print(json.dumps({
                "model": path, "slice": [theta, phi, exposure], "pixels": int(inside.sum()),
                "skipped_by_bound": round(float(np.mean(bound < 1.0)), 4),
                "dark_in_network": round(float(np.mean(network < 1.0)), 4),
                "dark_not_skipped": round(float(np.mean(gap)), 4),
                "network_over_step_q": np.quantile(network[gap], quantiles).round(3).tolist() if gap.any() else [],
                "bound_over_step_q": np.quantile(bound[gap], quantiles).round(2).tolist() if gap.any() else [],
            }), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
