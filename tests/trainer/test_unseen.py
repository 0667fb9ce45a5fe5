"""trainer.unseen: the encoding's features that vanish at every training sample, silenced while training and
afterwards (one rule, two forms)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from gratnet.errors import GratNetError
from gratnet.modelfile import evaluate_keys
from gratnet.volume import volume_axes
from tests.helpers import top_sine_columns
from trainer.sampling import grid_to_key
from trainer.train import train
from trainer.train_config import TrainConfig
from trainer.unseen import silence_model_file, unseen_columns


@pytest.fixture(scope="module")
def unsilenced(tiny_volume, tmp_path_factory):
    """A tiny grid network trained with --no-zero-unseen-features, and its volume."""
    volume, _ = tiny_volume
    config = TrainConfig(architecture="grid", preset="tiny", epochs=2, batch_size=256, test_slices="2", seed=3,
                         grid_levels=1, grid_resolution=11, grid_t_resolution=3, grid_features=2,
                         zero_unseen_features=False)
    _, model_file, _ = train(volume, config, tmp_path_factory.mktemp("unsilenced"), progress=False)
    return volume, model_file


def test_the_unseen_columns_are_the_top_sines_of_every_group_and_of_t(unsilenced):
    _, model = unsilenced
    assert unseen_columns(model) == top_sine_columns(model)
    assert np.all(np.abs(model.weights[0][:, top_sine_columns(model)]).max(axis=0) > 0)  # trained without: still random


def test_silencing_a_model_file_keeps_every_sample_and_changes_what_lies_between(unsilenced):
    volume, model = unsilenced
    silenced = dataclasses.replace(model, weights=list(model.weights))
    columns = silence_model_file(silenced)
    assert columns == top_sine_columns(model) and np.all(silenced.weights[0][:, columns] == 0.0)
    assert np.array_equal(np.delete(silenced.weights[0], columns, axis=1), np.delete(model.weights[0], columns, axis=1))
    key = grid_to_key(volume_axes(volume.resolution), "simple-max")
    u, v = np.meshgrid(key, key)
    depth = np.sqrt(np.clip(4.0 - u**2 - v**2, 0.0, None))
    inside = u**2 + v**2 < 4.0
    t = np.linspace(0.0, 1.0, volume.slices)[2]
    at_samples = [part[inside] for part in (u, v, -t * depth)]
    before, after = evaluate_keys(model, *at_samples), evaluate_keys(silenced, *at_samples)
    np.testing.assert_allclose(after, before, rtol=1e-3, atol=1e-12)  # the inputs are float32 rounding there
    step = key[1] - key[0]  # half a cell off the lattice the sines are ±1: the outputs move
    between = [part + 0.5 * step for part in at_samples[:2]] + [at_samples[2]]
    inside_between = between[0] ** 2 + between[1] ** 2 < 3.9
    moved = np.abs(evaluate_keys(silenced, *(p[inside_between] for p in between))
                   - evaluate_keys(model, *(p[inside_between] for p in between)))
    assert moved.max() > 1e-3 * np.abs(before).max()


def test_a_model_file_without_its_training_volume_is_refused(unsilenced):
    _, model = unsilenced
    anonymous = dataclasses.replace(model, metadata={})
    with pytest.raises(GratNetError, match="training volume"):
        unseen_columns(anonymous)
