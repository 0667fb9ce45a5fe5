#!/usr/bin/env python3
"""Render every shipped material and compare the renders of two drivers (issue 32 item 4: "the same picture on
every driver"; docs/physics.md, "Float32 error budget").

    python scripts/gpu_check_compare.py render OUT [--materials a,b] [--meshes cd,sphere] [--paths forward,deferred]
                                        [--size 640,480] [--weights-path texture] [--like DIR]
    python scripts/gpu_check_compare.py compare REFERENCE_DIR TEST_DIR [--json FILE] [--target 0.001]
    python scripts/gpu_check_compare.py check GPU_DIR [--local DIR]   # render here like GPU_DIR, then compare
                                                                      # (DIR: out/gpu-check-llvmpipe)

``render`` writes ``MATERIAL_MESH_PATH.exr`` (linear sRGB, exposure applied: ``gratnet render``'s EXR) and its
``.config.json`` for every shipped material (assets/*/model.npz) on each mesh and render path, at each
material's default view; ``--like DIR`` takes the light, camera and exposure of DIR's renders of the same names
instead, so both sides draw exactly the same scene. scripts/gpu_check.sh runs ``render`` on a lent GPU.

``compare`` reports per image the mean LDR-FLIP of the display sRGB (``gratnet.display.ldr_flip``; target ≤
0.001), the largest and median relative difference over lit pixels (≥ 10⁻³ of the image's peak) and how many
lit pixels differ by more than 1 %, as a table on stdout and, with ``--json``, a file. Exit status 1 when an
image misses the FLIP target, 0 otherwise.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

from viewer.scene_config import read_render_exr

REPO = Path(__file__).resolve().parents[1]
if str(REPO) not in sys.path:  # run as a script from anywhere: the checkout's packages first
    sys.path.insert(0, str(REPO))

MESHES = ("cd", "sphere")
PATHS = ("forward", "deferred")
SIZE = "640,480"
#: The issue's target: mean FLIP per image between two drivers.
FLIP_TARGET = 0.001
#: Lit pixels: at least this share of the image's brightest channel value (darker ones are FLIP's business).
LIT_SHARE = 1e-3


def shipped_materials() -> list[str]:
    """Names of the shipped materials: folders of assets/ with a model.npz, sorted."""
    return sorted(path.parent.name for path in (REPO / "assets").glob("*/model.npz"))


def _view_flags(config_file: Path) -> list[str]:
    """The light, camera and exposure of a render's ``.config.json`` as ``gratnet render`` flags."""
    render = json.loads(config_file.read_text())["render"]
    flags = ["--camera", f"{render['camera_distance']!r},{render['camera_azimuth_degrees']!r},"
                         f"{render['camera_elevation_degrees']!r}",
             "--exposure", repr(render["exposure"]), "--fov", repr(render["fov_degrees"])]
    if render.get("point_light"):
        flags += ["--point-light", ",".join(repr(float(c)) for c in render["point_light"])]
    else:
        flags += ["--light", f"{render['light_theta_degrees']!r},{render['light_phi_degrees']!r}"]
    return flags


def render_all(out: Path, materials: list[str], meshes: list[str], paths: list[str], size: str, weights: str,
               like: Path | None = None) -> list[dict[str, Any]]:
    """Render every (material, mesh, path) into ``out`` with ``gratnet render`` (in this process); with ``like``,
    only the names ``like`` has, at its views. Returns one record per render (name, seconds, exit status)."""
    from gratnet.cli import main

    out.mkdir(parents=True, exist_ok=True)
    records = []
    for material in materials:
        for mesh in meshes:
            for path in paths:
                name = f"{material}_{mesh}_{path}"
                flags = []
                if like is not None:
                    config = like / f"{name}.config.json"
                    if not config.is_file():
                        continue
                    flags = _view_flags(config)
                start = time.perf_counter()
                status = main(["render", "--material", material, "--mesh", mesh, "--size", size, "--render-path", path,
                               "--weights-path", weights, "--quiet", "--out", str(out / f"{name}.exr"), *flags])
                records.append({"name": name, "seconds": round(time.perf_counter() - start, 2), "status": status})
                print(f"{name}: exit {status}, {records[-1]['seconds']} s", flush=True)
    (out / "renders.json").write_text(json.dumps(records, indent=1) + "\n")
    return records


def display(linear: np.ndarray) -> np.ndarray:
    """Linear sRGB (exposure applied) → display sRGB in [0, 1] (clipped, the sRGB transfer function)."""
    import colour

    encoded = colour.cctf_encoding(np.clip(linear, 0.0, 1.0), function="sRGB")
    return np.clip(np.asarray(encoded, dtype=np.float64), 0.0, 1.0)


def compare_images(reference: np.ndarray, test: np.ndarray) -> dict[str, float]:
    """FLIP of the display images and relative differences over lit pixels of two linear sRGB images."""
    from gratnet.display import ldr_flip

    if reference.shape != test.shape:
        return {"flip": float("inf"), "max_relative": float("inf"), "median_relative": float("inf"),
                "over_1_percent": -1, "lit": 0}
    flip, _ = ldr_flip(display(reference), display(test))
    peak = float(np.abs(reference).max())
    lit = np.abs(reference).max(axis=-1) >= LIT_SHARE * peak if peak > 0 else np.zeros(reference.shape[:2], bool)
    relative = (np.abs(test - reference) / np.maximum(np.abs(reference), LIT_SHARE * peak)).max(axis=-1)[lit]
    return {"flip": float(flip), "max_relative": float(relative.max(initial=0.0)),
            "median_relative": float(np.median(relative)) if relative.size else 0.0,
            "over_1_percent": int(np.count_nonzero(relative > 0.01)), "lit": int(lit.sum())}


def compare_dirs(reference_dir: Path, test_dir: Path) -> list[dict[str, Any]]:
    """:func:`compare_images` for every EXR of ``reference_dir`` that ``test_dir`` has too, by name."""
    rows = []
    for reference in sorted(reference_dir.glob("*.exr")):
        test = test_dir / reference.name
        if not test.is_file():
            rows.append({"name": reference.stem, "missing": True})
            continue
        rows.append({"name": reference.stem, **compare_images(read_render_exr(reference), read_render_exr(test))})
    return rows


def table(rows: list[dict[str, Any]], target: float) -> str:
    lines = ["| image | FLIP | max relative | median relative | lit pixels > 1 % | verdict |",
             "|---|---|---|---|---|---|"]
    for row in rows:
        if row.get("missing"):
            lines.append(f"| {row['name']} | — | — | — | — | missing |")
            continue
        verdict = "ok" if row["flip"] <= target else f"FLIP > {target}"
        lines.append(f"| {row['name']} | {row['flip']:.6f} | {row['max_relative']:.3g} | {row['median_relative']:.2g} "
                     f"| {row['over_1_percent']} of {row['lit']} | {verdict} |")
    return "\n".join(lines)


def _report(rows: list[dict[str, Any]], target: float, json_file: Path | None) -> int:
    print(table(rows, target))
    if json_file is not None:
        json_file.write_text(json.dumps({"target_flip": target, "images": rows}, indent=1) + "\n")
    missed = [row["name"] for row in rows if row.get("missing") or not row["flip"] <= target]
    print(f"{len(rows) - len(missed)} of {len(rows)} images within FLIP {target}" +
          (f"; not: {', '.join(missed)}" if missed else ""))
    return 1 if missed else 0


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    commands = parser.add_subparsers(dest="command", required=True)
    render = commands.add_parser("render", help="render every shipped material into a folder")
    render.add_argument("out", type=Path)
    render.add_argument("--materials", help="comma-separated (default: every shipped material)")
    render.add_argument("--meshes", default=",".join(MESHES))
    render.add_argument("--paths", default=",".join(PATHS))
    render.add_argument("--size", default=SIZE)
    render.add_argument("--weights-path", default="texture",
                        help="texture (default: seconds to compile everywhere), baked or auto")
    render.add_argument("--like", type=Path, help="take each render's view from this folder's renders")
    compare = commands.add_parser("compare", help="FLIP and relative differences of two folders' renders")
    compare.add_argument("reference", type=Path)
    compare.add_argument("test", type=Path)
    compare.add_argument("--json", type=Path)
    compare.add_argument("--target", type=float, default=FLIP_TARGET)
    check = commands.add_parser("check", help="render here like a GPU folder, then compare")
    check.add_argument("gpu", type=Path)
    check.add_argument("--local", type=Path, help="where to render here (default: out/gpu-check-llvmpipe; the GPU's "
                                                  "folder may be read-only)")
    check.add_argument("--weights-path", default="texture")
    check.add_argument("--json", type=Path)
    check.add_argument("--target", type=float, default=FLIP_TARGET)
    args = parser.parse_args(argv)
    if args.command == "render":
        materials = args.materials.split(",") if args.materials else shipped_materials()
        records = render_all(args.out, materials, args.meshes.split(","), args.paths.split(","), args.size,
                             args.weights_path, args.like)
        return 1 if any(record["status"] != 0 for record in records) else 0
    if args.command == "compare":
        return _report(compare_dirs(args.reference, args.test), args.target, args.json)
    local = args.local or REPO / "out" / "gpu-check-llvmpipe"
    materials = [m for m in shipped_materials() if any(p.stem.startswith(f"{m}_") for p in args.gpu.glob("*.exr"))]
    size = "{width},{height}".format(**json.loads(next(args.gpu.glob("*.config.json")).read_text())["render"])
    render_all(local, materials, list(MESHES), list(PATHS), size, args.weights_path, like=args.gpu)
    return _report(compare_dirs(args.gpu, local), args.target, args.json or local / "compare.json")


if __name__ == "__main__":
    sys.exit(main())
