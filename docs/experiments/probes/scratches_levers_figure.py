"""Plot the CPU trainings on paper-scratches that each change one thing in the shipped recipe (feature-grid size,
off-lattice points, display-weighted loss, a full-resolution grid level): mean FLIP over eight views per run,
with the recipe's seed-to-seed range and the volume's interpolation oracle
(docs/data/cpu_runs_scratches_levers.json; docs/experiments/2026-11-23-scratches-levers.md).

python docs/experiments/probes/scratches_levers_figure.py [--data docs/data/cpu_runs_scratches_levers.json]
                                             [--out docs/images/scratches_levers.png]
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from gratnet.figures import save_figure


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", default="docs/data/cpu_runs_scratches_levers.json")
    parser.add_argument("--out", default="docs/images/scratches_levers.png")
    arguments = parser.parse_args()
    data = json.loads(Path(arguments.data).read_text())
    volumes = sorted({run["volume"] for run in data["runs"]})
    counts = [sum(run["volume"] == volume for run in data["runs"]) for volume in volumes]
    figure, panels = plt.subplots(len(volumes), 1, figsize=(12.5, 1.2 + 0.42 * sum(counts) + 0.8 * len(volumes)),
                                  squeeze=False, height_ratios=counts)
    for panel, volume in zip(panels[:, 0], volumes, strict=True):
        runs = [run for run in data["runs"] if run["volume"] == volume]
        rows = np.arange(len(runs))[::-1]
        means = [float(np.mean(list(run["flip"].values()))) for run in runs]
        first = [next(iter(run["flip"].values())) for run in runs]  # (0°, 0°) 2000 RU
        panel.barh(rows, means, color=["tab:grey" if run.get("baseline") else "tab:blue" for run in runs],
                   label="mean over the 8 views")
        panel.scatter(first, rows, color="black", marker="|", s=200, zorder=3, label="(0°, 0°) 2000 RU alone")
        panel.set_yticks(rows, [f"{run['label']} ({run['grid_bytes'] / 1e6:.1f} MB)" for run in runs], fontsize=8)
        baseline = [mean for mean, run in zip(means, runs, strict=True) if run.get("baseline")]
        if len(baseline) > 1:
            panel.axvspan(min(baseline), max(baseline), color="tab:grey", alpha=0.25, label="seed-to-seed range")
        oracle = data["oracle_mean"].get(volume)
        if oracle is not None:
            panel.axvline(oracle, color="tab:green", linestyle=":", label=f"oracle of the volume, mean ({oracle:.4f})")
        budget = data["grid_budget_bytes"].get(volume)
        title = volume + (f"; grid budget 1/20 of the volume: {budget / 1e6:.1f} MB" if budget else "")
        panel.set_title(title, fontsize=9)
        panel.set_xlabel("mean FLIP (256²)")
        panel.grid(True, axis="x", alpha=0.3)
        panel.legend(fontsize=7, loc="center left", bbox_to_anchor=(1.01, 0.5))
    figure.suptitle("paper-scratches, 10 CPU epochs at batch 2,048: one change at a time (one run per point)")
    figure.tight_layout()
    save_figure(figure, arguments.out, dpi=100)
    plt.close(figure)
    print(f"wrote {arguments.out}")


if __name__ == "__main__":
    main()
