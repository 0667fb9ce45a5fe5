"""Plot the CPU runs on paper-scratches' 11-slice volume that vary the feature grid (finest u*/v* nodes,
features per node): training loss by epoch, and the five BRDF slices' FLIP against the volume's interpolation
oracle (docs/data/cpu_runs_scratches_grid.json, written from the runs' history.json and evaluation;
docs/experiments/2026-11-23-scratches-finer-grid.md).

python docs/experiments/probes/grid_size_figure.py [--data docs/data/cpu_runs_scratches_grid.json]
                                      [--out docs/images/grid_size_scratches.png]
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from analysis.results_table import PAPER_FLIP_PAPER_DATASETS, SLICE_ORDER
from gratnet.figures import save_figure


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", default="docs/data/cpu_runs_scratches_grid.json")
    parser.add_argument("--out", default="docs/images/grid_size_scratches.png")
    arguments = parser.parse_args()
    data = json.loads(Path(arguments.data).read_text())
    runs, oracle = data["runs"], data["oracle_flip"]
    figure, axes = plt.subplots(1, 2, figsize=(11, 4.2))
    colours = plt.get_cmap("viridis")(np.linspace(0.0, 0.85, len(runs)))
    for run, colour in zip(runs, colours, strict=True):
        epochs = np.arange(1, len(run["train_loss"]) + 1)
        axes[0].plot(epochs, run["train_loss"], marker="o", markersize=3, color=colour, label=run["label"])
    axes[0].set_yscale("log")
    axes[0].set_xlabel("epoch (11.0 M samples each, batch 2,048)")
    axes[0].set_ylabel("training LogCosh loss (running mean)")
    axes[0].grid(True, which="both", alpha=0.3)
    axes[0].legend(fontsize=8)

    width = 0.8 / (len(runs) + 1)
    positions = np.arange(len(SLICE_ORDER))
    for index, (run, colour) in enumerate(zip(runs, colours, strict=True)):
        axes[1].bar(positions + index * width, [run["flip"][name] for name in SLICE_ORDER], width, color=colour,
                    label=run["label"])
    axes[1].bar(positions + len(runs) * width, [oracle[name] for name in SLICE_ORDER], width, color="lightgrey",
                label="oracle: trilinear interpolation of the volume")
    paper = PAPER_FLIP_PAPER_DATASETS["paper-scratches"]
    axes[1].axhline(paper, color="tab:red", linestyle="--", linewidth=1, label=f"paper at (0°, 0°) ({paper:.4g})")
    axes[1].set_xticks(positions + 0.4 - width / 2, [name.replace(") ", ")\n") for name in SLICE_ORDER],
                       fontsize=7)
    axes[1].set_ylabel("mean FLIP, BRDF slice (256²)")
    axes[1].set_ylim(0, 1.9 * max(max(run["flip"].values()) for run in runs))  # room for the legend above the bars
    axes[1].legend(fontsize=7, loc="upper left")
    axes[1].grid(True, axis="y", alpha=0.3)
    figure.suptitle("paper-scratches, 11 w-slices, 10 CPU epochs: a finer feature grid (one run per setting)")
    figure.tight_layout()
    save_figure(figure, arguments.out, dpi=110)
    plt.close(figure)
    print(f"wrote {arguments.out}")


if __name__ == "__main__":
    main()
