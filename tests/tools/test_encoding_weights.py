"""analysis.encoding_weights: per-frequency column norms land on the frequency eq. 6's layout gives them."""

from __future__ import annotations

import dataclasses
import subprocess
import sys

import numpy as np
import pytest

from analysis.encoding_weights import frequency_norms
from gratnet.modelfile import load_model
from tests.helpers import REPO


@pytest.mark.parametrize("asset", ["blazed", "paper-blazed"])  # a pure MLP and a feature-grid model
def test_a_single_column_shows_at_its_own_frequency(asset):
    model = load_model(REPO / "assets" / asset / "model.npz")
    grid, frequencies = model.grid_feature_count, model.encoding.frequencies
    first = np.zeros_like(model.weights[0])
    column = grid + 3 + (2 * 2 + 1) * frequencies + 5  # group u*+v* (2), cosine (1), frequency 5
    first[:, column] = 3.0  # every output row: norm 3·sqrt(rows)
    first[0, grid + 3 + 8 * frequencies + model.encoding.t_frequencies + 1] = 2.0  # t, cosine, frequency 1
    if grid:
        first[1, 0] = 4.0
    norms = frequency_norms(dataclasses.replace(model, weights=[first, *model.weights[1:]]))
    expected = np.zeros(frequencies)
    expected[5] = 3.0 * np.sqrt(first.shape[0])
    np.testing.assert_allclose(norms["spatial"], expected)
    np.testing.assert_allclose(norms["t"], [0.0, 2.0] + [0.0] * (model.encoding.t_frequencies - 2))
    np.testing.assert_allclose(norms["spatial_cos"], expected)
    np.testing.assert_allclose(norms["spatial_sin"], 0.0)
    np.testing.assert_allclose(norms["t_cos"], norms["t"])
    assert norms["grid_features"] == pytest.approx(4.0 / grid if grid else 0.0)


def test_a_missing_model_is_one_message():
    result = subprocess.run([sys.executable, "-m", "analysis.encoding_weights", "no/such.npz"], cwd=REPO,
                            capture_output=True, text=True)
    assert result.returncode != 0 and "no such file" in result.stderr and "Traceback" not in result.stderr
