"""How small a network's error must be for a FLIP target: FLIP against an error of known size and kind.

    python -m analysis.error_budget MODEL.npz --heightfield paper-scratches [--volume VOLUME.exr]
        [--sigmas 5e-4,1e-3,1.5e-3,2e-3,3e-3] [--views '0,0,2000;30,0,5000'] [--cache-dir out/cache]
        [--target 0.0123] [--json OUT.json] [--figure OUT.png]

Errors are measured in the range-transformed y of eq. 7 (what the LogCosh loss sees), per BRDF-slice pixel:
y(network at the pixel's key vector) − y(exact ground truth there), with XYZ = slice / (exposure · A). For each
view (mean FLIP over the 256² image, exactly as `gratnet evaluate` scores it):

- ``network``: the model's FLIP and the RMS σ_px of its y error over the disc's pixels;
- ``shuffled``: the truth plus the network's own per-pixel errors randomly permuted over the disc's pixels (the
  same error values, no spatial structure). When it scores like the network, FLIP sees the size of the errors,
  not their pattern;
- ``scaled``: the truth plus the network's own errors (in place) times k, for k in :data:`SCALES`, and the k at
  which FLIP crosses ``--target``: by how much this network's errors, as they are, must shrink;
- ``white``: the truth plus Gaussian noise of RMS σ in y on every pixel (independent per X, Y, Z), for each
  ``--sigmas``: FLIP against σ, and the σ at which it crosses ``--target`` (log-log interpolation): the
  per-pixel error a network may make to reach the target.

With ``--volume`` (the volume the model was trained on), also the oracle of that volume with Gaussian noise of
RMS σ added to every reachable sample's y (``samples`` rows), and the model's own σ at a random subset of the
samples: the error budget at the samples, if errors there were white. Every noise is drawn from a fixed seed.
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
from gratnet.errors import GratNetError
from gratnet.modelfile import ModelFile, load_model, mlp_forward, network_inputs
from gratnet.volume import Volume, read_volume, volume_axes
from trainer.brdfslice import SliceConfig, expose_slice, slice_geometry
from trainer.diagnostics import VolumeOracle
from trainer.evaluate import (
    EvaluateConfig,
    ground_truth_brdf_slice,
    model_ground_truth_inputs,
    network_brdf_slice,
    slice_label,
)
from trainer.metrics import image_metrics
from trainer.sampling import grid_to_key, physical_mask
from trainer.train import volume_samples

#: Factors k of the ``scaled`` rows.
SCALES = (0.25, 0.35, 0.5, 0.7, 1.0)
#: Views scored by default: the paper's (0°, 0°) slice and one oblique one.
DEFAULT_VIEWS = "0,0,2000;30,0,5000"


def reachable_mask(volume: Volume) -> np.ndarray:
    """(R, R) True where u² + v² ≤ 4 on the volume's lattice (rows v*, columns u*)."""
    key = grid_to_key(volume_axes(volume.resolution), volume.metadata["scheme"])
    return physical_mask(key, key)


def noisy_volume(volume: Volume, range_spec: RangeSpec, sigma: float, seed: int = 0) -> Volume:
    """``volume`` with Gaussian noise of RMS ``sigma`` (independent per channel) added to every reachable
    sample's y = T(XYZ), mapped back through T⁻¹; unreachable samples stay 0."""
    rng = np.random.default_rng(seed)
    reachable = reachable_mask(volume)
    xyz = np.zeros_like(volume.xyz)
    for index in range(volume.slices):  # a slice at a time: float64 y of a whole volume is 0.5 GB more
        y = range_forward(volume.xyz[index][reachable].astype(np.float64), range_spec)
        xyz[index][reachable] = range_inverse(y + sigma * rng.standard_normal(y.shape), range_spec).astype(np.float32)
    return Volume(xyz, dict(volume.metadata))


def sample_error(model: ModelFile, volume: Volume, count: int, seed: int = 0, chunk: int = 200_000) -> float:
    """RMS of (network − target) in y at ``count`` random reachable samples of ``volume``."""
    coordinates, targets, _ = volume_samples(volume, model.range)
    pick = np.random.default_rng(seed).choice(len(coordinates), size=min(count, len(coordinates)), replace=False)
    squares = 0.0
    for start in range(0, len(pick), chunk):  # chunks: the MLP's activations of 2 M points are gigabytes
        part = pick[start:start + chunk]
        squares += float(np.sum((mlp_forward(model, network_inputs(model, coordinates[part].astype(np.float64)))
                                 - targets[part]) ** 2))
    return float(np.sqrt(squares / (3 * len(pick))))


def pixel_y(config: SliceConfig, image: np.ndarray, range_spec: RangeSpec) -> np.ndarray:
    """y = T(image / (exposure · A)) of the disc's pixels (N, 3): a slice's exposed values back to the network's
    range-transformed domain."""
    light, views, inside = slice_geometry(config)
    scale = expose_slice(config, light, views, inside, np.ones(views.shape))[inside]
    return range_forward(image[inside] / np.where(scale > 0, scale, 1.0), range_spec)


def image_of(config: SliceConfig, y: np.ndarray, range_spec: RangeSpec) -> np.ndarray:
    """The exposed slice (size, size, 3) whose disc pixels have range-transformed values ``y`` (N, 3)."""
    light, views, inside = slice_geometry(config)
    xyz = np.zeros(views.shape)
    xyz[inside] = range_inverse(y, range_spec)
    return expose_slice(config, light, views, inside, xyz)


def crossing(sigmas: list[float], flips: list[float], target: float) -> float | None:
    """σ where FLIP(σ) reaches ``target``, interpolated in log-log between the measured points (None if the
    measured FLIPs do not bracket it)."""
    for (s0, f0), (s1, f1) in zip(zip(sigmas, flips, strict=True), zip(sigmas[1:], flips[1:], strict=True),
                                  strict=False):
        if min(f0, f1) <= target <= max(f0, f1) and f0 != f1 and s0 > 0:
            fraction = (np.log(target) - np.log(f0)) / (np.log(f1) - np.log(f0))
            return float(np.exp(np.log(s0) + fraction * (np.log(s1) - np.log(s0))))
    return None


def parse_floats(text: str, what: str) -> list[float]:
    try:
        values = [float(part) for part in text.split(",") if part.strip()]
    except ValueError:
        sys.exit(f"error_budget: {what} must be comma-separated numbers, got {text!r}")
    if not values or not all(np.isfinite(values)):
        sys.exit(f"error_budget: {what} must be finite numbers, got {text!r}")
    return values


def view_rows(model: ModelFile, config: SliceConfig, reference: np.ndarray, sigmas: list[float],
              seed: int = 0) -> dict[str, Any]:
    """The network, shuffled and white rows of the module docstring for one view."""
    _, _, inside = slice_geometry(config)
    truth = pixel_y(config, reference, model.range)
    network = network_brdf_slice(model, config)
    error = pixel_y(config, network, model.range) - truth
    rng = np.random.default_rng(seed)

    def flip_of(y: np.ndarray) -> float:
        return image_metrics(reference, image_of(config, y, model.range), mask=inside)["flip"]

    return {
        "network": {"flip": image_metrics(reference, network, mask=inside)["flip"],
                    "sigma_px": float(np.sqrt(np.mean(error**2))),
                    "channel_correlation": float(np.mean(np.corrcoef(error.T)[np.triu_indices(3, 1)]))},
        "shuffled": {"flip": flip_of(truth + error[rng.permutation(len(error))])},
        "scaled": [{"k": k, "flip": flip_of(truth + k * error)} for k in SCALES],
        "white": [{"sigma": sigma, "flip": flip_of(truth + sigma * rng.standard_normal(truth.shape))}
                  for sigma in sigmas],
    }


def figure(path: str, result: dict[str, Any], target: float | None) -> None:
    """Left: FLIP against white noise σ per pixel, each view's network (★) and its shuffled errors (×) at its own
    σ, and the noisy-samples oracle (dashed) where measured. Right: FLIP against k, the network's errors × k."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from gratnet.figures import save_figure

    fig, (left, right) = plt.subplots(1, 2, figsize=(11.5, 4.6), sharey=True)
    for index, view in enumerate(result["views"]):
        colour = f"C{index}"
        left.plot([row["sigma"] for row in view["white"]], [row["flip"] for row in view["white"]], "-o", color=colour,
                  ms=3, lw=1, label=view["label"])
        left.plot([view["network"]["sigma_px"]], [view["network"]["flip"]], "*", color=colour, ms=11)
        left.plot([view["network"]["sigma_px"]], [view["shuffled"]["flip"]], "x", color=colour, ms=7)
        if view.get("samples"):
            left.plot([row["sigma"] for row in view["samples"]], [row["flip"] for row in view["samples"]], "--",
                      color=colour, lw=1, alpha=0.7)
        right.plot([row["k"] for row in view["scaled"]], [row["flip"] for row in view["scaled"]], "-o", color=colour,
                   ms=3, lw=1, label=view["label"])
    for ax in (left, right):
        if target is not None:
            ax.axhline(target, color="k", lw=0.8, ls=":")
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.grid(True, which="both", alpha=0.3)
    left.set_xlabel("RMS error σ per pixel in the range-transformed y")
    left.set_ylabel("mean FLIP")
    left.set_title("truth + white noise σ (lines); ★ the network at its σ,\n× its errors shuffled over the pixels"
                   + ("; dashed: noise at the samples" if any(v.get("samples") for v in result["views"]) else ""),
                   fontsize=9)
    right.set_xlabel("k: the network's own errors scaled by k")
    right.set_title("truth + k × the network's errors" + (f" (dotted: target {target:g})" if target else ""),
                    fontsize=9)
    right.legend(fontsize=7, loc="lower right")
    save_figure(fig, path)
    plt.close(fig)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("model", help="model file (.npz)")
    parser.add_argument("--heightfield", required=True, help="height field or paper dataset of the ground truth")
    parser.add_argument("--volume", help="the volume the model was trained on: adds the noisy-samples oracle")
    parser.add_argument("--sigmas", default="5e-4,1e-3,1.5e-3,2e-3,3e-3", help="RMS noise levels in y")
    parser.add_argument("--views", default=DEFAULT_VIEWS, help="'θ,φ,RU' triples separated by ';'")
    parser.add_argument("--size", type=int, default=256, help="slice width and height (pixels)")
    parser.add_argument("--cache-dir", default="out/cache", help="ground-truth slice cache (as gratnet evaluate's)")
    parser.add_argument("--samples", type=int, default=2_000_000, help="samples at which the model's σ is measured")
    parser.add_argument("--target", type=float, help="a FLIP target: report the σ that reaches it, and draw it")
    parser.add_argument("--json", help="write the figures here (JSON)")
    parser.add_argument("--figure", help="write a plot of FLIP against σ here (PNG)")
    args = parser.parse_args()
    sigmas = sorted(parse_floats(args.sigmas, "--sigmas"))
    if min(sigmas) <= 0:
        sys.exit(f"error_budget: --sigmas must be positive, got {args.sigmas!r}")
    try:  # gratnet evaluate's own parsing and checks of --views
        views = EvaluateConfig(views=args.views).extra_views()
    except GratNetError as error:
        sys.exit(f"error_budget: {error}")
    if not views or args.size < 2 or args.samples < 1:
        sys.exit("error_budget: give at least one view, --size ≥ 2 and --samples ≥ 1")
    if args.target is not None and not args.target > 0:
        sys.exit(f"error_budget: --target must be a positive FLIP, got {args.target}")
    for path in filter(None, (args.model, args.volume)):
        if not Path(path).is_file():
            sys.exit(f"error_budget: no such file: {path}")

    model = load_model(args.model)
    field, optics = model_ground_truth_inputs(model, args.heightfield)
    volume = read_volume(args.volume) if args.volume else None
    result: dict[str, Any] = {"model": args.model, "volume": args.volume, "heightfield": args.heightfield,
                              "range": dataclasses.asdict(model.range), "target": args.target, "views": []}
    if volume is not None:
        result["model_sample_sigma"] = sample_error(model, volume, args.samples)
        print(f"the model's σ at {args.samples} random samples of the volume: {result['model_sample_sigma']:.3e}",
              flush=True)
    scored = []  # (row, config, reference) per view
    for theta, phi, exposure in views:
        started = time.perf_counter()
        config = SliceConfig(theta, phi, size=args.size, exposure=exposure, ior=1.5)
        reference = ground_truth_brdf_slice(field, optics, config, args.cache_dir)
        row = {"label": slice_label(theta, phi, exposure), "view": [theta, phi, exposure],
               **view_rows(model, config, reference, sigmas)}
        if args.target is not None:
            row["white_sigma_at_target"] = crossing(sigmas, [item["flip"] for item in row["white"]], args.target)
            row["scale_at_target"] = crossing([item["k"] for item in row["scaled"]],
                                              [item["flip"] for item in row["scaled"]], args.target)
        result["views"].append(row)
        scored.append((row, config, reference))
        network = row["network"]
        print(f"{row['label']}: network FLIP {network['flip']:.4f} at σ_px {network['sigma_px']:.2e} (channel "
              f"correlation {network['channel_correlation']:.2f}); its errors shuffled {row['shuffled']['flip']:.4f}; "
              "white σ → FLIP " + ", ".join(f"{item['sigma']:.1e} → {item['flip']:.4f}" for item in row["white"])
              + (f"; σ at the target {row['white_sigma_at_target']:.2e}" if row.get("white_sigma_at_target") else "")
              + "; its errors × k → FLIP " + ", ".join(f"{item['k']:g} → {item['flip']:.4f}" for item in row["scaled"])
              + (f"; k at the target {row['scale_at_target']:.2f}" if row.get("scale_at_target") else "")
              + f" ({time.perf_counter() - started:.0f} s)", flush=True)
    if volume is not None:  # one noisy volume per σ (a quarter GB each), scored on every view
        for sigma in sigmas:
            oracle = VolumeOracle(noisy_volume(volume, model.range, sigma))
            for row, config, reference in scored:
                flip = image_metrics(reference, oracle.brdf_slice(config), mask=slice_geometry(config)[2])["flip"]
                row.setdefault("samples", []).append({"sigma": sigma, "flip": flip})
                print(f"{row['label']}: white noise σ = {sigma:.1e} at the volume's samples → oracle FLIP {flip:.4f}",
                      flush=True)
    if args.json:
        with atomic_path(args.json) as temporary:
            Path(temporary).write_text(json.dumps(result, indent=1))
    if args.figure:
        figure(args.figure, result, args.target)


if __name__ == "__main__":
    main()
