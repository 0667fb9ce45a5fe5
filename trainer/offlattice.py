"""Training points between the volume's samples (``gratnet train --off-lattice F``).

A volume samples each w-slice on a uniform R² lattice of (u*, v*) (trainer/sampling.py); the network is trained
at those samples and rendered everywhere between them. On paper-scratches its error between samples was
measured 1.1–1.6× its error at them, while the bilinear interpolation of the four corner samples lies within
0.36–0.47·10⁻³ (RMS in the range-transformed y) of the truth at the cell centres, 5–6× closer than the network
(docs/experiments/2026-11-23-scratches-truth-between-samples.md). So points drawn between the samples,
with the bilinear value of their cell as target, teach the network what lies there at the accuracy of that
interpolation.

An off-lattice point is a uniform random point of a u*/v* cell of one training slice whose four corners are all
training samples (cells that touch an unreachable key vector, a held-out sample or one left out by
``--max-train-samples`` are never drawn): network coordinates

    c_u = −1 + 2(j + f_u)/(R − 1),  c_v = −1 + 2(i + f_v)/(R − 1),  c_t = 2 t_s − 1,   f_u, f_v ~ U[0, 1)

and target the bilinear interpolation, in the range-transformed y, of the corners (i, j), (i, j + 1),
(i + 1, j), (i + 1, j + 1) of slice s. Slices are never interpolated: along w the 11-slice interpolation
oracle is measurably worse than the network's own t (docs/results.md and the logs it links).
"""

from __future__ import annotations

import numpy as np
import torch

from gratnet.errors import GratNetError


def lattice_position(coordinates: np.ndarray, resolution: int) -> tuple[np.ndarray, np.ndarray]:
    """(row, column) (int64) on the ``resolution``² u*/v* lattice of samples at network coordinates (N, 3):
    the nearest node, c = −1 + 2k/(R − 1) inverted."""
    to_index = (resolution - 1) / 2
    row = np.rint((coordinates[:, 1].astype(np.float64) + 1) * to_index).astype(np.int64)
    column = np.rint((coordinates[:, 0].astype(np.float64) + 1) * to_index).astype(np.int64)
    return row, column


class OffLattice:
    """The training samples placed on their lattice, and draws of off-lattice points from them (on ``device``)."""

    def __init__(self, coordinates: np.ndarray, targets: np.ndarray, slice_index: np.ndarray,
                 slice_c_t: np.ndarray, resolution: int, device: torch.device) -> None:
        """``coordinates`` (N, 3) network coordinates and ``targets`` (N, 3) of the training samples, each on the
        ``resolution``² lattice of slice ``slice_index`` (N,); ``slice_c_t[s]``: slice s's c_t = 2 t_s − 1."""
        if resolution < 2:
            raise GratNetError(f"--off-lattice needs a volume of at least 2² samples per slice, got {resolution}²")
        row, column = lattice_position(coordinates, resolution)
        slices = len(slice_c_t)
        flat = (slice_index.astype(np.int64) * resolution + row) * resolution + column
        present = np.zeros(slices * resolution * resolution, dtype=bool)
        present[flat] = True
        lattice = np.zeros((slices * resolution * resolution, targets.shape[1]), dtype=np.float32)
        lattice[flat] = targets
        cube = present.reshape(slices, resolution, resolution)
        # A cell (s, i, j) is drawn from when its four corners are all training samples.
        complete = cube[:, :-1, :-1] & cube[:, 1:, :-1] & cube[:, :-1, 1:] & cube[:, 1:, 1:]
        cells = np.flatnonzero(complete)
        if len(cells) == 0:
            raise GratNetError("--off-lattice: no u*/v* cell has all four corners among the training samples "
                               "(too few samples: a larger volume, fewer held out, or no --max-train-samples)")
        self.resolution = resolution
        self.device = device
        self.cells = torch.from_numpy(cells).to(device)  # flat (s, i, j) on the (S, R − 1, R − 1) cell grid
        self.lattice = torch.from_numpy(lattice).to(device)  # (S·R·R, 3), row-major (s, i, j)
        self.slice_c_t = torch.from_numpy(np.asarray(slice_c_t, dtype=np.float32)).to(device)

    def __len__(self) -> int:
        """The number of cells drawn from."""
        return len(self.cells)

    def draw(self, count: int, generator: torch.Generator) -> tuple[torch.Tensor, torch.Tensor]:
        """``count`` off-lattice points: network coordinates (count, 3) and bilinear targets (count, 3), float32 on
        the device. ``generator`` (a CPU generator) makes the draw reproducible."""
        pick = torch.randint(len(self.cells), (count,), generator=generator).to(self.device)
        fraction = torch.rand((count, 2), generator=generator, dtype=torch.float64).to(self.device)
        cell = self.cells[pick]
        intervals = self.resolution - 1
        s = cell // (intervals * intervals)
        i = (cell // intervals) % intervals
        j = cell % intervals
        base = (s * self.resolution + i) * self.resolution + j
        f_u, f_v = fraction[:, 0:1].float(), fraction[:, 1:2].float()
        y00, y01 = self.lattice[base], self.lattice[base + 1]
        y10, y11 = self.lattice[base + self.resolution], self.lattice[base + self.resolution + 1]
        targets = (1 - f_v) * ((1 - f_u) * y00 + f_u * y01) + f_v * ((1 - f_u) * y10 + f_u * y11)
        c_u = -1.0 + 2.0 * (j.double() + fraction[:, 0]) / intervals
        c_v = -1.0 + 2.0 * (i.double() + fraction[:, 1]) / intervals
        coordinates = torch.stack([c_u.float(), c_v.float(), self.slice_c_t[s]], dim=1)
        return coordinates, targets
