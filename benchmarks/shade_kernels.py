"""The deferred path's shading kernels alone (issue 32): GL-timer time of the SHADE / SHADE_TILED dispatches on a
list of N key vectors, per model and deferred weights form, one JSON line each.

    python benchmarks/shade_kernels.py cd paper-cd --keys 699052 --forms ssbo,tiled,tiled-fp16
    python benchmarks/shade_kernels.py cd --keys 8192 --forms texture,tiled --repeats 3   # llvmpipe

A frame of ``gratnet bench`` also draws the G-buffer, compacts it and reads the float image back; this times
only what the network costs (``DeferredRenderer.shade_keys(timings=…)``: the keys uploaded again before each
repeat, outside the timing). The keys: uniformly random directions' key vectors (seed 0), the CD disc's count
at 1920×1080 by default. Each line: the best and median milliseconds (``clock``: the GL timer's, or the wall
time's after ``ctx.finish()`` where the timer reads about 0, as llvmpipe's does for compute work), TMAC/s of
the best (MACs per evaluation × N / time) and its share of the device's FP32 rate (bench.devices; none for
llvmpipe), the tile plan, ``GL_RENDERER`` and the 1-minute load average. A form the driver refuses
(tiled-half without half arithmetic) is a line with its reason. Runs on whatever EGL gives.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics

import numpy as np

from bench.devices import fp32_tmac_per_s
from gratnet.errors import GratNetError
from gratnet.modelfile import load_model
from viewer.catalog import resolve_material
from viewer.context import create_headless_context
from viewer.deferred import DeferredRenderer
from viewer.renderer import NetworkRenderer


def random_keys(count: int, seed: int = 0) -> np.ndarray:
    """``count`` key vectors −(ωi + ωo) of directions uniform over the upper hemisphere, (count, 3)."""
    rng = np.random.default_rng(seed)
    cos_theta = rng.uniform(0.0, 1.0, (2, count))  # gratnet.brdf.direction's frame, vectorised
    sin_theta = np.sqrt(1.0 - cos_theta**2)
    phi = rng.uniform(0.0, 2.0 * np.pi, (2, count))
    directions = np.stack([sin_theta * np.cos(phi), sin_theta * np.sin(phi), cos_theta], axis=-1)
    return -(directions[0] + directions[1])


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("materials", nargs="+", help="shipped material names or model-file paths")
    parser.add_argument("--keys", type=int, default=699_052, help="list entries (default: the CD disc at 1080p)")
    parser.add_argument("--forms", default="ssbo,tiled,tiled-fp16", help="deferred weights forms, comma-separated")
    parser.add_argument("--repeats", type=int, default=5)
    arguments = parser.parse_args()
    keys = random_keys(arguments.keys)
    ctx = create_headless_context()
    renderer_name = str(ctx.info.get("GL_RENDERER", "?"))
    peak = fp32_tmac_per_s(renderer_name)
    try:
        for material in arguments.materials:
            model = load_model(resolve_material(material))
            network = NetworkRenderer(ctx, model, weights_path="texture")
            try:
                for form in (part.strip() for part in arguments.forms.split(",") if part.strip()):
                    row: dict[str, object] = {"material": material, "form": form, "keys": arguments.keys,
                                              "macs_per_evaluation": model.macs_per_evaluation,
                                              "renderer": renderer_name}
                    try:
                        deferred = DeferredRenderer(network, form)
                    except GratNetError as error:
                        print(json.dumps({**row, "refused": str(error)}), flush=True)
                        continue
                    try:
                        deferred.shade_keys(keys[:1024])  # compile and first dispatch
                        timings: list[tuple[float, float]] = []
                        deferred.shade_keys(keys, timings=timings, repeats=arguments.repeats)
                        gpu = [timer for timer, _ in timings]
                        wall = [seconds for _, seconds in timings]
                        # The GL timer where it measures the dispatches (a GPU), else the wall time (llvmpipe's
                        # timer reads about 0 for compute work).
                        chosen, clock = (gpu, "gl_timer") if min(gpu) > 0.05 * min(wall) else (wall, "wall")
                        best = min(chosen)
                        tmacs = model.macs_per_evaluation * arguments.keys / best / 1e12
                        plan = deferred.tile_plan
                        print(json.dumps({
                            **row, "best_ms": round(best * 1e3, 3), "clock": clock,
                            "median_ms": round(statistics.median(chosen) * 1e3, 3),
                            "wall_best_ms": round(min(wall) * 1e3, 3), "tmac_per_s": tmacs,
                            "fp32_share": None if peak is None else tmacs / peak,
                            "plan": None if plan is None else plan.describe(network.layout),
                            "load_average_1min": round(os.getloadavg()[0], 2),
                        }), flush=True)
                    finally:
                        deferred.release()
            finally:
                network.release()
    finally:
        ctx.release()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
