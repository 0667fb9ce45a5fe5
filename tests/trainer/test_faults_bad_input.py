"""Bad training and evaluation options are refused before any work (issue 36): ``gratnet train`` checks every option
when its configs are made, before the volume is read, so a bad value is one line naming its flag, exit status 2,
nothing written. The volume given here does not exist: a check that came after loading it would report the
missing file instead of the flag.

These are the checks the sweep file reuses (tests/tools/test_sweep.py: the same values in TOML, named by table and key).
"""

from __future__ import annotations

from pathlib import Path

import pytest

from gratnet.cli import main

#: flags → what the one line must say (the flag and the rule).
BAD_TRAIN_FLAGS = {
    "unknown preset": (["--preset", "huge"], "--preset 'huge' is unknown"),
    "hidden not widths": (["--hidden", "a,b"], "--hidden must be comma-separated widths"),
    "unknown activation": (["--activation", "tanh"], "--activation must be one of silu, relu, leaky_relu"),
    "unknown output activation": (["--output-activation", "relu"], "--output-activation must be one of"),
    "unknown range transform": (["--range-kind", "linear"], "unknown range transform 'linear'"),
    "range bits negative": (["--range-bits", "-1"], "range transform needs finite B > 0"),
    "no frequencies": (["--frequencies", "0"], "--frequencies must be ≥ 1"),
    "held-out slices not numbers": (["--test-slices", "x"], "--test-slices must be comma-separated integers"),
    "held-out slice negative": (["--test-slices", "-1"], "--test-slices must name slices, indices from 0"),
    "test fraction beyond 1": (["--split", "random", "--test-fraction", "1.5"], "--test-fraction must lie in (0, 1)"),
    "max train samples negative": (["--max-train-samples", "-1"], "--max-train-samples must be ≥ 0"),
    "final rate ratio negative": (["--final-learning-rate-ratio", "-1"], "--final-learning-rate-ratio must be"),
    "seed negative": (["--seed", "-1"], "--seed must be ≥ 0"),
    "unknown device": (["--device", "tpu"], "--device must be auto, cpu, cuda or cuda:N"),
    "epochs negative": (["--epochs", "-1"], "--epochs and --batch-size must be ≥ 1"),
    "evaluation size 0": (["--size", "0"], "--size must be from 2 to 4096"),
    "evaluation ior negative": (["--ior", "-1.5"], "--ior must be 0 (no Fresnel)"),
    "evaluation views": (["--views", "1,2"], "--views: each view is"),
    "evaluation size 0 without evaluation": (["--no-evaluate", "--size", "0"], "--size must be from 2 to 4096"),
}


@pytest.mark.parametrize("case", sorted(BAD_TRAIN_FLAGS))
def test_bad_train_option_is_refused_before_the_volume_is_read(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                                               case: str) -> None:
    flags, message = BAD_TRAIN_FLAGS[case]
    out = tmp_path / "run"
    code = main(["train", str(tmp_path / "missing.exr"), "--out", str(out), "--quiet", *flags])
    stderr = capsys.readouterr().err
    assert code == 2, stderr
    assert message in stderr and "missing.exr" not in stderr, stderr
    assert len(stderr.strip().splitlines()) == 1, stderr
    assert not out.exists()


def test_the_same_run_with_good_options_gets_to_the_volume(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """The control: with every option good, the run reaches the (missing) volume, so the cases above were refused
    by their options and not by something they share."""
    code = main(["train", str(tmp_path / "missing.exr"), "--out", str(tmp_path / "run"), "--quiet"])
    stderr = capsys.readouterr().err
    assert code == 2 and "missing.exr" in stderr, stderr


@pytest.mark.parametrize(("flags", "message"), [(["--size", "1"], "--size must be from 2 to 4096"),
                                                (["--ior", "1e31"], "--ior must be 0 (no Fresnel)")])
def test_bad_evaluate_option_is_refused_before_the_model_is_read(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                                                 flags: list[str], message: str) -> None:
    code = main(["evaluate", str(tmp_path / "missing.npz"), "--out", str(tmp_path / "report"), "--quiet", *flags])
    stderr = capsys.readouterr().err
    assert code == 2 and message in stderr and "missing.npz" not in stderr, stderr
    assert not (tmp_path / "report").exists()
