"""analysis.error_budget: noise of a stated RMS in y, the slice ↔ y round trip, and the target crossing."""

from __future__ import annotations

import numpy as np
import pytest

from analysis.error_budget import crossing, image_of, noisy_volume, pixel_y, reachable_mask
from gratnet.encoding import RangeSpec, range_forward
from gratnet.volume import Volume
from trainer.brdfslice import SliceConfig, slice_geometry


def _volume(resolution: int = 65, slices: int = 3) -> Volume:
    rng = np.random.default_rng(1)
    xyz = rng.uniform(1e-6, 1e-2, (slices, resolution, resolution, 3)).astype(np.float32)
    volume = Volume(xyz, {"scheme": "simple-max", "slice_t": list(np.linspace(0.0, 1.0, slices))})
    volume.xyz[:, ~reachable_mask(volume)] = 0.0
    return volume


def test_sample_noise_has_the_stated_rms_in_y_and_leaves_unreachable_samples_at_zero():
    volume, spec, sigma = _volume(), RangeSpec(power=4.0), 1e-3
    noisy = noisy_volume(volume, spec, sigma)
    reachable = reachable_mask(volume)
    difference = (range_forward(noisy.xyz[:, reachable].astype(np.float64), spec)
                  - range_forward(volume.xyz[:, reachable].astype(np.float64), spec))
    np.testing.assert_allclose(np.sqrt(np.mean(difference**2)), sigma, rtol=0.02)
    assert abs(np.corrcoef(difference.reshape(-1, 3).T)[0, 1]) < 0.05  # independent per channel
    assert (noisy.xyz[:, ~reachable] == 0).all()
    assert noisy.metadata == volume.metadata


def test_a_slice_goes_to_y_and_back_unchanged():
    config = SliceConfig(30.0, 20.0, size=40, exposure=3000.0, ior=1.5)
    _, views, inside = slice_geometry(config)
    spec = RangeSpec(power=4.0)
    y = np.random.default_rng(2).uniform(0.2, 0.9, (int(inside.sum()), 3))
    image = image_of(config, y, spec)
    assert (image[~inside] == 0).all()
    np.testing.assert_allclose(pixel_y(config, image, spec), y, atol=1e-9)


def test_crossing_interpolates_in_log_log_and_says_when_the_target_is_not_bracketed():
    sigmas, flips = [1e-4, 1e-3, 1e-2], [0.001, 0.01, 0.1]  # FLIP ∝ σ
    assert crossing(sigmas, flips, 0.003) == pytest.approx(3e-4)
    assert crossing(sigmas, flips, 0.5) is None
    assert crossing(sigmas, flips, 0.0001) is None
