"""The honest baseline: the ground-truth volume as a look-up table against the network, in memory, time and error.

For one material and its training volume: the network, and the volume looked up per pixel (viewer.reference:
trilinear in (u*, v*, t), float16 storage) at full resolution and with only every k-th u*/v* sample kept
(``--strides 1,4``: 1001² and 251², the finest grid level of the shipped paper models), each given as

- memory (MB): the network's model file (weights and grids as stored) against the look-up's texture bytes;
- milliseconds per frame: the CD disc at the material's default view (``gratnet render``'s), ``--frame`` pixels
  (1920x1080), 1 sample per pixel, the median of ``--repeats`` renders after one untimed render, on this
  machine's OpenGL (llvmpipe here);
- mean LDR-FLIP on the exact BRDF slices (the paper's five at ``--slice-size``): the network's from its
  metrics.json (``gratnet evaluate``), the table's from ``analysis.oracle_table``'s oracle (the same
  trilinear look-up in float32; the float16 texture's rounding, 2⁻¹¹, is below what FLIP resolves).

    python benchmarks/lut_baseline.py paper-cd VOLUME.exr [--strides 1,4] [--frame 1920x1080] [--repeats 3]
        [--cache-dir out/cache] [--json docs/data/lut_baseline_paper-cd.json] [--figure docs/images/lut_baseline.png]
    python benchmarks/lut_baseline.py --plot-only --json ROWS.json [ROWS.json ...] --figure PLOT.png

Prints a markdown table; --json writes every figure, --figure plots error against frame time (one colour per
material, a circle for the network, a square for the full table and triangles for smaller ones; the legend gives
each one's memory). --plot-only draws the rows of one or more earlier runs (several materials in one plot) without
measuring anything. The benchmark's command is benchmarks/lut_baseline.py (``python -m analysis.lut_baseline``
runs the same).
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

from analysis.oracle_table import decimated, oracle_rows  # the oracle's slices and metrics
from gratnet.atomic import atomic_path, write_text_atomic
from gratnet.modelfile import load_model
from gratnet.reference import texture_bytes
from gratnet.volume import Volume, read_volume
from trainer.evaluate import STANDARD_SLICE_LABELS
from viewer.camera import Camera, Light
from viewer.catalog import build_mesh, resolve_material
from viewer.context import create_headless_context
from viewer.defaults import resolve_defaults
from viewer.scene import SceneRenderer


def frame_ms(scene: SceneRenderer, size: tuple[int, int], material: str, repeats: int) -> float:
    """Median wall time (ms) of one CD-disc render at ``material``'s default view, after one untimed render."""
    view = resolve_defaults(material, "cd")
    camera = Camera(view.camera_distance, view.camera_azimuth_degrees, view.camera_elevation_degrees)
    light = Light.directional(view.light_theta_degrees, view.light_phi_degrees)
    mesh = scene.upload(build_mesh("cd"))
    try:
        scene.render_rgba(mesh, camera, light, size, view.exposure)
        times = []
        for _ in range(repeats):
            start = time.perf_counter()
            scene.render_rgba(mesh, camera, light, size, view.exposure)
            scene.ctx.finish()
            times.append(1e3 * (time.perf_counter() - start))
    finally:
        mesh.release()
    return statistics.median(times)


def measure(material: str, volume_path: Path, strides: list[int], size: tuple[int, int], repeats: int,
            slice_size: int, cache_dir: str) -> list[dict[str, Any]]:
    """One row for the network, one per stride for the look-up table."""
    model_path = resolve_material(material)
    metrics = json.loads((model_path.parent / "metrics.json").read_text(encoding="utf-8"))
    paper_slices = set(STANDARD_SLICE_LABELS)
    network_flip = [entry["flip"] for entry in metrics["brdf_slices"] if entry["slice"] in paper_slices]
    if len(network_flip) != len(paper_slices):  # like for like: the oracle scores exactly these five
        raise SystemExit(f"lut_baseline: {model_path.parent / 'metrics.json'} lacks some of the paper's five slices")
    volume = read_volume(volume_path)
    ctx = create_headless_context()
    rows: list[dict[str, Any]] = []
    try:
        with SceneRenderer(ctx, load_model(model_path)) as scene:
            assert scene.network is not None  # a model file's scene shades with its network
            rows.append({"what": "network", "material": material, "mb": model_path.stat().st_size / 1e6,
                         "ms_per_frame": frame_ms(scene, size, material, repeats),
                         "flip_slices": network_flip, "renderer": ctx.info.get("GL_RENDERER"),
                         "weights_path": scene.network.weights_path, "render_path": scene.render_path})
        for stride in strides:
            table = decimated(volume, stride) if stride > 1 else volume
            oracle, _ = oracle_rows(volume_path, slice_size, cache_dir, True, uv_stride=stride)
            with SceneRenderer(ctx, Volume(table.xyz, table.metadata)) as scene:
                rows.append({"what": f"look-up {table.resolution}² × {table.slices}", "material": material,
                             "mb": texture_bytes(table.slices, table.resolution) / 1e6,
                             "ms_per_frame": frame_ms(scene, size, material, repeats),
                             "flip_slices": [entry["flip"] for entry in oracle["brdf_slices"]], "uv_stride": stride,
                             "renderer": ctx.info.get("GL_RENDERER")})
    finally:
        ctx.release()
    for row in rows:
        row["flip_mean"] = float(np.mean(row["flip_slices"]))
        row["frame"] = f"{size[0]}x{size[1]}"
    return rows


def markdown(rows: list[dict[str, Any]]) -> str:
    lines = ["| material | shading | memory (MB) | ms per frame | FLIP (0°, 0°) | mean FLIP, 5 slices |",
             "|---|---|---|---|---|---|"]
    for row in rows:
        lines.append(f"| {row['material']} | {row['what']} | {row['mb']:.1f} | {row['ms_per_frame']:.0f} | "
                     f"{row['flip_slices'][0]:.4f} | {row['flip_mean']:.4f} |")
    return "\n".join(lines) + "\n"


def figure(rows: list[dict[str, Any]], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    drawing = plt.figure(figsize=(8.0, 4.2), layout="constrained")
    axes = drawing.gca()
    materials = list(dict.fromkeys(row["material"] for row in rows))
    markers = {}  # the network a circle; each material's tables, largest first: square, triangles, diamond
    for material in materials:
        tables = sorted((row for row in rows if row["material"] == material and row["what"] != "network"),
                        key=lambda row: -row["mb"])
        markers.update({id(row): ("s", "^", "v", "D")[min(rank, 3)] for rank, row in enumerate(tables)})
    for row in rows:  # a legend rather than labels at the points: tables of several materials lie close together
        axes.scatter(row["ms_per_frame"], row["flip_mean"], marker=markers.get(id(row), "o"), s=40,
                     color=f"C{materials.index(row['material']) % 10}",
                     label=f"{row['material']} {row['what']}, {row['mb']:.1f} MB")
    axes.set_xlabel(f"ms per {rows[0]['frame']} frame (CD disc, 1 spp, {rows[0].get('renderer', '?')})", fontsize=8)
    axes.set_ylabel("mean LDR-FLIP, the paper's five BRDF slices")
    axes.set_title("network against the ground-truth volume as a look-up table", fontsize=9)
    axes.set_yscale("log")
    axes.set_xscale("log")
    axes.legend(fontsize=7, loc="center left", bbox_to_anchor=(1.01, 0.5), frameon=False)
    with atomic_path(path) as temporary:
        drawing.savefig(temporary, format="png", dpi=110)
    plt.close(drawing)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("material", nargs="?", help="shipped material (not with --plot-only)")
    parser.add_argument("volume", type=Path, nargs="?", help="its training volume, VOLUME.exr (not with --plot-only)")
    parser.add_argument("--strides", default="1,4", help="u*/v* strides of the table, comma-separated")
    parser.add_argument("--frame", default="1920x1080", help="frame size WxH, pixels")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--slice-size", type=int, default=256)
    parser.add_argument("--cache-dir", default="out/cache")
    parser.add_argument("--json", type=Path, nargs="+", help="where to write the rows (one file); with --plot-only, "
                        "the rows to draw (one or more files)")
    parser.add_argument("--figure", type=Path)
    parser.add_argument("--plot-only", action="store_true", help="draw --figure from the rows in --json (no runs)")
    arguments = parser.parse_args(argv)
    if arguments.plot_only:
        if not (arguments.json and arguments.figure) or arguments.material or arguments.volume:
            parser.error("--plot-only takes --json ROWS.json [...] and --figure, and no material or volume")
        missing = [str(path) for path in arguments.json if not path.is_file()]
        if missing:
            parser.error(f"--json: no such file: {', '.join(missing)}")
        figure([row for path in arguments.json for row in json.loads(path.read_text(encoding="utf-8"))],
               arguments.figure)
        return 0
    if not (arguments.material and arguments.volume):
        parser.error("a material and its volume are needed (or --plot-only)")
    if arguments.json and len(arguments.json) > 1:
        parser.error("--json takes one file when measuring")
    try:
        strides = [int(part) for part in arguments.strides.split(",")]
        width, height = (int(part) for part in arguments.frame.lower().split("x"))
    except ValueError:
        parser.error("--strides takes integers (1,4) and --frame WxH (1920x1080)")
    rows = measure(arguments.material, arguments.volume, strides, (width, height), arguments.repeats,
                   arguments.slice_size, arguments.cache_dir)
    sys.stdout.write(markdown(rows))
    if arguments.json:
        write_text_atomic(arguments.json[0], json.dumps(rows, indent=1) + "\n")
    if arguments.figure:
        figure(rows, arguments.figure)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
