"""Bad input through the real CLI (issue 5, "Bad input"): malformed or truncated height fields, volumes and
model files, a model file of another format version, no EGL and no display, unwritable outputs.

Every case must end with a non-zero exit status, exactly one line on stderr ("gratnet CMD: error: …", no
traceback), and nothing (not even a temporary file) at the destination.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from gratnet.cli import main
from gratnet.encoding import EncodingSpec, RangeSpec
from gratnet.modelfile import ModelFile, save_model
from gratnet.volume import Volume, write_volume

TINY_FIELD = ["--dx-um", "0.1", "--height-scale-um", "0.5"]


def run_cli(argv: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str]:
    code = main(argv)
    return code, capsys.readouterr().err


def assert_one_clear_error(code: int, stderr: str, command: str, *needles: str) -> None:
    lines = stderr.strip().splitlines()
    assert code != 0, stderr
    assert len(lines) == 1, stderr
    assert lines[0].startswith(f"gratnet {command}: error: "), stderr
    assert "Traceback" not in stderr
    for needle in needles:
        assert needle in lines[0], stderr


def assert_nothing_written(folder: Path, before: set[str]) -> None:
    """No new file in ``folder`` (atomic writers leave no ``.NAME.*.tmp*`` behind either)."""
    after = {path.name for path in folder.iterdir()} if folder.is_dir() else set()
    assert after <= before, sorted(after - before)


# --------------------------------------------------------------------------------------------------
# Height fields


def _npy_bytes(array: np.ndarray) -> bytes:
    import io

    buffer = io.BytesIO()
    np.save(buffer, array, allow_pickle=True)
    return buffer.getvalue()


def _npz_bytes(**arrays: object) -> bytes:
    import io

    buffer = io.BytesIO()
    np.savez(buffer, **arrays)
    return buffer.getvalue()


def _png_bytes() -> bytes:
    import io

    from PIL import Image

    buffer = io.BytesIO()
    Image.fromarray(np.arange(64, dtype=np.uint8).reshape(8, 8)).save(buffer, format="PNG")
    return buffer.getvalue()


def _exr_bytes(tmp_path: Path) -> bytes:
    import OpenEXR

    path = tmp_path / "source.exr"
    with OpenEXR.File({"type": OpenEXR.scanlineimage}, {"Y": np.ones((8, 8), np.float32)}) as exr:
        exr.write(str(path))
    data = path.read_bytes()
    path.unlink()
    return data


def _gsf_bytes(columns: int = 4, rows: int = 4, data: bytes | None = None, extra: str = "") -> bytes:
    header = f"Gwyddion Simple Field 1.0\nXRes = {columns}\nYRes = {rows}\nXReal = 4e-7\nYReal = 4e-7\n{extra}"
    encoded = header.encode()
    encoded += b"\0" * (4 - len(encoded) % 4)
    return encoded + (data if data is not None else np.zeros(columns * rows, "<f4").tobytes())


def _flip(data: bytes, fraction: float) -> bytes:
    index = int(len(data) * fraction)
    return data[:index] + bytes([data[index] ^ 0xFF]) + data[index + 1:]


HEIGHT_FIELDS: dict[str, tuple[str, Callable[[Path], bytes], str]] = {
    "npy empty": (".npy", lambda _: b"", "empty"),
    "npy header only": (".npy", lambda _: _npy_bytes(np.zeros((8, 8)))[:80], "npy"),
    "npy truncated data": (".npy", lambda _: _npy_bytes(np.zeros((8, 8)))[:-100], "npy"),
    "npy pickled objects": (".npy", lambda _: _npy_bytes(np.array([{"a": 1}], dtype=object)), "npy"),
    "npy 1-D": (".npy", lambda _: _npy_bytes(np.zeros(8)), "2-D"),
    "npy 3-D": (".npy", lambda _: _npy_bytes(np.zeros((2, 4, 4))), "2-D"),
    "npy one row": (".npy", lambda _: _npy_bytes(np.zeros((1, 8))), "degenerate"),
    "npy NaN": (".npy", lambda _: _npy_bytes(np.full((4, 4), np.nan)), "NaN"),
    "npy strings": (".npy", lambda _: _npy_bytes(np.full((4, 4), "a")), "real numbers"),
    "npy complex": (".npy", lambda _: _npy_bytes(np.zeros((4, 4), complex)), "real numbers"),
    "npy is a text file": (".npy", lambda _: b"1 2 3\n4 5 6\n", "npy"),
    "npz text": (".npz", lambda _: b"not a zip at all", "zip"),
    "npz truncated": (".npz", lambda _: _npz_bytes(heights_um=np.zeros((16, 16)), dx_um=0.1)[:300], "npz"),
    "npz corrupted": (".npz", lambda _: _flip(_npz_bytes(heights_um=np.zeros((16, 16)), dx_um=0.1), 0.5), "npz"),
    "npz without heights": (".npz", lambda _: _npz_bytes(other=np.zeros((4, 4))), "heights_um"),
    "npz pickled heights": (".npz", lambda _: _npz_bytes(heights_um=np.array([None, 1], dtype=object)), "npz"),
    "npz dx negative": (".npz", lambda _: _npz_bytes(heights_um=np.zeros((4, 4)), dx_um=-1.0), "dx"),
    "npz dx NaN": (".npz", lambda _: _npz_bytes(heights_um=np.zeros((4, 4)), dx_um=np.nan), "dx"),
    "npz dx vector": (".npz", lambda _: _npz_bytes(heights_um=np.zeros((4, 4)), dx_um=np.ones(2)), "dx_um"),
    "npz dx text": (".npz", lambda _: _npz_bytes(heights_um=np.zeros((4, 4)), dx_um="abc"), "dx"),
    "png truncated": (".png", lambda _: _png_bytes()[:40], "PNG"),
    "png corrupted": (".png", lambda _: _flip(_png_bytes(), 0.6), "PNG"),
    "png is text": (".png", lambda _: b"hello", "PNG"),
    "exr truncated": (".exr", lambda tmp: _exr_bytes(tmp)[:200], "EXR"),
    "exr is text": (".exr", lambda _: b"hello, world", "EXR"),
    "gsf no magic": (".gsf", lambda _: b"XRes = 4\n", "Gwyddion"),
    "gsf no NUL": (".gsf", lambda _: b"Gwyddion Simple Field 1.0\nXRes = 4\n", "NUL"),
    "gsf truncated data": (".gsf", lambda _: _gsf_bytes()[:-8], "truncated"),
    "gsf zero size": (".gsf", lambda _: _gsf_bytes(0, 4, b""), "XRes"),
    "gsf bad number": (".gsf", lambda _: _gsf_bytes(extra="XReal = abc\n"), "XReal"),
    "gsf huge size": (".gsf", lambda _: _gsf_bytes(10**9, 10**9, b""), "truncated"),
    "gsf NaN heights": (".gsf", lambda _: _gsf_bytes(data=np.full(16, np.nan, "<f4").tobytes()), "NaN"),
    "gsf bad unit": (".gsf", lambda _: _gsf_bytes(extra="ZUnits = furlong\n"), "ZUnits"),
}


@pytest.mark.parametrize("case", list(HEIGHT_FIELDS))
def test_bad_height_field_is_one_line_and_writes_nothing(tmp_path, capsys, case):
    suffix, make, needle = HEIGHT_FIELDS[case]
    source = tmp_path / f"field{suffix}"
    source.write_bytes(make(tmp_path))
    out = tmp_path / "out"
    out.mkdir()
    extra = TINY_FIELD if suffix in (".npy", ".png", ".exr") else []
    code, stderr = run_cli(["heightfield", "convert", str(source), *extra, "--out", str(out / "f.npz"),
                            "--preview", str(out / "f.png")], capsys)
    assert_one_clear_error(code, stderr, "heightfield", needle)
    assert_nothing_written(out, set())


# --------------------------------------------------------------------------------------------------
# Volumes


@pytest.fixture(scope="module")
def volume_bytes(tmp_path_factory) -> bytes:
    path = tmp_path_factory.mktemp("volume") / "v.exr"
    rng = np.random.default_rng(0)
    write_volume(path, Volume(rng.uniform(0, 1, (3, 9, 9, 3)).astype(np.float32),
                              {"scheme": "regular", "resolution": 9, "slices": 3, "slice_t": [0.0, 0.5, 1.0]}))
    return path.read_bytes()


VOLUMES: dict[str, Callable[[bytes, Path], bytes]] = {
    "empty": lambda data, _: b"",
    "text": lambda data, _: b"not an image" * 20,
    "truncated 10%": lambda data, _: data[: len(data) // 10],
    "truncated 60%": lambda data, _: data[: 6 * len(data) // 10],
    "last byte missing": lambda data, _: data[:-1],
    "pixels corrupted": lambda data, _: _flip(data, 0.97),
    "plain EXR image": lambda data, tmp: _exr_bytes(tmp),
}


@pytest.mark.parametrize("case", list(VOLUMES))
def test_bad_volume_is_one_line_and_writes_nothing(tmp_path, capsys, volume_bytes, case):
    source = tmp_path / "volume.exr"
    source.write_bytes(VOLUMES[case](volume_bytes, tmp_path))
    out = tmp_path / "run"
    code, stderr = run_cli(["train", str(source), "--out", str(out), "--epochs", "1", "--preset", "tiny",
                            "--quiet", "--no-evaluate"], capsys)
    assert_one_clear_error(code, stderr, "train", str(source))
    assert not out.exists()


# --------------------------------------------------------------------------------------------------
# Model files


@pytest.fixture(scope="module")
def model_path(tmp_path_factory) -> Path:
    spec = EncodingSpec(frequencies=1, t_frequencies=0)
    rng = np.random.default_rng(1)
    sizes = [spec.features, 5, 3]
    weights = [rng.standard_normal((o, i)).astype(np.float32) for i, o in zip(sizes, sizes[1:], strict=False)]
    biases = [np.zeros(o, np.float32) for o in sizes[1:]]
    model = ModelFile(sizes, weights, biases, "relu", "clamp", spec, RangeSpec(), "regular")
    path = tmp_path_factory.mktemp("model") / "model.npz"
    save_model(path, model)
    return path


def _rewrite(path: Path, change: Callable[[dict[str, np.ndarray]], None]) -> bytes:
    with np.load(path, allow_pickle=False) as archive:
        arrays = {name: archive[name] for name in archive.files}
    change(arrays)
    return _npz_bytes(**arrays)


def _set_header(arrays: dict[str, np.ndarray], **changes: object) -> None:
    header = json.loads(str(arrays["metadata_json"][()]))
    header.update(changes)
    arrays["metadata_json"] = np.array(json.dumps(header))


MODELS: dict[str, tuple[Callable[[Path], bytes], str]] = {
    "empty": (lambda path: b"", "model"),
    "text": (lambda path: b"weights = 1, 2, 3", "not an .npz"),
    "truncated": (lambda path: path.read_bytes()[: len(path.read_bytes()) // 2], "truncated or corrupt"),
    "last byte missing": (lambda path: path.read_bytes()[:-1], "truncated or corrupt"),
    "corrupted": (lambda path: _flip(path.read_bytes(), 0.5), "model"),
    "format version 2": (lambda path: _rewrite(path, lambda a: _set_header(a, format_version=2)), "version 2"),
    "format version 0.9": (lambda path: _rewrite(path, lambda a: _set_header(a, format_version=0.9)), "version"),
    "not a model": (lambda path: _rewrite(path, lambda a: _set_header(a, format="gratnet-volume")), "not a GratNet"),
    "missing bias": (lambda path: _rewrite(path, lambda a: a.pop("bias_0")), "bias_0"),
    "missing header": (lambda path: _rewrite(path, lambda a: a.pop("metadata_json")), "metadata_json"),
    "height field archive": (lambda path: _npz_bytes(heights_um=np.zeros((4, 4)), dx_um=0.1), "metadata_json"),
    "single npy": (lambda path: _npy_bytes(np.zeros((4, 4), np.float32)), ".npy"),
}


@pytest.mark.parametrize("case", list(MODELS))
def test_bad_model_file_is_one_line_and_writes_nothing(tmp_path, capsys, model_path, case):
    make, needle = MODELS[case]
    source = tmp_path / "bad.npz"
    source.write_bytes(make(model_path))
    out = tmp_path / "out"
    out.mkdir()
    code, stderr = run_cli(["render", "--material", str(source), "--size", "8,8", "--out", str(out / "x.png")],
                           capsys)
    assert_one_clear_error(code, stderr, "render", needle)
    assert_nothing_written(out, set())
    code, stderr = run_cli(["evaluate", str(source), "--out", str(out / "report")], capsys)
    assert_one_clear_error(code, stderr, "evaluate", needle)
    assert_nothing_written(out, set())


# --------------------------------------------------------------------------------------------------
# No EGL, no display (fresh processes: the GL libraries are loaded once per process)


def _gratnet(arguments: list[str], environment: dict[str, str], cwd: Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "gratnet.cli", *arguments], capture_output=True, text=True,
                          env=environment, cwd=cwd, timeout=300)


def test_missing_egl_and_missing_display_are_one_line_in_a_fresh_process(tmp_path):
    # libglvnd reads the EGL vendor list from this variable: a missing file leaves no EGL driver at all.
    environment = {key: value for key, value in os.environ.items() if key not in ("DISPLAY", "WAYLAND_DISPLAY")}
    environment["__EGL_VENDOR_LIBRARY_FILENAMES"] = str(tmp_path / "no-such-vendor.json")
    result = _gratnet(["render", "--size", "8,8", "--out", str(tmp_path / "x.png")], environment, tmp_path)
    assert_one_clear_error(result.returncode, result.stderr, "render", "EGL", "apt-get install")
    result = _gratnet(["view", "--mesh", "plane", "--size", "16,16", "--max-frames", "1"], environment, tmp_path)
    assert_one_clear_error(result.returncode, result.stderr, "view", "display")
    assert sorted(path.name for path in tmp_path.iterdir()) == []


# --------------------------------------------------------------------------------------------------
# Unwritable outputs (we run as root: permissions do not stop writes, so use paths that cannot exist)


def unwritable_targets(tmp_path: Path) -> dict[str, Path]:
    blocker = tmp_path / "a-file"
    blocker.write_text("in the way")
    folder = tmp_path / "a-folder"
    folder.mkdir()
    return {
        "parent is a file": blocker / "out",
        "in /proc": Path("/proc/gratnet-stress-test") / "out",
        "a folder in its place": folder / "out",
    }


@pytest.mark.parametrize("where", ["parent is a file", "in /proc", "a folder in its place"])
@pytest.mark.parametrize(
    "command",
    [
        ["heightfield", "generate", "sinusoidal", "--out", "{out}.npz"],
        ["heightfield", "generate", "sinusoidal", "--out", "{out}.gsf"],
        ["heightfield", "convert", "sinusoidal", "--out", "{out}.npz"],
        ["heightfield", "preview", "sinusoidal", "--out", "{out}.png"],
        ["groundtruth", "sinusoidal", "--res", "5", "--slices", "2", "--sigma-s", "0.5", "--quiet",
         "--wavelength-step-nm", "200", "--out", "{out}.exr"],
        ["train", "{volume}", "--epochs", "1", "--preset", "tiny", "--quiet", "--no-evaluate", "--out", "{out}"],
    ],
    ids=["generate-npz", "generate-gsf", "convert", "preview", "groundtruth", "train"],
)
def test_unwritable_output_is_one_line_and_leaves_nothing(tmp_path, capsys, volume_bytes, where, command):
    base = unwritable_targets(tmp_path)[where]
    volume = tmp_path / "volume.exr"
    volume.write_bytes(volume_bytes)
    argv = [part.format(out=base, volume=volume) for part in command]
    out = Path(argv[argv.index("--out") + 1])
    if where == "a folder in its place":
        if command[0] == "train":
            out.write_text("a file where the run folder should go")  # train's --out is itself a folder
        else:
            out.mkdir()
    parent = out.parent
    before = {path.name for path in parent.iterdir()} if parent.is_dir() else set()
    code, stderr = run_cli(argv, capsys)
    assert_one_clear_error(code, stderr, command[0])
    assert_nothing_written(parent, before)
    assert_nothing_written(tmp_path, {"a-file", "a-folder", "volume.exr"})
