"""benchmarks/environment_convergence.py and environment_agreement.py at tiny sizes: each writes its record and its
figure together, with a figure per strategy (convergence) or per renderer (agreement)."""

from __future__ import annotations

import importlib.util
import json
import os
import subprocess
import sys

import pytest

from tests.helpers import REPO, random_model


@pytest.fixture(scope="module")
def tiny_material(tmp_path_factory) -> str:
    """A small random network (compiles in well under a second, unlike a shipped one's baked shader)."""
    from gratnet.encoding import EncodingSpec
    from gratnet.modelfile import save_model

    spec = EncodingSpec(frequencies=2, t_frequencies=1, scale=2.0, t_scale=2.0)
    path = tmp_path_factory.mktemp("tiny") / "model.npz"
    save_model(path, random_model([spec.features, 16, 3], spec=spec, seed=5))
    return str(path)


def _run(script: str, *arguments: str, cache) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, f"benchmarks/{script}", *arguments], cwd=REPO, text=True,
                          capture_output=True, env={**os.environ, "XDG_CACHE_HOME": str(cache)}, check=False)


def test_convergence_scores_every_strategy(tmp_path, ctx, tiny_material):  # ctx: skipped without GL
    out, figure = tmp_path / "convergence.json", tmp_path / "convergence.png"
    done = _run("environment_convergence.py", "--material", tiny_material, "--environment", "studio", "--size", "12",
                "--max-spp", "2", "--reference-spp", "4", "--out", str(out), "--figure", str(figure),
                cache=tmp_path / "cache")
    assert done.returncode == 0, done.stderr
    record = json.loads(out.read_text())
    assert set(record["strategies"]) == {"mis", "light", "material", "resampled"}
    for points in record["strategies"].values():
        assert [point["spp"] for point in points] == [1, 2]
        assert all(0.0 <= point["flip"] <= 1.0 and point["seconds"] > 0.0 for point in points)
    assert figure.stat().st_size > 1000


def test_convergence_refuses_no_environment_and_writes_nothing(tmp_path):
    out = tmp_path / "convergence.json"
    done = _run("environment_convergence.py", "--environment", "none", "--out", str(out), "--figure",
                str(tmp_path / "c.png"), cache=tmp_path / "cache")
    assert done.returncode == 2 and "nothing to converge" in done.stderr
    assert not list(tmp_path.glob("*.json")) and not list(tmp_path.glob("*.png"))


@pytest.mark.skipif(importlib.util.find_spec("mitsuba") is None, reason="the mitsuba extra is not installed")
def test_agreement_renders_both_and_scores_them(tmp_path, ctx, tiny_material):
    out, figure = tmp_path / "agreement.json", tmp_path / "agreement.png"
    done = _run("environment_agreement.py", "--material", tiny_material, "--environment", "studio", "--size", "8",
                "--spp", "2", "--out", str(out), "--figure", str(figure), cache=tmp_path / "cache")
    assert done.returncode == 0, done.stderr
    record = json.loads(out.read_text())
    assert 0.0 <= record["flip_frame"] <= 1.0 and record["seconds"]["gl"] > 0.0 and record["seconds"]["mitsuba"] > 0.0
    assert figure.stat().st_size > 1000
