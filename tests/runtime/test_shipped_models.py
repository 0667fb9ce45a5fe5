"""Every shipped model loads, and the shader's BRDF slice of it matches the trainer's numpy slice.

The texture path for every model; the baked path (what ``auto`` picks on llvmpipe for the shipped size)
for one, since its first compile takes ~25 s per model on the CI's CPU rasterizer.
"""

from __future__ import annotations

import numpy as np
import pytest

from gratnet.modelfile import load_model
from tests.helpers import ASSETS
from trainer.brdfslice import SliceConfig
from trainer.evaluate import network_brdf_slice
from trainer.metrics import flip

MODELS = sorted(ASSETS.glob("*/model.npz"))


#: The paper's footprint: 60k network parameters, 130k for corner cubes and spherical pits (issue 15).
LARGER_FOOTPRINT = {"paper-corner-cubes", "paper-pits"}


@pytest.mark.parametrize("path", MODELS, ids=[path.parent.name for path in MODELS])
def test_shipped_model_loads_and_is_small(path):
    model = load_model(path)
    assert model.parameter_count <= (130_000 if path.parent.name in LARGER_FOOTPRINT else 60_000)
    if not model.grids:
        assert path.stat().st_size < 1_000_000
        return
    # A feature grid counts in bytes, at most 1/20 of the ground-truth volume it was trained on (issue 15).
    training = model.metadata["training"]
    assert training["grid_bytes"] == model.grid_bytes <= training["volume_bytes"] / 20
    assert path.stat().st_size < model.grid_bytes + 1_000_000


BAKED = ASSETS / "blazed" / "model.npz"
CASES = [(path, "texture") for path in MODELS] + [(BAKED, "baked")]


@pytest.mark.parametrize(("path", "weights_path"), CASES, ids=[f"{p.parent.name}-{w}" for p, w in CASES])
def test_shader_slice_matches_numpy_slice(path, weights_path, ctx):
    from viewer.renderer import NetworkRenderer

    model = load_model(path)
    config = SliceConfig(30.0, 0.0, size=48, exposure=5000.0, ior=1.5)
    expected = network_brdf_slice(model, config)
    with NetworkRenderer(ctx, model, weights_path=weights_path) as renderer:
        assert renderer.weights_path == weights_path
        rendered = renderer.render_brdf_slice(30.0, 0.0, 48, exposure=5000.0, ior=1.5).astype(np.float64)
    mean_flip, _ = flip(expected, rendered)
    assert mean_flip <= 0.005
    scale = max(float(expected.max()), 1e-6)
    assert np.max(np.abs(rendered - expected)) <= 1e-3 * scale
