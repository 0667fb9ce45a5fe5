"""A network's error on its training samples against its error between them, per volume slice (y-space).

    python benchmarks/between_samples.py VOLUME.exr MODEL.npz [MODEL.npz …] [--slices 2,5,8]

For each slice of the volume, with the model's own range transform (targets y as in training):

- ``on_sample_rms``: RMS of (network − target) at the slice's samples (what the training loss sees);
- ``mid_cell_rms``: RMS of (network − bilinear) at the centre of every u*/v* cell whose four corners are
  reachable, where bilinear is the mean of the four corner targets: the interpolation oracle's value there;
- ``corner_spread_rms``: RMS of the four corners about their mean: how much the data itself changes across
  one cell. Where it is as large as ``mid_cell_rms``, the volume barely resolves the signal (e.g. speckle at
  the sampling limit) and what lies between samples is not fixed by them.

The network runs through the runtime's numpy evaluator (gratnet.modelfile), as the renderers do. Prints one
JSON line per model.
"""

from __future__ import annotations

import argparse
import json
from collections.abc import Callable

import numpy as np

from gratnet.modelfile import load_model, mlp_forward, network_inputs
from gratnet.volume import read_volume
from trainer.train import volume_samples


def slice_errors(network: Callable[[np.ndarray], np.ndarray], coordinates: np.ndarray, targets: np.ndarray,
                 resolution: int) -> dict[str, float]:
    """The three figures of the module docstring for one slice's samples (network coordinates (N, 3) and targets
    (N, 3) on a ``resolution``² lattice); ``network`` maps network coordinates to y."""
    to_index = (resolution - 1) / 2
    column = np.rint((coordinates[:, 0] + 1) * to_index).astype(int)
    row = np.rint((coordinates[:, 1] + 1) * to_index).astype(int)
    lattice = np.full((resolution, resolution, 3), np.nan)
    lattice[row, column] = targets
    t_lattice = np.full((resolution, resolution), np.nan)
    t_lattice[row, column] = coordinates[:, 2]
    corners = np.stack([lattice[:-1, :-1], lattice[1:, :-1], lattice[:-1, 1:], lattice[1:, 1:]])
    complete = ~np.isnan(corners).any(axis=(0, 3))
    bilinear = corners.mean(axis=0)[complete]
    cell_row, cell_column = np.nonzero(complete)
    t_corners = np.stack([t_lattice[:-1, :-1], t_lattice[1:, :-1], t_lattice[:-1, 1:], t_lattice[1:, 1:]])
    centres = np.stack([-1 + (2 * cell_column + 1) / (resolution - 1), -1 + (2 * cell_row + 1) / (resolution - 1),
                        t_corners.mean(axis=0)[complete]], axis=1)

    return {
        "on_sample_rms": float(np.sqrt(np.mean((network(coordinates) - targets) ** 2))),
        "mid_cell_rms": float(np.sqrt(np.mean((network(centres) - bilinear) ** 2))),
        "corner_spread_rms": float(np.sqrt(np.mean((corners[:, complete] - bilinear) ** 2))),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("volume", help="the ground-truth volume the models were trained on")
    parser.add_argument("models", nargs="+", help="model files (model.npz)")
    parser.add_argument("--slices", default="2,5,8", help="volume slice indices, comma-separated")
    arguments = parser.parse_args()
    volume = read_volume(arguments.volume)
    slices = [int(part) for part in arguments.slices.split(",")]
    for path in arguments.models:
        model = load_model(path)
        coordinates, targets, slice_index = volume_samples(volume, model.range)
        rows = {}
        for index in slices:
            chosen = slice_index == index
            rows[index] = slice_errors(lambda points: mlp_forward(model, network_inputs(model, points)),  # noqa: B023
                                       coordinates[chosen].astype(np.float64),
                                       targets[chosen].astype(np.float64), volume.resolution)
        print(json.dumps({"model": path, "slices": rows}), flush=True)


if __name__ == "__main__":
    main()
