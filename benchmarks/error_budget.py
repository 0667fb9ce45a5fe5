"""How small a network's error at the volume's samples must be for a FLIP target: the oracle of a noisy volume.

    python benchmarks/error_budget.py VOLUME.exr --heightfield paper-scratches [--model MODEL.npz]
        [--sigmas 2.5e-4,5e-4,1e-3,2e-3] [--views '0,0,2000;…'] [--cache-dir out/cache]
        [--json OUT.json] [--figure OUT.png] [--target 0.0123]

A network trained on a volume errs at the volume's own samples by some RMS σ in the range-transformed y
(eq. 7; what the LogCosh loss sees) and renders between them. This adds Gaussian noise of RMS σ to every
reachable sample's y, maps back to CIE XYZ and scores the interpolation oracle of that noisy volume
(trilinear in u*, v*, t, trainer/diagnostics.py) on the BRDF slices against the exact ground truth, as
`gratnet evaluate` scores a network (mean FLIP over the 256² image). Two noise models bracket a network's
errors: ``independent`` (each of X, Y, Z its own noise: colour and brightness errors) and ``shared`` (one
noise for all three: brightness only). FLIP against σ then says what error at the samples a target needs.

With ``--model``, the model's own σ is measured at a random subset of the samples (and its error's
correlation between channels), and the noisy oracle at that σ is scored beside the network's measured FLIP:
where they agree, the noise model predicts the network, and the σ read off for the target is what its fit
at the samples must reach. Noise is drawn from a fixed seed: each σ is one draw.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

from gratnet.atomic import atomic_path
from gratnet.encoding import RangeSpec, range_forward, range_inverse
from gratnet.modelfile import load_model, mlp_forward, network_inputs
from gratnet.volume import Volume, read_volume, volume_axes
from trainer.brdfslice import SliceConfig, slice_view_directions
from trainer.diagnostics import VolumeOracle
from trainer.evaluate import STANDARD_SLICES, ground_truth_brdf_slice, network_brdf_slice
from trainer.fourier import OpticsConfig
from trainer.loaders import LoadOptions, load_heightfield
from trainer.metrics import image_metrics
from trainer.sampling import grid_to_key
from trainer.train import volume_samples

NOISE_MODELS = ("independent", "shared")


def reachable_mask(volume: Volume) -> np.ndarray:
    """(R, R) True where u² + v² ≤ 4 on the volume's lattice (rows v*, columns u*)."""
    key = grid_to_key(volume_axes(volume.resolution), volume.metadata["scheme"])
    u_grid, v_grid = np.meshgrid(key, key, indexing="xy")
    return u_grid**2 + v_grid**2 <= 4.0 + 1e-12


def noisy_volume(volume: Volume, range_spec: RangeSpec, sigma: float, model: str, seed: int = 0) -> Volume:
    """``volume`` with Gaussian noise of RMS ``sigma`` added to every reachable sample's y = T(XYZ) (``model``:
    one of :data:`NOISE_MODELS`), mapped back through T⁻¹; unreachable samples stay 0."""
    if model not in NOISE_MODELS:
        raise SystemExit(f"error_budget: noise model must be one of {', '.join(NOISE_MODELS)}, got {model!r}")
    rng = np.random.default_rng(seed)
    reachable = reachable_mask(volume)
    xyz = np.zeros_like(volume.xyz)
    for index in range(volume.slices):  # one slice at a time: float64 y of a whole volume is 0.5 GB more
        y = range_forward(volume.xyz[index][reachable].astype(np.float64), range_spec)
        shape = y.shape if model == "independent" else (y.shape[0], 1)
        y = y + sigma * rng.standard_normal(shape)
        xyz[index][reachable] = range_inverse(y, range_spec).astype(np.float32)
    return Volume(xyz, dict(volume.metadata))


def model_sample_error(model_path: str, volume: Volume, count: int, seed: int = 0) -> dict[str, float]:
    """RMS of (network − target) in y at ``count`` random reachable samples of ``volume``, and the mean
    correlation of that error between the X, Y and Z channels."""
    model = load_model(model_path)
    coordinates, targets, _ = volume_samples(volume, model.range)
    pick = np.random.default_rng(seed).choice(len(coordinates), size=min(count, len(coordinates)), replace=False)
    error = mlp_forward(model, network_inputs(model, coordinates[pick].astype(np.float64))) - targets[pick]
    correlation = np.corrcoef(error.T)
    return {"rms": float(np.sqrt(np.mean(error**2))), "samples": int(len(pick)),
            "channel_correlation": float(np.mean(correlation[np.triu_indices(3, 1)]))}


def parse_floats(text: str, what: str) -> list[float]:
    try:
        values = [float(part) for part in text.split(",") if part.strip()]
    except ValueError:
        sys.exit(f"error_budget: {what} must be comma-separated numbers, got {text!r}")
    if not values or min(values) < 0:
        sys.exit(f"error_budget: {what} must be non-negative numbers, got {text!r}")
    return values


def parse_views(text: str) -> list[tuple[float, float, float]]:
    if not text:
        return list(STANDARD_SLICES[:1])
    views = []
    for part in filter(None, (item.strip() for item in text.split(";"))):
        values = parse_floats(part, "--views")
        if len(values) != 3:
            sys.exit(f"error_budget: --views: each view is 'θ,φ,RU', got {part!r}")
        views.append((values[0], values[1], values[2]))
    return views


def figure(path: str, rows: list[dict[str, Any]], target: float | None, measured: dict[str, Any] | None) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from gratnet.figures import save_figure

    fig, ax = plt.subplots(figsize=(6.4, 4.2))
    views = sorted({tuple(row["view"]) for row in rows})
    for view in views:
        for model, style in zip(NOISE_MODELS, ("-o", "--s"), strict=True):
            points = sorted((row["sigma"], row["flip"]) for row in rows if tuple(row["view"]) == view
                            and row["noise"] == model and row["sigma"] > 0)
            if points:
                ax.plot(*zip(*points, strict=True), style, label=f"({view[0]:g}°, {view[1]:g}°), {model} noise")
    if target is not None:
        ax.axhline(target, color="k", lw=0.8, ls=":", label=f"target {target:g}")
    if measured is not None:
        ax.axvline(measured["rms"], color="tab:red", lw=0.8, ls=":", label=f"the model's σ ({measured['rms']:.2e})")
        for view, flip in measured["network_flip"].items():
            ax.plot([measured["rms"]], [flip], "r*", ms=10, label=f"the model's FLIP at {view}")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("RMS noise σ added to every sample (range-transformed y)")
    ax.set_ylabel("mean FLIP of the noisy volume's oracle")
    ax.set_title("Error budget: FLIP against the error at the samples")
    ax.legend(fontsize=7)
    ax.grid(True, which="both", alpha=0.3)
    save_figure(fig, path)
    plt.close(fig)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("volume", help="ground-truth volume (.exr)")
    parser.add_argument("--heightfield", required=True, help="height field or paper dataset of the ground truth")
    parser.add_argument("--model", help="a model trained on this volume: its σ at the samples and its FLIP")
    parser.add_argument("--sigmas", default="2.5e-4,5e-4,1e-3,2e-3", help="RMS noise levels in y, comma-separated")
    parser.add_argument("--noise", default="independent,shared", help="noise models, comma-separated")
    parser.add_argument("--views", default="", help="'θ,φ,RU' triples separated by ';' (default: (0°, 0°) 2000 RU)")
    parser.add_argument("--range-power", type=float, default=4.0, help="n of the power-log transform (no --model)")
    parser.add_argument("--size", type=int, default=256, help="slice width and height (pixels)")
    parser.add_argument("--cache-dir", default="out/cache", help="ground-truth slice cache (as gratnet evaluate's)")
    parser.add_argument("--samples", type=int, default=2_000_000, help="samples at which the model's σ is measured")
    parser.add_argument("--target", type=float, help="a FLIP target to draw")
    parser.add_argument("--json", help="write the figures here (JSON)")
    parser.add_argument("--figure", help="write a plot of FLIP against σ here (PNG)")
    args = parser.parse_args()
    sigmas = parse_floats(args.sigmas, "--sigmas")
    noises = [part.strip() for part in args.noise.split(",") if part.strip()]
    if not noises or any(noise not in NOISE_MODELS for noise in noises):
        sys.exit(f"error_budget: --noise must name some of {', '.join(NOISE_MODELS)}, got {args.noise!r}")
    views = parse_views(args.views)
    for path in filter(None, (args.volume, args.model)):
        if not Path(path).is_file():
            sys.exit(f"error_budget: no such file: {path}")

    volume = read_volume(args.volume)
    field = load_heightfield(args.heightfield, LoadOptions())
    optics = OpticsConfig.from_volume_metadata(volume.metadata)
    range_spec = load_model(args.model).range if args.model else RangeSpec(power=args.range_power)
    _, inside = slice_view_directions(args.size)
    configs = [SliceConfig(theta, phi, size=args.size, exposure=exposure, ior=1.5) for theta, phi, exposure in views]
    references = [ground_truth_brdf_slice(field, optics, config, args.cache_dir) for config in configs]
    labels = [f"({view[0]:g}°, {view[1]:g}°)" for view in views]

    measured = None
    if args.model:
        measured = model_sample_error(args.model, volume, args.samples)
        model = load_model(args.model)
        measured["network_flip"] = {label: image_metrics(reference, network_brdf_slice(model, config),
                                                         mask=inside)["flip"]
                                    for label, config, reference in zip(labels, configs, references, strict=True)}
        print(f"model: σ at {measured['samples']} samples = {measured['rms']:.3e} (y), channel correlation "
              f"{measured['channel_correlation']:.2f}; FLIP {measured['network_flip']}", flush=True)
        sigmas = sorted({*sigmas, measured["rms"]})
    rows = []
    for noise in noises:
        for sigma in [0.0, *sigmas] if noise == noises[0] else sigmas:
            started = time.perf_counter()
            oracle = VolumeOracle(noisy_volume(volume, range_spec, sigma, noise) if sigma > 0 else volume)
            for view, label, config, reference in zip(views, labels, configs, references, strict=True):
                flip = image_metrics(reference, oracle.brdf_slice(config), mask=inside)["flip"]
                rows.append({"noise": noise if sigma > 0 else "none", "sigma": sigma, "view": list(view),
                             "flip": flip})
                print(f"{noise if sigma > 0 else 'no noise':>11}  σ = {sigma:.3e}  {label}  FLIP {flip:.4f}  "
                      f"({time.perf_counter() - started:.0f} s)", flush=True)
    result = {"volume": args.volume, "model": args.model, "range": dataclasses.asdict(range_spec),
              "measured": measured, "rows": rows}
    if args.json:
        with atomic_path(args.json) as temporary:
            Path(temporary).write_text(json.dumps(result, indent=1))
    if args.figure:
        figure(args.figure, rows, args.target, measured)


if __name__ == "__main__":
    main()
