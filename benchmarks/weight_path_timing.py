"""Compile time and BRDF-slice frame time of one weight path (texture or baked) per model.

For each model: ``bench.slices.shader_frame_times`` (what ``gratnet bench`` times: a ``NetworkRenderer``
on ``--weights-path``, one 8×8 (30°, 0°) 5000 RU slice for the compile, link and Mesa's JIT at the first
draw, "compile_s"; then per size a warm-up frame and the median of ``--repeats`` frames, read-back
included, skip-work off). Prints one JSON line per model and size, with GMAC/s over the disc's pixels
(π/4 of the square). Run with ``MESA_SHADER_CACHE_DISABLE=true`` to time the first compile rather than
Mesa's disk cache:

    MESA_SHADER_CACHE_DISABLE=true python benchmarks/weight_path_timing.py assets/blazed/model.npz \\
        --weights-path baked --sizes 256,512

``gratnet bench`` is the full comparison (both paths, torch, error); this is the quick probe behind
docs/benchmarks.md's "Weight paths" tables.
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

from bench.slices import BenchConfig, ModelEntry, shader_frame_times


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("models", nargs="+", help="model files (.npz)")
    parser.add_argument("--weights-path", default="baked", choices=("auto", "texture", "baked"))
    parser.add_argument("--sizes", default="512", help="slice sizes, comma-separated")
    parser.add_argument("--repeats", type=int, default=3, help="timed frames per size (median)")
    arguments = parser.parse_args(argv)
    config = BenchConfig(sizes=arguments.sizes, repeats=arguments.repeats)  # checks the sizes

    from viewer.context import create_headless_context

    ctx = create_headless_context()
    try:
        for path in arguments.models:
            entry = ModelEntry.load(Path(path))
            macs = entry.model.macs_per_evaluation
            for row in shader_frame_times(ctx, entry, arguments.weights_path, config, config.size_list()):
                size, frame = row["size"], row["seconds"]
                print(json.dumps({
                    "model": path, "layer_sizes": list(entry.model.layer_sizes), "macs_per_pixel": macs,
                    "weights_path": row["weights_path"], "compile_s": round(row["setup_s"], 2), "size": size,
                    "frame_s": round(frame, 4), "gmac_per_s": round(size * size * math.pi / 4 * macs / frame / 1e9, 2),
                }), flush=True)
    finally:
        ctx.release()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
