"""``gratnet bench``: run time against error for trained models (a benchmark, not a test).

    gratnet bench assets/*/model.npz out/sweep/*/model.npz --out out/bench

Each MATERIAL is a shipped material name (``assets/NAME/model.npz``) or a model-file path; the error
figures come from the ``metrics.json`` beside each model file. Writes OUT/bench.json, OUT/bench.md,
OUT/pareto.png and OUT/bench.config.json. See :mod:`trainer.bench` for what is measured.
"""

from __future__ import annotations

import argparse

from gratnet.config import add_arguments, add_quiet_flag, from_arguments, save_config

__all__ = ["register", "run"]


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``bench`` subcommand."""
    parser = subparsers.add_parser(
        "bench", help="shader frame time and MLP throughput vs torch, against each model's error (table + plot)",
        description="Time the GLSL BRDF-slice program (texture and baked weight paths, skip-work off) and the same "
        "MLP in torch on the same key vectors, for each model; plot its error (mean FLIP of the evaluation "
        "slices, from metrics.json beside the model) against frame time, with the Pareto front.",
        epilog="typical use:\n  gratnet bench --sizes 256,512 --out out/bench",
    )
    parser.add_argument("models", nargs="*", metavar="MATERIAL",
                        help="shipped material names or model-file paths (default: every shipped material)")
    parser.add_argument("--out", required=True, metavar="DIR", help="output folder (bench.json, bench.md, pareto.png)")
    add_quiet_flag(parser)
    from trainer.bench import BenchConfig

    add_arguments(parser, BenchConfig)
    parser.set_defaults(handler=run)


def run(arguments: argparse.Namespace) -> int:
    from gratnet.atomic import check_output_folder
    from gratnet.brdf import check_exposure
    from trainer.bench import BenchConfig, ModelEntry, run_bench, write_outputs
    from viewer.context import create_headless_context
    from viewer.render_cli import resolve_material, shipped_materials

    config = from_arguments(BenchConfig, arguments)
    config.size_list(), config.path_list()  # validate before any work
    check_exposure(config.exposure)
    out = check_output_folder(arguments.out)
    names = arguments.models or shipped_materials()
    entries = []
    for name in names:
        path = resolve_material(name)
        label = path.parent.name if path.name == "model.npz" else path.stem
        entries.append(ModelEntry.load(path, label))
    ctx = create_headless_context()
    try:
        results = run_bench(ctx, entries, config, progress=not arguments.quiet)
    finally:
        ctx.release()
    write_outputs(results, out)
    save_config(out / "bench.json", bench=config, models=[str(entry.path) for entry in entries])
    print(f"wrote {out / 'bench.md'}, {out / 'bench.json'} and {out / 'pareto.png'}")
    return 0
