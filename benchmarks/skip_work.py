"""Issue 5, "Skip what a scene doesn't need": MLP evaluations and time with work skipping off and on.

For each model (default: every shipped ``assets/*/model.npz``) this renders the standard views — the CD
disc of scripts/main.sh (``--mesh cd --light 35,200 --camera 0.16,0,55 --exposure 250``) and the five
BRDF slices of ``trainer.evaluate.STANDARD_SLICES`` — twice:

* baseline: no skipping, no depth pre-pass (every rasterized fragment that passes the depth test in
  submission order, every in-disc slice pixel runs the MLP);
* skip: ``skip_threshold = DISPLAY_SKIP_THRESHOLD`` (the bound of gratnet/bounds.py) and the depth pre-pass.

Per view it prints one JSON line: MLP evaluations (baseline, skip; from a counting variant of the
programs), their ratio, the ``oracle_ratio`` (baseline evaluations / pixels whose displayed baseline is
not black: the most any image-preserving skip could achieve), wall time of the render (median of
``--repeats``, counting off, after a warm-up render) and speed-up, mean FLIP between the two displayed
images (``trainer.metrics.flip``), the max 8-bit difference and the fraction of pixels that differ.

    python benchmarks/skip_work.py --models assets/cd/model.npz --slice-size 256 --disc-size 320,240 \\
        --plot out/skip_work.png

The bound is read from (or computed into) the cache of ``gratnet.bounds.output_bounds``.
"""

from __future__ import annotations

import argparse
import glob
import json
import statistics as stats
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from gratnet.bounds import DISPLAY_SKIP_THRESHOLD, BoundParameters, output_bounds
from gratnet.display import xyz_to_display_srgb8
from gratnet.modelfile import load_model

DISC_LIGHT = (35.0, 200.0)
DISC_CAMERA = (0.16, 0.0, 55.0)
DISC_EXPOSURE = 250.0


def _timed(function: Callable[[], np.ndarray], repeats: int) -> tuple[np.ndarray, float]:
    result = function()  # warm-up: compile, upload
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        result = function()
        times.append(time.perf_counter() - start)
    return result, stats.median(times)


def _compare(name: str, baseline: np.ndarray, skipped: np.ndarray, counts: tuple[dict[str, int], dict[str, int]],
             times: tuple[float, float], covered: np.ndarray) -> dict[str, Any]:
    from trainer.metrics import flip

    first, second = (xyz_to_display_srgb8(np.asarray(image, dtype=np.float64)) for image in (baseline, skipped))
    difference = np.abs(first.astype(np.int16) - second.astype(np.int16))
    lit = int(np.count_nonzero(np.any(first > 0, axis=-1) & covered))
    evaluations = counts[0]["evaluations"], counts[1]["evaluations"]
    mean_flip = flip(np.asarray(baseline, dtype=np.float64), np.asarray(skipped, dtype=np.float64))[0]
    return {
        "view": name, "pixels_covered": int(np.count_nonzero(covered)), "pixels_lit": lit,
        "evaluations_baseline": evaluations[0], "evaluations_skip": evaluations[1],
        "ratio": evaluations[0] / max(evaluations[1], 1),
        "oracle_ratio": evaluations[0] / max(lit, 1),
        "skipped_bound": counts[1]["skipped_bound"], "skipped_a_zero": counts[1]["skipped_a_zero"],
        "time_baseline_s": round(times[0], 4), "time_skip_s": round(times[1], 4),
        "speedup": times[0] / max(times[1], 1e-9),
        "flip": float(mean_flip), "max_8bit_diff": int(difference.max()),
        "fraction_pixels_changed": float(np.mean(np.any(difference > 0, axis=-1))),
    }


def run_model(ctx: Any, path: str, slice_size: int, disc_size: tuple[int, int], repeats: int, weights_path: str,
              parameters: BoundParameters) -> list[dict[str, Any]]:
    from trainer.evaluate import STANDARD_SLICES
    from viewer.camera import Camera, Light
    from viewer.meshes import compact_disc
    from viewer.scene import SceneRenderer

    model = load_model(path)
    start = time.perf_counter()
    bounds = output_bounds(model, parameters)
    bound_seconds = time.perf_counter() - start
    rows = []
    with SceneRenderer(ctx, model, weights_path=weights_path) as scene:
        network = scene.network
        assert network is not None  # a model file's scene shades with its network
        network.set_output_bounds(bounds)
        chosen = network.weights_path
        # The CD disc of scripts/main.sh.
        camera = Camera(*DISC_CAMERA)
        light = Light.directional(*DISC_LIGHT)
        buffers = scene.upload(compact_disc())
        try:
            def disc(skip: bool, counts: dict[str, int] | None = None) -> np.ndarray:
                return scene.render_rgba(buffers, camera, light, disc_size, DISC_EXPOSURE,
                                         skip_threshold=DISPLAY_SKIP_THRESHOLD if skip else None,
                                         depth_prepass=skip, statistics=counts)

            counts: tuple[dict[str, int], dict[str, int]] = ({}, {})
            disc(False, counts[0])
            disc(True, counts[1])
            baseline, time_baseline = _timed(lambda: disc(False), repeats)
            skipped, time_skip = _timed(lambda: disc(True), repeats)
            row = _compare("cd_disc", baseline[..., :3], skipped[..., :3], counts, (time_baseline, time_skip),
                           baseline[..., 3] > 0)
            rows.append(row)
        finally:
            buffers.release()
        # The five standard BRDF slices.
        for theta, phi, exposure in STANDARD_SLICES:
            def brdf(skip: bool, counts: dict[str, int] | None = None, theta: float = theta, phi: float = phi,
                     exposure: float = exposure) -> np.ndarray:
                return network.render_brdf_slice(theta, phi, slice_size, exposure,
                                                 skip_threshold=DISPLAY_SKIP_THRESHOLD if skip else None,
                                                 statistics=counts)

            counts = ({}, {})
            brdf(False, counts[0])
            brdf(True, counts[1])
            baseline, time_baseline = _timed(lambda: brdf(False), repeats)
            skipped, time_skip = _timed(lambda: brdf(True), repeats)
            centres = (2.0 * np.arange(slice_size) + 1.0) / slice_size - 1.0
            inside = centres[None, :] ** 2 + centres[:, None] ** 2 < 1.0
            rows.append(_compare(f"slice_{theta:g}_{phi:g}", baseline, skipped, counts, (time_baseline, time_skip),
                                 inside))
    for row in rows:
        row.update({"model": path, "weights_path": chosen, "bound_cells": list(bounds.cells),
                    "bound_dilation": parameters.dilation, "bound_margin_bits": parameters.margin_bits,
                    "bound_seconds": round(bound_seconds, 2)})
    return rows


def plot(rows: list[dict[str, Any]], target: Path) -> None:
    """Per view: MLP evaluations baseline / skip / oracle (pixels not black), log scale."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from gratnet.figures import save_figure

    labels = [f"{Path(row['model']).parent.name}\n{row['view']}" for row in rows]
    x = np.arange(len(rows))
    figure, axes = plt.subplots(figsize=(max(6.0, 0.9 * len(rows)), 4.0))
    axes.bar(x - 0.27, [row["evaluations_baseline"] for row in rows], 0.27, label="baseline")
    axes.bar(x, [row["evaluations_skip"] for row in rows], 0.27, label="skip (bound + pre-pass)")
    axes.bar(x + 0.27, [row["pixels_lit"] for row in rows], 0.27, label="oracle: pixels not black")
    axes.set_xticks(x, labels, fontsize=7)
    axes.set_ylabel("MLP evaluations per frame")
    axes.set_yscale("log")
    axes.legend(fontsize=8)
    axes.set_title("MLP evaluations, skipping off / on")
    figure.tight_layout()
    target.parent.mkdir(parents=True, exist_ok=True)
    save_figure(figure, target, dpi=120)
    plt.close(figure)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--models", nargs="*", default=None, help="model files (default: assets/*/model.npz)")
    parser.add_argument("--slice-size", type=int, default=256)
    parser.add_argument("--disc-size", default="320,240", help="WIDTH,HEIGHT of the CD disc view")
    parser.add_argument("--repeats", type=int, default=3, help="timed renders per configuration (median)")
    parser.add_argument("--weights-path", default="auto", choices=("auto", "texture", "baked"))
    parser.add_argument("--cells", type=int, default=BoundParameters.cells_uv, help="bound cells per u*/v* axis")
    parser.add_argument("--dilation", type=int, default=BoundParameters.dilation,
                        help="bound: neighbouring cells merged into each cell's maximum")
    parser.add_argument("--margin-bits", type=float, default=BoundParameters.margin_bits,
                        help="bound: safety factor 2^bits on the CIE XYZ bound")
    parser.add_argument("--plot", type=Path, default=None, help="write a bar chart PNG here")
    arguments = parser.parse_args(argv)
    models = arguments.models or sorted(glob.glob(str(Path(__file__).resolve().parent.parent / "assets/*/model.npz")))
    width, height = (int(part) for part in arguments.disc_size.split(","))

    from viewer.context import create_headless_context

    ctx = create_headless_context()
    rows: list[dict[str, Any]] = []
    try:
        for path in models:
            for row in run_model(ctx, path, arguments.slice_size, (width, height), arguments.repeats,
                                 arguments.weights_path,
                                 BoundParameters(cells_uv=arguments.cells, dilation=arguments.dilation,
                                                 margin_bits=arguments.margin_bits)):
                print(json.dumps(row), flush=True)
                rows.append(row)
    finally:
        ctx.release()
    if arguments.plot is not None and rows:
        plot(rows, arguments.plot)
        print(f"plot: {arguments.plot}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
