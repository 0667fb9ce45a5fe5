"""How much each encoding frequency weighs in a network: the first layer's column norms per frequency.

    python -m analysis.encoding_weights MODEL.npz … [--json OUT.json]

The first layer of the funnel MLP reads [grid features (feature-grid models), (u*, v*, t), eq. 6's sines and
cosines]. The spatial part holds G groups (u*, v*, u*+v*, u*−v*; u*, v* alone for eq. 6a) × (sin, cos) × L
frequencies, the t part
(sin, cos) × L_t (gratnet.encoding.encode). Per frequency this prints the Frobenius norm of the first layer's
columns of that frequency (all groups, sine and cosine), and the mean column norm of the grid features. The top
frequency of each part sits at the volume's Nyquist rate: between samples the samples do not constrain it, so a
large weight there shows as oscillation between the samples (docs/experiments/2026-11-25-scratches-adam-epsilon.md).
At the samples that frequency's sine is zero (up to rounding), so its columns are printed apart from the cosine's.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

import numpy as np

from gratnet.atomic import atomic_path
from gratnet.errors import GratNetError
from gratnet.modelfile import ModelFile, load_model


def split_first_layer(columns: np.ndarray, grid: int, frequencies: int,
                      t_frequencies: int, groups: int = 4) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The first layer's columns (any array of shape (outputs, inputs)) by eq. 6's layout: the grid features
    (outputs, grid), the spatial part (outputs, G groups, sin/cos, L) and the t part (outputs, sin/cos, L_t)."""
    start = grid + 3  # grid features, then the raw coordinates (u*, v*, t)
    spatial_end = start + 2 * groups * frequencies
    spatial = columns[:, start:spatial_end].reshape(columns.shape[0], groups, 2, frequencies)
    t_part = columns[:, spatial_end:spatial_end + 2 * t_frequencies]
    return columns[:, :grid], spatial, t_part.reshape(columns.shape[0], 2, t_frequencies)


def frequency_norms(model: ModelFile) -> dict[str, Any]:
    """{"spatial": [L norms], "t": [L_t norms], the same of the sine and cosine columns alone ("spatial_sin",
    "spatial_cos", "t_sin", "t_cos"), "grid_features": mean column norm (0 without grids)}."""
    weights = np.asarray(model.weights[0], dtype=np.float64)  # (outputs, inputs)
    grid = model.grid_feature_count
    grid_columns, spatial, t_part = split_first_layer(weights, grid, model.encoding.frequencies,
                                                      model.encoding.t_frequencies, model.encoding.groups)
    return {
        "spatial": np.sqrt((spatial**2).sum(axis=(0, 1, 2))).tolist(),
        "spatial_sin": np.sqrt((spatial[:, :, 0] ** 2).sum(axis=(0, 1))).tolist(),
        "spatial_cos": np.sqrt((spatial[:, :, 1] ** 2).sum(axis=(0, 1))).tolist(),
        "t": np.sqrt((t_part**2).sum(axis=(0, 1))).tolist(),
        "t_sin": np.sqrt((t_part[:, 0] ** 2).sum(axis=0)).tolist(),
        "t_cos": np.sqrt((t_part[:, 1] ** 2).sum(axis=0)).tolist(),
        "grid_features": float(np.sqrt((grid_columns**2).sum(axis=0)).mean()) if grid else 0.0,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("models", nargs="+", type=Path, help="model files (.npz)")
    parser.add_argument("--json", type=Path, help="write the norms here as JSON")
    args = parser.parse_args()
    try:
        for path in args.models:
            if not path.is_file():
                raise GratNetError(f"no such file: {path}")
        norms = {str(path): frequency_norms(load_model(path)) for path in args.models}
    except GratNetError as error:
        sys.exit(f"encoding_weights: {error}")
    for path, entry in norms.items():
        print(f"{path}: grid-feature columns (mean norm) {entry['grid_features']:.3g}")
        print("  spatial, lowest to top frequency: " + " ".join(f"{value:.3g}" for value in entry["spatial"]))
        print("  t, lowest to top frequency:       " + " ".join(f"{value:.3g}" for value in entry["t"]))
        print(f"  top frequency, sine / cosine columns: spatial {entry['spatial_sin'][-1]:.3g} / "
              f"{entry['spatial_cos'][-1]:.3g}, t {entry['t_sin'][-1]:.3g} / {entry['t_cos'][-1]:.3g}")
    if args.json:
        with atomic_path(args.json) as temporary:
            temporary.write_text(json.dumps(norms, indent=1) + "\n")


if __name__ == "__main__":
    main()
