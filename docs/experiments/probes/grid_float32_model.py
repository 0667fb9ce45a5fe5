"""Write RUN/model-fp32.npz: RUN/model.npz (float16 grids) with the float32 grids of RUN/checkpoint.pt.

    python docs/experiments/probes/grid_float32_model.py RUN
    gratnet evaluate RUN/model-fp32.npz --volume VOLUME.exr --out RUN/eval-fp32

measures what storing a feature-grid model's grids as float16 costs
(docs/experiments/2026-11-23-learned-feature-grid.md).
"""

from __future__ import annotations

import argparse
from pathlib import Path

import torch

from gratnet.modelfile import load_model, save_model


def main() -> None:
    """Write the float32 twin of a trained feature-grid model."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("run", type=Path, help="a `gratnet train --architecture grid` output folder")
    folder = parser.parse_args().run
    model = load_model(folder / "model.npz")
    state = torch.load(folder / "checkpoint.pt", map_location="cpu", weights_only=False)["model"]
    # The trainer holds each level as (C, T, R, R); the model file as (T, R, R, C).
    model.grids = [state[f"grids.{level}"].permute(1, 2, 3, 0).contiguous().numpy()
                   for level in range(len(model.grids))]
    save_model(folder / "model-fp32.npz", model)
    print(f"wrote {folder / 'model-fp32.npz'}")


if __name__ == "__main__":
    main()
