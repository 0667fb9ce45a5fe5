"""A network's BRDF-slice error against the distance of each pixel's key vector from the nearest w-slice.

    python -m analysis.between_slices MODEL.npz --heightfield paper-scratches [--volume VOLUME.exr]
        [--views '0,0,2000;30,135,5000'] [--cache-dir out/cache] [--bins 5] [--json OUT.json]

A volume holds S w-slices at t_s = s/(S − 1) (trainer/sampling.py); the network is trained on them only and
rendered everywhere between them. Every pixel of a BRDF slice has a key vector, hence a slice position
p = t·(S − 1) and a distance d = |p − round(p)| ∈ [0, 0.5] (in slice spacings) from the nearest w-slice.
This bins the pixels of each view's disc by d and reports, per bin, the mean FLIP (NVIDIA's flip-evaluator,
as `gratnet evaluate` computes it: the error map of the whole image, averaged over the bin's pixels) and the
median |ln(Y_network / Y_truth)| over pixels lit in the truth, for the network and, with ``--volume``, the
interpolation oracle (trilinear in u*, v*, t). If the network's error grows with d faster than the oracle's,
what the network does between w-slices is a lever; if it is flat, its error at the samples is.

Ground-truth slices come from the same cache as `gratnet evaluate` (--cache-dir), computed when missing.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

import numpy as np

from gratnet.atomic import atomic_path
from gratnet.encoding import network_coordinates
from gratnet.errors import GratNetError
from gratnet.modelfile import load_model
from gratnet.volume import read_volume
from trainer.brdfslice import SliceConfig, slice_geometry
from trainer.diagnostics import VolumeOracle
from trainer.evaluate import (
    STANDARD_SLICES,
    EvaluateConfig,
    ground_truth_brdf_slice,
    model_ground_truth_inputs,
    network_brdf_slice,
    slice_label,
)
from trainer.metrics import flip

#: Pixels whose true Y (exposed) is below this are left out of the log-ratio median (display black).
LIT_Y = 1e-3


def slice_distance(config: SliceConfig, scheme: str, slices: int) -> tuple[np.ndarray, np.ndarray]:
    """(d, inside): per pixel of the slice's disc, the distance (in slice spacings, 0 … 0.5) of its key vector's
    t from the nearest of ``slices`` uniform w-slices; ``inside`` the disc mask."""
    light, views, inside = slice_geometry(config)
    key = -(light + views)
    distance = np.full(inside.shape, np.nan)
    coordinates = network_coordinates(key[inside][:, 0], key[inside][:, 1], key[inside][:, 2], scheme)
    position = (np.clip(coordinates[:, 2], -1.0, 1.0) + 1.0) * 0.5 * (slices - 1)
    distance[inside] = np.abs(position - np.rint(position))
    return distance, inside


def binned(reference: np.ndarray, test: np.ndarray, distance: np.ndarray, inside: np.ndarray,
           edges: np.ndarray) -> list[dict[str, float]]:
    """Per bin of ``distance`` (``edges``): pixel count, mean FLIP and median |ln(Y_test / Y_ref)| over lit pixels."""
    _, error_map = flip(reference, test)
    y_ref, y_test = reference[..., 1], test[..., 1]
    lit = inside & (y_ref > LIT_Y)
    log_ratio = np.abs(np.log(np.maximum(y_test, 1e-12) / np.maximum(y_ref, 1e-12)))
    rows = []
    for low, high in zip(edges[:-1], edges[1:], strict=True):
        in_bin = inside & (distance >= low) & (distance <= high if high == edges[-1] else distance < high)
        lit_bin = in_bin & lit
        rows.append({"d_low": float(low), "d_high": float(high), "pixels": int(in_bin.sum()),
                     "flip": float(error_map[in_bin].mean()) if in_bin.any() else float("nan"),
                     "median_abs_log_y": float(np.median(log_ratio[lit_bin])) if lit_bin.any() else float("nan")})
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("model", help="model file (.npz)")
    parser.add_argument("--heightfield", required=True, help="height field or paper dataset of the ground truth")
    parser.add_argument("--volume", help="the volume the model was trained on: adds the interpolation oracle")
    parser.add_argument("--views", default="", help="'θ,φ,RU' triples separated by ';' (default: the paper's five)")
    parser.add_argument("--size", type=int, default=256, help="slice width and height (pixels)")
    parser.add_argument("--cache-dir", default="out/cache", help="ground-truth slice cache (as gratnet evaluate's)")
    parser.add_argument("--bins", type=int, default=5, help="bins of d over [0, 0.5]")
    parser.add_argument("--t-nodes", type=int, default=0,
                        help="measure d from a uniform lattice of this many t nodes instead of the volume's w-slices "
                        "(e.g. a coarse grid level's, --grid-level-t)")
    parser.add_argument("--json", help="also write the figures here (JSON)")
    args = parser.parse_args()
    try:  # gratnet evaluate's own parsing and checks of --views
        views = list(EvaluateConfig(views=args.views).extra_views()) or list(STANDARD_SLICES)
    except GratNetError as error:
        sys.exit(f"between_slices: {error}")
    if args.bins < 1 or args.t_nodes == 1 or args.t_nodes < 0:
        sys.exit("between_slices: --bins must be ≥ 1 and --t-nodes 0 (the w-slices) or ≥ 2")
    for path in filter(None, (args.model, args.volume)):
        if not Path(path).is_file():
            sys.exit(f"between_slices: no such file: {path}")

    model = load_model(args.model)
    field, optics = model_ground_truth_inputs(model, args.heightfield)
    scheme = model.metadata["volume"]["scheme"]
    slices = args.t_nodes or int(model.metadata["volume"]["slices"])
    oracle = VolumeOracle(read_volume(args.volume)) if args.volume else None
    edges = np.linspace(0.0, 0.5, args.bins + 1)
    results = []
    for theta, phi, exposure in views:
        config = SliceConfig(theta, phi, size=args.size, exposure=exposure, ior=1.5)
        reference = ground_truth_brdf_slice(field, optics, config, args.cache_dir)
        distance, inside = slice_distance(config, scheme, slices)
        row: dict[str, Any] = {"view": [theta, phi, exposure], "t_nodes": slices,
               "network": binned(reference, network_brdf_slice(model, config), distance, inside, edges)}
        if oracle is not None:
            row["oracle"] = binned(reference, oracle.brdf_slice(config), distance, inside, edges)
        results.append(row)
        print(f"{slice_label(theta, phi, exposure)}, d from {slices} uniform t nodes:")
        print("  d (slice spacings)   pixels   FLIP network   FLIP oracle   med|ln Y ratio| network   oracle")
        for index, bin_row in enumerate(row["network"]):
            oracle_row = row["oracle"][index] if oracle is not None else {}
            print(f"  {bin_row['d_low']:.2f}–{bin_row['d_high']:.2f}          {bin_row['pixels']:7d}   "
                  f"{bin_row['flip']:.4f}         {oracle_row.get('flip', float('nan')):.4f}        "
                  f"{bin_row['median_abs_log_y']:.4f}                   "
                  f"{oracle_row.get('median_abs_log_y', float('nan')):.4f}")
    if args.json:
        with atomic_path(args.json) as temporary:
            Path(temporary).write_text(json.dumps({"model": args.model, "volume": args.volume, "rows": results},
                                                  indent=1))


if __name__ == "__main__":
    main()
