"""Speed against error (issue 42): every shipped paper-* model, each of its quality points, and the look-up-table
baseline, as points of error against 1080p frame time and against bytes, one figure per dataset family.

    python -m analysis.pareto [--assets assets] [--images docs/images] [--json docs/data/pareto.json]

Data alone: each point's metrics.json (its BRDF-slice FLIP, ``gratnet evaluate``), its model file (bytes on disk,
gratnet.cost), docs/data/frame_times_1080p.json (benchmarks/frame_time_1080p.py: the 1080p CD frame on the
machine that ran it) and docs/data/lut_baseline_NAME.json (benchmarks/lut_baseline.py: the full and the reduced
table, with the network measured in the same run). The error axis is the mean FLIP over the paper's five BRDF
slices, the one error every source states. The figures are written by :func:`write_figures`; docs/results.md
shows them with one sentence per dataset (:func:`pareto_section`, called by analysis.results_table).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import statistics
from pathlib import Path
from typing import Any

from gratnet.atomic import atomic_path, write_text_atomic
from gratnet.cost import MEGABYTE, ModelCost
from gratnet.quality import ACCURATE, FAST
from trainer.datasets import PRESETS
from trainer.evaluate import STANDARD_SLICE_LABELS
from viewer.catalog import material_points

__all__ = ["FAST_ERROR_RATIO", "Point", "advice", "collect", "families", "pareto_section", "write_figures"]

#: benchmarks/frame_time_1080p.py's record and benchmarks/lut_baseline.py's, one per dataset.
FRAME_TIMES_JSON = Path("docs/data/frame_times_1080p.json")
LUT_JSON = "docs/data/lut_baseline_{name}.json"
#: Issue 42's rule for a fast point: its error at most this many times the accurate point's.
FAST_ERROR_RATIO = 1.25


@dataclasses.dataclass(frozen=True)
class Point:
    """One model or table of a dataset: its error, its frame time (ms, None where unmeasured) and its bytes."""

    dataset: str
    kind: str  # a quality point (gratnet.quality), or "look-up" for a table
    label: str
    flip: float  # mean FLIP over the paper's five BRDF slices
    flip_0_0: float | None
    ms: float | None
    megabytes: float
    macs: int = 0  # multiply-adds per pixel (a table: 0)
    source: str = ""  # where the frame time comes from

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)


def _paper_flips(metrics_path: Path) -> tuple[float, float]:
    """(mean FLIP of the paper's five slices, FLIP at (0°, 0°)) of a metrics.json."""
    entries = json.loads(metrics_path.read_text(encoding="utf-8"))["brdf_slices"]
    flips = {entry["slice"]: entry["flip"] for entry in entries if not entry.get("extra_view")}
    return statistics.fmean(flips[label] for label in STANDARD_SLICE_LABELS), flips[STANDARD_SLICE_LABELS[0]]


def frame_times(path: Path = FRAME_TIMES_JSON) -> dict | None:
    """benchmarks/frame_time_1080p.py's record, or None when there is none."""
    return json.loads(path.read_text(encoding="utf-8")) if path.exists() else None


def frame_row(record: dict | None, material: str, quality: str = ACCURATE) -> dict | None:
    """The record's measured frame of ``material`` at ``quality`` (a row without a quality is the accurate one's), or
    None."""
    if record is None:
        return None
    return next((row for row in record["models"] if row.get("material") == material and "ms" in row
                 and (row.get("quality") or ACCURATE) == quality), None)


def _frame_ms(record: dict | None, dataset: str, quality: str) -> float | None:
    if record is None or (record.get("width"), record.get("height")) != (1920, 1080):
        return None
    row = frame_row(record, dataset, quality)
    return None if row is None else float(row["ms"])


def collect(assets: Path = Path("assets"), frame_times_path: Path = FRAME_TIMES_JSON,
            lut_pattern: str = LUT_JSON) -> list[Point]:
    """Every paper-* dataset's points: its quality points (with metrics), then its tables."""
    record = frame_times(frame_times_path)
    points = []
    for dataset in sorted(PRESETS):
        if not (assets / dataset / "model.npz").is_file():
            continue
        for quality, model in material_points(dataset, assets).items():
            if not (model.parent / "metrics.json").is_file():
                continue
            flip, flip_0_0 = _paper_flips(model.parent / "metrics.json")
            cost = ModelCost.of_file(model)
            ms = _frame_ms(record, dataset, quality)
            points.append(Point(dataset, quality, f"{dataset} {quality}", flip, flip_0_0, ms,
                                (cost.bytes_on_disk or 0) / MEGABYTE, cost.macs_per_pixel,
                                "frame_times_1080p.json" if ms is not None else ""))
        lut = Path(lut_pattern.format(name=dataset))
        if lut.exists():
            for row in json.loads(lut.read_text(encoding="utf-8")):
                if row.get("what") == "network":  # the accurate model, timed in the tables' own run
                    points = [dataclasses.replace(point, ms=float(row["ms_per_frame"]), source=lut.name)
                              if point.dataset == dataset and point.kind == ACCURATE and point.ms is None else point
                              for point in points]
                if not str(row.get("what", "")).startswith("look-up"):
                    continue
                points.append(Point(dataset, "look-up", f"{dataset} {row['what']}", float(row["flip_mean"]),
                                    float(row["flip_slices"][0]), float(row["ms_per_frame"]), float(row["mb"]),
                                    0, lut.name))
    return points


def families(points: list[Point]) -> dict[str, list[Point]]:
    """The points grouped by their dataset's family (trainer.datasets), in the presets' order."""
    grouped: dict[str, list[Point]] = {}
    for point in points:
        grouped.setdefault(PRESETS[point.dataset].family or point.dataset, []).append(point)
    return grouped


def figure_name(family: str) -> str:
    return "pareto_" + "_".join(family.split()) + ".png"


MARKERS = {FAST: "^", ACCURATE: "o", "look-up": "s"}


def write_figures(points: list[Point], images: Path) -> list[Path]:
    """One figure per family: mean FLIP against the 1080p frame (ms, log) and against MB on disk (log)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    written = []
    for family, members in families(points).items():
        figure, (by_time, by_bytes) = plt.subplots(1, 2, figsize=(10, 4), sharey=True)
        datasets = sorted({point.dataset for point in members})
        colours = {name: f"C{index}" for index, name in enumerate(datasets)}
        for point in members:
            style = {"marker": MARKERS.get(point.kind, "x"), "color": colours[point.dataset], "markersize": 8,
                     "linestyle": "none", "fillstyle": "none" if point.kind == "look-up" else "full"}
            if point.ms is not None:
                by_time.plot(point.ms, point.flip, **style)
            by_bytes.plot(point.megabytes, point.flip, **style)
        for axis, label in ((by_time, "1080p CD frame (ms, llvmpipe; log)"), (by_bytes, "MB on disk (log)")):
            axis.set_xscale("log")
            axis.set_yscale("log")  # the datasets' errors span 0.002 … 0.1
            axis.set_xlabel(label)
            axis.grid(True, which="both", alpha=0.3)
        by_time.set_ylabel("mean FLIP, the paper's five BRDF slices (log)")
        handles = [plt.Line2D([], [], color=colours[name], marker="o", linestyle="none", label=name)
                   for name in datasets]
        handles += [plt.Line2D([], [], color="0.3", marker=marker, linestyle="none", label=kind,
                               fillstyle="none" if kind == "look-up" else "full")
                    for kind, marker in MARKERS.items()]
        by_bytes.legend(handles=handles, fontsize=8, loc="best")
        if not any(point.ms is not None for point in members):
            by_time.text(0.5, 0.5, "no frame times recorded yet\n(benchmarks/frame_time_1080p.py)",
                         transform=by_time.transAxes, ha="center", va="center", fontsize=9)
        figure.suptitle(f"Speed against error: {family}")
        figure.tight_layout()
        path = images / figure_name(family)
        with atomic_path(path) as temporary:
            figure.savefig(temporary, dpi=100, format="png")
        plt.close(figure)
        written.append(path)
    return written


def advice(points: list[Point], dataset: str) -> str:
    """One sentence on what a user of ``dataset`` should pick, from its points."""
    own = {point.kind: point for point in points if point.dataset == dataset}
    accurate, fast = own.get(ACCURATE), own.get(FAST)
    tables = [point for point in points if point.dataset == dataset and point.kind == "look-up"]
    if accurate is None:
        return f"{dataset}: no evaluated model."
    text = (f"{dataset}: accurate point {accurate.macs:,} MACs/pixel, mean FLIP {accurate.flip:.4f}"
            + (f", {accurate.ms:.4g} ms" if accurate.ms is not None else ""))
    if fast is None:
        text += "; no fast point is shipped yet, so every quality setting renders the accurate one"
    else:
        ratio = fast.flip / accurate.flip
        text += (f"; fast point {fast.macs:,} MACs/pixel ({fast.macs / accurate.macs:.0%} of the work), mean FLIP "
                 f"{fast.flip:.4f} ({ratio:.2f}× the accurate)"
                 + (f", {fast.ms:.4g} ms" if fast.ms is not None else ""))
        text += (": pick fast for interaction and accurate for stills" if ratio <= FAST_ERROR_RATIO else
                 f": its error is over {FAST_ERROR_RATIO}× the accurate point's, so pick it only where speed rules")
    if tables:
        best = min(tables, key=lambda point: point.flip)
        table = best.label.split(" ", 1)[1].removeprefix("look-up ")
        if best.flip < accurate.flip:
            text += f"; a table look-up of the volume at {table} reaches FLIP {best.flip:.4f} at " \
                    f"{best.megabytes:.0f} MB"
    return text + "."


def pareto_section(points: list[Point], images_link: str = "images") -> list[str]:
    """docs/results.md's section: the figures and one sentence per dataset."""
    lines = ["## Speed against error: which point to pick", "",
             "Each shipped paper-* model and its quality points (`--quality fast|accurate`, docs/usage.md) against the "
             "look-up-table baseline (benchmarks/lut_baseline.py: the full volume and a reduced one): mean FLIP over "
             "the paper's five BRDF slices against the 1080p CD frame on this project's CPU rasterizer (llvmpipe) and "
             "against the bytes on disk. Frame times of models: docs/data/frame_times_1080p.json where it has them, "
             "else the network's frame in the table benchmark's run; of tables: their own benchmark runs (dates and "
             "loads in docs/data/lut_baseline_*.json), so not every pair of points was timed in the same run. "
             "`python -m analysis.pareto` redraws the figures.", ""]
    for family, members in families(points).items():
        lines += [f"### {family}", "", f"![speed against error: {family}]({images_link}/{figure_name(family)})", ""]
        for dataset in sorted({point.dataset for point in members}):
            lines.append(f"- {advice(points, dataset)}")
        lines.append("")
    return lines


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--assets", type=Path, default=Path("assets"))
    parser.add_argument("--images", type=Path, default=Path("docs/images"))
    parser.add_argument("--json", type=Path, default=None, help="also write the points here")
    arguments = parser.parse_args(argv)
    points = collect(arguments.assets)
    for path in write_figures(points, arguments.images):
        print(f"wrote {path}")
    if arguments.json:
        write_text_atomic(arguments.json, json.dumps([point.to_dict() for point in points], indent=1) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

