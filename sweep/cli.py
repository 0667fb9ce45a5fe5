"""``gratnet sweep SWEEP.toml``: datasets × presets × seeds × training variants, as tasks on Ray.

    gratnet sweep benchmarks/size_sweep.toml --out out/sweep --workers 2
    gratnet sweep SWEEP.toml --address auto            # a cluster started with `ray start --head`

Writes OUT/volumes/, OUT/runs/RUN/ (as ``gratnet train`` does), OUT/results.{csv,md,json}, OUT/pareto.png
and OUT/sweep.config.json (the resolved grid). Running the same command again skips finished volumes and
runs and resumes interrupted trainings. The file format is described in :mod:`sweep.spec`.
"""

from __future__ import annotations

import argparse
import sys

__all__ = ["register", "run"]


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``sweep`` subcommand."""
    parser = subparsers.add_parser(
        "sweep", help="run a grid of ground truth, training and evaluation (datasets × presets × seeds) on Ray",
        description="Read a sweep file (TOML: datasets, presets, seeds, training variants, resources), compute "
        "each volume once, train and evaluate every run as Ray tasks (a local Ray instance, or a cluster with "
        "--address), skip finished runs, resume interrupted ones, and write one results table (CSV, markdown, "
        "JSON) with a Pareto plot (mean FLIP against multiply-adds per pixel). Needs the sweep extra "
        "(pip install 'gratnet[sweep]').",
    )
    parser.add_argument("sweep", metavar="SWEEP.toml", help="the sweep file (format: see the README, Sweeps on Ray)")
    parser.add_argument("--out", metavar="DIR", help="results folder (default: the file's out, else out/sweep)")
    parser.add_argument("--address", metavar="ADDRESS",
                        help="join a running Ray cluster (host:port from `ray start --head`, or auto); "
                        "default: start a local Ray instance")
    parser.add_argument("--workers", type=int, metavar="N",
                        help="CPUs of the local Ray instance (default: all; e.g. 2 on a 2-core machine)")
    parser.add_argument("--dry-run", action="store_true", help="check the file, print the plan, run nothing")
    parser.add_argument("--quiet", action="store_true", help="no progress display")
    parser.set_defaults(handler=run)


def run(arguments: argparse.Namespace) -> int:
    """Check everything up front, then run the sweep; exit 1 when tasks failed (the others' results are kept)."""
    from gratnet.atomic import check_output_folder
    from gratnet.errors import GratNetError
    from sweep.runner import Stopped, import_ray, plan_sweep, run_sweep
    from sweep.spec import load_sweep

    if arguments.workers is not None and arguments.workers < 1:
        raise GratNetError(f"--workers must be ≥ 1, got {arguments.workers}")
    if arguments.workers is not None and arguments.address:
        raise GratNetError("--workers sizes a local Ray instance; a cluster's size is set where it is started")
    spec = load_sweep(arguments.sweep, arguments.out)
    check_output_folder(spec.out, "--out" if arguments.out is not None else f"{arguments.sweep}: out")
    if arguments.dry_run:
        plan = plan_sweep(spec)
        print(f"{spec.source}: {plan.summary()}; results in {spec.out}")
        for run in spec.runs:
            print(f"  {plan.runs[run.name]:6s} {run.name}")
        return 0
    import_ray()  # before any work: one line when Ray is missing
    try:
        rows, failures = run_sweep(spec, arguments.address, arguments.workers, progress=not arguments.quiet)
    except KeyboardInterrupt as error:  # Ctrl-C, or SIGTERM / SIGHUP (Stopped): Ray's processes are gone
        how = f" ({error})" if isinstance(error, Stopped) else ""
        print(f"gratnet sweep: interrupted{how}; finished volumes and runs are kept, and the same command resumes "
              "the rest (trainings from their last checkpoint)", file=sys.stderr)
        return 128 + error.signum if isinstance(error, Stopped) else 130
    for failure in failures:
        print(f"gratnet sweep: failed: {failure}", file=sys.stderr)
    if rows:
        print(f"wrote {spec.out / 'results.md'} (.csv, .json) and {spec.out / 'pareto.png'}: {len(rows)} of "
              f"{len(spec.runs)} runs finished")
    return 1 if failures else 0
