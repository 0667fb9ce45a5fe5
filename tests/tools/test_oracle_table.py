"""analysis.oracle_table --uv-stride: a decimated volume keeps the coarser lattice's own nodes."""

from __future__ import annotations

import numpy as np
import pytest

from analysis.oracle_table import decimated
from gratnet.volume import Volume, volume_axes
from trainer.diagnostics import VolumeOracle


def _volume(resolution: int) -> Volume:
    """A 3-slice simple-max volume whose X is a smooth function of (u*, v*) and the slice index."""
    axes = volume_axes(resolution)
    u, v = np.meshgrid(axes, axes, indexing="xy")
    xyz = np.stack([np.stack([np.sin(u + 0.3 * s) * np.cos(2 * v), u * 0 + s, v], axis=-1) for s in range(3)])
    return Volume(xyz.astype(np.float32), {"scheme": "simple-max", "slice_t": [0.0, 0.5, 1.0]})


def test_decimation_keeps_the_coarse_lattices_nodes_and_metadata():
    fine = _volume(9)
    coarse = decimated(fine, 2)
    assert coarse.resolution == 5 and coarse.slices == 3
    np.testing.assert_array_equal(volume_axes(9)[::2], volume_axes(5))
    np.testing.assert_array_equal(coarse.xyz, _volume(5).xyz)  # the same field sampled on the 5² lattice
    assert coarse.metadata == fine.metadata and coarse.metadata is not fine.metadata
    assert decimated(fine, 1).xyz.shape == fine.xyz.shape


def test_a_coarser_lattice_interpolates_a_curved_field_worse():
    fine, coarse = _volume(33), decimated(_volume(33), 4)
    rng = np.random.default_rng(0)
    u, v = rng.uniform(-0.3, 0.3, (2, 200))
    w = np.full(200, -1.5)
    truth = VolumeOracle(_volume(257))(u, v, w)
    error_fine = np.abs(VolumeOracle(fine)(u, v, w) - truth)[:, 0].max()
    error_coarse = np.abs(VolumeOracle(coarse)(u, v, w) - truth)[:, 0].max()
    assert error_coarse > 4 * error_fine  # linear interpolation: error ∝ spacing², 16× here


@pytest.mark.parametrize("stride", [0, 3])
def test_a_stride_that_does_not_divide_the_lattice_is_refused(stride: int):
    with pytest.raises(SystemExit, match="--uv-stride"):
        decimated(_volume(9), stride)
