"""Off-lattice training points (trainer/offlattice.py, ``gratnet train --off-lattice``): analytic checks of the
draws, then the trainer with them."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from gratnet.errors import GratNetError
from trainer.offlattice import OffLattice
from trainer.train import slice_parameters, split_samples, train
from trainer.train_config import TrainConfig

RESOLUTION = 9
SLICE_C_T = np.array([-1.0, 0.0, 1.0])


def bilinear_field(coordinates: np.ndarray) -> np.ndarray:
    """A target that bilinear interpolation reproduces exactly: per slice and channel a + b·c_u + c·c_v + d·c_u·c_v."""
    c_u, c_v, c_t = (coordinates[:, axis:axis + 1].astype(np.float64) for axis in range(3))
    channel = np.arange(3)[None, :]
    return (0.3 + 0.1 * channel + (0.2 - 0.05 * c_t) * c_u - 0.15 * c_v * (1 + channel) + 0.25 * c_t * c_u * c_v)


def lattice_samples(missing: list[tuple[int, int, int]]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Every lattice sample of three slices but ``missing`` ((slice, row, column) triples)."""
    s, row, column = np.meshgrid(np.arange(len(SLICE_C_T)), np.arange(RESOLUTION), np.arange(RESOLUTION),
                                 indexing="ij")
    keep = np.ones(s.shape, dtype=bool)
    for index in missing:
        keep[index] = False
    s, row, column = s[keep], row[keep], column[keep]
    coordinates = np.stack([-1 + 2 * column / (RESOLUTION - 1), -1 + 2 * row / (RESOLUTION - 1), SLICE_C_T[s]],
                           axis=1).astype(np.float32)
    return coordinates, bilinear_field(coordinates).astype(np.float32), s.astype(np.int16)


def test_draws_lie_in_complete_cells_and_carry_the_bilinear_value():
    hole = (1, 4, 6)
    coordinates, targets, slices = lattice_samples([hole])
    sampler = OffLattice(coordinates, targets, slices, SLICE_C_T, RESOLUTION, torch.device("cpu"))
    assert len(sampler) == 3 * (RESOLUTION - 1) ** 2 - 4  # the four cells around the hole are left out
    points, values = (array.numpy() for array in sampler.draw(20_000, torch.Generator().manual_seed(0)))
    # A bilinear field is reproduced exactly: the targets are the corners' bilinear interpolation.
    np.testing.assert_allclose(values, bilinear_field(points), atol=2e-6)
    # Every point keeps its slice's c_t and lies strictly inside [−1, 1]².
    slice_of = np.searchsorted(SLICE_C_T, points[:, 2])
    np.testing.assert_array_equal(SLICE_C_T[slice_of], points[:, 2])
    assert np.all(np.abs(points[:, :2]) <= 1)
    # No point falls in a cell with the missing corner.
    cell = np.floor((points[:, :2] + 1) * (RESOLUTION - 1) / 2).astype(int)  # (column, row)
    in_hole_cells = ((slice_of == hole[0]) & np.isin(cell[:, 1], [hole[1] - 1, hole[1]])
                     & np.isin(cell[:, 0], [hole[2] - 1, hole[2]]))
    assert not in_hole_cells.any()
    # Points are spread over every cell and within cells: all cells are hit, fractions uniform on [0, 1).
    hit = {(int(s), int(r), int(c)) for s, (c, r) in zip(slice_of, cell, strict=True)}
    assert len(hit) == len(sampler)
    fraction = (points[:, 0] + 1) * (RESOLUTION - 1) / 2 - cell[:, 0]
    assert abs(fraction.mean() - 0.5) < 0.01 and abs(np.median(fraction) - 0.5) < 0.02


def test_the_draw_is_reproducible_and_generator_driven():
    coordinates, targets, slices = lattice_samples([])
    sampler = OffLattice(coordinates, targets, slices, SLICE_C_T, RESOLUTION, torch.device("cpu"))
    first = sampler.draw(100, torch.Generator().manual_seed(5))
    again = sampler.draw(100, torch.Generator().manual_seed(5))
    other = sampler.draw(100, torch.Generator().manual_seed(6))
    assert torch.equal(first[0], again[0]) and torch.equal(first[1], again[1])
    assert not torch.equal(first[0], other[0])


def test_no_complete_cell_is_refused_in_one_line():
    coordinates, targets, slices = lattice_samples([])
    checkerboard = ((np.rint((coordinates[:, 0] + 1) * 4) + np.rint((coordinates[:, 1] + 1) * 4)) % 2) == 0
    with pytest.raises(GratNetError, match="no u\\*/v\\* cell has all four corners"):
        OffLattice(coordinates[checkerboard], targets[checkerboard], slices[checkerboard], SLICE_C_T, RESOLUTION,
                   torch.device("cpu"))


@pytest.mark.parametrize("fraction", [-0.1, 1.0, float("nan")])
def test_bad_off_lattice_fraction_is_refused(fraction):
    with pytest.raises(GratNetError, match="--off-lattice must be a fraction"):
        TrainConfig(off_lattice=fraction)


def test_held_out_slices_and_the_unreachable_corner_are_never_drawn(tiny_volume):
    volume, _ = tiny_volume
    samples, _ = split_samples(volume, TrainConfig(test_slices="2"))
    c_t = 2 * slice_parameters(volume) - 1
    sampler = OffLattice(samples.coordinates, samples.targets, samples.slice_index, c_t, volume.resolution,
                         torch.device("cpu"))
    points, values = (array.numpy() for array in sampler.draw(5000, torch.Generator().manual_seed(1)))
    assert not np.isclose(points[:, 2], c_t[2]).any()
    assert set(np.round(points[:, 2], 6)) <= set(np.round(np.delete(c_t, 2), 6).tolist())
    # Inside the reachable disc u² + v² ≤ 4 (the network coordinates c = u*/2, u = 2 sign(u*)(u*/2)²).
    u, v = (2 * np.sign(points[:, axis]) * points[:, axis] ** 2 for axis in (0, 1))
    assert np.all(u**2 + v**2 <= 4 + 1e-5)
    assert np.all(np.isfinite(values)) and values.min() >= 0


def test_training_with_off_lattice_points_learns_and_differs(tiny_volume, tmp_path):
    volume, _ = tiny_volume
    base = dict(preset="tiny", epochs=3, batch_size=256, test_slices="2", seed=2, device="cpu")
    _, _, plain = train(volume, TrainConfig(**base), tmp_path / "plain", progress=False)
    model, _, mixed = train(volume, TrainConfig(**base, off_lattice=0.5), tmp_path / "mixed", progress=False)
    losses = [record["train_loss"] for record in mixed["epochs"]]
    assert all(np.isfinite(losses)) and losses[-1] < losses[0]
    assert mixed["train_samples"] == plain["train_samples"]  # the epoch keeps its size
    assert losses != [record["train_loss"] for record in plain["epochs"]]
    # Resuming the finished run with the same options is accepted (the options match the checkpoint).
    train(volume, TrainConfig(**base, off_lattice=0.5), tmp_path / "mixed", resume=True, progress=False)


def test_checkpoints_from_before_an_option_existed_resume_with_its_default(tiny_volume, tmp_path):
    volume, _ = tiny_volume
    config = TrainConfig(preset="tiny", epochs=1, batch_size=512, test_slices="2", device="cpu")
    train(volume, config, tmp_path, progress=False)
    state = torch.load(tmp_path / "checkpoint.pt", weights_only=False)
    del state["config"]["off_lattice"]
    torch.save(state, tmp_path / "checkpoint.pt")
    _, _, history = train(volume, config, tmp_path, resume=True, progress=False)  # no "different configuration"
    assert len(history["epochs"]) == 1
