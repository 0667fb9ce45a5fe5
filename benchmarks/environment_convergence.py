"""How fast an environment-lit render converges: FLIP against samples per pixel and against seconds, per strategy.

    python benchmarks/environment_convergence.py                       # paper-cd on the CD under the sky, 64²
    python benchmarks/environment_convergence.py --material paper-snake --environment studio --mesh sphere
    python benchmarks/environment_convergence.py --volume out/volumes/paper-cd.exr --size 256 --max-spp 64 \
        --reference-spp 4096 --out docs/data/environment_convergence_256.json \
        --figure docs/images/environment_convergence_256.png

For one material, mesh and environment (the map as it is, unturned; the camera of the material's default view,
``gratnet render``'s), a reference is rendered with the default sampling (resampled) at ``--reference-spp`` passes
(seed 1000), then each strategy of ``--environment-sampling`` (mis, light, material, resampled; seed 0)
progressively up to ``--max-spp``: after 1, 2, 4, … passes the mean so far is scored against the reference by FLIP
(``gratnet.display.ldr_flip``, both at the exposure the reference's picture calls for:
gratnet.showcase.suggest_exposure) and by the relative RMSE of the lit pixels. Each pass is timed (wall, this
machine's GL: llvmpipe on a CPU machine; the load average is recorded). Writes a JSON record (atomically) and a
figure (FLIP against spp and against seconds, log-log), and prints one line per point. docs/benchmarks.md shows the
figure of the shipped run.

``--volume``: shade with the material's ground-truth volume looked up per pixel (``gratnet render --reference``)
instead of its network: the same estimator and the same noise at a small fraction of the network's cost per pass,
so that larger pictures and 4,096-pass references fit this machine.
"""

from __future__ import annotations

import argparse
import json
import os
import shlex
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

from gratnet.atomic import atomic_paths
from gratnet.codes import DEFAULT_ENVIRONMENT_SAMPLING, ENVIRONMENT_SAMPLING
from gratnet.display import ldr_flip, xyz_to_display_srgb8
from gratnet.environment import load_environment
from gratnet.errors import GratNetError
from gratnet.modelfile import load_model
from gratnet.showcase import suggest_exposure
from viewer.camera import Camera, Light
from viewer.catalog import build_mesh, resolve_material
from viewer.context import create_headless_context
from viewer.defaults import resolve_defaults
from viewer.scene import SceneRenderer
from viewer.scene_config import load_reference

REPO = Path(__file__).resolve().parents[1]
DEFAULT_JSON = REPO / "docs" / "data" / "environment_convergence.json"
DEFAULT_FIGURE = REPO / "docs" / "images" / "environment_convergence.png"
_PASSES_PER_CALL = 16  # passes per render call for the reference (fewer GL round trips)


def _arguments(argv: list[str] | None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--material", default="paper-cd")
    parser.add_argument("--mesh", default="cd")
    parser.add_argument("--environment", default="sky", help="as gratnet render --environment")
    parser.add_argument("--size", type=int, default=64, help="square image side, pixels")
    parser.add_argument("--max-spp", type=int, default=256)
    parser.add_argument("--reference-spp", type=int, default=1024)
    parser.add_argument("--volume", default="", help="a ground-truth volume of the material (gratnet groundtruth's "
                        "EXR) to shade with instead of the network (gratnet render --reference)")
    parser.add_argument("--out", type=Path, default=DEFAULT_JSON)
    parser.add_argument("--figure", type=Path, default=DEFAULT_FIGURE)
    arguments = parser.parse_args(argv)
    for name in ("size", "max_spp", "reference_spp"):
        if getattr(arguments, name) < 1:
            parser.error(f"--{name.replace('_', '-')} must be ≥ 1")
    return arguments


def _display(xyz: np.ndarray, exposure: float) -> np.ndarray:
    return xyz_to_display_srgb8(xyz, exposure).astype(np.float32) / 255.0


def main(argv: list[str] | None = None) -> int:
    arguments = _arguments(argv)
    environment = load_environment(arguments.environment, what="--environment")
    if environment is None:
        raise GratNetError("--environment none: nothing to converge")
    defaults = resolve_defaults(arguments.material, arguments.mesh)
    camera = Camera(defaults.camera_distance, defaults.camera_azimuth_degrees, defaults.camera_elevation_degrees)
    no_light = Light.directional(0.0, 0.0, 0.0)
    size = (arguments.size, arguments.size)
    mesh = build_mesh(arguments.mesh)
    load_before = os.getloadavg()[0]
    ctx = create_headless_context()
    record: dict[str, Any] = {
        "date": time.strftime("%Y-%m-%d"), "command": shlex.join(["python", *sys.argv]),
        "material": arguments.material, "mesh": arguments.mesh, "environment": environment.name,
        "size": list(size), "reference_spp": arguments.reference_spp,
        "reference_sampling": DEFAULT_ENVIRONMENT_SAMPLING, "gl_renderer": None,
        "shading": f"reference volume {Path(arguments.volume).name}" if arguments.volume else "network",
        "load_average_before": round(load_before, 2), "strategies": {}}
    try:
        source: Any = (load_reference(arguments.volume, "float16", arguments.material) if arguments.volume
                       else load_model(resolve_material(arguments.material)))
        # auto: sampled light renders deferred on a CPU rasterizer (4-15x faster passes), forward on a GPU.
        with SceneRenderer(ctx, source, render_path="auto") as scene:
            record["gl_renderer"] = ctx.info.get("GL_RENDERER")
            uploaded = scene.upload(mesh)

            def passes(first: int, count: int, seed: int, sampling: str) -> np.ndarray:
                return scene.render_rgba(uploaded, camera, no_light, size, 1.0, 1.5, samples=count,
                                         first_sample=first, environment=environment, seed=seed,
                                         sampling=sampling).astype(np.float64)

            # Compiles the program and builds the importance table: not timed.
            passes(0, 1, 0, DEFAULT_ENVIRONMENT_SAMPLING)
            reference_sum = np.zeros((*size[::-1], 4))
            done = 0
            while done < arguments.reference_spp:
                count = min(_PASSES_PER_CALL, arguments.reference_spp - done)
                reference_sum += passes(done, count, 1000, DEFAULT_ENVIRONMENT_SAMPLING) * count
                done += count
                print(f"reference: {done}/{arguments.reference_spp} passes", file=sys.stderr, end="\r")
            print(file=sys.stderr)
            reference = reference_sum[..., :3] / done
            exposure = suggest_exposure(reference, 1.0) or 1.0
            record["exposure"] = exposure
            reference_display = _display(reference, exposure)
            lit = np.mean(reference, axis=-1) > 0.0
            for sampling in ENVIRONMENT_SAMPLING.names:
                points = []
                total = np.zeros_like(reference_sum)
                done, seconds = 0, 0.0
                while done < arguments.max_spp:
                    count = max(1, done)  # doubles: 1, 1, 2, 4, … so the means land on powers of two
                    started = time.perf_counter()
                    total += passes(done, count, 0, sampling) * count
                    seconds += time.perf_counter() - started
                    done += count
                    mean = total[..., :3] / done
                    flip, _ = ldr_flip(reference_display, _display(mean, exposure))
                    difference = (mean - reference)[lit]
                    rmse = float(np.sqrt(np.mean(difference**2)) / max(np.sqrt(np.mean(reference[lit] ** 2)), 1e-30))
                    points.append({"spp": done, "seconds": round(seconds, 3), "flip": round(flip, 5),
                                   "relative_rmse": round(rmse, 5)})
                    print(json.dumps({"sampling": sampling, **points[-1]}))
                record["strategies"][sampling] = points
            uploaded.release()
    finally:
        ctx.release()
    record["load_average_after"] = round(os.getloadavg()[0], 2)
    _write(record, arguments.out, arguments.figure)
    return 0


def _write(record: dict[str, Any], out: Path, figure: Path) -> None:
    """The record and its figure, landing together."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(9.0, 3.6))
    for sampling, points in record["strategies"].items():
        spp = [p["spp"] for p in points]
        flips = [p["flip"] for p in points]
        axes[0].loglog(spp, flips, marker="o", label=sampling)
        axes[1].loglog([max(p["seconds"], 1e-3) for p in points], flips, marker="o", label=sampling)
    axes[0].set_xlabel("samples per pixel")
    axes[1].set_xlabel("seconds (this machine's GL)")
    for axis in axes:
        axis.set_ylabel(f"FLIP vs {record['reference_spp']}-spp {record.get('reference_sampling', 'mis')}")
        axis.grid(True, which="both", alpha=0.3)
        axis.legend()
    shading = "" if record.get("shading", "network") == "network" else " (ground-truth look-up)"
    fig.suptitle(f"{record['material']}{shading} on the {record['mesh']} under {record['environment']}, "
                 f"{record['size'][0]}², {record['gl_renderer']}", fontsize=9)
    fig.tight_layout()
    out.parent.mkdir(parents=True, exist_ok=True)
    figure.parent.mkdir(parents=True, exist_ok=True)
    with atomic_paths(out, figure) as (json_temporary, figure_temporary):
        Path(json_temporary).write_text(json.dumps(record, indent=1) + "\n", encoding="utf-8")
        fig.savefig(figure_temporary, format="png", dpi=110)
    plt.close(fig)
    print(f"wrote {out} and {figure}")


if __name__ == "__main__":
    try:
        sys.exit(main())
    except GratNetError as error:
        print(f"environment_convergence: error: {error}", file=sys.stderr)
        sys.exit(2)
    except KeyboardInterrupt:
        print("environment_convergence: interrupted; nothing was written", file=sys.stderr)
        sys.exit(130)
