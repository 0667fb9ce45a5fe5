"""analysis.adam_state: sqrt(v̂) and the share below ε, read back from an optimiser of known gradients."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from analysis.adam_state import adam_table, first_layer_sqrt_v


def test_sqrt_v_is_the_gradient_size_after_one_step_and_untouched_entries_are_counted_apart():
    small, large = torch.nn.Parameter(torch.zeros(100)), torch.nn.Parameter(torch.zeros(4, 25))
    optimizer = torch.optim.Adam([{"params": [small]}, {"params": [large], "eps": 1e-15}], eps=1e-8)
    small.grad = torch.full((100,), 1e-9)
    small.grad[:30] = 1e-7
    large.grad = torch.full((4, 25), 1e-10)
    large.grad[0] = 0.0  # a quarter never reached
    optimizer.step()
    mlp, grids = adam_table({"optimizer": optimizer.state_dict()})
    assert (mlp["group"], grids["group"]) == ("mlp", "grids") and grids["shape"] == [4, 25]
    np.testing.assert_allclose(mlp["sqrt_v_percentiles_10_50_90"], [1e-9, 1e-9, 1e-7], rtol=1e-6)
    assert mlp["below_eps"] == 0.7 and mlp["never_touched"] == 0.0  # bias-corrected: sqrt(v̂) = |g| at step 1
    assert grids["below_eps"] == 0.0 and grids["never_touched"] == 0.25 and grids["eps"] == 1e-15


def test_first_layer_columns_land_on_their_encoding_frequency():
    # layout of eq. 6 with 1 grid feature, L = 2, L_t = 2: [grid, u*, v*, t, 4 groups × (sin, cos) × 2, (sin, cos) × 2]
    grid, frequencies, t_frequencies = 1, 2, 2
    first = torch.nn.Parameter(torch.zeros(3, grid + 3 + 8 * frequencies + 2 * t_frequencies))
    grids = torch.nn.Parameter(torch.zeros(grid, 2, 4, 4))
    optimizer = torch.optim.Adam([{"params": [first]}, {"params": [grids], "eps": 1e-15}], eps=1e-8)
    gradient = torch.full_like(first, 1e-8)
    for group in range(4):  # the top frequency's sine in every spatial group
        gradient[:, grid + 3 + group * 2 * frequencies + 1] = 1e-13
    gradient[:, grid + 3 + 8 * frequencies + 1] = 1e-14  # t sine, top frequency
    gradient[:, 0] = 3e-8  # the grid feature
    first.grad, grids.grad = gradient, torch.zeros_like(grids)
    optimizer.step()
    state = {"optimizer": optimizer.state_dict(), "model": {"grids.0": grids.detach(), "mlp.network.0.weight": first},
             "config": {"frequencies": frequencies, "t_frequencies": t_frequencies}}
    columns = first_layer_sqrt_v(state)
    np.testing.assert_allclose(columns["spatial_sin"], [1e-8, 1e-13], rtol=1e-6)
    np.testing.assert_allclose(columns["spatial_cos"], [1e-8, 1e-8], rtol=1e-6)
    np.testing.assert_allclose(columns["t_sin"], [1e-8, 1e-14], rtol=1e-6)
    np.testing.assert_allclose(columns["t_cos"], [1e-8, 1e-8], rtol=1e-6)
    assert columns["grid_features"] == pytest.approx(3e-8) and columns["coordinates"] == pytest.approx(1e-8)
    assert columns["eps"] == 1e-8
