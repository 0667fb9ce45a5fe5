"""analysis.between_slices: each pixel's distance from the nearest w-slice, and the per-distance bins."""

from __future__ import annotations

import numpy as np

from analysis.between_slices import binned, slice_distance
from gratnet.encoding import key_to_t
from trainer.brdfslice import SliceConfig, slice_geometry


def test_distance_is_that_of_the_keys_t_from_the_uniform_slices():
    config = SliceConfig(0.0, 0.0, size=64, exposure=1.0)
    distance, inside = slice_distance(config, "simple-max", 21)
    light, views, _ = slice_geometry(config)
    key = -(light + views)[inside]
    t = key_to_t(key[:, 0], key[:, 1], key[:, 2], "simple-max")
    np.testing.assert_allclose(distance[inside], np.abs(t * 20 - np.rint(t * 20)), atol=1e-9)
    assert np.isnan(distance[~inside]).all()
    assert distance[inside].min() >= 0 and distance[inside].max() <= 0.5
    # Normal light, view along the normal: key (0, 0, −2), t = 1, on the last slice.
    centre = np.unravel_index(np.argmin(np.hypot(views[..., 0], views[..., 1]) + ~inside * 9), inside.shape)
    assert distance[centre] < 0.05


def test_bins_cover_the_disc_and_an_exact_image_scores_zero():
    config = SliceConfig(30.0, 45.0, size=48, exposure=1.0)
    distance, inside = slice_distance(config, "simple-max", 11)
    rng = np.random.default_rng(0)
    reference = np.where(inside[..., None], rng.uniform(0.01, 0.5, (48, 48, 3)), 0.0)
    edges = np.linspace(0.0, 0.5, 6)
    rows = binned(reference, reference.copy(), distance, inside, edges)
    assert sum(row["pixels"] for row in rows) == int(inside.sum())
    assert all(row["flip"] == 0.0 and row["median_abs_log_y"] == 0.0 for row in rows if row["pixels"])
    # A 10 % error in Y on the pixels far from any slice shows only in the far bins.
    far = inside & (distance >= 0.3)
    test = reference.copy()
    test[far] *= 1.1
    rows = binned(reference, test, distance, inside, edges)
    assert rows[0]["median_abs_log_y"] == 0.0
    np.testing.assert_allclose(rows[-1]["median_abs_log_y"], np.log(1.1), rtol=1e-9)
