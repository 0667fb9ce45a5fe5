"""Compile time and BRDF-slice frame time of one weight path (texture or baked) per model.

For each model: build a ``NetworkRenderer`` on ``--weights-path``, draw one 8×8 (30°, 0°) slice (compile,
link and Mesa's JIT at the first draw: "compile_s"), then per size one warm-up frame and the median of
``--repeats`` frames (read-back included, skip-work off). Prints one JSON line per model and size, with
GMAC/s over the disc's pixels (π/4 of the square). Run with ``MESA_SHADER_CACHE_DISABLE=true`` to time
the first compile rather than Mesa's disk cache:

    MESA_SHADER_CACHE_DISABLE=true python benchmarks/weight_path_timing.py assets/blazed/model.npz \\
        --weights-path baked --sizes 256,512

``gratnet bench`` is the full comparison (both paths, torch, error); this is the quick probe behind
docs/benchmarks.md's "Weight paths" tables.
"""

from __future__ import annotations

import argparse
import json
import math
import statistics
import time

from gratnet.modelfile import load_model


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("models", nargs="+", help="model files (.npz)")
    parser.add_argument("--weights-path", default="baked", choices=("auto", "texture", "baked"))
    parser.add_argument("--sizes", default="512", help="slice sizes, comma-separated")
    parser.add_argument("--repeats", type=int, default=3, help="timed frames per size (median)")
    arguments = parser.parse_args(argv)
    sizes = [int(size) for size in arguments.sizes.split(",")]

    from viewer.context import create_headless_context
    from viewer.renderer import NetworkRenderer

    ctx = create_headless_context()
    try:
        for path in arguments.models:
            model = load_model(path)
            start = time.perf_counter()
            with NetworkRenderer(ctx, model, weights_path=arguments.weights_path) as renderer:
                renderer.render_brdf_slice(30.0, 0.0, 8, 5000.0, skip_threshold=0.0)
                compile_seconds = time.perf_counter() - start
                for size in sizes:
                    renderer.render_brdf_slice(30.0, 0.0, size, 5000.0, skip_threshold=0.0)  # warm-up
                    times = []
                    for _ in range(arguments.repeats):
                        begin = time.perf_counter()
                        renderer.render_brdf_slice(30.0, 0.0, size, 5000.0, skip_threshold=0.0)
                        times.append(time.perf_counter() - begin)
                    frame = statistics.median(times)
                    print(json.dumps({
                        "model": path, "layer_sizes": list(model.layer_sizes),
                        "macs_per_pixel": model.macs_per_evaluation, "weights_path": renderer.weights_path,
                        "compile_s": round(compile_seconds, 2), "size": size, "frame_s": round(frame, 4),
                        "gmac_per_s": round(size * size * math.pi / 4 * model.macs_per_evaluation / frame / 1e9, 2),
                    }), flush=True)
    finally:
        ctx.release()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
