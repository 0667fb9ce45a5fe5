"""Where Adam's ε sets the step: sqrt(v) of every parameter tensor of a training checkpoint, against ε.

    python -m analysis.adam_state RUN/checkpoint.pt [--json OUT.json]

Adam moves a parameter by lr · m̂ / (sqrt(v̂) + ε). Where sqrt(v̂) ≪ ε the step is lr · m̂ / ε: plain momentum
SGD at rate lr/ε, proportional to the gradient, not normalised by it. The LogCosh loss of range-transformed
targets is ~1e-6 late in training, so its gradients are small: this prints, per parameter tensor (MLP layers,
then the feature grids), the 10th/50th/90th percentiles of sqrt(v̂) (bias-corrected with the checkpoint's step
count) and the share of entries whose sqrt(v̂) is below the group's ε. Entries that never had a gradient
(sqrt(v) = 0: grid nodes no sample reaches) are left out of both.

It also prints the median sqrt(v̂) of the first layer's weight columns per encoding frequency (eq. 6's layout,
sine and cosine apart; analysis.encoding_weights): the columns of the top frequency's sine, which is zero at
every training sample up to float32 rounding, get only rounding-noise gradients, and this shows how far below
the other columns' their sqrt(v̂) lies, i.e. which ε keeps them still while normalising the rest.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

import numpy as np

from analysis.encoding_weights import split_first_layer
from gratnet.atomic import atomic_path
from gratnet.errors import GratNetError


def _sqrt_v_hat(entry: dict[str, Any], group: dict[str, Any]) -> np.ndarray:
    """sqrt(v̂) of one parameter's Adam state, bias-corrected with its step count (float64, the tensor's shape)."""
    return np.sqrt(entry["exp_avg_sq"].double().numpy() / (1.0 - group["betas"][1] ** float(entry["step"])))


def adam_table(state: dict[str, Any]) -> list[dict[str, Any]]:
    """One row per parameter tensor of ``state`` (a trainer checkpoint): group, shape, sqrt(v̂) percentiles,
    share below ε, and entries with no gradient yet."""
    optimizer = state["optimizer"]
    rows = []
    for number, group in enumerate(optimizer["param_groups"]):
        name = ("mlp", "grids")[number] if len(optimizer["param_groups"]) == 2 else "all"
        for index in group["params"]:
            entry = optimizer["state"].get(index)
            if entry is None:
                continue
            root = _sqrt_v_hat(entry, group).ravel()
            touched = root > 0
            rows.append({
                "group": name,
                "shape": list(entry["exp_avg_sq"].shape),
                "eps": group["eps"],
                "sqrt_v_percentiles_10_50_90": np.percentile(root[touched], [10, 50, 90]).tolist()
                if touched.any() else None,
                "below_eps": float(np.mean(root[touched] < group["eps"])) if touched.any() else None,
                "never_touched": float(np.mean(~touched)),
            })
    return rows


def first_layer_sqrt_v(state: dict[str, Any]) -> dict[str, Any]:
    """Median sqrt(v̂) (bias-corrected) of the first layer's weight columns of ``state`` (a trainer checkpoint):
    grid-feature columns, raw (u*, v*, t) columns, and per encoding frequency (lowest to top) the spatial and
    t sine and cosine columns. The first layer's weight is the first parameter of the first group in both
    architectures (trainer.train's optimiser)."""
    optimizer, config = state["optimizer"], state["config"]
    group = optimizer["param_groups"][0]
    root = _sqrt_v_hat(optimizer["state"][group["params"][0]], group)
    grid = sum(int(tensor.shape[0]) for name, tensor in state["model"].items() if name.startswith("grids."))
    groups = 4 if config.get("diagonal_frequencies", True) else 2  # eq. 6a: a checkpoint's config may have it
    grid_columns, spatial, t_part = split_first_layer(root, grid, config["frequencies"], config["t_frequencies"],
                                                      groups)
    return {
        "eps": group["eps"],
        "grid_features": float(np.median(grid_columns)) if grid else None,
        "coordinates": float(np.median(root[:, grid:grid + 3])),
        "spatial_sin": np.median(spatial[:, :, 0], axis=(0, 1)).tolist(),
        "spatial_cos": np.median(spatial[:, :, 1], axis=(0, 1)).tolist(),
        "t_sin": np.median(t_part[:, 0], axis=0).tolist(),
        "t_cos": np.median(t_part[:, 1], axis=0).tolist(),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("checkpoint", type=Path, help="a `gratnet train` checkpoint.pt")
    parser.add_argument("--json", type=Path, help="write the table here as JSON")
    args = parser.parse_args()
    if not args.checkpoint.is_file():
        sys.exit(f"adam_state: no such file: {args.checkpoint}")
    from trainer.train import read_checkpoint

    try:
        state = read_checkpoint(args.checkpoint)
        rows = adam_table(state)
        columns = first_layer_sqrt_v(state)
    except (GratNetError, KeyError) as error:
        sys.exit(f"adam_state: {args.checkpoint} is not a training checkpoint with Adam's state: {error}")
    epochs = len(state.get("history", {}).get("epochs", []))
    print(f"{args.checkpoint}: after epoch {epochs}, step {int(state.get('steps', 0))}")
    print("| group | shape | ε | sqrt(v̂): 10th / 50th / 90th percentile | share below ε | no gradient yet |")
    print("|---|---|---|---|---|---|")
    for row in rows:
        percentiles = (" / ".join(f"{value:.2g}" for value in row["sqrt_v_percentiles_10_50_90"])
                       if row["sqrt_v_percentiles_10_50_90"] else "—")
        below = f"{100 * row['below_eps']:.0f} %" if row["below_eps"] is not None else "—"
        print(f"| {row['group']} | {'×'.join(map(str, row['shape']))} | {row['eps']:.0e} | {percentiles} | {below} "
              f"| {100 * row['never_touched']:.1f} % |")
    print(f"first layer, median sqrt(v̂) of its weight columns (ε {columns['eps']:.0e}):")
    if columns["grid_features"] is not None:
        print(f"  grid features {columns['grid_features']:.2g}, (u*, v*, t) {columns['coordinates']:.2g}")
    for part in ("spatial", "t"):
        for kind in ("sin", "cos"):
            values = " ".join(f"{value:.1e}" for value in columns[f"{part}_{kind}"])
            print(f"  {part} {kind}, lowest to top frequency: {values}")
    if args.json:
        with atomic_path(args.json) as temporary:
            temporary.write_text(json.dumps({"checkpoint": str(args.checkpoint), "epochs": epochs,
                                             "tensors": rows, "first_layer_columns": columns}, indent=1) + "\n")


if __name__ == "__main__":
    main()
