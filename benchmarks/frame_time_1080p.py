"""The 1080p CD frame time of every shipped material (or the given models) on this machine, with each model's cost.

    python benchmarks/frame_time_1080p.py        # every shipped material, each point → docs/data/frame_times_1080p.json
    python benchmarks/frame_time_1080p.py paper-cd assets/cd/model.npz --out /tmp/frames.json
    python benchmarks/frame_time_1080p.py paper-cd --update   # re-time one material's points (all in one run)

Each model is timed by ``gratnet bench`` in a child process, exactly as ``gratnet evaluate --frame-time`` times it
(trainer.evaluate.measure_frame_time): the CD disc as ``gratnet render --mesh cd`` draws it at 1920×1080, one sample
per pixel, auto weights and render paths; the figure is the median wall time of ``--repeats`` frames after a
warm-up (read-back included). The models run one after another, so that no two share the machine. Prints one JSON
line per model and writes one JSON record (atomically): the date, the machine (CPU, cores, GL_RENDERER), this
command, the load average before and after, and per model its frame and its cost (gratnet.cost).
docs/results.md shows the record's frames beside each material (python -m analysis.results_table). A CPU
rasterizer's times follow the machine's load: run it on an otherwise idle machine.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import shlex
import sys
import time
from pathlib import Path
from typing import Any

from analysis.pareto import FRAME_TIMES_JSON
from gratnet.atomic import write_text_atomic
from gratnet.cost import ModelCost
from gratnet.errors import GratNetError
from trainer.evaluate import FRAME_TIME_REPEATS, FRAME_TIME_SIZE, measure_frame_time
from viewer.catalog import material_points, resolve_material, shipped_materials

#: Where docs/results.md (analysis.results_table, analysis.pareto) reads the frames from.
DEFAULT_OUT = FRAME_TIMES_JSON


def _size(text: str) -> tuple[int, int]:
    try:
        width, height = (int(part) for part in text.lower().replace("×", "x").split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected WxH such as 1920x1080, got {text!r}") from None
    if not (1 <= width <= 16384 and 1 <= height <= 16384):
        raise argparse.ArgumentTypeError(f"each side must lie in 1 … 16384, got {text!r}")
    return width, height


def machine() -> dict[str, Any]:
    """The CPU (its model name from /proc/cpuinfo where there is one), its cores and the platform."""
    cpu = platform.processor() or "unknown"
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return {"cpu": cpu, "cores": os.cpu_count(), "platform": platform.platform(), "python": platform.python_version()}


def _label(path: Path) -> str:
    return path.parent.name if path.name == "model.npz" else path.stem


def _shown(path: Path) -> str:
    """``path`` relative to the working folder where it lies below it (the record is committed), else as is."""
    try:
        return path.resolve().relative_to(Path.cwd().resolve()).as_posix()
    except ValueError:
        return str(path)


def _updated(old: dict[str, Any] | None, record: dict[str, Any]) -> dict[str, Any]:
    """The record ``old`` with ``record``'s rows in place of its rows of the same model (material and point) and
    ``record``'s run added to its ``updates``; ``record`` itself where there is no ``old``."""
    if old is None:
        return record
    timed = {(row["material"], row["quality"]) for row in record["models"]}
    kept = [row for row in old["models"] if (row["material"], row["quality"]) not in timed]
    run = {key: record[key] for key in ("date", "command", "load_average_before", "load_average_after")}
    models = kept + record["models"]
    # A run stays listed while some row is still its (a row names its run by the run's start date).
    runs = [entry for entry in [*old.get("updates", []), run] if any(row.get("run") == entry["date"] for row in models)]
    return {**old, "models": models, "updates": runs}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("models", nargs="*", metavar="MATERIAL",
                        help="shipped material names (each with all its quality points: accurate, fast) or model-file "
                             "paths (default: every shipped material)")
    parser.add_argument("--size", type=_size, default=FRAME_TIME_SIZE, metavar="WxH",
                        help="frame size (default 1920x1080; another size needs its own --out)")
    parser.add_argument("--repeats", type=int, default=FRAME_TIME_REPEATS, help="timed frames per model (median)")
    parser.add_argument("--timeout", type=float, default=1800.0, help="seconds one model's bench may take")
    parser.add_argument("--out", type=Path, default=None, help=f"the JSON record (default {DEFAULT_OUT})")
    parser.add_argument("--update", action="store_true",
                        help="keep the record's other models and replace only the rows timed now (each row keeps "
                             "its own date, load and command; the record lists under 'updates' each later run that "
                             "still owns rows)")
    arguments = parser.parse_args(argv)
    if arguments.out is None and tuple(arguments.size) != FRAME_TIME_SIZE:
        parser.error(f"--size {arguments.size[0]}x{arguments.size[1]} is not 1080p: give --out (the default "
                     f"{DEFAULT_OUT} holds 1920x1080 frames only)")
    if arguments.repeats < 1:
        parser.error("--repeats must be ≥ 1")
    out = arguments.out or DEFAULT_OUT
    try:  # (material, quality point or None for a model-file path, model file)
        items: list[tuple[str, str | None, Path]] = []
        for name in arguments.models or shipped_materials():
            path = resolve_material(name)  # an unknown name: one line, before any timing
            try:
                items += [(name, quality, point) for quality, point in material_points(name).items()]
            except GratNetError:  # a model-file path: no points of its own
                items.append((_label(path), None, path))
    except GratNetError as error:
        print(f"frame_time_1080p: {error}", file=sys.stderr)
        return 2
    old = None
    if arguments.update and out.exists():  # checked before any timing
        try:
            old = json.loads(out.read_text(encoding="utf-8"))
        except (OSError, ValueError) as error:
            parser.error(f"--update: cannot read {out}: {error}")
        if (old.get("width"), old.get("height")) != tuple(arguments.size):
            parser.error(f"--update: {out} holds {old.get('width')}x{old.get('height')} frames, not "
                         f"{arguments.size[0]}x{arguments.size[1]}")
    command = shlex.join(["python", "benchmarks/frame_time_1080p.py", *(argv if argv is not None else sys.argv[1:])])
    load_before = [round(value, 2) for value in os.getloadavg()]
    started = time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())
    rows, failed = [], 0
    for material, quality, path in items:
        row: dict[str, Any] = {"material": material, "quality": quality, "model_file": _shown(path), "run": started}
        try:
            row.update(ModelCost.of_file(path).to_dict())
            row.update(measure_frame_time(path, tuple(arguments.size), arguments.repeats, arguments.timeout))
        except GratNetError as error:
            row["error"] = str(error)
            failed += 1
        rows.append(row)
        print(json.dumps(row), flush=True)
    renderers = sorted({row["gl_renderer"] for row in rows if "gl_renderer" in row})
    record = {
        "what": "CD frame time per model, as gratnet render --mesh cd draws it (median wall ms, 1 spp, auto paths)",
        "date": started, "command": command, "machine": {**machine(), "gl_renderer": ", ".join(renderers) or None},
        "width": arguments.size[0], "height": arguments.size[1], "repeats": arguments.repeats,
        "load_average_before": load_before, "load_average_after": [round(value, 2) for value in os.getloadavg()],
        "models": rows,
    }
    if arguments.update:
        record = _updated(old, record)
    write_text_atomic(out, json.dumps(record, indent=1, allow_nan=False) + "\n")
    print(f"wrote {out}", file=sys.stderr)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
