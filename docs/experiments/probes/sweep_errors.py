"""Error and training time of trained runs, one line each: the size sweep's and its seed repeats.

For each run folder (holding model.npz, metrics.json and history.json from ``gratnet train``): layer
sizes, MACs per pixel, training samples, epochs, training seconds, mean FLIP over the five evaluation
slices, FLIP at (0°, 0°) and mean PSNR (as ``gratnet bench`` reads them).

    python docs/experiments/probes/sweep_errors.py out/sweep/* out/sweep_seed1/* out/sweep_seed2/* assets/blazed

``gratnet sweep`` writes the same figures for its runs as OUT/results.{csv,md,json} (sweep/tasks.py
``result_row``); this script remains for run folders made by hand.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from bench.slices import ModelEntry


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("runs", nargs="+", type=Path, help="run folders (model.npz, metrics.json, history.json)")
    arguments = parser.parse_args(argv)
    for folder in arguments.runs:
        if not (folder / "model.npz").is_file():
            continue
        entry = ModelEntry.load(folder / "model.npz", str(folder))
        history_path = folder / "history.json"
        history = json.loads(history_path.read_text()) if history_path.is_file() else {}
        print(json.dumps({
            "run": str(folder), "layer_sizes": list(entry.model.layer_sizes),
            "macs_per_pixel": entry.model.macs_per_evaluation, "train_samples": history.get("train_samples"),
            "epochs": len(history.get("epochs", [])), "train_seconds": history.get("train_seconds"),
            "mean_flip": entry.flip_mean, "flip_normal": entry.flip_normal, "mean_psnr": entry.psnr_mean,
        }))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
