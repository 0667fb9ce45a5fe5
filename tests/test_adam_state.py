"""benchmarks/adam_state.py: sqrt(v̂) and the share below ε, read back from an optimiser of known gradients."""

from __future__ import annotations

import numpy as np
import torch

from benchmarks.adam_state import adam_table


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
