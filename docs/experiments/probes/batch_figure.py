"""Plot the H100 batch-size runs on the paper's CD: (0°, 0°) FLIP against optimiser steps and against samples
seen (docs/data/gpu_runs_batch.json, written from the runs' history.json and evaluation;
docs/experiments/2026-11-23-smaller-batches-h100.md).

python docs/experiments/probes/batch_figure.py [--data docs/data/gpu_runs_batch.json]
    [--out docs/images/batch_size_cd.png]
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from analysis.results_table import PAPER_FLIP_PAPER_DATASETS, SLICE_ORDER
from gratnet.figures import save_figure

#: The same recipe at every batch size (no loss weighting, encoding or grid change): the runs compared.
PLAIN_RUNS = ("base", "b8k", "b8k-rep", "b4k", "b4k-b", "b2k")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", default="docs/data/gpu_runs_batch.json")
    parser.add_argument("--out", default="docs/images/batch_size_cd.png")
    arguments = parser.parse_args()
    normal = SLICE_ORDER[0]  # (0°, 0°) 2000 RU
    paper = PAPER_FLIP_PAPER_DATASETS["paper-cd"]
    # The interpolation oracle of the volume these runs trained on, as the shipped model's evaluation scored it.
    shipped = json.loads(Path("assets/paper-cd/metrics.json").read_text())["brdf_slices"]
    oracle = next(row["oracle_flip"] for row in shipped if row["slice"] == normal)
    runs = [run for run in json.loads(Path(arguments.data).read_text())
            if run["dataset"] == "paper-cd" and run["run"] in PLAIN_RUNS]
    batches = sorted({run["batch_size"] for run in runs}, reverse=True)
    colours = dict(zip(batches, plt.get_cmap("viridis")([0.0, 0.35, 0.65, 0.9][: len(batches)]), strict=True))
    figure, axes = plt.subplots(1, 2, figsize=(10, 4), sharey=True)
    for axis, key, label in ((axes[0], "steps", "optimiser steps (thousands)"),
                             (axes[1], "samples", "samples seen (millions: epochs × 10.2 M)")):
        for run in runs:
            x = run["steps"] / 1e3 if key == "steps" else run["epochs"] * run["train_samples"] / 1e6
            axis.scatter(x, run["flip"][normal], color=colours[run["batch_size"]], s=50, zorder=3)
            axis.annotate(f"{run['epochs']} ep", (x, run["flip"][normal]), textcoords="offset points", xytext=(5, 4),
                          fontsize=8)
        axis.axhline(paper, color="tab:red", linestyle="--", linewidth=1, label=f"paper ({paper:.4g})")
        axis.axhline(oracle, color="grey", linestyle=":", linewidth=1, label=f"oracle of the volume ({oracle:.2g})")
        axis.set_xlim(left=0)
        axis.set_xlabel(label)
        axis.grid(True, which="both", alpha=0.3)
    for batch in batches:
        axes[0].scatter([], [], color=colours[batch], label=f"batch {batch:,}")
    axes[0].set_ylabel("mean FLIP, BRDF slice (0°, 0°) 2000 RU")
    axes[0].set_ylim(0, 0.035)
    axes[0].legend(fontsize=8, loc="lower left")
    figure.suptitle("paper-cd feature grid on an H100: smaller batches, lower error (one run per point)")
    figure.tight_layout()
    save_figure(figure, arguments.out, dpi=110)
    print(f"wrote {arguments.out}")


if __name__ == "__main__":
    main()
