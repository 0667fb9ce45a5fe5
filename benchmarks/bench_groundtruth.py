"""Benchmark: wall time and peak memory of a full ground-truth volume (not a timed test).

    python benchmarks/bench_groundtruth.py                     # CD, 1001² × 11 slices, 81 λ, regular
    python benchmarks/bench_groundtruth.py --sampling simple-max --material corner_cube

Prints one JSON line of figures (and writes it with --json); the volume goes to --out if given.
Peak memory is the process's maximum resident set size (ru_maxrss), which includes Python itself.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import resource
import sys
import time

from gratnet.volume import write_volume
from trainer.fourier import OpticsConfig, prepare_surface
from trainer.groundtruth import VolumeConfig, compute_volume
from trainer.loaders import load_heightfield


def main() -> int:
    """Run one benchmark and print its figures."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--material", default="cd", help="built-in generator or height-field file")
    parser.add_argument("--res", type=int, default=1001)
    parser.add_argument("--slices", type=int, default=11)
    parser.add_argument("--sampling", default="regular")
    parser.add_argument("--out", help="write the volume here (EXR), timed separately")
    parser.add_argument("--json", help="append the figures as one JSON line to this file")
    arguments = parser.parse_args()

    optics = OpticsConfig()
    config = VolumeConfig(resolution=arguments.res, slices=arguments.slices, sampling=arguments.sampling)
    field = load_heightfield(arguments.material)
    started = time.perf_counter()
    surface = prepare_surface(field, optics, report=lambda message: print(message, file=sys.stderr))
    volume = compute_volume(field, config, optics, progress=True, surface=surface)
    compute_seconds = time.perf_counter() - started
    write_seconds = None
    if arguments.out:
        started = time.perf_counter()
        write_volume(arguments.out, volume)
        write_seconds = time.perf_counter() - started
    figures = {
        "material": arguments.material,
        "resolution": arguments.res,
        "slices": arguments.slices,
        "sampling": arguments.sampling,
        "wavelengths": len(volume.metadata["wavelengths_nm"]),
        "integration_grid": volume.metadata["grid_samples"],
        "dx_um": round(surface.dx_um, 5),
        "height_span_um": round(2 * surface.half_span_um, 4),
        "chebyshev_nodes": volume.metadata["chebyshev_nodes"],
        "compute_seconds": round(compute_seconds, 1),
        "write_seconds": None if write_seconds is None else round(write_seconds, 1),
        "peak_rss_gib": round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20, 2),
        "cpus": os.cpu_count(),
        "machine": platform.machine(),
        "python": platform.python_version(),
    }
    line = json.dumps(figures)
    print(line)
    if arguments.json:
        with open(arguments.json, "a", encoding="utf-8") as handle:
            handle.write(line + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
