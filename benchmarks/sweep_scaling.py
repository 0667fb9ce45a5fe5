"""Wall time of a small ``gratnet sweep`` on a local Ray instance with 1 and 2 workers, and the split ground
truth's agreement with the unsplit one.

1. The same sweep (written to OUT/small.toml: two datasets × three presets × two seeds, 129² volumes of 11
   slices, 41 wavelengths, 4 epochs, 64² evaluation slices) run from scratch with ``--workers 1`` and
   ``--workers 2`` into separate folders; wall time of the whole command (Ray start-up included), and
   whether both tables hold the same numbers (timings aside); with the machine's load average (other jobs
   on the same cores lengthen every figure) and the sum of the runs' own seconds.
2. One volume (default 257² × 11, 81 wavelengths, the CD) computed whole as one Ray task and as 4
   wavelength blocks (sweep.tasks.volume_part, the sweep's own task) on a local Ray instance of 2 workers;
   wall times, and the largest relative difference between the two (bit-for-bit or ≤ 1e-6 expected).
   Both run with one BLAS thread per task; the same volume computed in this process with OpenBLAS's default
   thread count is compared too (the thread count alone changes the last bits of complex64 products).

    nice -n 19 python benchmarks/sweep_scaling.py --out /tmp/sweep_scaling

Prints one JSON line per measurement. Timings are wall-clock and vary with what else runs on the machine.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

SMALL = """
presets = ["tiny", "small", "medium"]
seeds = [0, 1]

[groundtruth]
resolution = 129
slices = 11
sigma_s_um = 4.0
wavelength_step_nm = 10.0

[train]
epochs = 4
batch_size = 8192

[evaluate]
size = 64

[[datasets]]
generator = "blazed"
params = { size_um = 12.0 }

[[datasets]]
generator = "cd"
params = { size_um = 12.0 }
"""
TIMINGS = {"train_seconds", "run_seconds", "model"}


def sweep_wall_time(folder: Path, workers: int) -> dict:
    out = folder / f"workers{workers}"
    started = time.perf_counter()
    subprocess.run([sys.executable, "-m", "gratnet.cli", "sweep", str(folder / "small.toml"), "--out", str(out),
                    "--workers", str(workers), "--quiet"], check=True)
    seconds = time.perf_counter() - started
    rows = json.loads((out / "results.json").read_text())
    return {"measurement": "sweep wall time", "workers": workers, "runs": len(rows), "seconds": round(seconds, 1),
            "sum_of_run_seconds": round(sum(row["run_seconds"] for row in rows), 1),
            "load_average_1min_after": round(os.getloadavg()[0], 2),
            "rows": [{key: value for key, value in row.items() if key not in TIMINGS} for row in rows]}


def split_agreement(generator: str, resolution: int, slices: int, parts: int, workers: int) -> list[dict]:
    """The volume whole (one task, one CPU) and in ``parts`` wavelength blocks (tasks of one CPU on ``workers``
    CPUs), both on Ray so that every product runs with one BLAS thread; then whole in this process (BLAS's
    default threads), to show what the thread count alone changes."""
    import numpy as np
    import ray

    from sweep import tasks
    from sweep.spec import DatasetSpec
    from trainer.fourier import OpticsConfig, prepare_surface
    from trainer.generators import generate
    from trainer.groundtruth import VolumeConfig, compute_volume, volume_from_sum
    from trainer.loaders import LoadOptions

    field = generate(generator)
    optics = OpticsConfig()
    config = VolumeConfig(resolution=resolution, slices=slices)
    dataset = DatasetSpec(generator, generator, {}, None, LoadOptions(), config, optics, parts)
    root = str(Path(__file__).resolve().parents[1])
    ray.init(num_cpus=workers, include_dashboard=False, log_to_driver=False, configure_logging=False,
             runtime_env={"env_vars": {"PYTHONPATH": root}})
    try:
        started = time.perf_counter()
        whole = ray.get(ray.remote(compute_volume).options(num_cpus=1).remote(field, config, optics,
                                                                               progress=False))  # type: ignore[call-arg]  # ray types .remote() with positional arguments only
        whole_seconds = time.perf_counter() - started
        started = time.perf_counter()
        surface = prepare_surface(field, optics)
        surface_ref = ray.put(surface)
        part = ray.remote(tasks.volume_part).options(num_cpus=1)
        results = ray.get([part.remote(dataset, surface_ref, block) for block in range(parts)])
        total = results[0][0].copy()
        for xyz, _, _ in results[1:]:
            total += xyz
        split = volume_from_sum(field, config, optics, surface, total, results[0][1])
        split_seconds = time.perf_counter() - started
    finally:
        ray.shutdown()
    started = time.perf_counter()
    here = compute_volume(field, config, optics, progress=False)
    here_seconds = time.perf_counter() - started

    def compare(a: np.ndarray, b: np.ndarray) -> dict:
        difference = np.abs(a.astype(np.float64) - b)
        relative = difference / np.maximum(np.abs(b.astype(np.float64)), 1e-30)
        peak = float(np.abs(b).max())
        return {"bit_identical": bool(np.array_equal(a, b)), "max_relative_difference": float(relative.max()),
                "max_absolute_difference_over_peak": float(difference.max() / peak)}

    common = {"generator": generator, "resolution": resolution, "slices": slices,
              "wavelengths": len(whole.metadata["wavelengths_nm"])}
    return [
        {"measurement": "split ground truth vs whole (1 BLAS thread each)", **common, "blocks": parts,
         "workers": workers, "whole_seconds": round(whole_seconds, 1), "split_seconds": round(split_seconds, 1),
         **compare(split.xyz, whole.xyz)},
        {"measurement": "whole, BLAS default threads in this process vs 1 thread", **common,
         "seconds": round(here_seconds, 1), **compare(here.xyz, whole.xyz)},
    ]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", type=Path, required=True, help="scratch folder (emptied sweeps land here)")
    parser.add_argument("--skip-sweep", action="store_true", help="only the split ground truth")
    parser.add_argument("--generator", default="cd", help="height field of the split ground truth")
    parser.add_argument("--res", type=int, default=257, help="resolution of the split ground truth's volume")
    parser.add_argument("--slices", type=int, default=11, help="slices of the split ground truth's volume")
    parser.add_argument("--parts", type=int, default=4, help="wavelength blocks of the split ground truth")
    arguments = parser.parse_args(argv)
    arguments.out.mkdir(parents=True, exist_ok=True)
    if not arguments.skip_sweep:
        (arguments.out / "small.toml").write_text(SMALL)
        measured = [sweep_wall_time(arguments.out, workers) for workers in (1, 2)]
        for entry in measured:
            print(json.dumps({key: value for key, value in entry.items() if key != "rows"}), flush=True)
        print(json.dumps({"measurement": "same table with 1 and 2 workers",
                          "equal": measured[0]["rows"] == measured[1]["rows"],
                          "speed-up": round(measured[0]["seconds"] / measured[1]["seconds"], 2)}), flush=True)
    for entry in split_agreement(arguments.generator, arguments.res, arguments.slices, arguments.parts, 2):
        print(json.dumps(entry), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
