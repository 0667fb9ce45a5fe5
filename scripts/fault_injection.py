"""Fault injection (issue 36): ``kill -9`` of gratnet commands at seeded moments, and what each kill leaves.

    .venv/bin/python scripts/fault_injection.py --kills 10 --seed 1 --work out/faults --json out/faults.json

For each command on tiny inputs (``groundtruth``, ``train``, ``evaluate``, ``render``, ``mitsuba-render`` when
Mitsuba is installed, ``sweep`` when Ray is): run it once to the end (the reference, which also times it, T),
then K times in fresh folders, each killed with SIGKILL at a seeded moment after its start: [0.05 T, 0.95 T]
cut in K equal spans, kill k at a uniformly drawn place in span k (:func:`kill_moments`). After each kill:

- processes: no process of the command is alive 10 s later. Every process the command starts (Ray's local
  instance and workers included, whatever their process group) inherits an environment variable
  (:data:`TAG_VARIABLE`) with a value unique to that command, read back from ``/proc/PID/environ``, and its
  working folder (the command's own: a process that retitled itself has overwritten its environment);
- files: every file left in its folder loads as what it is (a volume with gratnet.volume.read_volume, a model
  with gratnet.modelfile.load_model, a checkpoint, an EXR or PNG image, JSON, CSV, ``.npy``), or is a
  temporary of gratnet.atomic (a hidden ``.NAME.HOST-PID-RANDOM.tmp.EXT`` or ``.NAME.EXT.HOST-PID.backup``;
  before issue 36's last change ``.NAME.RANDOM.tmp.EXT`` and ``.NAME.PID.backup``), which no command reads: a
  broken file is a finding; the rerun must have removed the killed writer's temporaries from the folders it
  writes in (those left after it are counted);
- the rerun: the same command (``train``: with ``--resume`` when a checkpoint was left) to the end; every output
  then equals the reference's, arrays bit for bit, JSON and tables with their timings (keys naming seconds, a
  render path's measured reason), the folder's own path and the sweep's task records left out.

With ``--signal INT`` the signal is SIGINT (Ctrl-C) instead, and each stopped command is also checked for exit
status 130, the seconds from the signal to its exit (the issue: 1 s) and one line on stderr after the signal.

The commands run in a fresh process with one thread (OMP_NUM_THREADS=1), so that the CPU results are
deterministic. tests/tools/test_faults_kill.py runs 2–3 kills per command; this script's larger run is recorded in
docs/robustness.md.
"""

from __future__ import annotations

import argparse
import csv
import dataclasses
import io
import json
import math
import os
import random
import re
import shutil
import signal
import subprocess
import sys
import time
import uuid
from collections.abc import Callable
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parents[1]
#: The environment variable whose value marks every process of one command (descendants inherit it).
TAG_VARIABLE = "GRATNET_FAULT_TAG"
#: Seconds a killed command's processes may take to go (the issue: a Ray process was alive 10 s after the kill).
GRACE_SECONDS = 10.0
#: Kill moments, as fractions of the uninterrupted run's duration.
MOMENTS = (0.05, 0.95)
#: gratnet.atomic's temporaries and backups, hidden files: ``.NAME.HOST-PID-RANDOM.tmp.EXT`` and
#: ``.NAME.EXT.HOST-PID.backup`` (gratnet.atomic.TEMPORARY_NAME), and the older ``.NAME.RANDOM.tmp.EXT`` and
#: ``.NAME.PID.backup``.
TEMPORARY = re.compile(r"^\..+(\.tmp(\.[A-Za-z0-9]+)?|\.([0-9a-f]{6}-)?\d+\.backup)$")
#: Folders of a sweep that only it reads: its task records (one file per task attempt; they differ by design).
RECORDS = "records"

#: The gratnet command as its console script runs it (main() without arguments: under gratnet.interrupts' supervisor).
_RUNNER = "import sys\nfrom gratnet.cli import main\nsys.exit(main())"

SWEEP_FILE = """\
presets = ["tiny"]
seeds = [0]

[groundtruth]
resolution = 33
slices = 5
sigma_s_um = 1.5
wavelength_step_nm = 100.0
parts = 2

[train]
epochs = 2
test_slices = "2"
batch_size = 256

[evaluate]
size = 16

[resources]
train_cpus = 1

[[datasets]]
generator = "blazed"
params = { size_um = 5.0 }
"""


@dataclasses.dataclass
class Case:
    """One command: its arguments (run in its own folder, outputs named relative to it) and its rerun's."""

    name: str
    arguments: list[str]
    rerun: Callable[[Path], list[str]] | None = None  # the rerun's arguments, from the killed folder's state
    needs: str | None = None  # a module the command needs (the case is skipped without it)


@dataclasses.dataclass
class Kill:
    """What one kill left and what its rerun gave."""

    case: str
    folder: str  # where it ran (its output folder)
    moment_s: float
    killed: bool  # False: the command ended before the moment came
    left: list[str]  # files (relative) present after the kill, temporaries included
    checked: int  # files that loaded as what they are
    temporaries: list[str]
    broken: list[str]  # 'PATH: why' for every file that did not load
    survivors: list[str]  # 'PID COMMAND' of processes alive GRACE_SECONDS after the kill
    gone_after_s: float  # seconds until the last process of the command was gone
    rerun_status: int | None = None
    rerun_arguments: list[str] = dataclasses.field(default_factory=list)
    differences: list[str] = dataclasses.field(default_factory=list)
    compared: int = 0  # output files compared with the reference's after the rerun
    temporaries_after_rerun: list[str] = dataclasses.field(default_factory=list)  # the kill's, still there
    signal: str = "SIGKILL"  # what was sent
    exit_status: int | None = None  # the command's own (SIGINT: 130 expected when it was stopped)
    stop_s: float | None = None  # seconds from the signal to the command's exit
    lines: list[str] = dataclasses.field(default_factory=list)  # stderr after the signal, as a terminal shows it

    @property
    def ok(self) -> bool:
        return not (self.broken or self.survivors or self.differences) and self.rerun_status == 0


# --------------------------------------------------------------------------------------------------
# Processes


def environment(tag: str) -> dict[str, str]:
    """The command's environment: one thread everywhere, the repository on the path, and its tag."""
    return {**os.environ, "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1",
            "RAY_USAGE_STATS_ENABLED": "0", TAG_VARIABLE: tag,
            "PYTHONPATH": os.pathsep.join(filter(None, [str(REPO), os.environ.get("PYTHONPATH")]))}


def start(arguments: list[str], folder: Path, tag: str) -> subprocess.Popen:
    """``gratnet ARGUMENTS`` in ``folder``, in a session of its own, output to folder/../NAME.log."""
    log = open(folder.with_name(folder.name + ".log"), "ab")  # noqa: SIM115 - handed to the child
    try:
        return subprocess.Popen([sys.executable, "-c", _RUNNER, *arguments], cwd=folder, env=environment(tag),
                                stdin=subprocess.DEVNULL, stdout=log, stderr=log, start_new_session=True)
    finally:
        log.close()


def tagged_processes(tag: str, folder: Path) -> dict[int, str]:
    """PID → command line of every live process of the command: its environment holds ``TAG_VARIABLE=tag``, or
    its working folder is the command's ``folder`` (or in it). The second catches processes that overwrote
    their environment (setproctitle does, for titles such as ``ray::DashboardAgent``). Zombies have neither."""
    needle = f"{TAG_VARIABLE}={tag}".encode()
    inside = str(folder.resolve())
    found: dict[int, str] = {}
    for entry in os.scandir("/proc"):
        if not entry.name.isdigit() or int(entry.name) == os.getpid():
            continue
        try:
            with open(f"/proc/{entry.name}/environ", "rb") as handle:
                variables = handle.read().split(b"\0")
            if needle not in variables:
                where = os.readlink(f"/proc/{entry.name}/cwd")
                if where != inside and not where.startswith(inside + os.sep):
                    continue
            with open(f"/proc/{entry.name}/cmdline", "rb") as handle:
                command = handle.read().replace(b"\0", b" ").decode(errors="replace").strip()
        except OSError:
            continue
        found[int(entry.name)] = command[:120]
    return found


def wait_until_gone(tag: str, folder: Path, grace: float = GRACE_SECONDS) -> tuple[float, dict[int, str]]:
    """Seconds until no process of the command (``tag``, ``folder``) is left (up to ``grace``), and those still
    alive then — which are then killed (SIGKILL), so that nothing outlives the check."""
    started = time.monotonic()
    alive = tagged_processes(tag, folder)
    while alive and time.monotonic() - started < grace:
        time.sleep(0.1)
        alive = tagged_processes(tag, folder)
    elapsed = time.monotonic() - started
    for pid in alive:
        try:
            os.kill(pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
    return elapsed, alive


def run_to_end(arguments: list[str], folder: Path, timeout: float = 600.0) -> tuple[int, float]:
    """Run the command to its end; its exit status and wall time (its processes are checked gone)."""
    tag = uuid.uuid4().hex
    began = time.monotonic()
    process = start(arguments, folder, tag)
    try:
        status = process.wait(timeout=timeout)
    finally:
        if process.poll() is None:
            process.kill()
            process.wait()
        wait_until_gone(tag, folder)
    return status, time.monotonic() - began


# --------------------------------------------------------------------------------------------------
# Files: loaded as what they are, compared with normalised timings


def _timing_key(key: str) -> bool:
    # A model file's size follows the training times its metadata records (a few bytes between reruns), and so
    # does the cost summary that states it (gratnet.cost).
    return "second" in key or key in ("reason", "created", "bytes_on_disk", "summary")


def normalise(value: Any, folder: str) -> Any:
    """A JSON value without timings, and with the folder's own path written as <FOLDER>."""
    if isinstance(value, dict):
        return {key: normalise(item, folder) for key, item in value.items() if not _timing_key(str(key))}
    if isinstance(value, list):
        return [normalise(item, folder) for item in value]
    if isinstance(value, str):
        return value.replace(folder, "<FOLDER>")
    if isinstance(value, float) and math.isnan(value):
        return "nan"
    return value


def _exr_channels(path: Path) -> dict[str, Any]:
    import OpenEXR

    with OpenEXR.File(str(path), separate_channels=True) as exr:
        return {f"{index}:{name}": channel.pixels.copy() for index, part in enumerate(exr.parts)
                for name, channel in part.channels.items()}


def load(path: Path) -> tuple[str, Any]:
    """``path`` read as what its name says it is: (kind, contents for comparison); raises when it is broken."""
    import numpy as np

    suffix = path.suffix.lower()
    if suffix == ".exr":
        from gratnet.volume import read_volume

        if path.stem.startswith("render"):  # the cases' renders: R, G, B channels
            return "EXR image", _exr_channels(path)
        volume = read_volume(path)
        return "volume", {"xyz": volume.xyz, "metadata": volume.metadata}
    if suffix == ".npz":
        from gratnet.modelfile import load_model

        metadata = load_model(path).metadata
        with np.load(path, allow_pickle=False) as archive:
            arrays = {name: archive[name] for name in archive.files if name != "metadata_json"}
        return "model", {"arrays": arrays, "metadata": metadata}
    if suffix == ".pt":
        from trainer.train import read_checkpoint

        return "checkpoint", read_checkpoint(path)
    if suffix == ".png":
        from PIL import Image

        with Image.open(path) as image:
            image.load()
            return "PNG image", np.asarray(image)
    if suffix == ".npy":
        return "array", np.load(path, allow_pickle=False)
    if suffix == ".json":
        return "JSON", json.loads(path.read_text(encoding="utf-8"))
    if suffix == ".csv":
        return "CSV", list(csv.DictReader(io.StringIO(path.read_text(encoding="utf-8"))))
    if suffix in (".md", ".txt", ".toml", ".log"):
        return "text", path.read_text(encoding="utf-8")
    raise ValueError(f"no reader for {suffix or 'files without a suffix'}")


#: A model file's size in a report's cost line (it follows the recorded training times: _timing_key).
_DISK_SIZE = re.compile(r"[0-9.,]+ MB on disk")


def _markdown_without_timings(text: str) -> list[list[str]]:
    """The lines of a markdown text, table cells split, with the columns whose header names seconds left out."""
    lines: list[list[str]] = []
    dropped: set[int] = set()
    for line in text.splitlines():
        if line.startswith("|"):
            cells = [cell.strip() for cell in line.strip("|").split("|")]
            if not line.startswith("|-") and not set(line) <= set("|- :"):
                header = [index for index, cell in enumerate(cells) if "(s)" in cell or "second" in cell]
                if header and not dropped:
                    dropped = set(header)
            lines.append([cell for index, cell in enumerate(cells) if index not in dropped])
        else:
            dropped = set()
            lines.append([_DISK_SIZE.sub("<size> MB on disk", line)])
    return lines


def same(kind: str, mine: Any, theirs: Any, mine_folder: str, their_folder: str) -> str | None:
    """None when the two contents are equal (bit for bit for arrays, timings left out), else why not."""
    import numpy as np

    def equal(a: Any, b: Any, where: str) -> str | None:
        if hasattr(a, "dtype") and hasattr(a, "shape"):  # numpy arrays and torch tensors
            a_array = a.numpy() if hasattr(a, "numpy") else a
            b_array = b.numpy() if hasattr(b, "numpy") else b
            if np.shape(a_array) != np.shape(b_array) or not np.array_equal(a_array, b_array, equal_nan=True):
                return f"{where}: arrays differ"
            return None
        if isinstance(a, dict) and isinstance(b, dict):
            keys = {k for k in a if not _timing_key(str(k))}, {k for k in b if not _timing_key(str(k))}
            if keys[0] != keys[1]:
                return f"{where}: keys differ ({sorted(map(str, keys[0] ^ keys[1]))[:4]})"
            for key in sorted(keys[0], key=str):
                problem = equal(a[key], b[key], f"{where}.{key}")
                if problem:
                    return problem
            return None
        if isinstance(a, (list, tuple)) and isinstance(b, (list, tuple)):
            if len(a) != len(b):
                return f"{where}: lengths {len(a)} and {len(b)}"
            for index, (x, y) in enumerate(zip(a, b, strict=True)):
                problem = equal(x, y, f"{where}[{index}]")
                if problem:
                    return problem
            return None
        if normalise(a, mine_folder) != normalise(b, their_folder):
            return f"{where}: {str(a)[:60]!r} vs {str(b)[:60]!r}"
        return None

    if kind == "text":
        if _markdown_without_timings(mine.replace(mine_folder, "<FOLDER>")) != \
                _markdown_without_timings(theirs.replace(their_folder, "<FOLDER>")):
            return "text differs"
        return None
    if kind == "CSV":
        strip = [[{k: v for k, v in row.items() if not _timing_key(k)} for row in rows] for rows in (mine, theirs)]
        return equal(strip[0], strip[1], "rows")
    return equal(mine, theirs, "")


def inventory(folder: Path) -> list[Path]:
    """Every file under ``folder`` (hidden ones included), relative, sorted."""
    return sorted(path.relative_to(folder) for path in folder.rglob("*") if path.is_file())


def check_files(folder: Path) -> tuple[dict[Path, tuple[str, Any]], list[str], list[str]]:
    """Every file left in ``folder``: {path: (kind, contents)} of those that load, the temporaries, and
    'PATH: why' of the broken ones."""
    loaded: dict[Path, tuple[str, Any]] = {}
    temporaries: list[str] = []
    broken: list[str] = []
    for relative in inventory(folder):
        if TEMPORARY.match(relative.name):
            temporaries.append(str(relative))
            continue
        try:
            loaded[relative] = load(folder / relative)
        except Exception as error:  # noqa: BLE001 - any failure to read is the finding
            first = str(error).splitlines()[0][:160] if str(error).strip() else ""
            broken.append(f"{relative}: {type(error).__name__}: {first}")
    return loaded, temporaries, broken


def compare(folder: Path, reference: Path, loaded: dict[Path, tuple[str, Any]] | None = None) -> tuple[int, list[str]]:
    """(files compared, differences) between ``folder``'s outputs and ``reference``'s; temporaries and task
    records are not outputs."""
    if loaded is None:
        loaded, _, broken = check_files(folder)
        if broken:
            return 0, [f"broken after the rerun: {item}" for item in broken]
    theirs, _, _ = check_files(reference)

    def outputs(files: dict[Path, Any]) -> set[Path]:
        return {path for path in files if RECORDS not in path.parts}

    differences = [f"only after the kill and rerun: {path}" for path in sorted(outputs(loaded) - outputs(theirs))]
    differences += [f"missing after the kill and rerun: {path}" for path in sorted(outputs(theirs) - outputs(loaded))]
    compared = 0
    for path in sorted(outputs(loaded) & outputs(theirs)):
        (kind, mine), (their_kind, reference_contents) = loaded[path], theirs[path]
        compared += 1
        problem = (f"kinds {kind} and {their_kind}" if kind != their_kind
                   else same(kind, mine, reference_contents, str(folder.resolve()), str(reference.resolve())))
        if problem:
            differences.append(f"{path}: {problem}")
    return compared, differences


# --------------------------------------------------------------------------------------------------
# The cases


def _train_rerun(arguments: list[str]) -> Callable[[Path], list[str]]:
    def rerun(folder: Path) -> list[str]:
        return arguments + (["--resume"] if (folder / "checkpoint.pt").is_file() else [])

    return rerun


def has_module(name: str) -> bool:
    import importlib.util

    return importlib.util.find_spec(name) is not None


def make_cases(inputs: Path) -> list[Case]:
    """The commands on tiny inputs; ``inputs`` receives the shared ones (volume and model: made by the
    groundtruth and train cases' references, which therefore run first)."""
    volume, model = str(inputs / "volume.exr"), str(inputs / "model.npz")
    train = ["train", volume, "--out", ".", "--preset", "tiny", "--epochs", "3", "--batch-size", "256",
             "--test-slices", "2", "--seed", "1", "--device", "cpu", "--size", "16", "--cache-dir", "cache", "--quiet"]
    (inputs / "sweep.toml").write_text(SWEEP_FILE, encoding="utf-8")
    return [
        Case("groundtruth", ["groundtruth", "generator:blazed(size_um=5.0)", "--res", "33", "--slices", "5",
                             "--sigma-s", "1.5", "--wavelength-step-nm", "50", "--out", "volume.exr", "--preview",
                             "volume.png", "--quiet"]),
        Case("train", train, _train_rerun(train)),
        Case("evaluate", ["evaluate", model, "--volume", volume, "--out", ".", "--size", "16", "--cache-dir", "cache",
                          "--quiet"]),
        Case("render", ["render", "--material", model, "--mesh", "cd", "--size", "64,64", "--spp", "2",
                        "--weights-path", "texture", "--render-path", "forward", "--out", "render.exr", "--quiet"]),
        Case("mitsuba-render", ["mitsuba-render", "--material", model, "--mesh", "plane", "--size", "32,32", "--spp",
                                "4", "--seed", "0", "--out", "render.png", "--quiet"], needs="mitsuba"),
        Case("sweep", ["sweep", str(inputs / "sweep.toml"), "--out", "out", "--workers", "2", "--quiet"],
             needs="ray"),
    ]


def _share_inputs(case: Case, reference: Path, inputs: Path) -> None:
    """The groundtruth reference's volume and the train reference's model become the later cases' inputs."""
    if case.name == "groundtruth":
        shutil.copy2(reference / "volume.exr", inputs / "volume.exr")
        shutil.copy2(reference / "volume.config.json", inputs / "volume.config.json")
    elif case.name == "train":
        shutil.copy2(reference / "model.npz", inputs / "model.npz")
        shutil.copy2(reference / "history.json", inputs / "history.json")


def visible_lines(text: str) -> list[str]:
    """The lines a terminal would show: each line's text after its last carriage return (a progress bar redrawn
    with \\r), blank ones left out."""
    return [line.rsplit("\r", 1)[-1] for line in text.split("\n") if line.rsplit("\r", 1)[-1].strip()]


def kill_once(case: Case, folder: Path, moment: float, reference: Path, number: int = signal.SIGKILL) -> Kill:
    """Start the command in ``folder``, send it ``number`` (SIGKILL; or SIGINT, Ctrl-C) ``moment`` seconds later,
    check, rerun, compare."""
    folder.mkdir(parents=True)
    log = folder.with_name(folder.name + ".log")
    tag = uuid.uuid4().hex
    process = start(case.arguments, folder, tag)
    deadline = time.monotonic() + moment
    while process.poll() is None and time.monotonic() < deadline:
        time.sleep(0.005)
    killed = process.poll() is None
    offset = log.stat().st_size if log.exists() else 0
    sent = time.monotonic()
    if killed:
        os.kill(process.pid, number)
    status = process.wait()
    stop_s = time.monotonic() - sent
    gone_after, survivors = wait_until_gone(tag, folder)
    left = [str(path) for path in inventory(folder)]
    loaded, temporaries, broken = check_files(folder)
    result = Kill(case.name, str(folder), round(moment, 3), killed, left, len(loaded), temporaries, broken,
                  [f"{pid} {command}" for pid, command in sorted(survivors.items())], round(gone_after, 2))
    result.signal = signal.Signals(number).name
    result.exit_status = status
    if killed:
        result.stop_s = round(stop_s, 3)
        with open(log, "rb") as handle:
            handle.seek(offset)
            result.lines = visible_lines(handle.read().decode("utf-8", "replace"))
    arguments = case.rerun(folder) if case.rerun else case.arguments
    result.rerun_arguments = arguments[len(case.arguments):]
    result.rerun_status, _ = run_to_end(arguments, folder)
    result.temporaries_after_rerun = [name for name in temporaries if (folder / name).exists()]
    if result.rerun_status == 0:
        result.compared, result.differences = compare(folder, reference)
    else:
        result.differences = [f"the rerun exited with status {result.rerun_status} (log: {folder}.log)"]
    return result


def run_reference(case: Case, work: Path, inputs: Path, control: bool = False) -> tuple[float, list[str]]:
    """The uninterrupted command in WORK/CASE/reference: its duration T (its outputs become later cases' inputs),
    and with ``control`` the differences between it and a first uninterrupted run (WORK/CASE/control), which
    should be none (the comparison can tell runs apart only if uninterrupted ones agree); that first run also
    fills the caches a first run fills (Mesa's shader cache), so that T is a warm run's."""
    differences: list[str] = []
    folders = (["control"] if control else []) + ["reference"]
    for name in folders:
        folder = work / case.name / name
        folder.mkdir(parents=True)
        status, duration = run_to_end(case.arguments, folder)
        if status != 0:
            raise RuntimeError(f"{case.name}: the uninterrupted command exited with status {status} "
                               f"(log: {folder}.log)")
    if control:
        compared, differences = compare(work / case.name / "reference", work / case.name / "control")
        if not compared:
            differences.append("nothing to compare")
    _share_inputs(case, work / case.name / "reference", inputs)
    return duration, differences


def kill_moments(case: Case, duration: float, kills: int, seed: int) -> list[float]:
    """[0.05 T, 0.95 T] cut in ``kills`` equal spans, one seeded moment in each (a few kills cover the whole run:
    start-up, computation, writing)."""
    rng = random.Random(f"{seed}:{case.name}")
    low, high = MOMENTS
    return [(low + (high - low) * (index + rng.random()) / kills) * duration for index in range(kills)]


def kill_runs(case: Case, work: Path, duration: float, kills: int, seed: int,
              number: int = signal.SIGKILL) -> list[Kill]:
    """``kills`` killed runs of ``case`` in WORK/CASE/killK (SIGINT: intK), each checked, rerun and compared with
    the reference."""
    prefix = "int" if number == signal.SIGINT else "kill"
    return [kill_once(case, work / case.name / f"{prefix}{index}", moment, work / case.name / "reference", number)
            for index, moment in enumerate(kill_moments(case, duration, kills, seed))]


def run_all(work: Path, kills: int, seed: int, names: list[str] | None = None, control: bool = True,
            report: Callable[[str], None] = print, number: int = signal.SIGKILL) -> dict[str, Any]:
    """Every case (or those named) with ``kills`` kills each (``number``: SIGKILL, or SIGINT for Ctrl-C; and a
    control run each); a JSON-ready summary."""
    inputs = work / "inputs"
    inputs.mkdir(parents=True, exist_ok=True)
    summary: dict[str, Any] = {"seed": seed, "kills_per_command": kills, "signal": signal.Signals(number).name,
                               "commands": {}}
    started = time.monotonic()
    for case in make_cases(inputs):
        if names and case.name not in names:
            continue
        if case.needs and not has_module(case.needs):
            summary["commands"][case.name] = {"skipped": f"{case.needs} is not installed"}
            report(f"{case.name}: skipped ({case.needs} is not installed)")
            continue
        duration, control_differences = run_reference(case, work, inputs, control)
        if control:
            report(f"{case.name}: two uninterrupted runs: {len(control_differences)} outputs differ "
                   f"{control_differences[:3]}")
        results = kill_runs(case, work, duration, kills, seed, number)
        summary["commands"][case.name] = {"uninterrupted_s": round(duration, 2), "control": control_differences
                                          if control else None,
                                          "kills": [dataclasses.asdict(result) for result in results]}
        for result in results:
            state = "ok" if result.ok else "FAILED"
            flags = " ".join(["rerun", *result.rerun_arguments])
            report(f"{case.name}: kill at {result.moment_s:6.2f} s of {duration:.1f} s "
                   f"({'killed' if result.killed else 'had ended'}): {len(result.left)} files left, "
                   f"{result.checked} load, {len(result.temporaries)} temporaries "
                   f"({len(result.temporaries_after_rerun)} left after the rerun), {len(result.broken)} broken; "
                   f"processes gone after {result.gone_after_s} s, {len(result.survivors)} alive at "
                   f"{GRACE_SECONDS:g} s; {flags}: {result.compared} outputs compared, "
                   f"{len(result.differences)} differ: {state}")
            if result.signal != "SIGKILL" and result.killed:
                report(f"    {result.signal}: exit {result.exit_status} after {result.stop_s} s; {result.lines}")
            for line in result.broken + result.survivors + result.differences:
                report(f"    {line}")
    every = [kill for entry in summary["commands"].values() for kill in entry.get("kills", [])]
    summary["totals"] = {
        "faults_injected": sum(kill["killed"] for kill in every),
        "runs": len(every),
        "files_checked_after_kills": sum(kill["checked"] for kill in every),
        "temporaries_left": sum(len(kill["temporaries"]) for kill in every),
        "temporaries_left_after_reruns": sum(len(kill.get("temporaries_after_rerun", [])) for kill in every),
        "broken_files": sum(len(kill["broken"]) for kill in every),
        "processes_alive_after_grace": sum(len(kill["survivors"]) for kill in every),
        "outputs_compared_after_reruns": sum(kill["compared"] for kill in every),
        "outputs_differing": sum(len(kill["differences"]) for kill in every),
        "control_runs_differing": sum(bool(entry.get("control")) for entry in summary["commands"].values()),
        "seconds": round(time.monotonic() - started, 1),
    }
    if number != signal.SIGKILL:  # Ctrl-C: exit 130, within a second, one line (issue 36)
        stopped = [kill for kill in every if kill["killed"]]
        summary["totals"].update({
            "exit_not_130": sum(kill["exit_status"] != 130 for kill in stopped),
            "stopped_after_more_than_1_s": sum(kill["stop_s"] > 1.0 for kill in stopped),
            "slowest_stop_s": max((kill["stop_s"] for kill in stopped), default=None),
            "not_one_line": sum(len(kill["lines"]) != 1 for kill in stopped),
        })
    return summary


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--kills", type=int, default=10, help="kills per command (default 10)")
    parser.add_argument("--seed", type=int, default=1, help="seed of the kill moments (default 1)")
    parser.add_argument("--work", type=Path, default=Path("out/faults"), help="working folder (must not exist)")
    parser.add_argument("--commands", default="", help="comma-separated commands (default: all)")
    parser.add_argument("--json", type=Path, help="write the summary here")
    parser.add_argument("--signal", choices=("KILL", "INT"), default="KILL",
                        help="what is sent: SIGKILL (default), or SIGINT, Ctrl-C (then also checked: exit 130 within "
                             "1 s, one line on stderr)")
    parser.add_argument("--no-control", action="store_true",
                        help="no control run (a second uninterrupted run compared with the first) per command")
    arguments = parser.parse_args(argv)
    if arguments.work.exists():
        parser.error(f"--work {arguments.work} exists; give a new folder")
    names = [name.strip() for name in arguments.commands.split(",") if name.strip()] or None
    if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
        # Started in the background (`cmd &`): SIGINT is ignored, and the commands would inherit that across exec
        # and never see their Ctrl-C. A handled signal is reset to the default at exec instead.
        signal.signal(signal.SIGINT, signal.default_int_handler)
    summary = run_all(arguments.work.resolve(), arguments.kills, arguments.seed, names, not arguments.no_control,
                      number=signal.Signals[f"SIG{arguments.signal}"])
    text = json.dumps(summary, indent=1) + "\n"
    if arguments.json:
        arguments.json.write_text(text, encoding="utf-8")
    print(json.dumps(summary["totals"]))
    totals = summary["totals"]
    failed = ("broken_files", "processes_alive_after_grace", "outputs_differing", "control_runs_differing",
              "exit_not_130", "not_one_line")
    return 1 if any(totals.get(key) for key in failed) else 0


if __name__ == "__main__":
    sys.exit(main())
