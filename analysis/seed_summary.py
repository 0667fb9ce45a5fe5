"""Seeds against targets: the mean and spread of each paper dataset's (0°, 0°) FLIP over its seeds.

    python -m analysis.seed_summary RUNS_DIR [--json OUT.json] [--markdown OUT.md]

RUNS_DIR holds NAME/seed-K/metrics.json and, for a material's quality points, NAME/POINT/seed-K/metrics.json
(``SEEDS="0 1 2" bash scripts/reproduce_paper_models.sh``; a point's row is named NAME/POINT). Per dataset:
the seeds found, the mean, standard deviation (ddof 1), lowest and highest FLIP at (0°, 0°) 2000 RU, the paper's
column for it (its preset's ``paper_flip``, trainer/datasets.py) and whether the mean beats it (the rule for shipping a
recipe), the mean over the seeds of the worst other paper slice and the worst further view, each over the
(0°, 0°) FLIP (the 1.5× rule), and the mean and standard deviation over the seeds of the FLIP averaged over every
evaluated view (``views_mean``, ``views_std``).
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
from pathlib import Path
from typing import Any

from gratnet.atomic import write_text_atomic
from trainer.datasets import PRESETS
from trainer.evaluate import STANDARD_SLICE_LABELS as SLICE_ORDER


def summarise(runs: Path) -> list[dict[str, Any]]:
    """One row per dataset folder (and per quality point folder inside one) with at least one finished seed."""
    rows = []
    folders = []
    for folder in sorted(path for path in runs.iterdir() if path.is_dir()):
        folders.append((folder.name, folder))
        folders += [(f"{folder.name}/{point.name}", point) for point in sorted(folder.iterdir())
                    if point.is_dir() and not point.name.startswith("seed-")]
    for name, folder in folders:
        seeds = sorted(folder.glob("seed-*/metrics.json"))
        flips, slice_ratios, view_ratios, view_means = [], [], [], []
        for path in seeds:
            entries = json.loads(path.read_text(encoding="utf-8"))["brdf_slices"]
            paper = {entry["slice"]: entry for entry in entries if not entry.get("extra_view")}
            normal = paper[SLICE_ORDER[0]]["flip"]
            flips.append(normal)
            view_means.append(statistics.fmean(entry["flip"] for entry in entries))  # every evaluated view
            slice_ratios.append(max(paper[name]["flip"] for name in SLICE_ORDER[1:]) / normal)
            views = [entry["flip"] for entry in entries if entry.get("extra_view")]
            if views:
                view_ratios.append(max(views) / normal)
        if not flips:
            continue
        preset = PRESETS.get(name.split("/")[0])  # a quality point has its material's paper target
        column, target = (preset.paper_column or "—", preset.paper_flip) if preset is not None else ("—", None)
        mean = statistics.fmean(flips)
        rows.append({
            "dataset": name, "seeds": [path.parent.name for path in seeds], "flip_0_0": flips,
            "mean": mean, "std": statistics.stdev(flips) if len(flips) > 1 else 0.0, "min": min(flips),
            "max": max(flips), "paper_column": column, "paper": target,
            "mean_beats_paper": None if target is None else mean <= target,
            "other_slices_worst_ratio": statistics.fmean(slice_ratios),
            "views_worst_ratio": statistics.fmean(view_ratios) if view_ratios else None,
            "views_mean": statistics.fmean(view_means),
            "views_std": statistics.stdev(view_means) if len(view_means) > 1 else 0.0,
        })
    return rows


def markdown(rows: list[dict[str, Any]]) -> str:
    lines = ["| dataset | seeds | FLIP (0°, 0°): mean ± std (min … max) | paper's column | paper | mean beats it "
             "| other slices: worst / (0°, 0°) | further views: worst / (0°, 0°) | every view's mean: mean ± std |",
             "|---|---|---|---|---|---|---|---|---|"]
    for row in rows:
        verdict = "—" if row["mean_beats_paper"] is None else ("**yes**" if row["mean_beats_paper"] else "no")
        views = "—" if row["views_worst_ratio"] is None else f"{row['views_worst_ratio']:.2f}×"
        everything = "—" if row.get("views_mean") is None else f"{row['views_mean']:.4f} ± {row['views_std']:.4f}"
        lines.append(f"| {row['dataset']} | {len(row['seeds'])} | {row['mean']:.4f} ± {row['std']:.4f} "
                     f"({row['min']:.4f} … {row['max']:.4f}) | {row['paper_column']} | "
                     f"{'—' if row['paper'] is None else row['paper']} | {verdict} | "
                     f"{row['other_slices_worst_ratio']:.2f}× | {views} | {everything} |")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("runs", type=Path)
    parser.add_argument("--json", type=Path)
    parser.add_argument("--markdown", type=Path)
    arguments = parser.parse_args(argv)
    if not arguments.runs.is_dir():
        parser.error(f"{arguments.runs} is not a folder")
    rows = summarise(arguments.runs)
    text = markdown(rows)
    sys.stdout.write(text)
    if arguments.json:
        write_text_atomic(arguments.json, json.dumps(rows, indent=1) + "\n")
    if arguments.markdown:
        write_text_atomic(arguments.markdown, text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
