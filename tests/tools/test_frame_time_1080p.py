"""benchmarks/frame_time_1080p.py: one model at a small size, timed by `gratnet bench` in a child, into its record."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np

from gratnet.cost import ModelCost
from gratnet.encoding import EncodingSpec, RangeSpec
from gratnet.modelfile import ModelFile, save_model
from tests.helpers import REPO


def _tiny_model(path: Path) -> Path:
    rng = np.random.default_rng(3)
    spec = EncodingSpec.for_grid(33, 5, frequencies=3, t_frequencies=2)
    sizes = [spec.features, 12, 8, 3]
    model = ModelFile(sizes, [(rng.standard_normal((b, a)) / np.sqrt(a)).astype(np.float32)
                              for a, b in zip(sizes[:-1], sizes[1:], strict=True)],
                      [(0.1 * rng.standard_normal(b)).astype(np.float32) for b in sizes[1:]], "silu", "clamp", spec,
                      RangeSpec(), "simple-max", metadata={"volume": {"source": "generator:sinusoidal"}})
    path.parent.mkdir(parents=True)
    save_model(path, model)
    return path


def _run(*arguments: str, env_cache: Path) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "benchmarks/frame_time_1080p.py", *arguments], cwd=REPO, text=True,
                          capture_output=True, env={**os.environ, "XDG_CACHE_HOME": str(env_cache)}, check=False)


def test_the_record_holds_each_models_frame_and_cost(tmp_path, ctx):  # ctx: skipped without GL
    model = _tiny_model(tmp_path / "tiny" / "model.npz")
    out = tmp_path / "frames.json"
    done = _run(str(model), "--size", "48x32", "--repeats", "2", "--out", str(out), env_cache=tmp_path / "cache")
    assert done.returncode == 0, done.stderr
    record = json.loads(out.read_text())
    assert (record["width"], record["height"], record["repeats"]) == (48, 32, 2)
    assert record["command"].startswith("python benchmarks/frame_time_1080p.py ")
    assert record["machine"]["cores"] >= 1 and record["machine"]["gl_renderer"] == str(ctx.info["GL_RENDERER"])
    assert len(record["load_average_before"]) == len(record["load_average_after"]) == 3
    (row,) = record["models"]
    assert row["material"] == "tiny" and row["mesh"] == "cd" and (row["width"], row["height"]) == (48, 32)
    assert len(row["times_ms"]) == 2 and row["ms"] > 0
    assert {key: row[key] for key in ModelCost.of_file(model).to_dict()} == ModelCost.of_file(model).to_dict()
    assert json.loads(done.stdout.splitlines()[0]) == row  # one JSON line per model as it goes


def test_a_size_other_than_1080p_needs_its_own_record(tmp_path):
    """The default record (docs/data/frame_times_1080p.json, read by docs/results.md) holds 1080p frames only."""
    done = _run("cd", "--size", "64x36", env_cache=tmp_path)
    assert done.returncode == 2 and "give --out" in done.stderr.splitlines()[-1]  # refused before any work


def test_update_replaces_only_the_rows_timed_now(tmp_path, ctx):  # ctx: skipped without GL
    """`--update` keeps the record's other models (each row its own date and load) and lists every run."""
    first, second = _tiny_model(tmp_path / "one" / "model.npz"), _tiny_model(tmp_path / "two" / "model.npz")
    out = tmp_path / "frames.json"
    common = ("--size", "48x32", "--repeats", "1", "--out", str(out))
    assert _run(str(first), str(second), *common, env_cache=tmp_path / "cache").returncode == 0
    before = json.loads(out.read_text())
    done = _run(str(second), *common, "--update", env_cache=tmp_path / "cache")
    assert done.returncode == 0, done.stderr
    after = json.loads(out.read_text())
    rows = {row["material"]: row for row in after["models"]}
    assert set(rows) == {"one", "two"}
    assert rows["one"] == before["models"][0]  # untouched
    assert rows["two"]["date"] >= before["models"][1]["date"] and rows["two"]["times_ms"] != []
    assert after["date"] == before["date"] and len(after["updates"]) == 1
    assert "--update" in after["updates"][0]["command"] and rows["two"]["run"] == after["updates"][0]["date"]
    again = _run(str(second), *common, "--update", env_cache=tmp_path / "cache")  # its rows replaced: one run listed
    assert again.returncode == 0, again.stderr
    assert len(json.loads(out.read_text())["updates"]) == 1


def test_update_of_a_record_of_another_size_is_refused_before_any_timing(tmp_path):
    out = tmp_path / "frames.json"
    out.write_text(json.dumps({"width": 64, "height": 36, "models": []}))
    done = _run("cd", "--size", "48x32", "--out", str(out), "--update", env_cache=tmp_path)
    assert done.returncode == 2 and "64x36" in done.stderr.splitlines()[-1]
    assert json.loads(out.read_text()) == {"width": 64, "height": 36, "models": []}
