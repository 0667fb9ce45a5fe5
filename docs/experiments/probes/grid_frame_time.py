"""Frame time of feature-grid models against the pure MLP on the texture path (docs/benchmarks.md).

    python docs/experiments/probes/grid_frame_time.py [--size 256] [--repeats 5]

Random weights of the sizes in CASES (the time does not depend on the values: skipping is off), 256² BRDF
slice at (30°, 0°), renders interleaved across the cases, median and minimum per case.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from gratnet.encoding import EncodingSpec, RangeSpec
from gratnet.modelfile import ModelFile
from viewer.context import create_headless_context
from viewer.renderer import NetworkRenderer

GRID_LEVELS = (63, 126, 251)  # nodes per u*/v* axis of the three levels


def random_model(frequencies: int, t_frequencies: int, hidden: list[int], grid: bool, seed: int = 0,
                 t_nodes: int = 11, features: int = 2) -> ModelFile:
    """Random weights (and float16 grids) of the given sizes, for the paper's 1001² × 11 grid."""
    rng = np.random.default_rng(seed)
    spec = EncodingSpec.for_grid(1001, 11, frequencies, t_frequencies)
    grids = [(0.1 * rng.standard_normal((t_nodes, nodes, nodes, features))).astype(np.float16)
             for nodes in GRID_LEVELS] if grid else []
    sizes = [spec.features + features * len(grids), *hidden, 3]
    weights = [(rng.standard_normal((b, a)) / np.sqrt(a)).astype(np.float32) for a, b in zip(sizes[:-1], sizes[1:],
                                                                                             strict=True)]
    biases = [np.full(b, 0.1, np.float32) for b in sizes[1:]]
    return ModelFile(sizes, weights, biases, "silu", "clamp", spec, RangeSpec(), "simple-max", grids=grids)


def main() -> None:
    """Print one line per case."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", type=int, default=256)
    parser.add_argument("--repeats", type=int, default=5)
    arguments = parser.parse_args()
    ctx = create_headless_context()
    small = random_model(19, 4, [108, 66, 40, 24], grid=False)
    full = random_model(19, 4, [64, 32, 16], grid=True)
    reduced = random_model(8, 2, [64, 32, 16], grid=True)
    wide = random_model(19, 4, [108, 66, 40, 24], grid=True, t_nodes=6, features=4)
    cases = [("mlp small", small, "manual"), ("grid C=4 T=6 small manual", wide, "manual"),
             ("grid C=4 T=6 small hardware", wide, "hardware"), ("grid L=19 manual", full, "manual"),
             ("grid L=19 hardware", full, "hardware"), ("grid L=8 manual", reduced, "manual"),
             ("grid L=8 hardware", reduced, "hardware")]
    renderers = {name: NetworkRenderer(ctx, model, weights_path="texture", grid_filter=grid_filter)
                 for name, model, grid_filter in cases}
    for renderer in renderers.values():
        renderer.render_brdf_slice(30.0, 0.0, 64, 1.0)  # compile and JIT first
    times: dict[str, list[float]] = {name: [] for name in renderers}
    for _ in range(arguments.repeats):
        for name, renderer in renderers.items():
            started = time.perf_counter()
            renderer.render_brdf_slice(30.0, 0.0, arguments.size, 1.0)
            times[name].append(time.perf_counter() - started)
    for name, values in times.items():
        print(f"{name}: median {np.median(values) * 1e3:.0f} ms, min {min(values) * 1e3:.0f} ms per "
              f"{arguments.size}² BRDF slice ({renderers[name].model.macs_per_evaluation} MLP MACs)")


if __name__ == "__main__":
    main()
