"""Issue 42's screening table: every run of fast_models_screen.sh with its cost and its BRDF-slice FLIP.

    python docs/experiments/probes/fast_models_table.py out/fast/runs/e3 [--json docs/data/fast_models_e3.json]

Per run: layer sizes, MACs per pixel (MLP + grid interpolation), grid values read per pixel, model file bytes,
training seconds (wall, as recorded), mean FLIP at (0°, 0°) 2000 RU, mean over the eight views, and each
view's FLIP relative to the run named ``base`` (today's recipe at the same budget).
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path


def read_run(folder: Path) -> dict[str, object] | None:
    """One run's figures, or None while it has no metrics.json."""
    metrics_path = folder / "metrics.json"
    if not metrics_path.is_file():
        return None
    metrics = json.loads(metrics_path.read_text())
    model = metrics["model"]
    levels = model.get("grid_levels") or []
    # Trilinear (or smoothstep) interpolation reads 8 nodes of C features per level.
    grid_values = sum(8 * level[3] for level in levels)
    seconds_path = folder / "train_seconds.txt"
    flips = {row["slice"]: row["flip"] for row in metrics["brdf_slices"]}
    return {
        "name": folder.name,
        "layer_sizes": model["layer_sizes"],
        "macs": model["macs_per_evaluation"] + model.get("grid_interpolation_macs", 0),
        "grid_values_read": grid_values,
        "model_bytes": (folder / "model.npz").stat().st_size,
        "train_seconds": float(seconds_path.read_text()) if seconds_path.is_file() else math.nan,
        "flip": flips,
        "flip_0_0": flips["(0°, 0°) 2000 RU"],
        "flip_mean": sum(flips.values()) / len(flips),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("runs", type=Path, help="folder of runs (one sub-folder each)")
    parser.add_argument("--json", type=Path, help="write the rows here too")
    arguments = parser.parse_args()
    rows = [row for folder in sorted(arguments.runs.iterdir()) if folder.is_dir()
            if (row := read_run(folder)) is not None]
    base = next((row for row in rows if row["name"] == "base"), None)
    print("| run | layers | MACs | grid values | file MB | train s | FLIP (0°, 0°) | mean of 8 | ×base (0°,0°) "
          "| ×base mean |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for row in sorted(rows, key=lambda r: r["macs"]):
        ratio = (f"{row['flip_0_0'] / base['flip_0_0']:.2f} | {row['flip_mean'] / base['flip_mean']:.2f}"
                 if base else "— | —")
        print(f"| {row['name']} | {'-'.join(map(str, row['layer_sizes']))} | {row['macs']:,} | "
              f"{row['grid_values_read']} | {row['model_bytes'] / 1e6:.2f} | {row['train_seconds']:.0f} | "
              f"{row['flip_0_0']:.4f} | {row['flip_mean']:.4f} | {ratio} |")
    if arguments.json:
        arguments.json.write_text(json.dumps(rows, indent=1, ensure_ascii=False) + "\n")


if __name__ == "__main__":
    main()
