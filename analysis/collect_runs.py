"""Gather finished training runs into one JSON record and a Markdown table (the run tables of docs/experiments/).

    python -m analysis.collect_runs RUN[=LABEL] … [--json docs/data/NAME.json] [--meta KEY=VALUE …]
        [--figure docs/images/NAME.png]

Each RUN is a folder written by `gratnet train` (model.config.json, history.json) and evaluated by `gratnet
evaluate` (metrics.json in RUN/eval or in RUN itself, as in assets/NAME); RUN/error_budget.json, written by
analysis.error_budget --json, is added when present. A run stopped before its end has only its
checkpoint.pt: its configuration and epochs so far are read from there, with no views.

Per run the record holds the command that rebuilds it (the flags that differ from `gratnet train`'s
defaults), grid and volume bytes, parameters, training seconds, the training loss and the (0°, 0°) FLIP of
--epoch-flip-size per epoch, and per view the FLIP, PSNR (XYZ, dB), the interpolation oracle's FLIP and the
error budget. Nothing is recomputed: every figure is read from the files the runs wrote, so a table in the
docs can be regenerated from them. --figure plots every run's training loss and its per-epoch (0°, 0°)
FLIP against the epoch, side by side.
"""

from __future__ import annotations

import argparse
import datetime
import json
import math
import shlex
import sys
from pathlib import Path
from typing import Any

import numpy as np

from gratnet.atomic import atomic_path
from gratnet.config import changed_flags, flat_fields
from gratnet.errors import GratNetError
from trainer.evaluate import STANDARD_SLICES, slice_label
from trainer.train_config import TrainConfig

#: The view every ratio is taken against: the paper's headline BRDF slice.
HEADLINE = slice_label(*STANDARD_SLICES[0])


def _read_json(path: Path) -> Any:
    try:
        return json.loads(path.read_text())
    except (OSError, ValueError) as error:
        raise GratNetError(f"cannot read {path}: {error}") from error


def metrics_path(run: Path) -> Path:
    """RUN/eval/metrics.json (a training folder evaluated into eval/) or RUN/metrics.json (a shipped asset)."""
    for candidate in (run / "eval" / "metrics.json", run / "metrics.json"):
        if candidate.is_file():
            return candidate
    raise GratNetError(f"{run}: no eval/metrics.json or metrics.json (run `gratnet evaluate` on its model first)")


def check_run(run: Path) -> None:
    """Raise with one clear message if ``run`` lacks a file the record needs: a finished run's
    model.config.json, history.json and metrics, or a stopped run's checkpoint.pt."""
    if not run.is_dir():
        raise GratNetError(f"{run}: not a folder")
    if not (run / "model.config.json").is_file() and (run / "checkpoint.pt").is_file():
        return  # stopped before its end: its checkpoint holds the configuration and the epochs so far
    for name in ("model.config.json", "history.json"):
        if not (run / name).is_file():
            raise GratNetError(f"{run}: no {name} and no checkpoint.pt (not a `gratnet train` output folder)")
    metrics_path(run)


def _stopped_run(run: Path) -> tuple[dict[str, Any], dict[str, Any]]:
    """(model config, history) of a run stopped before its end, from its checkpoint.pt."""
    from trainer.train import read_checkpoint

    state = read_checkpoint(run / "checkpoint.pt")
    return {"train": state["config"], "volume": None}, state["history"]


def train_config(train: dict[str, Any]) -> TrainConfig:
    """The run's TrainConfig from its saved dict (fields added since take their defaults; unknown ones are dropped)."""
    known = set(TrainConfig.__dataclass_fields__) | set(flat_fields(TrainConfig))  # nested and pre-nesting flat keys
    return TrainConfig(**{name: value for name, value in train.items() if name in known})


def train_command(config: TrainConfig, volume: str | None) -> str:
    """`gratnet train VOLUME --out RUN FLAGS…` with only the flags that differ from the defaults."""
    return shlex.join(["gratnet", "train", Path(volume).name if volume else "VOLUME", "--out", "RUN",
                       *changed_flags(config)])


def _grid_bytes(config: TrainConfig) -> int:
    """Bytes of the run's grids as the model file stores them (``--grid-dtype``)."""
    return sum(t * rv * ru * c for t, rv, ru, c in config.grid_shapes()) * np.dtype(config.grid.dtype).itemsize


def collect_run(run: Path, label: str) -> dict[str, Any]:
    """One run's record (see the module docstring)."""
    check_run(run)
    stopped = not (run / "model.config.json").is_file()
    if stopped:
        model_config, history = _stopped_run(run)
        metrics: dict[str, Any] = {}
    else:
        model_config = _read_json(run / "model.config.json")
        history = _read_json(run / "history.json")
        metrics = _read_json(metrics_path(run))
    epochs = history.get("epochs", [])
    slices = metrics.get("brdf_slices", [])
    config = train_config(model_config.get("train", {}))
    record: dict[str, Any] = {
        "run": label,
        "folder": str(run),
        "command": train_command(config, model_config.get("volume")),
        "stopped_after_epoch": len(epochs) if stopped else None,
        "epochs_planned": config.epochs,
        "grid_bytes": history.get("grid_bytes", _grid_bytes(config)),
        "volume_bytes": history.get("volume_bytes"),
        "parameters": history.get("parameters"),
        "train_seconds": history.get("train_seconds"),
        "final_loss": epochs[-1]["train_loss"] if epochs else None,
        "epoch_loss": [epoch.get("train_loss") for epoch in epochs],
        "epoch_slice_flip_128": [epoch.get("slice_flip") for epoch in epochs],
        "flip": {view["slice"]: view["flip"] for view in slices},
        "psnr_xyz": {view["slice"]: view["psnr_xyz"] for view in slices},
        "oracle_flip": {view["slice"]: view["oracle_flip"] for view in slices if view.get("oracle_flip") is not None},
    }
    budget_file = run / "error_budget.json"
    if budget_file.is_file():
        budget = _read_json(budget_file)
        target = budget.get("target")
        record["error_budget"] = {
            view["label"]: {
                "network": view["network"]["flip"],
                "sigma_px": view["network"]["sigma_px"],
                "shuffled": view["shuffled"]["flip"],
                f"k_at_{target}": view.get("scale_at_target"),
                f"white_sigma_at_{target}": view.get("white_sigma_at_target"),
            }
            for view in budget.get("views", [])
        }
    return record


def markdown_table(runs: list[dict[str, Any]]) -> str:
    """One row per run: grid bytes and share, loss, training time, FLIP per view, their mean and the worst
    other view against (0°, 0°), and PSNR at (0°, 0°). Views in the order the runs first name them."""
    views = list(dict.fromkeys(view for run in runs for view in run["flip"]))
    head = ["run", "grid (share of the volume)", "final loss", "training", *views, "mean", "worst other / (0°, 0°)",
            "PSNR (0°, 0°)"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for run in runs:
        flips = [run["flip"].get(view) for view in views]
        present = [value for value in flips if value is not None]
        headline = run["flip"].get(HEADLINE)
        others = [value for view, value in run["flip"].items() if view != HEADLINE]
        share = (f"{run['grid_bytes'] / 1e6:.2f} MB ({100 * run['grid_bytes'] / run['volume_bytes']:.1f} %)"
                 if run.get("volume_bytes") else f"{run['grid_bytes'] / 1e6:.2f} MB")
        name = run["run"]
        if run.get("stopped_after_epoch") is not None:
            name += f" (stopped after epoch {run['stopped_after_epoch']} of {run['epochs_planned']})"
        cells = [
            name, share,
            f"{run['final_loss']:.3g}" if run.get("final_loss") is not None else "—",
            f"{run['train_seconds']:,.0f} s" if run.get("train_seconds") is not None else "—",
            *(f"{value:.4f}" if value is not None else "—" for value in flips),
            f"{sum(present) / len(present):.4f}" if present else "—",
            f"{max(others) / headline:.2f}×" if headline and others else "—",
            f"{run['psnr_xyz'][HEADLINE]:.1f} dB" if HEADLINE in run["psnr_xyz"] else "—",
        ]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def plot_runs(runs: list[dict[str, Any]], target: Path) -> None:
    """Two panels against the epoch: the training loss (log scale) and the (0°, 0°) 2000 RU FLIP at 128² that
    `gratnet train --epoch-flip-size 128` records; a run without one is left out of that panel."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from gratnet.figures import save_figure

    figure, (loss_axis, flip_axis) = plt.subplots(1, 2, figsize=(10.0, 3.8), dpi=110, layout="constrained")
    try:
        for run in runs:
            losses = [math.nan if value is None else value for value in run["epoch_loss"]]
            line, = loss_axis.plot(range(1, len(losses) + 1), losses, marker=".", label=run["run"])
            flips = [math.nan if value is None else value for value in run["epoch_slice_flip_128"]]
            if not all(math.isnan(value) for value in flips):
                flip_axis.plot(range(1, len(flips) + 1), flips, marker="o", markersize=3, color=line.get_color(),
                               label=run["run"])
        loss_axis.set_yscale("log")
        loss_axis.set_xlabel("epoch")
        loss_axis.set_ylabel("training loss (LogCosh of range-transformed XYZ)")
        loss_axis.legend(fontsize=7)
        flip_axis.set_yscale("log")
        flip_axis.set_xlabel("epoch")
        flip_axis.set_ylabel(f"mean FLIP, {HEADLINE} at 128²")
        flip_axis.grid(alpha=0.3, which="both")
        save_figure(figure, target)
    finally:
        plt.close(figure)


def parse_run(text: str) -> tuple[Path, str]:
    """``RUN`` or ``RUN=LABEL`` → (folder, label); the label defaults to the folder's name."""
    folder, _, label = text.partition("=")
    return Path(folder), label or Path(folder).name


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("runs", nargs="+", metavar="RUN[=LABEL]", help="training output folders")
    parser.add_argument("--json", type=Path, help="write the record here (atomically)")
    parser.add_argument("--meta", action="append", default=[], metavar="KEY=VALUE",
                        help="a top-level field of the record (machine, volume, evaluate command …); repeatable")
    parser.add_argument("--figure", type=Path, help="write the loss and per-epoch FLIP curves here (PNG)")
    args = parser.parse_args()
    try:
        runs = [parse_run(text) for text in args.runs]
        meta = {}
        for item in args.meta:
            key, separator, value = item.partition("=")
            if not separator or not key:
                raise GratNetError(f"--meta needs KEY=VALUE, got {item!r}")
            meta[key] = value
        for folder, _ in runs:
            check_run(folder)
        records = [collect_run(folder, label) for folder, label in runs]
    except GratNetError as error:
        sys.exit(f"collect_runs: {error}")
    print(markdown_table(records))
    if args.json:
        record = {"date": datetime.date.today().isoformat(), **meta, "runs": records}
        with atomic_path(args.json) as temporary:
            temporary.write_text(json.dumps(record, indent=1, ensure_ascii=False) + "\n")
    if args.figure:
        plot_runs(records, args.figure)


if __name__ == "__main__":
    main()
