"""How much MLP work a perfect skip could save on the paper's five BRDF slices, per shipped material.

A pixel can be skipped without changing the 8-bit display image only if it displays as black (display sRGB
0 in every channel). This script counts, inside the unit disc of each standard slice, the pixels that are
lit (display sRGB > 0):

- in the ground truth (exact key vectors, from the evaluation cache: the limit for a perfect network), and
- in the shipped network's slice (numpy, the same numbers as the shader to float32 rounding),

and prints the largest possible reduction of MLP evaluations, 1 / lit fraction, for both. JSON lines.

    python docs/experiments/probes/skip_oracle.py [--size 256] [--cache-dir out/cache]
        [--plot docs/images/skip_oracle.png]

Ground-truth slices missing from the cache are computed (minutes each, 81 wavelengths).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from gratnet.brdf import slice_view_directions
from gratnet.display import xyz_to_display_srgb8
from gratnet.modelfile import load_model
from trainer.brdfslice import SliceConfig
from trainer.evaluate import STANDARD_SLICES, ground_truth_brdf_slice, network_brdf_slice, slice_label
from trainer.fourier import OpticsConfig
from trainer.loaders import load_heightfield

ASSETS = Path(__file__).resolve().parents[1] / "assets"


def lit_fraction(xyz: np.ndarray, inside: np.ndarray) -> float:
    """Fraction of the disc's pixels whose 8-bit display sRGB is above 0 in some channel."""
    return float((xyz_to_display_srgb8(np.asarray(xyz, dtype=np.float64), 1.0).max(axis=-1) > 0)[inside].mean())


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", type=int, default=256)
    parser.add_argument("--cache-dir", default="out/cache")
    parser.add_argument("--plot", default=None, help="bar chart PNG")
    arguments = parser.parse_args()
    _, inside = slice_view_directions(arguments.size)
    rows = []
    for model_path in sorted(ASSETS.glob("*/model.npz")):
        model = load_model(model_path)
        volume = model.metadata["volume"]
        field = load_heightfield(volume["source"])
        optics = OpticsConfig.from_volume_metadata(volume)
        for theta, phi, exposure in STANDARD_SLICES:
            config = SliceConfig(theta, phi, size=arguments.size, exposure=exposure, ior=1.5)
            truth = ground_truth_brdf_slice(field, optics, config, arguments.cache_dir, progress=False)
            network = network_brdf_slice(model, config)
            row = {"material": model_path.parent.name, "slice": slice_label(theta, phi, exposure),
                   "lit_ground_truth": lit_fraction(truth, inside), "lit_network": lit_fraction(network, inside)}
            row["best_reduction_ground_truth"] = 1.0 / max(row["lit_ground_truth"], 1.0 / inside.sum())
            row["best_reduction_network"] = 1.0 / max(row["lit_network"], 1.0 / inside.sum())
            rows.append(row)
            print(json.dumps(row), flush=True)
    if arguments.plot:
        _plot(rows, Path(arguments.plot))


def _plot(rows: list[dict], output: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from gratnet.figures import save_figure

    labels = [f"{row['material']}\n{row['slice'].split(' ')[0]} {row['slice'].split(' ')[1]}" for row in rows]
    positions = np.arange(len(rows))
    figure, axis = plt.subplots(figsize=(max(8.0, 0.45 * len(rows)), 4.2))
    axis.bar(positions - 0.2, [row["lit_ground_truth"] for row in rows], 0.4, label="ground truth")
    axis.bar(positions + 0.2, [row["lit_network"] for row in rows], 0.4, label="shipped network")
    axis.axhline(0.2, color="grey", linestyle="--", linewidth=0.8, label="lit fraction that allows 5× fewer MLP runs")
    axis.set_xticks(positions, labels, rotation=90, fontsize=6)
    axis.set_ylabel("fraction of the disc's pixels with display sRGB > 0")
    axis.set_title("Pixels a display-exact skip must shade, standard BRDF slices (256²)", fontsize=9)
    axis.legend(fontsize=7)
    figure.tight_layout()
    save_figure(figure, output, dpi=110)
    plt.close(figure)


if __name__ == "__main__":
    main()
