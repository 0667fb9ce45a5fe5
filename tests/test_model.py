"""Funnel sizes, presets, the loss, a CPU smoke train, and the torch → model file → numpy round trip."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch

from gratnet.modelfile import evaluate_keys, load_model
from gratnet.volume import write_volume
from trainer.fourier import OpticsConfig
from trainer.generators import generate
from trainer.groundtruth import VolumeConfig, compute_volume
from trainer.model import PRESETS, FunnelMLP, funnel_sizes, log_cosh_loss
from trainer.train import split_samples, train
from trainer.train_config import TrainConfig


def test_funnel_sizes_follow_the_golden_ratio_like_the_paper():
    assert funnel_sizes(464) == [464, 288, 176, 108, 68, 40, 24, 16]
    sizes = funnel_sizes(900)
    ratios = np.array(sizes[:-2]) / np.array(sizes[1:-1])
    assert np.all(np.abs(ratios - 1.618) < 0.15) and sizes[-1] == 16


def test_preset_parameter_counts():
    counts = {name: FunnelMLP(163, hidden).parameter_count for name, hidden in PRESETS.items()}
    assert counts["funnel-176"] <= 60_000 and counts["small"] <= 60_000
    assert counts["paper"] > 200_000
    assert counts["tiny"] < counts["small"] < counts["funnel-176"] < counts["medium"] < counts["paper"]


def test_log_cosh_loss_is_stable_and_correct():
    difference = torch.tensor([0.0, 0.1, 5.0, 100.0])
    expected = torch.log(torch.cosh(difference[:3].double())).float()
    value = log_cosh_loss(difference, torch.zeros(4))
    assert torch.isfinite(value)
    np.testing.assert_allclose(log_cosh_loss(difference[:3], torch.zeros(3)).item(), expected.mean().item(), rtol=1e-5)


@pytest.fixture(scope="module")
def tiny_volume(tmp_path_factory):
    optics = OpticsConfig(sigma_s_um=1.5, wavelength_step_nm=100.0)
    volume = compute_volume(generate("blazed", size_um=5.0), VolumeConfig(resolution=21, slices=5,
                            sampling="simple-max"), optics, progress=False)
    path = tmp_path_factory.mktemp("volume") / "blazed.exr"
    write_volume(path, volume)
    return volume, path


def test_split_by_slices_holds_out_whole_slices(tiny_volume):
    volume, _ = tiny_volume
    train_samples, test_samples = split_samples(volume, TrainConfig(test_slices="1,3"))
    assert len(test_samples) * 3 == len(train_samples) * 2  # 2 of 5 equal slices held out
    t_held_out = np.unique(np.round((test_samples.coordinates[:, 2] + 1) / 2, 6))
    # simple-max: on the rim u² + v² = 4 every slice has w = 0, where t is defined as 0.
    assert {0.25, 0.75} <= set(t_held_out.tolist()) <= {0.0, 0.25, 0.75}


def test_smoke_train_lowers_the_loss_and_round_trips(tiny_volume, tmp_path):
    volume, _ = tiny_volume
    config = TrainConfig(preset="tiny", epochs=3, batch_size=256, learning_rate=3e-3, test_slices="2", seed=1)
    model, model_file, history = train(volume, config, tmp_path, progress=False)
    losses = [record["train_loss"] for record in history["epochs"]]
    assert losses[-1] < losses[0]
    loaded = load_model(tmp_path / "model.npz")
    assert loaded.layer_sizes == [163, 21, 21, 3]
    # numpy evaluation of the loaded file equals torch's output on the same key vectors.
    rng = np.random.default_rng(0)
    u, v = rng.uniform(-1.3, 1.3, (2, 64))
    w = -rng.uniform(0, 1, 64) * np.sqrt(4 - u**2 - v**2)
    from gratnet.encoding import encode, network_coordinates, range_inverse

    with torch.no_grad():
        encoded = encode(torch.from_numpy(network_coordinates(u, v, w, "simple-max")).float(), model_file.encoding)
        expected = range_inverse(model.predict(encoded).double(), model_file.range).numpy()
    np.testing.assert_allclose(evaluate_keys(loaded, u, v, w), expected, rtol=2e-4, atol=1e-12)
    assert json.loads((tmp_path / "history.json").read_text())["parameters"] == model.parameter_count


def test_resume_continues_from_the_checkpoint(tiny_volume, tmp_path):
    volume, _ = tiny_volume
    first = TrainConfig(preset="tiny", epochs=2, batch_size=512, test_slices="2")
    train(volume, first, tmp_path, progress=False)
    from gratnet.errors import GratNetError

    with pytest.raises(GratNetError, match="different configuration"):
        train(volume, TrainConfig(preset="tiny", epochs=3, batch_size=256, test_slices="2"), tmp_path,
              resume=True, progress=False)
