"""``gratnet train --preset fast`` (issue 42; trainer/train_config.py ``RECIPES``): a preset that sets the architecture,
widths, grid and encoding at once, under which every option given explicitly still wins, as ``--hidden`` wins over
a size preset; the saved config holds the resolved values.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from gratnet.cli import build_parser, main
from gratnet.config import config_to_dict
from gratnet.errors import GratNetError
from gratnet.modelfile import ModelFile, load_model
from gratnet.quality import FAST
from tests.helpers import ASSETS
from trainer.train_config import RECIPES, TrainConfig, config_from_arguments, preset_config

#: The screen's recipe (docs/experiments/2026-11-27-fast-models-screen.md), as the issue gives it in flags.
FAST_FLAGS = {"architecture": "grid", "hidden": "40,24,12", "grid_levels": 3, "grid_resolution": 251,
              "grid_t_resolution": 5, "grid_features": 8, "frequencies": 19, "t_frequencies": 2,
              "diagonal_frequencies": False}


def config_of(*flags: str) -> TrainConfig:
    """The config ``gratnet train`` makes of ``flags`` (nothing is read or trained)."""
    return config_from_arguments(build_parser("train").parse_args(["train", "v.exr", "--out", "run", *flags]))


def resolved(config: TrainConfig) -> dict[str, object]:
    return {name: getattr(config, name) for name in FAST_FLAGS}


def test_the_fast_preset_is_the_screens_recipe():
    assert RECIPES[FAST] == FAST_FLAGS
    config = config_of("--preset", "fast")
    assert config.preset == FAST and resolved(config) == FAST_FLAGS
    # The saved config (gratnet.config.save_config beside model.npz) holds the resolved values.
    saved = config_to_dict(config)
    assert saved["preset"] == "fast" and saved["hidden"] == "40,24,12" and saved["architecture"] == "grid"
    assert saved["frequencies"] == 19 and saved["t_frequencies"] == 2 and saved["diagonal_frequencies"] is False
    assert {key: saved["grid"][key] for key in ("levels", "resolution", "t_resolution", "features")} == {
        "levels": 3, "resolution": 251, "t_resolution": 5, "features": 8}


@pytest.mark.parametrize(("flags", "expected"), [
    (["--hidden", "64,32"], {"hidden": "64,32"}),
    (["--frequencies", "12"], {"frequencies": 12}),
    (["--diagonal-frequencies"], {"diagonal_frequencies": True}),  # the field's default, given: it wins
    (["--t-frequencies", "4", "--grid-features", "2"], {"t_frequencies": 4, "grid_features": 2}),
    (["--grid-levels", "2", "--grid-resolution", "125", "--grid-t-resolution", "11"],
     {"grid_levels": 2, "grid_resolution": 125, "grid_t_resolution": 11}),
    (["--architecture", "grid"], {}),
])
def test_explicit_flags_win_over_the_recipe(flags, expected):
    for order in (["--preset", "fast", *flags], [*flags, "--preset", "fast"]):
        assert resolved(config_of(*order)) == {**FAST_FLAGS, **expected}


def test_a_size_preset_is_what_it_was():
    config = config_of("--preset", "small")
    assert config.architecture == "mlp" and config.hidden == "" and config.frequencies == 19
    assert config.t_frequencies == 4 and config.grid.features == 2 and config.grid.t_resolution == 11
    assert config == TrainConfig(preset="small")
    explicit = config_of("--frequencies", "12", "--architecture", "grid")
    assert explicit == TrainConfig(frequencies=12, architecture="grid")


def test_the_recipe_takes_keywords_as_the_command_line_takes_flags():
    assert resolved(preset_config(preset="fast")) == FAST_FLAGS
    assert preset_config(preset="fast", frequencies=12, grid_levels=2).frequencies == 12
    assert preset_config(preset="tiny") == TrainConfig(preset="tiny")
    with pytest.raises(GratNetError, match="--preset fast sets several options: make its config with "
                                           "trainer.train_config.preset_config"):
        TrainConfig(preset="fast")


def test_the_fast_preset_on_the_mlp_architecture_is_refused_before_the_volume_is_read(tmp_path, capsys):
    with pytest.raises(GratNetError, match="feature-grid recipe"):
        preset_config(preset="fast", architecture="mlp")
    out = tmp_path / "run"
    code = main(["train", str(tmp_path / "missing.exr"), "--out", str(out), "--preset", "fast", "--architecture",
                 "mlp", "--quiet"])
    lines = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(lines) == 1, lines
    assert lines[0] == ("gratnet train: error: --preset fast is a feature-grid recipe (--architecture grid); leave "
                        "out --architecture mlp, or take a size preset (paper, funnel-176, medium, small, tiny)")
    assert not out.exists()


def test_help_gives_each_recipe_value_beside_the_default(capsys):
    assert main(["train", "--help"]) == 0
    text = " ".join(capsys.readouterr().out.split())
    assert "(default: 4; --preset fast: 2)" in text and "(default: mlp; --preset fast: grid)" in text
    assert "(default: True; --preset fast: False)" in text  # --no-diagonal-frequencies


def test_a_fast_training_saves_the_resolved_config_and_its_network(tiny_volume: tuple[object, Path], tmp_path: Path):
    _, volume = tiny_volume
    out = tmp_path / "run"
    assert main(["train", str(volume), "--out", str(out), "--preset", "fast", "--grid-resolution", "21",
                 "--epochs", "1", "--batch-size", "512", "--max-train-samples", "1024", "--test-slices", "2",
                 "--device", "cpu", "--no-evaluate", "--quiet"]) == 0
    saved = json.loads((out / "model.config.json").read_text())["train"]
    assert saved["preset"] == "fast" and saved["hidden"] == "40,24,12" and saved["frequencies"] == 19
    assert saved["grid"]["features"] == 8 and saved["grid"]["resolution"] == 21 and saved["grid"]["t_resolution"] == 5
    model = load_model(out / "model.npz")
    assert model.layer_sizes[1:] == [40, 24, 12, 3] and len(model.grids) == 3 and not model.encoding.diagonals
    assert [grid.shape[0] for grid in model.grids] == [5, 5, 5] and model.grids[-1].shape[-1] == 8

    def macs(model_file: ModelFile) -> int:  # the MLP's and the grid interpolation's (8 corners per feature)
        return model_file.macs_per_evaluation + 8 * sum(grid.shape[-1] for grid in model_file.grids)

    # The point of the preset: at most a fifth of the shipped paper-cd network's work per pixel.
    assert 5 * macs(model) <= macs(load_model(ASSETS / "paper-cd" / "model.npz"))
