"""Funnel sizes, presets, the loss, a CPU smoke train, and the torch → model file → numpy round trip."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest
import torch

from gratnet.encoding import EncodingSpec
from gratnet.errors import GratNetError
from gratnet.modelfile import evaluate_keys, load_model
from tests.helpers import top_sine_columns
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
    # The model carries its relief's slopes (Smith's shadowing at render time, gratnet.shadowing).
    assert loaded.metadata["volume"]["slope_covariance"] == volume.metadata["slope_covariance"]


def test_a_model_of_an_older_volume_gets_the_slope_covariance_from_its_height_field(tiny_volume, capsys):
    import argparse

    from trainer.generators import generate
    from trainer.train import model_volume_metadata
    from trainer.train_cli import with_slope_covariance

    volume, _ = tiny_volume
    older = {key: value for key, value in volume.metadata.items() if key != "slope_covariance"}
    assert "slope_covariance" not in model_volume_metadata(older)
    arguments = argparse.Namespace(heightfield=None)
    with_slope_covariance(arguments, older)
    assert older["slope_covariance"] == list(generate("blazed", size_um=5.0).slope_covariance())
    assert model_volume_metadata(older)["slope_covariance"] == older["slope_covariance"]
    unknown = {**older, "source": "no-such-field.npy"}
    del unknown["slope_covariance"]
    with_slope_covariance(arguments, unknown)
    assert "slope_covariance" not in unknown and "render unshadowed" in capsys.readouterr().err


def test_zero_unseen_features_silences_exactly_the_top_sines_and_keeps_them_silent(tiny_volume, tmp_path):
    """The top frequency of each spatial group and of t sits at the lattice's Nyquist rate: its sine is zero at
    every training sample. --zero-unseen-features gives those columns zero weight, and training keeps it."""
    volume, _ = tiny_volume
    config = TrainConfig(preset="tiny", epochs=2, batch_size=256, test_slices="2", seed=1)
    _, model_file, _ = train(volume, config, tmp_path, progress=False)
    top_sines = top_sine_columns(model_file)
    weight = model_file.weights[0]
    assert np.all(weight[:, top_sines] == 0.0)
    others = np.delete(weight, top_sines, axis=1)
    assert np.all(np.abs(others).max(axis=0) > 0)  # nothing else silenced
    # The flag is the default; --no-zero-unseen-features trains those columns as before (they barely move).
    assert TrainConfig().zero_unseen_features
    _, before, _ = train(volume, dataclasses.replace(config, zero_unseen_features=False), tmp_path / "off",
                         progress=False)
    assert np.all(np.abs(before.weights[0][:, top_sines]).max(axis=0) > 0)


def test_resume_continues_from_the_checkpoint(tiny_volume, tmp_path):
    volume, _ = tiny_volume
    first = TrainConfig(preset="tiny", epochs=2, batch_size=512, test_slices="2")
    train(volume, first, tmp_path, progress=False)
    from gratnet.errors import GratNetError

    with pytest.raises(GratNetError, match="different configuration"):
        train(volume, TrainConfig(preset="tiny", epochs=3, batch_size=256, test_slices="2"), tmp_path,
              resume=True, progress=False)


def test_weighted_log_cosh_is_the_weighted_mean_of_the_per_sample_losses():
    prediction = torch.tensor([[0.1, 0.2, 0.3], [0.5, 0.5, 0.5], [0.9, 0.0, 0.4]])
    target = torch.zeros(3, 3)
    per_sample = torch.log(torch.cosh(prediction.double())).mean(dim=1)
    weight = torch.tensor([1.0, 4.0, 1.0])
    expected = float((per_sample * weight.double()).sum() / weight.sum())
    np.testing.assert_allclose(log_cosh_loss(prediction, target, weight).item(), expected, rtol=1e-5)
    # Equal weights, whatever their value, give the plain mean.
    np.testing.assert_allclose(log_cosh_loss(prediction, target, torch.full((3,), 7.0)).item(),
                               log_cosh_loss(prediction, target).item(), rtol=1e-6)


def test_visible_weight_marks_exactly_the_samples_whose_y_is_in_the_band():
    from gratnet.encoding import range_forward
    from trainer.objective import visible_weight

    config = TrainConfig(loss_visible_y="1e-7,1e-3", loss_visible_weight=4.0, range_power=4.0)
    weighting = visible_weight(config)
    assert weighting is not None
    y = np.array([1e-12, 0.5e-7, 2e-7, 1e-5, 0.9e-3, 2e-3, 0.5])
    xyz = np.stack([np.full_like(y, 0.3), y, np.full_like(y, 1e-20)], axis=1)  # only Y decides
    weights = weighting(torch.from_numpy(range_forward(xyz, config.range_spec())))
    assert weights.tolist() == [1.0, 1.0, 4.0, 4.0, 4.0, 1.0, 1.0]
    # Off: no band, or a weight of 1.
    assert visible_weight(TrainConfig()) is None
    assert visible_weight(TrainConfig(loss_visible_y="1e-7,1e-3")) is None


@pytest.mark.parametrize("band, weight, message", [
    ("1e-3,1e-7", 4.0, "0 < LOW < HIGH"),
    ("0,1e-3", 4.0, "0 < LOW < HIGH"),
    ("dark,bright", 4.0, "two numbers"),
    ("1e-7", 4.0, "two numbers"),
    ("1e-300,1e-3", 4.0, "inside what the range transform resolves"),
    ("1e-7,2.0", 4.0, "inside what the range transform resolves"),
    ("1e-7,1e-3", 0.0, "--loss-visible-weight"),
    ("1e-7,1e-3", float("nan"), "--loss-visible-weight"),
])
def test_bad_visible_band_is_refused_in_one_line(band, weight, message):
    from gratnet.errors import GratNetError

    with pytest.raises(GratNetError, match=message):
        TrainConfig(loss_visible_y=band, loss_visible_weight=weight)


def test_display_weighted_training_trains_on_the_weighted_loss(tiny_volume, tmp_path):
    """The weighting reaches the optimiser: one train_step's loss is the weighted mean of the per-sample losses
    (an empty band gives the plain mean), and training with it ends at other weights than without."""
    from gratnet.encoding import encode
    from trainer.objective import visible_weight
    from trainer.train import build_model, make_optimizer, make_scheduler, train_step

    volume, _ = tiny_volume
    base = dict(preset="tiny", epochs=1, batch_size=256, test_slices="2", seed=3, device="cpu")
    samples, _ = split_samples(volume, TrainConfig(**base))
    coordinates = torch.from_numpy(samples.coordinates[:512])
    targets = torch.from_numpy(samples.targets[:512])

    def step_loss(config: TrainConfig) -> float:
        torch.manual_seed(0)
        encoding = config.encoding_for(volume)
        model = build_model(config, encoding)
        optimizer = make_optimizer(model, config)
        with torch.no_grad():
            per_sample = torch.log(torch.cosh(model(encode(coordinates, encoding)).double() - targets.double()))
        weighting = visible_weight(config)
        weight = torch.ones(len(targets)) if weighting is None else weighting(targets)
        expected = float((per_sample.mean(dim=1) * weight.double()).sum() / weight.double().sum())
        loss = float(train_step(model, optimizer, make_scheduler(optimizer, config, 1, False), coordinates,
                                targets, encoding, weighting))
        np.testing.assert_allclose(loss, expected, rtol=1e-5)
        return loss

    band = dict(loss_visible_y="1e-9,1e-2", loss_visible_weight=9.0)
    assert visible_weight(TrainConfig(**base, **band))(targets).eq(9.0).float().mean() > 0.1  # the band holds samples
    plain = step_loss(TrainConfig(**base))
    np.testing.assert_allclose(step_loss(TrainConfig(**base, loss_visible_y="0.5,0.6", loss_visible_weight=9.0)),
                               plain, rtol=1e-6)  # no sample of the tiny grating is that bright
    assert abs(step_loss(TrainConfig(**base, **band)) - plain) > 1e-3 * plain

    first = train(volume, TrainConfig(**base), tmp_path / "plain", progress=False)[1]
    second = train(volume, TrainConfig(**base, **band), tmp_path / "weighted", progress=False)[1]
    assert max(float(np.abs(a - b).max()) for a, b in zip(first.weights, second.weights, strict=True)) > 1e-4


@pytest.mark.parametrize("architecture", ["mlp", "grid"])
def test_adam_epsilon_reaches_every_parameter_group_and_sets_the_step_of_tiny_gradients(architecture):
    """Adam's first step is lr·g/(|g| + ε): with gradients of 1e-10 (the grids' scale late in training), ε = 1e-8
    shrinks it about a hundredfold and ε = 1e-15 leaves the full lr step."""
    from trainer.train import build_model, make_optimizer

    def first_step(epsilon: float) -> list[float]:
        torch.manual_seed(0)
        config = TrainConfig(architecture=architecture, preset="tiny", grid_levels=1, grid_resolution=5,
                             grid_t_resolution=2, device="cpu", adam_epsilon=epsilon, grid_adam_epsilon=epsilon)
        model = build_model(config, EncodingSpec())
        optimizer = make_optimizer(model, config)
        assert all(group["eps"] == epsilon for group in optimizer.param_groups)
        pairs = [(parameter, group["lr"]) for group in optimizer.param_groups for parameter in group["params"]]
        assert len(pairs) == len(list(model.parameters()))
        before = [parameter.detach().clone() for parameter, _ in pairs]
        for parameter, _ in pairs:
            parameter.grad = torch.full_like(parameter, 1e-10)
        optimizer.step()
        return [float((parameter.detach() - start).abs().max()) / rate
                for (parameter, rate), start in zip(pairs, before, strict=True)]

    np.testing.assert_allclose(first_step(1e-15), 1.0, rtol=1e-4)
    np.testing.assert_allclose(first_step(1e-8), 1e-10 / (1e-10 + 1e-8), rtol=1e-3)


def test_the_grids_and_the_mlp_take_their_own_adam_epsilon():
    from trainer.train import build_model, make_optimizer

    config = TrainConfig(architecture="grid", preset="tiny", grid_levels=1, grid_resolution=5, grid_t_resolution=2,
                         device="cpu", adam_epsilon=1e-8, grid_adam_epsilon=1e-15)
    model = build_model(config, EncodingSpec())
    mlp, grids = make_optimizer(model, config).param_groups
    assert (mlp["eps"], grids["eps"]) == (1e-8, 1e-15)
    assert {id(p) for p in grids["params"]} == {id(p) for p in model.grids.parameters()}


@pytest.mark.parametrize("epsilon", [0.0, -1e-8, float("nan")])
@pytest.mark.parametrize("field", ["adam_epsilon", "grid_adam_epsilon"])
def test_adam_epsilon_must_be_positive(field, epsilon):
    with pytest.raises(GratNetError, match="--" + field.replace("_", "-")):
        TrainConfig(**{field: epsilon})


def test_cpu_adam_is_fused_and_takes_the_same_steps_as_the_default():
    """On the CPU the optimiser is torch's fused Adam (the default foreach Adam took half a grid network's step);
    ten steps on real gradients land where the default's do, up to float rounding, with both groups' ε."""
    from trainer.objective import batch_loss
    from trainer.train import build_model, make_optimizer

    config = TrainConfig(architecture="grid", preset="tiny", grid_levels=2, grid_resolution=9, grid_t_resolution=3,
                         device="cpu", adam_epsilon=1e-8, grid_adam_epsilon=1e-15)
    encoding = EncodingSpec()
    generator = torch.Generator().manual_seed(1)
    coordinates = torch.rand(256, 3, generator=generator) * 2 - 1
    targets = torch.rand(256, 3, generator=generator) * 1e-2
    models = []
    for fused in (True, False):
        torch.manual_seed(0)
        model = build_model(config, encoding)
        start = [parameter.detach().clone() for parameter in model.parameters()]
        # The CPU's own choice (fused), and the reference: torch's default implementation, same groups and rates.
        optimizer = make_optimizer(model, config, fused=None if fused else False)
        assert all(bool(group["fused"]) == fused for group in optimizer.param_groups)
        assert [group["eps"] for group in optimizer.param_groups] == [1e-8, 1e-15]
        for _ in range(10):
            optimizer.zero_grad(set_to_none=True)
            batch_loss(model, coordinates, targets, encoding).backward()
            optimizer.step()
        models.append([(parameter.detach() - before).numpy() for parameter, before in
                       zip(model.parameters(), start, strict=True)])
    # Each tensor's moves agree to 1e-3 of its largest move (a grid node whose gradient is rounding noise takes
    # a noise-sized step at ε 1e-15 in either implementation, hence no per-element relative bound).
    for mine, theirs in zip(*models, strict=True):
        assert np.abs(theirs).max() > 0.0
        np.testing.assert_allclose(mine, theirs, rtol=0, atol=1e-3 * float(np.abs(theirs).max()))


def test_a_checkpoint_of_the_default_adam_resumes_fused(tiny_volume, tmp_path, stop_in_epoch_two):
    """Checkpoints written before the CPU's Adam was fused carry ``fused: None`` in their groups: a resume takes
    the current device's choice (its next checkpoint says so) and ends where the resume of a fused checkpoint does."""
    import shutil

    volume, _ = tiny_volume
    config = TrainConfig(preset="tiny", epochs=2, batch_size=512, test_slices="2", device="cpu")
    with pytest.raises(KeyboardInterrupt):
        train(volume, config, tmp_path / "fused", progress=False, per_epoch=stop_in_epoch_two)
    shutil.copytree(tmp_path / "fused", tmp_path / "older")
    checkpoint = tmp_path / "older" / "checkpoint.pt"
    state = torch.load(checkpoint, weights_only=False)
    assert all(group["fused"] for group in state["optimizer"]["param_groups"])
    for group in state["optimizer"]["param_groups"]:
        group["fused"] = None  # as the trainer wrote it before
    torch.save(state, checkpoint)
    models = [train(volume, config, tmp_path / name, resume=True, progress=False)[1] for name in ("older", "fused")]
    resaved = torch.load(checkpoint, weights_only=False)
    assert resaved["epoch"] == 2 and all(group["fused"] for group in resaved["optimizer"]["param_groups"])
    for mine, theirs in zip(*(model.weights for model in models), strict=True):
        np.testing.assert_allclose(mine, theirs, rtol=1e-5, atol=1e-7)
