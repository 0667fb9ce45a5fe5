"""Frame times of the forward and deferred render paths (issue 12), one JSON line per configuration.

    python benchmarks/render_paths.py --material cd --mesh cd --sizes 640x480,1920x1080 \\
        --samples 1,4 --variants forward:texture,forward:baked,deferred:texture,deferred:ssbo,deferred:baked

A variant is ``PATH:WEIGHTS``: ``forward:texture|baked`` (the fragment-shader network, depth pre-pass),
``deferred:texture|ssbo|shared|baked|ssbo-fp16|shared-fp16`` (viewer/deferred.py's compute pass reading the
weights from there).
Scene: the material's default light, camera and exposure on the mesh (viewer.defaults, as ``gratnet render``:
bench.scenes.scene_view). Each line: the best and median wall time (ms, after ``ctx.finish()``) of
``--repeats`` renders, the variants interleaved so that all see the same machine load, after one untimed
render that compiles the programs (its time is ``first_ms``), the network evaluations (the counters of a
separate render), ``GL_RENDERER`` and the 1-minute load average (other work on the machine slows a CPU
rasterizer). Runs on whatever EGL gives (llvmpipe here; the NVIDIA driver on a GPU machine).
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import time

import numpy as np

from bench.scenes import scene_view
from gratnet.modelfile import ModelFile, load_model
from viewer.camera import Light
from viewer.catalog import build_mesh, resolve_material
from viewer.context import create_headless_context
from viewer.scene import SceneRenderer
from viewer.surface import MeshBuffers


def _sizes(text: str) -> list[tuple[int, int]]:
    return [(int(width), int(height)) for width, height in (item.split("x") for item in text.split(","))]


def _random_net(like: ModelFile, hidden: list[int]) -> ModelFile:
    """A random SiLU funnel with ``like``'s encoding, scheme and range (outputs mostly inside (0, 1))."""
    rng = np.random.default_rng(0)
    sizes = [like.encoding.features, *hidden, 3]
    weights = [(rng.standard_normal((o, i)) / np.sqrt(i)).astype(np.float32)
               for i, o in zip(sizes, sizes[1:], strict=False)]
    biases = [(0.1 * rng.standard_normal(o)).astype(np.float32) for o in sizes[1:]]
    biases[-1] = np.array([0.55, 0.6, 0.65], dtype=np.float32)
    return ModelFile(sizes, weights, biases, "silu", "clamp", like.encoding, like.range, like.scheme)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--material", default="cd")
    parser.add_argument("--mesh", default="cd")
    parser.add_argument("--sizes", default="640x480,1920x1080")
    parser.add_argument("--samples", default="1,4")
    parser.add_argument("--variants", default="forward:texture,forward:baked,deferred:texture,deferred:ssbo,"
                        "deferred:baked")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--light", default="", metavar="θ,φ",
                        help="directional light instead of the default view's (degrees); e.g. 100,0 puts it below "
                        "the horizon: nothing is evaluated, so the time is the path's fixed overhead")
    parser.add_argument("--random-net", default="", metavar="H1,H2,…",
                        help="instead of the material's net: a random funnel with these hidden widths and the "
                        "material's encoding (seed 0), e.g. 16,8 (3.0k MACs: its weights fit 32 KiB of shared memory)")
    arguments = parser.parse_args()
    model_path = resolve_material(arguments.material)
    model = load_model(model_path)
    if arguments.random_net:
        model = _random_net(model, [int(width) for width in arguments.random_net.split(",")])
    mesh = build_mesh(arguments.mesh)
    view = scene_view(str(model_path), arguments.mesh)
    light = Light.directional(*(float(v) for v in arguments.light.split(","))) if arguments.light else view.light
    ctx = create_headless_context()
    renderer_name = ctx.info.get("GL_RENDERER", "?")
    scenes: dict[str, tuple[SceneRenderer, MeshBuffers]] = {}
    for variant in arguments.variants.split(","):
        path, weights = variant.split(":")
        scene = SceneRenderer(ctx, model, weights_path="baked" if weights == "baked" else "texture", render_path=path,
                              deferred_weights=weights if path == "deferred" else "auto")
        scenes[variant] = (scene, scene.upload(mesh))
    for size in _sizes(arguments.sizes):
        for samples in (int(n) for n in arguments.samples.split(",")):
            def render(variant: str, counts_out: dict[str, int] | None = None, samples: int = samples,
                       size: tuple[int, int] = size) -> float:
                scene, uploaded = scenes[variant]
                start = time.perf_counter()
                scene.render_rgba(uploaded, view.camera, light, size, view.exposure, view.ior,
                                  statistics=counts_out, samples=samples)
                ctx.finish()
                return time.perf_counter() - start

            first = {variant: render(variant) for variant in scenes}
            times: dict[str, list[float]] = {variant: [] for variant in scenes}
            for _ in range(arguments.repeats):  # interleaved: every variant sees the same machine load
                for variant in scenes:
                    times[variant].append(render(variant))
            for variant in scenes:
                counts: dict[str, int] = {}
                render(variant, counts)
                path, weights = variant.split(":")
                print(json.dumps({
                    "material": arguments.material, "net": "-".join(map(str, model.layer_sizes)),
                    "mesh": arguments.mesh, "size": list(size), "samples": samples,
                    "path": path, "weights": weights, "best_ms": round(1e3 * min(times[variant]), 1),
                    "median_ms": round(1e3 * statistics.median(times[variant]), 1),
                    "first_ms": round(1e3 * first[variant], 1),
                    "evaluations": counts.get("evaluations"), "fragments": counts.get("fragments"),
                    "macs_per_evaluation": model.macs_per_evaluation, "renderer": renderer_name,
                    "load_average_1min": round(os.getloadavg()[0], 2),
                }), flush=True)
    for scene, uploaded in scenes.values():
        uploaded.release()
        scene.release()
    ctx.release()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
