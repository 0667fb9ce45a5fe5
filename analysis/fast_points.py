"""Issue 42's targets for every shipped fast point, against the same dataset's network at main 1374b1d (the
issue's "today's model"), for docs/results.md.

    python -m analysis.fast_points --baseline-from 1374b1d   # docs/data/accurate_1374b1d.json, from git history
    python -m analysis.fast_points                            # print the section

The baseline record is made once from the repository's history (``git show REV:…``): per paper-* dataset its
network's MACs per pixel and model-file bytes, its FLIP at (0°, 0°) 2000 RU and its mean over the eight views of
``gratnet evaluate`` (metrics.json) and its mean mesh FLIP of ``gratnet compare`` (docs/data/compare/NAME.json).
The fast point's figures come from assets/NAME/fast/ (metrics.json, the model file: gratnet.cost), its mesh FLIP
from docs/data/compare/fast/NAME.json (scripts/compare_paper_models.sh NAME/fast), its frame and the accurate
point's from docs/data/frame_times_1080p.json (both points must come from one run of
benchmarks/frame_time_1080p.py), its seeds from docs/data/seeds_fast.json (analysis.seed_summary).
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any

from analysis.pareto import FAST_ERROR_RATIO, frame_row, frame_times
from gratnet.atomic import write_text_atomic
from gratnet.cost import MEGABYTE, ModelCost
from gratnet.quality import ACCURATE, FAST
from trainer.datasets import PRESETS
from trainer.evaluate import STANDARD_SLICE_LABELS

__all__ = ["BASELINE_JSON", "Targets", "baseline_from_history", "fast_section", "mesh_flip", "network_description",
           "view_flips"]

BASELINE_REV = "1374b1d"
BASELINE_JSON = Path(f"docs/data/accurate_{BASELINE_REV}.json")
FAST_COMPARE = Path("docs/data/compare") / FAST
FAST_SEEDS_JSON = Path("docs/data/seeds_fast.json")


class Targets:
    """Issue 42's floors for a fast point, each against the same dataset's network at the baseline."""

    MAC_SHARE = 0.2  # MACs per pixel at most a fifth of the baseline's
    MEGABYTES = 8.0  # model file at most 8 MB (10⁶ bytes)
    FLIP_RATIO = FAST_ERROR_RATIO  # FLIP at (0°, 0°), the eight-view mean and the mesh FLIP: each ≤ 1.25×
    SPEED_UP = 3.0  # the 1080p CD frame on llvmpipe at least 3× faster, both timed in one run


def network_description(folder: Path) -> str:
    """A run folder's network in one cell: its grid (levels × features @ top resolution², t nodes, interpolation)
    and its MLP's layer sizes, from history.json and model.config.json."""
    history = json.loads((folder / "history.json").read_text(encoding="utf-8"))
    network = "-".join(map(str, history["layer_sizes"]))
    shapes = history.get("grid_shapes") or []
    if not shapes:
        return network
    config = json.loads((folder / "model.config.json").read_text(encoding="utf-8"))["train"]
    interpolation = config.get("grid", {}).get("interpolation", config.get("grid_interpolation", "linear"))
    return f"grid {len(shapes)}×{shapes[-1][3]}@{shapes[-1][1]}², t {shapes[-1][0]}, {interpolation}; MLP {network}"


def view_flips(metrics: dict[str, Any]) -> tuple[float, float]:
    """(FLIP at (0°, 0°) 2000 RU, mean FLIP over every evaluated view) of a metrics.json."""
    entries = metrics["brdf_slices"]
    normal = next(entry for entry in entries if entry["slice"] == STANDARD_SLICE_LABELS[0])
    return float(normal["flip"]), statistics.fmean(float(entry["flip"]) for entry in entries)


def mesh_flip(compare: dict[str, Any]) -> float:
    """The mean LDR-FLIP over the covered pixels of every view of a compare.json."""
    return statistics.fmean(float(view["flip_covered"]) for view in compare["views"])


REPOSITORY = Path(__file__).resolve().parents[1]


def _git(*arguments: str) -> bytes:
    return subprocess.run(["git", *arguments], cwd=REPOSITORY, check=True, capture_output=True).stdout


def baseline_from_history(revision: str = BASELINE_REV) -> dict[str, Any]:
    """Each paper-* dataset's accurate network as it was at ``revision`` (the module docstring lists the fields)."""
    commit = _git("rev-parse", "--verify", f"{revision}^{{commit}}").decode().strip()  # an unknown one fails here
    datasets: dict[str, Any] = {}
    for name in sorted(PRESETS):
        try:
            metrics = json.loads(_git("show", f"{commit}:assets/{name}/metrics.json"))
            compare = json.loads(_git("show", f"{commit}:docs/data/compare/{name}.json"))
            model = _git("show", f"{commit}:assets/{name}/model.npz")
        except subprocess.CalledProcessError:
            continue  # not shipped at that revision
        with tempfile.TemporaryDirectory() as folder:
            path = Path(folder) / "model.npz"
            path.write_bytes(model)
            cost = ModelCost.of_file(path)
        flip_0_0, flip_views = view_flips(metrics)
        datasets[name] = {"macs_per_pixel": cost.macs_per_pixel, "bytes_on_disk": len(model),
                          "flip_0_0": flip_0_0, "flip_views_mean": flip_views,
                          "views": len(metrics["brdf_slices"]), "mesh_flip_mean": mesh_flip(compare),
                          "mesh_views": len(compare["views"]), "mesh_image": compare.get("image")}
    return {"revision": commit,
            "command": f"python -m analysis.fast_points --baseline-from {revision}",
            "datasets": datasets}


def _ratio(value: float, reference: float, limit: float, *, below: bool = True) -> tuple[str, bool]:
    ratio = value / reference
    met = ratio <= limit if below else ratio >= limit
    return f"{ratio:.2f}×" + ("" if met else " (**over**)" if below else " (**under**)"), met


def _seeds(rows: list[dict[str, Any]], dataset: str) -> str:
    row = next((row for row in rows if row["dataset"] == f"{dataset}/{FAST}"), None)
    if row is None:
        return "1"
    text = f"{len(row['seeds'])}: {row['mean']:.4f} ± {row['std']:.4f}"
    if row.get("views_mean") is not None:
        text += f"; 8 views {row['views_mean']:.4f} ± {row['views_std']:.4f}"
    return text


def fast_section(assets: Path = Path("assets"), baseline_path: Path = BASELINE_JSON,
                 compare_folder: Path = FAST_COMPARE, seeds_path: Path = FAST_SEEDS_JSON,
                 record: dict | None = None) -> list[str]:
    """docs/results.md's table of the fast points against issue 42's floors (empty when none is shipped)."""
    folders = [assets / name / FAST for name in sorted(PRESETS) if (assets / name / FAST / "metrics.json").is_file()]
    if not folders or not baseline_path.exists():
        return []
    baseline = json.loads(baseline_path.read_text(encoding="utf-8"))
    seeds = json.loads(seeds_path.read_text(encoding="utf-8")) if seeds_path.exists() else []
    record = frame_times() if record is None else record
    lines = [
        "## Fast points against issue 42's floors",
        "",
        f"Each shipped fast point (`--quality fast`; assets/NAME/fast/) against the same dataset's network at main "
        f"{baseline['revision'][:7]} (docs/data/{baseline_path.name}, `{baseline['command']}`): MACs per pixel at "
        f"most {Targets.MAC_SHARE:.0%} of it, a model file of at most {Targets.MEGABYTES:g} MB, FLIP at (0°, 0°) "
        f"and over the eight views and the mean mesh FLIP of `gratnet compare` each at most {Targets.FLIP_RATIO}× "
        f"the baseline's, and the 1080p CD frame at least {Targets.SPEED_UP:g}× faster than the accurate point's, "
        "both timed in one run of benchmarks/frame_time_1080p.py. Ratios over a floor are marked **over** or "
        "**under**. Seeds: the FLIP at (0°, 0°) and the eight-view mean over the seeds trained (mean ± standard "
        "deviation; analysis.seed_summary); the shipped model is seed 0.",
        "",
        "| dataset | network | MACs/pixel (share) | grid values read | MB on disk | FLIP (0°, 0°) (ratio) "
        "| mean of 8 views (ratio) | mesh FLIP (ratio) | 1080p CD frame, fast / accurate (speed-up) | seeds "
        "| floors met |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for folder in folders:
        dataset = folder.parent.name
        old = baseline["datasets"].get(dataset)
        if old is None:
            continue
        cost = ModelCost.of_file(folder / "model.npz")
        flip_0_0, flip_views = view_flips(json.loads((folder / "metrics.json").read_text(encoding="utf-8")))
        checks = []
        share = cost.macs_per_pixel / old["macs_per_pixel"]
        checks.append(share <= Targets.MAC_SHARE)
        size = (cost.bytes_on_disk or 0) / MEGABYTE
        checks.append(size <= Targets.MEGABYTES)
        cell_0_0, met = _ratio(flip_0_0, old["flip_0_0"], Targets.FLIP_RATIO)
        checks.append(met)
        cell_views, met = _ratio(flip_views, old["flip_views_mean"], Targets.FLIP_RATIO)
        checks.append(met)
        compare_path = compare_folder / f"{dataset}.json"
        mesh = "—"
        if compare_path.exists():
            value = mesh_flip(json.loads(compare_path.read_text(encoding="utf-8")))
            cell, met = _ratio(value, old["mesh_flip_mean"], Targets.FLIP_RATIO)
            mesh = f"{value:.4f} ({cell}; [picture](images/compare_{dataset}_{FAST}.png))"
        checks.append(compare_path.exists() and met)
        fast_row, accurate_row = frame_row(record, dataset, FAST), frame_row(record, dataset, ACCURATE)
        frame = "—"
        same_run = (fast_row is not None and accurate_row is not None and record is not None
                    and fast_row.get("run", record["date"]) == accurate_row.get("run", record["date"]))
        if same_run:
            assert fast_row is not None and accurate_row is not None
            cell, met = _ratio(accurate_row["ms"], fast_row["ms"], Targets.SPEED_UP, below=False)
            frame = f"{fast_row['ms']:,.0f} / {accurate_row['ms']:,.0f} ms ({cell})"
        checks.append(same_run and met)
        lines.append(
            f"| {dataset} | {network_description(folder)} | {cost.macs_per_pixel:,} ({share:.0%}) | "
            f"{cost.grid_values_read:,} | "
            f"{size:.2f} | {flip_0_0:.4f} ({cell_0_0}) | {flip_views:.4f} ({cell_views}) | {mesh} | {frame} | "
            f"{_seeds(seeds, dataset)} | {'**all**' if all(checks) else f'{sum(checks)} of {len(checks)}'} |")
    lines += ["", "Datasets not listed have no fast point yet: `--quality fast` refuses them with one line.", ""]
    return lines


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--baseline-from", metavar="REV", help=f"write {BASELINE_JSON.parent}/accurate_REV.json from "
                        "git history instead of printing the section")
    arguments = parser.parse_args(argv)
    if arguments.baseline_from:
        try:
            baseline = baseline_from_history(arguments.baseline_from)
        except subprocess.CalledProcessError as error:
            reason = (error.stderr.decode().strip().splitlines() or ["git failed"])[0]
            print(f"fast_points: git cannot read {arguments.baseline_from}: {reason}", file=sys.stderr)
            return 2
        out = BASELINE_JSON.parent / f"accurate_{arguments.baseline_from}.json"
        write_text_atomic(out, json.dumps(baseline, indent=1) + "\n")
        print(f"wrote {out}")
        return 0
    sys.stdout.write("\n".join(fast_section()) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
