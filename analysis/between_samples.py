"""A network's error on its training samples against its error between them, per volume slice (y-space).

    python -m analysis.between_samples VOLUME.exr MODEL.npz [MODEL.npz …] [--slices 2,5,8]

For each slice of the volume, with the model's own range transform (targets y as in training):

- ``on_sample_rms``: RMS of (network − target) at the slice's samples (what the training loss sees);
- ``mid_cell_rms``: RMS of (network − bilinear) at the centre of every u*/v* cell whose four corners are
  reachable, where bilinear is the mean of the four corner targets: the interpolation oracle's value there;
- ``corner_spread_rms``: RMS of the four corners about their mean: how much the data itself changes across
  one cell. Where it is as large as ``mid_cell_rms``, the volume barely resolves the signal (e.g. speckle at
  the sampling limit) and what lies between samples is not fixed by them.

With ``--fine FINE.exr``, a volume of the same height field, slices and scheme on the (2R − 1)² lattice (every
other sample of it is one of the R² lattice's, the others lie between them; ``gratnet groundtruth --res``),
the truth at the cell centres is known, and two more figures compare with it there:

- ``mid_cell_truth_rms``: RMS of (network − truth) at the cell centres: the network's own error between samples;
- ``bilinear_truth_rms``: RMS of (bilinear − truth) there: the interpolation oracle's error between samples.

The network runs through the runtime's numpy evaluator (gratnet.modelfile), as the renderers do. Prints one
JSON line per model.
"""

from __future__ import annotations

import argparse
import json
from collections.abc import Callable

import numpy as np

from gratnet.encoding import RangeSpec
from gratnet.modelfile import load_model, mlp_forward, network_inputs
from gratnet.volume import read_volume
from trainer.offlattice import lattice_position
from trainer.train import volume_samples


def on_lattice(coordinates: np.ndarray, values: np.ndarray, resolution: int) -> np.ndarray:
    """``values`` (N, ...) of samples at network coordinates (N, 3) placed on their ``resolution``² lattice
    (rows v, columns u); NaN where no sample lies (unreachable key vectors)."""
    row, column = lattice_position(coordinates, resolution)
    lattice = np.full((resolution, resolution, *values.shape[1:]), np.nan)
    lattice[row, column] = values
    return lattice


def centre_truth(fine_coordinates: np.ndarray, fine_targets: np.ndarray, resolution: int) -> np.ndarray:
    """The targets of one slice of a (2R − 1)² volume at the centres of the R² lattice's cells: (R − 1, R − 1, 3),
    NaN where unreachable (R = ``resolution``)."""
    return on_lattice(fine_coordinates, fine_targets, 2 * resolution - 1)[1::2, 1::2]


def slice_errors(network: Callable[[np.ndarray], np.ndarray], coordinates: np.ndarray, targets: np.ndarray,
                 resolution: int, truth: np.ndarray | None = None) -> dict[str, float]:
    """The figures of the module docstring for one slice's samples (network coordinates (N, 3) and targets
    (N, 3) on a ``resolution``² lattice); ``network`` maps network coordinates to y. ``truth``: the targets at
    the cell centres (:func:`centre_truth`), for the two figures against the truth."""
    lattice = on_lattice(coordinates, targets, resolution)
    t_lattice = on_lattice(coordinates, coordinates[:, 2], resolution)
    corners = np.stack([lattice[:-1, :-1], lattice[1:, :-1], lattice[:-1, 1:], lattice[1:, 1:]])
    complete = ~np.isnan(corners).any(axis=(0, 3))
    bilinear = corners.mean(axis=0)[complete]
    cell_row, cell_column = np.nonzero(complete)
    t_corners = np.stack([t_lattice[:-1, :-1], t_lattice[1:, :-1], t_lattice[:-1, 1:], t_lattice[1:, 1:]])
    centres = np.stack([-1 + (2 * cell_column + 1) / (resolution - 1), -1 + (2 * cell_row + 1) / (resolution - 1),
                        t_corners.mean(axis=0)[complete]], axis=1)

    at_centres = network(centres)
    figures = {
        "on_sample_rms": float(np.sqrt(np.mean((network(coordinates) - targets) ** 2))),
        "mid_cell_rms": float(np.sqrt(np.mean((at_centres - bilinear) ** 2))),
        "corner_spread_rms": float(np.sqrt(np.mean((corners[:, complete] - bilinear) ** 2))),
    }
    if truth is not None:
        known = truth[complete]
        kept = ~np.isnan(known).any(axis=1)  # the truth lattice reaches no further than the samples
        figures["mid_cell_truth_rms"] = float(np.sqrt(np.mean((at_centres[kept] - known[kept]) ** 2)))
        figures["bilinear_truth_rms"] = float(np.sqrt(np.mean((bilinear[kept] - known[kept]) ** 2)))
    return figures


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("volume", help="the ground-truth volume the models were trained on")
    parser.add_argument("models", nargs="+", help="model files (model.npz)")
    parser.add_argument("--slices", default="2,5,8", help="volume slice indices, comma-separated")
    parser.add_argument("--fine", metavar="FINE.exr", help="the same volume on the (2R − 1)² lattice: the truth "
                        "between samples (module docstring)")
    arguments = parser.parse_args()
    volume = read_volume(arguments.volume)
    slices = [int(part) for part in arguments.slices.split(",")]
    if not slices or min(slices) < 0 or max(slices) >= volume.slices:
        parser.error(f"--slices {arguments.slices} out of range for a {volume.slices}-slice volume")
    fine = read_volume(arguments.fine) if arguments.fine else None
    if fine is not None:
        expected = (2 * volume.resolution - 1, volume.slices, volume.metadata.get("scheme"))
        found = (fine.resolution, fine.slices, fine.metadata.get("scheme"))
        if found != expected:
            parser.error(f"--fine must be a {expected[0]}² × {expected[1]} volume of scheme {expected[2]!r} "
                         f"(twice the lattice of {arguments.volume}), got {found[0]}² × {found[1]}, {found[2]!r}")
    Samples = tuple[np.ndarray, np.ndarray, np.ndarray]  # volume_samples: coordinates, targets, slice index
    # Per range transform: models that share one share the volumes' samples (the fine volume's are 4× as many).
    samples: dict[RangeSpec, tuple[Samples, Samples | None]] = {}
    for path in arguments.models:
        model = load_model(path)
        if model.range not in samples:
            samples[model.range] = (volume_samples(volume, model.range),
                                    volume_samples(fine, model.range) if fine is not None else None)
        (coordinates, targets, slice_index), fine_samples = samples[model.range]
        rows = {}
        for index in slices:
            chosen = slice_index == index
            truth = None
            if fine_samples is not None:
                fine_chosen = fine_samples[2] == index
                truth = centre_truth(fine_samples[0][fine_chosen], fine_samples[1][fine_chosen].astype(np.float64),
                                     volume.resolution)
            rows[index] = slice_errors(lambda points: mlp_forward(model, network_inputs(model, points)),  # noqa: B023
                                       coordinates[chosen].astype(np.float64),
                                       targets[chosen].astype(np.float64), volume.resolution, truth)
        print(json.dumps({"model": path, "slices": rows}), flush=True)


if __name__ == "__main__":
    main()
