"""``gratnet sweep`` on a local Ray instance (2 workers) against the same runs done one by one without Ray.

A tiny grid (65² volumes of 5 slices, 11 wavelengths, preset tiny, 1 epoch, 32² evaluation slices): two
datasets × two seeds, one of the datasets' volumes split into three wavelength blocks. The reference runs
are the ordinary commands (``gratnet groundtruth``, ``gratnet train``) in a fresh process with one thread,
as each sweep task has (1 CPU). Then: finished runs skipped, an interrupted run resumed from its
checkpoint, the split ground truth against the unsplit one, and bad sweep files refused up front.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from gratnet.cli import main
from gratnet.volume import read_volume
from tests.helpers import REPO

TINY = """
presets = ["tiny"]
seeds = [0, 1]

[groundtruth]
resolution = 65
slices = 5
sigma_s_um = 3.0
wavelength_step_nm = 40.0

[train]
epochs = 1
test_slices = "2"
batch_size = 4096

[evaluate]
size = 32

[resources]
train_cpus = 1

[[datasets]]
generator = "blazed"
params = { size_um = 10.0 }

[[datasets]]
name = "sine"
generator = "sinusoidal"
params = { size_um = 10.0 }
groundtruth = { parts = 3 }
"""
# The same grid as separate commands: dataset -> (height field, ground-truth flags); train flags.
REFERENCE_DATASETS = {
    "blazed": "generator:blazed(size_um=10.0)",
    "sine": "generator:sinusoidal(size_um=10.0)",
}
GROUNDTRUTH_FLAGS = ["--res", "65", "--slices", "5", "--sigma-s", "3.0", "--wavelength-step-nm", "40.0", "--quiet"]
TRAIN_FLAGS = ["--preset", "tiny", "--epochs", "1", "--test-slices", "2", "--batch-size", "4096", "--size", "32",
               "--quiet"]
TIMINGS = {"train_seconds", "run_seconds", "model", "run"}


@pytest.fixture(scope="module")
def swept(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The tiny sweep, run once on a local Ray instance with 2 CPUs."""
    pytest.importorskip("ray")
    folder = tmp_path_factory.mktemp("sweep")
    (folder / "tiny.toml").write_text(TINY)
    assert main(["sweep", str(folder / "tiny.toml"), "--out", str(folder / "out"), "--workers", "2", "--quiet"]) == 0
    return folder


def _rows(folder: Path) -> dict[str, dict]:
    return {row["run"]: row for row in json.loads((folder / "out" / "results.json").read_text())}


def test_sweep_table_matches_the_runs_done_one_by_one(swept, tmp_path):
    from sweep.spec import load_sweep
    from sweep.tasks import result_row

    rows = _rows(swept)
    assert sorted(rows) == ["blazed-tiny-base-s0", "blazed-tiny-base-s1", "sine-tiny-base-s0", "sine-tiny-base-s1"]
    text = (swept / "out" / "results.md").read_text()
    assert all(f"| {name} |" in text for name in rows)
    assert (swept / "out" / "results.csv").read_text().count("\n") == 5
    assert (swept / "out" / "pareto.png").stat().st_size > 1000
    config = json.loads((swept / "out" / "sweep.config.json").read_text())
    assert [run["name"] for run in config["runs"]] == list(rows)

    # One by one in a fresh process with one thread, as each task has (Ray sets OMP_NUM_THREADS to a task's CPUs;
    # OpenBLAS's complex products differ in the last bits between thread counts).
    commands = []
    for name, heightfield in REFERENCE_DATASETS.items():
        volume = str(tmp_path / f"{name}.exr")
        commands.append(["groundtruth", heightfield, "--out", volume, *GROUNDTRUTH_FLAGS])
        commands += [["train", volume, "--out", str(tmp_path / f"{name}-tiny-base-s{seed}"), "--seed", str(seed),
                      *TRAIN_FLAGS, "--cache-dir", str(tmp_path / "cache")] for seed in (0, 1)]
    script = ("import json, sys, torch\nfrom gratnet.cli import main\ntorch.set_num_threads(1)\n"
              "sys.exit(max(main(command) for command in json.loads(sys.argv[1])))")
    environment = {**os.environ, "OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1",
                   "PYTHONPATH": os.pathsep.join(filter(None, [str(REPO), os.environ.get("PYTHONPATH")]))}
    subprocess.run([sys.executable, "-c", script, json.dumps(commands)], env=environment, check=True,
                   capture_output=True)
    spec = load_sweep(swept / "tiny.toml", swept / "out")
    for name in REFERENCE_DATASETS:
        # The split volume (sine: three wavelength blocks on different workers) equals the unsplit one.
        assert np.array_equal(read_volume(tmp_path / f"{name}.exr").xyz,
                              read_volume(swept / "out" / "volumes" / f"{name}.exr").xyz), name
    for run in spec.runs:
        expected = {key: value for key, value in result_row(run, tmp_path / run.name).items() if key not in TIMINGS}
        got = {key: value for key, value in rows[run.name].items() if key not in TIMINGS}
        assert got == expected, run.name
    # The seeds differ (else the comparison above could not tell the runs apart).
    assert rows["blazed-tiny-base-s0"]["flip_mean"] != rows["blazed-tiny-base-s1"]["flip_mean"]


def test_finished_runs_are_skipped_and_an_interrupted_one_resumes(swept, capsys):
    runs = swept / "out" / "runs"
    before = {path: path.stat().st_mtime_ns for path in runs.glob("*/result.json")}
    rows = _rows(swept)
    # Nothing left: no Ray instance, no task, the same table.
    assert main(["sweep", str(swept / "tiny.toml"), "--out", str(swept / "out"), "--quiet"]) == 0
    assert {path: path.stat().st_mtime_ns for path in runs.glob("*/result.json")} == before
    assert _rows(swept) == rows
    assert main(["sweep", str(swept / "tiny.toml"), "--out", str(swept / "out"), "--dry-run"]) == 0
    assert capsys.readouterr().out.count("done ") == 4

    # Interrupted after its last checkpoint, before the model and the evaluation were written.
    interrupted = runs / "sine-tiny-base-s1"
    for name in ("result.json", "model.npz", "metrics.json", "history.json"):
        (interrupted / name).unlink()
    checkpoint = (interrupted / "checkpoint.pt").stat().st_mtime_ns
    assert main(["sweep", str(swept / "tiny.toml"), "--out", str(swept / "out"), "--dry-run"]) == 0
    assert "resume sine-tiny-base-s1" in capsys.readouterr().out
    # With a dataset whose ground truth fails in its task: reported (exit 1), the other work goes on.
    broken = TINY + '[[datasets]]\nname = "broken"\ngenerator = "blazed"\ngroundtruth = { sigma_s_um = 1000.0 }\n'
    (swept / "broken.toml").write_text(broken)
    assert main(["sweep", str(swept / "broken.toml"), "--out", str(swept / "out"), "--workers", "2", "--quiet"]) == 1
    stderr = capsys.readouterr().err
    assert "failed: broken: ground truth: " in stderr and "max_grid_samples" in stderr
    assert "more tasks failed with one of these errors" in stderr  # its BRDF slices and runs
    assert not (swept / "out" / "runs" / "broken-tiny-base-s0" / "model.npz").exists()
    # Resumed, not retrained: the checkpoint (rewritten after every epoch) was only read.
    assert (interrupted / "checkpoint.pt").stat().st_mtime_ns == checkpoint
    others = {path: time for path, time in before.items() if path.parent != interrupted}
    assert {path: path.stat().st_mtime_ns for path in others} == others
    after = _rows(swept)
    assert {key: value for key, value in after["sine-tiny-base-s1"].items() if key != "run_seconds"} == \
        {key: value for key, value in rows["sine-tiny-base-s1"].items() if key != "run_seconds"}


@pytest.mark.parametrize("scheme", ["regular", "simple-max"])
def test_split_ground_truth_agrees_with_the_unsplit_one(scheme):
    from trainer.fourier import OpticsConfig, prepare_surface
    from trainer.generators import generate
    from trainer.groundtruth import (
        VolumeConfig,
        compute_volume,
        compute_volume_part,
        volume_from_sum,
        wavelength_blocks,
    )

    field = generate("blazed", size_um=10.0)
    optics = OpticsConfig(sigma_s_um=3.0, wavelength_step_nm=40.0)
    config = VolumeConfig(resolution=33, slices=3, sampling=scheme)
    whole = compute_volume(field, config, optics, progress=False)
    surface = prepare_surface(field, optics)
    blocks = wavelength_blocks(optics, 4)
    assert [index for block in blocks for index in block] == list(range(11))
    parts = [compute_volume_part(surface, config, optics, block) for block in blocks]
    total = parts[0][0] + parts[1][0] + parts[2][0] + parts[3][0]
    split = volume_from_sum(field, config, optics, surface, total, parts[0][1])
    assert split.metadata["chebyshev_nodes"] == whole.metadata["chebyshev_nodes"]
    assert np.max(whole.xyz) > 0.01
    # Each block alone is a real part of the sum (not the whole, not nothing).
    assert 0 < np.max(parts[0][0]) < np.max(total)
    if scheme == "regular":  # one exact transform per slice and wavelength: the same numbers
        assert np.array_equal(split.xyz, whole.xyz)
    relative = np.abs(split.xyz - whole.xyz) / np.maximum(np.abs(whole.xyz), 1e-30)
    assert relative.max() <= 1e-6


def _write(tmp_path: Path, text: str) -> str:
    path = tmp_path / "bad.toml"
    path.write_text(text)
    return str(path)


DATASET = '[[datasets]]\ngenerator = "blazed"\n'
#: case -> (sweep file, what the one line must say: the table and key of the bad value, in the file's words).
BAD_FILES = {
    "not TOML": ("presets = [tiny", "not valid TOML"),
    "unknown top-level key": ("epochs = 3\n" + DATASET, "unknown key 'epochs'"),
    "unknown train key": ("[train]\nepoch = 3\n" + DATASET, "[train]: unknown key 'epoch'"),
    "preset in train": ("[train]\npreset = \"tiny\"\n" + DATASET, "[train]: unknown key 'preset'"),
    "train not a table": ("train = 3\n" + DATASET, "train must be a table, got 3"),
    "unknown preset": ('presets = ["huge"]\n' + DATASET, "presets entry 'huge' is unknown"),
    "presets not a list": ('presets = "tiny"\n' + DATASET, "presets must be a non-empty list, got 'tiny'"),
    "presets empty": ("presets = []\n" + DATASET, "presets must be a non-empty list, got []"),
    "preset not a string": ("presets = [3]\n" + DATASET, "presets entry 3 must be a string"),
    "seed a fraction": ("seeds = [0, 1.5]\n" + DATASET, "seeds entry 1.5 must be a whole number"),
    "seed twice": ("seeds = [1, 1]\n" + DATASET, "seeds lists an entry twice"),
    "negative seed": ("seeds = [-1]\n" + DATASET, "seeds entry must be ≥ 0, got -1"),
    "seed beyond int32": ("seeds = [3000000000]\n" + DATASET, "seeds entry 3000000000 must be a whole number the "
                          "command line accepts"),
    "unknown generator": ('[[datasets]]\ngenerator = "zebra"\n',
                          "[[datasets]] #1 generator: unknown generator 'zebra'"),
    "unknown generator parameter": (DATASET + "params = { pitch = 2 }\n",
                                    "[[datasets]] #1 params: unknown key 'pitch'"),
    "bad generator parameter": (DATASET + "params = { size_um = -1.0 }\n",
                                "[[datasets]] #1 params: blazed parameter size_um must be > 0"),
    "generator parameter a string": (DATASET + 'params = { size_um = "big" }\n',
                                     "[[datasets]] #1 params.size_um must be a number, got 'big'"),
    "wrong type": ('[groundtruth]\nresolution = "big"\n' + DATASET, "[groundtruth] resolution must be a whole number"),
    "resolution too small": ("[groundtruth]\nresolution = 1\n" + DATASET,
                             "[groundtruth] resolution must be at least 2"),
    "resolution beyond the CLI's limit": ("[groundtruth]\nresolution = 5000\n" + DATASET,
                                          "[groundtruth] resolution must be at most 4001"),
    "wavelength step below the CLI's limit": ("[groundtruth]\nwavelength_step_nm = 0.01\n" + DATASET,
                                              "[groundtruth] wavelength_step_nm must be at least 0.1 nm"),
    "dataset's own bad resolution": (DATASET + "groundtruth = { resolution = 1 }\n",
                                     "[[datasets]] #1 groundtruth.resolution must be at least 2"),
    "unknown ground-truth key": (DATASET + "groundtruth = { res = 65 }\n",
                                 "[[datasets]] #1 groundtruth: unknown key 'res'"),
    "no datasets": ('presets = ["tiny"]\n', "no [[datasets]]"),
    "missing file": ('[[datasets]]\nfile = "nowhere.gsf"\n', "[[datasets]] #1 file: height-field file"),
    "generator and file": (DATASET + 'file = "x.gsf"\n', "[[datasets]] #1 needs exactly one of"),
    "too many parts": ('[groundtruth]\nparts = 500\n' + DATASET,
                       "[groundtruth] parts: cannot split 81 wavelengths into 500"),
    "held-out slice out of range": ('[groundtruth]\nslices = 3\n' + DATASET,
                                    "[train] test_slices 4,7,10 out of range for a 3-slice volume"),
    "held-out slices not numbers": ('[train]\ntest_slices = "a,b"\n' + DATASET,
                                    "[train] test_slices must be comma-separated integers"),
    "same name twice": (DATASET + DATASET, "two [[datasets]] share the name 'blazed'"),
    "negative resources": ("[resources]\ntrain_gpus = -0.5\n" + DATASET, "[resources] train_gpus must be a number ≥ 0"),
    "epochs negative": ("[train]\nepochs = -1\n" + DATASET,
                        "[train] epochs and [train] batch_size must be ≥ 1, got -1"),
    "epochs a string": ('[train]\nepochs = "6"\n' + DATASET, "[train] epochs must be a whole number, got '6'"),
    "unknown activation": ('[train]\nactivation = "tanh"\n' + DATASET, "[train] activation must be one of"),
    "range bits negative": ("[train]\nrange_bits = -1.0\n" + DATASET, "[train] range_bits -1"),
    "unknown train device": ('[train]\ndevice = "tpu"\n' + DATASET, "[train] device must be auto, cpu, cuda"),
    "off-lattice out of range": ("[train]\noff_lattice = 1.0\n" + DATASET, "[train] off_lattice must be a fraction"),
    "learning rate beyond float32": ("[train]\nlearning_rate = 1e39\n" + DATASET,
                                     "[train] learning_rate must be a number the command line accepts"),
    "evaluation size 0": ("[evaluate]\nsize = 0\n" + DATASET, "[evaluate] size must be from 2 to 4096 pixels"),
    "evaluation ior out of range": ("[evaluate]\nior = -1.5\n" + DATASET, "[evaluate] ior must be 0 (no Fresnel)"),
    "evaluation views": ('[evaluate]\nviews = "1,2"\n' + DATASET, "[evaluate] views: each view is 'θ,φ,RU'"),
    "evaluation cache_dir": ('[evaluate]\ncache_dir = "x"\n' + DATASET, "[evaluate]: unknown key 'cache_dir'"),
    "unknown variant key": (DATASET + '[[variants]]\nname = "x"\nlearnrate = 1\n', "[[variants]] #1: unknown key"),
    "bad variant value": (DATASET + '[[variants]]\nname = "x"\n[[variants]]\nname = "y"\nbatch_size = 0\n',
                          "[train] epochs and [[variants]] #2 batch_size must be ≥ 1, got 6, 0"),
    "variants not tables": ("variants = [1, 2]\n" + DATASET, "[[variants]] #1 must be a table, got 1"),
    "variant name twice": (DATASET + '[[variants]]\nname = "x"\n[[variants]]\nname = "x"\n', "two variants share"),
    "variant's held-out slices": ('[groundtruth]\nslices = 5\n[train]\ntest_slices = "2"\n' + DATASET
                                  + '[[variants]]\nname = "x"\ntest_slices = "7"\n',
                                  "[[variants]] #1 test_slices 7 out of range for a 5-slice volume"),
    "grid option a string": ('[train]\ngrid_levels = "3"\n' + DATASET, "[train] grid_levels must be a whole number"),
    "bad grid option": ('[train]\narchitecture = "grid"\n' + DATASET + '[[variants]]\nname = "x"\ngrid_features = 99\n',
                        "[[variants]] #1 grid_features must be from 1 to 16, got 99"),
    "bench sizes": (DATASET + '[bench]\nsizes = "1"\n', "[bench] sizes must lie in 2 … 16384"),
    "bench exposure": (DATASET + "[bench]\nexposure = -1.0\n", "[bench] exposure must be a positive number"),
}


@pytest.mark.parametrize("case", sorted(BAD_FILES))
def test_bad_sweep_file_is_one_line_exit_2_before_any_work(tmp_path, capsys, case):
    """Exit status 2, one line that starts with the file's path and names the table and key, nothing written
    (no results folder, so no volume), and Ray never started."""
    text, message = BAD_FILES[case]
    path = _write(tmp_path, text)
    code = main(["sweep", path, "--out", str(tmp_path / "out"), "--quiet"])
    stderr = capsys.readouterr().err
    assert code == 2
    assert message in stderr
    assert len(stderr.strip().splitlines()) == 1, stderr
    assert stderr.startswith(f"gratnet sweep: error: {path}") or case == "not TOML", stderr
    assert not (tmp_path / "out").exists()
    assert sorted(item.name for item in tmp_path.iterdir()) == ["bad.toml"]


def test_the_reported_files_fail_before_the_ground_truth(tmp_path, capsys, monkeypatch):
    """Issue 36's files: a sweep that is valid but for [evaluate] size = 0 (or [train] epochs = -1) is refused
    before any task is submitted, with the TOML key, not the command-line flag, in its message."""
    from sweep import tasks

    def no_work(*_arguments: object) -> None:
        raise AssertionError("a ground truth was started")

    monkeypatch.setattr(tasks, "ground_truth", no_work)
    for bad, key in (("size = 32", "[evaluate] size"), ("epochs = 1", "[train] epochs")):
        broken = TINY.replace(bad, bad.split("=")[0] + ("= 0" if "size" in bad else "= -1"))
        assert broken != TINY
        code = main(["sweep", _write(tmp_path, broken), "--out", str(tmp_path / "out"), "--quiet"])
        stderr = capsys.readouterr().err
        assert code == 2 and key in stderr and "--" not in stderr.split(": error: ", 1)[1], stderr
        assert not (tmp_path / "out").exists()


def test_a_good_sweep_file_is_accepted_with_every_table(tmp_path):
    """The checks refuse bad values only: a file that sets every table loads, and its values arrive."""
    from sweep.spec import load_sweep

    text = TINY + '[bench]\nsizes = "64"\n[[variants]]\nname = "lr"\nlearning_rate = 1e-3\n'
    spec = load_sweep(_write(tmp_path, text), tmp_path / "out")
    assert [run.name for run in spec.runs][:2] == ["blazed-tiny-lr-s0", "blazed-tiny-lr-s1"]
    assert {run.train.learning_rate for run in spec.runs} == {1e-3}
    assert {run.evaluate.size for run in spec.runs} == {32}
    assert spec.bench.size_list() == [64]
    assert [dataset.parts for dataset in spec.datasets] == [1, 3]


def test_grid_options_are_keys_by_their_flags_names(tmp_path):
    """[train] and [[variants]] name the grid options as the flags do (grid_levels for --grid-levels); a variant's
    are set over [train]'s, into the run's nested TrainConfig.grid. A run recorded before the nesting (flat
    grid_* keys in run.json) is the same run, not another configuration's."""
    import json

    from sweep.spec import load_sweep
    from sweep.tasks import SPEC_FILE, run_folder, run_state
    from trainer.train_config import GridConfig

    text = (TINY.replace("epochs = 1\n", 'epochs = 1\narchitecture = "grid"\ngrid_features = 3\n')
            + '[[variants]]\nname = "g"\ngrid_levels = 2\ngrid_interpolation = "smoothstep"\n')
    spec = load_sweep(_write(tmp_path, text), tmp_path / "out")
    assert {run.train.grid for run in spec.runs} == {GridConfig(levels=2, features=3, interpolation="smoothstep")}
    run = spec.runs[0]
    recorded = json.loads(json.dumps(run.to_dict()))
    grid = recorded["train"].pop("grid")
    recorded["train"].update({f"grid_{key}": value for key, value in grid.items()})
    folder = run_folder(spec.out, run)
    folder.mkdir(parents=True)
    (folder / SPEC_FILE).write_text(json.dumps({"spec": recorded}))
    assert run_state(spec.out, run) == "todo"
    recorded["train"]["grid_levels"] = 3
    (folder / SPEC_FILE).write_text(json.dumps({"spec": recorded}))
    assert run_state(spec.out, run) == "conflict"


def test_a_folder_of_another_configuration_is_refused(swept, tmp_path, capsys):
    changed = TINY.replace("epochs = 1", "epochs = 2")
    code = main(["sweep", _write(tmp_path, changed), "--out", str(swept / "out"), "--quiet"])
    assert code == 2
    assert "made with a different configuration" in capsys.readouterr().err


def test_without_ray_only_the_sweep_itself_is_refused(tmp_path, capsys, monkeypatch):
    monkeypatch.setitem(sys.modules, "ray", None)  # import ray now raises ImportError
    path = _write(tmp_path, 'presets = ["tiny"]\n' + DATASET)
    assert main(["sweep", path, "--out", str(tmp_path / "out"), "--dry-run"]) == 0
    assert main(["sweep", path, "--out", str(tmp_path / "out")]) == 2
    stderr = capsys.readouterr().err
    assert "pip install 'gratnet[sweep]'" in stderr and len(stderr.strip().splitlines()) == 1
    assert not (tmp_path / "out").exists()


def test_bench_table_measures_every_finished_model(swept):
    """[bench]: gratnet bench's frame time against error, for the sweep's models (texture path, 16² frames)."""
    import dataclasses

    from bench.slices import BenchConfig
    from gratnet.errors import GratNetError
    from sweep.runner import collect_rows, run_bench
    from sweep.spec import load_sweep

    spec = load_sweep(swept / "tiny.toml", swept / "out")
    spec = dataclasses.replace(spec, bench=BenchConfig(sizes="16", weights_paths="texture", repeats=1,
                                                       torch_devices="cpu"))
    rows = collect_rows(spec)
    try:
        run_bench(spec, rows, progress=False)
    except GratNetError as error:
        pytest.skip(f"no headless OpenGL context: {error}")
    results = json.loads((swept / "out" / "bench" / "bench.json").read_text())
    assert sorted(result["model"] for result in results) == sorted(row["run"] for row in rows)
    assert all(result["flip_mean"] == next(row["flip_mean"] for row in rows if row["run"] == result["model"])
               for result in results)
    assert (swept / "out" / "bench" / "pareto.png").is_file()


def test_ground_truth_tasks_take_the_device_of_gpu_resources():
    """[resources] groundtruth_gpus > 0 runs the ground-truth tasks on CUDA (torch); the tasks take the device
    (here torch on the CPU, which the GPU path shares) and agree with numpy's part to float32 rounding."""
    from gratnet.errors import GratNetError
    from sweep.spec import Resources
    from sweep.tasks import volume_part
    from trainer.fourier import OpticsConfig, prepare_surface
    from trainer.generators import generate
    from trainer.groundtruth import VolumeConfig

    assert Resources().groundtruth_gpus == 0.0 and Resources(groundtruth_gpus=0.5).groundtruth_gpus == 0.5
    with pytest.raises(GratNetError, match="groundtruth_gpus must be a number ≥ 0"):
        Resources(groundtruth_gpus=-1.0)

    class Dataset:  # the fields volume_part reads
        volume = VolumeConfig(resolution=17, slices=3, sampling="simple-max")
        optics = OpticsConfig(sigma_s_um=3.0, wavelength_step_nm=40.0)
        parts = 2

    surface = prepare_surface(generate("blazed", size_um=10.0), Dataset.optics)
    numpy_part, nodes, _ = volume_part(Dataset, surface, 1)
    torch_part, torch_nodes, _ = volume_part(Dataset, surface, 1, "cpu")
    assert torch_nodes == nodes and np.max(numpy_part) > 0
    np.testing.assert_allclose(torch_part, numpy_part, rtol=0, atol=2e-6 * np.max(numpy_part))
