"""The sweep's results table (CSV, markdown, JSON) and its Pareto plot (error against multiply-adds per pixel).

The rows are the runs' ``result.json`` rows (sweep/tasks.py ``result_row``), error figures read the way
``gratnet bench`` reads them (bench.slices.ModelEntry); the front is bench.slices.pareto_front. For
shader frame time on the error axis, give the sweep a ``[bench]`` table (it then runs ``gratnet bench``'s
measurement on every model at the end) or run ``gratnet bench OUT/runs/*/model.npz`` later.
"""

from __future__ import annotations

import csv
import io
import json
import math
from pathlib import Path
from typing import Any

from bench.tables import format_cell
from gratnet.atomic import write_text_atomic
from gratnet.figures import save_figure

COLUMNS = ["run", "dataset", "preset", "variant", "seed", "parameters", "macs_per_pixel", "train_samples", "epochs",
           "train_seconds", "train_loss", "held_out_loss", "held_out_psnr_db", "flip_mean", "flip_0_0",
           "psnr_mean_db"]
_HEADERS = {"macs_per_pixel": "MACs/pixel", "train_seconds": "train (s)", "held_out_psnr_db": "held-out PSNR (dB)",
            "flip_mean": "mean FLIP (5 slices)", "flip_0_0": "FLIP (0°,0°)", "psnr_mean_db": "mean PSNR (dB)"}


def _format(value: object) -> str:
    return format_cell(value, 4)


def markdown_table(rows: list[dict[str, Any]]) -> str:
    """One line per run, in the sweep's order."""
    header = "| " + " | ".join(_HEADERS.get(column, column.replace("_", " ")) for column in COLUMNS) + " |"
    lines = [header, "|" + "---|" * len(COLUMNS)]
    lines += ["| " + " | ".join(_format(row.get(column)) for column in COLUMNS) + " |" for row in rows]
    return "\n".join(lines) + "\n"


def csv_text(rows: list[dict[str, Any]]) -> str:
    """The table as CSV (every column of the rows, layer sizes as ``a-b-c``)."""
    columns = COLUMNS + ["layer_sizes", "run_seconds", "model"]
    buffer = io.StringIO()
    writer = csv.DictWriter(buffer, fieldnames=columns, extrasaction="ignore", lineterminator="\n")
    writer.writeheader()
    for row in rows:
        writer.writerow({**row, "layer_sizes": "-".join(map(str, row.get("layer_sizes") or []))})
    return buffer.getvalue()


def plot_pareto(rows: list[dict[str, Any]], output: Path) -> None:
    """Mean FLIP against MACs per pixel, one colour and one Pareto front per dataset; written atomically."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from bench.slices import pareto_front

    figure, axis = plt.subplots(figsize=(7.0, 5.0))
    rated = [row for row in rows if row.get("flip_mean") is not None]
    for dataset in dict.fromkeys(row["dataset"] for row in rated):
        same = [row for row in rated if row["dataset"] == dataset]
        points = axis.scatter([row["macs_per_pixel"] for row in same], [row["flip_mean"] for row in same],
                              label=dataset, zorder=3)
        front = [same[index] for index in pareto_front([(row["macs_per_pixel"], row["flip_mean"]) for row in same])]
        axis.step([row["macs_per_pixel"] for row in front], [row["flip_mean"] for row in front], where="post",
                  linestyle="--", color=points.get_facecolor()[0], zorder=2)
        for row in same:
            axis.annotate(f"{row['preset']}/{row['variant']}/s{row['seed']}", (row["macs_per_pixel"], row["flip_mean"]),
                          fontsize=6, xytext=(3, 2), textcoords="offset points")
    if rated:
        axis.set_xscale("log")
        axis.set_yscale("log")
        axis.legend(fontsize=7, title="dataset (dashed: Pareto front)", title_fontsize=7)
    else:
        axis.text(0.5, 0.5, "no run has BRDF-slice metrics ([evaluate] brdf_slices = false)", ha="center",
                  va="center", transform=axis.transAxes)
    axis.set_xlabel("multiply-adds per pixel (log)")
    axis.set_ylabel("mean FLIP over the five evaluation slices (log)")
    axis.set_title("sweep: error against network cost", fontsize=9)
    axis.grid(True, which="both", alpha=0.3)
    figure.tight_layout()
    save_figure(figure, output, dpi=120)
    plt.close(figure)


def write_results(rows: list[dict[str, Any]], out: Path) -> list[Path]:
    """results.json, results.csv, results.md and pareto.png in ``out`` (each atomically); their paths."""
    from gratnet.jsontext import strict_json

    paths = [out / "results.json", out / "results.csv", out / "results.md", out / "pareto.png"]
    finite = [{key: (str(value) if isinstance(value, float) and not math.isfinite(value) else value)
               for key, value in row.items()} for row in rows]  # strict JSON: "inf" as metrics.json writes it
    write_text_atomic(paths[0], json.dumps(json.loads(strict_json(finite, "sweep results")), indent=1) + "\n")
    write_text_atomic(paths[1], csv_text(rows))
    write_text_atomic(paths[2], markdown_table(rows))
    plot_pareto(rows, paths[3])
    return paths
