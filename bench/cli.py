"""``gratnet bench``: run time against error for trained models, and mesh-scene frame times (a benchmark,
not a test).

    gratnet bench assets/*/model.npz out/sweep/*/model.npz --out out/bench
    gratnet bench cd --no-slices --scene-sizes 1920x1080 --spp 1,4 --out out/bench-scenes
    gratnet bench cd --no-slices --render-paths deferred --deferred-weights auto,tiled --out out/bench-tiled
    gratnet bench MODEL --no-slices --scene-sizes 1920x1080 --spp 1 --weights-paths auto --render-paths auto \
        --out DIR    # the 1080p CD frame as one row of DIR/scenes.jsonl (gratnet evaluate --frame-time's call)

Each MATERIAL is a shipped material name (``assets/NAME/model.npz``) or a model-file path; the error
figures come from the ``metrics.json`` beside each model file. Writes OUT/bench.json, OUT/bench.md and
OUT/pareto.png (BRDF slices), OUT/scenes.jsonl and OUT/scenes.md (mesh scenes), and OUT/bench.config.json.
Every row and table states the model's cost (gratnet.cost: MACs and grid values read per pixel, bytes on disk
and on the GPU). See :mod:`bench.slices` and :mod:`bench.scenes` for what is measured.
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
        "slices, from metrics.json beside the model) against frame time, with the Pareto front. Then time "
        "mesh scenes (the CD disc as gratnet render sets it up) per weights path, render path and samples "
        "per pixel, at full HD and the viewer's size.",
        epilog="typical use:\n  gratnet bench --sizes 256,512 --out out/bench\n"
        "  gratnet bench cd --no-slices --scene-sizes 1920x1080 --spp 1,4 --out out/bench-scenes",
    )
    parser.add_argument("models", nargs="*", metavar="MATERIAL",
                        help="shipped material names or model-file paths (default: every shipped material)")
    parser.add_argument("--out", required=True, metavar="DIR", help="output folder (bench.json, bench.md, pareto.png)")
    add_quiet_flag(parser)
    from bench.slices import BenchConfig

    add_arguments(parser, BenchConfig)
    parser.set_defaults(handler=run)


def run(arguments: argparse.Namespace) -> int:
    from bench.scenes import run_scene_bench, write_scene_outputs
    from bench.slices import BenchConfig, ModelEntry, run_bench, write_outputs
    from gratnet.atomic import check_output_folder
    from gratnet.brdf import check_exposure
    from gratnet.errors import GratNetError
    from viewer.catalog import check_mesh_spec, resolve_material, shipped_materials
    from viewer.context import create_headless_context

    config = from_arguments(BenchConfig, arguments)
    config.size_list(), config.path_list()  # validate before any work
    config.scene_size_list(), config.render_path_list(), config.spp_list(), config.deferred_weights_list()
    check_mesh_spec(config.scene_mesh)
    check_exposure(config.exposure)
    if not (config.slices or config.scenes):
        raise GratNetError("--no-slices and --no-scenes together leave nothing to measure")
    out = check_output_folder(arguments.out)
    names = arguments.models or shipped_materials()
    entries = []
    for name in names:
        path = resolve_material(name)
        label = path.parent.name if path.name == "model.npz" else path.stem
        entries.append(ModelEntry.load(path, label))
    ctx = create_headless_context()
    try:
        results = run_bench(ctx, entries, config, progress=not arguments.quiet) if config.slices else []
        scenes = run_scene_bench(ctx, entries, config, progress=not arguments.quiet) if config.scenes else []
    finally:
        ctx.release()
    written = []
    if config.slices:
        write_outputs(results, out)
        written += [out / "bench.md", out / "bench.json", out / "pareto.png"]
    if config.scenes:
        write_scene_outputs(scenes, out)
        written += [out / "scenes.md", out / "scenes.jsonl"]
    save_config(out / "bench.json", bench=config, models=[str(entry.path) for entry in entries])
    print(f"wrote {', '.join(str(path) for path in written)}")
    return 0
