"""benchmarks/error_budget.py: noise of a stated RMS in y, only where samples are reachable."""

from __future__ import annotations

import numpy as np
import pytest

from benchmarks.error_budget import noisy_volume, reachable_mask
from gratnet.encoding import RangeSpec, range_forward
from gratnet.volume import Volume


def _volume(resolution: int = 65, slices: int = 3) -> Volume:
    rng = np.random.default_rng(1)
    xyz = rng.uniform(1e-6, 1e-2, (slices, resolution, resolution, 3)).astype(np.float32)
    volume = Volume(xyz, {"scheme": "simple-max", "slice_t": list(np.linspace(0.0, 1.0, slices))})
    volume.xyz[:, ~reachable_mask(volume)] = 0.0
    return volume


@pytest.mark.parametrize("model", ["independent", "shared"])
def test_noise_has_the_stated_rms_in_y_and_leaves_unreachable_samples_at_zero(model):
    volume, spec, sigma = _volume(), RangeSpec(power=4.0), 1e-3
    noisy = noisy_volume(volume, spec, sigma, model)
    reachable = reachable_mask(volume)
    difference = (range_forward(noisy.xyz[:, reachable].astype(np.float64), spec)
                  - range_forward(volume.xyz[:, reachable].astype(np.float64), spec))
    np.testing.assert_allclose(np.sqrt(np.mean(difference**2)), sigma, rtol=0.02)
    assert (noisy.xyz[:, ~reachable] == 0).all()
    correlation = np.corrcoef(difference.reshape(-1, 3).T)[0, 1]
    assert correlation > 0.99 if model == "shared" else abs(correlation) < 0.05
    assert noisy.metadata == volume.metadata


def test_zero_noise_is_the_volume_itself_and_an_unknown_model_is_refused():
    volume = _volume()
    np.testing.assert_allclose(noisy_volume(volume, RangeSpec(power=4.0), 0.0, "shared").xyz, volume.xyz, rtol=1e-5)
    with pytest.raises(SystemExit):
        noisy_volume(volume, RangeSpec(), 1e-3, "pink")
