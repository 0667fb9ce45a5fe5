"""Bad input through the real CLI (issue 5, "Bad input"; issue 11, "Bad input refused before work starts"):
malformed or truncated height fields, volumes and model files, a model file of another format version, no EGL
and no display, unwritable outputs found before any work, outputs that land together or not at all, numbers a
float32 shader cannot hold, negative values in comma lists, --quiet and --help in every subcommand.

Every case must end with exit status 2, exactly one line on stderr ("gratnet CMD: error: …", no traceback,
no usage dump), and nothing (not even a temporary file) at the destination.
"""

from __future__ import annotations

import importlib.util
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
from gratnet.quality import FAST
from gratnet.volume import Volume, write_volume
from tests.helpers import ASSETS, assert_nothing_written, assert_one_clear_error, flip_in_member, run_cli
from viewer.catalog import material_points, shipped_materials

# Imported here, unpatched: these modules bind viewer.catalog.resolve_material by name when first imported,
# and a first import inside a test that patches it (bench, view) would keep the patch for the whole worker.
importlib.import_module("viewer.scene_supply")
importlib.import_module("viewer.app")

TINY_FIELD = ["--dx-um", "0.1", "--height-scale-um", "0.5"]


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
    # In the member's data: the file's middle byte may fall in a zip header's spare field, which no reader checks.
    "corrupted": (lambda path: flip_in_member(path, "weight_0.npy", mask=0xFF), "model"),
    "format version 3": (lambda path: _rewrite(path, lambda a: _set_header(a, format_version=3)), "version 3"),
    "version 2 without grids": (lambda path: _rewrite(path, lambda a: _set_header(a, format_version=2)), "grid"),
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


# --------------------------------------------------------------------------------------------------
# Issue 11: outputs are checked before any work, in every subcommand that writes

RENDER = ["render", "--size", "8,8", "--weights-path", "texture", "--quiet"]
MITSUBA = ["mitsuba-render", "--size", "8,8", "--spp", "1", "--quiet"]
needs_mitsuba = pytest.mark.skipif(importlib.util.find_spec("mitsuba") is None,
                                   reason="the mitsuba extra is not installed (pip install -e '.[mitsuba]')")


def with_mitsuba_marked(cases: list[str]) -> list[object]:
    """Parameters for ``cases``: those of ``gratnet mitsuba-render`` skipped where Mitsuba is not installed."""
    return [pytest.param(case, marks=needs_mitsuba) if case.startswith("mitsuba-render") else case for case in cases]


# (argv with {out}, the heavy step that must not start, is the output a folder)
WRITERS: dict[str, tuple[list[str], str, bool]] = {
    "render": ([*RENDER, "--out", "{out}.png"], "gratnet.modelfile.load_model", False),
    "render exr": ([*RENDER, "--out", "{out}.exr"], "gratnet.modelfile.load_model", False),
    "brdfslice": (["brdfslice", "blazed", "--quiet", "--out", "{out}.png"], "trainer.cli_support.load_heightfield",
                  False),
    # The paper's grid (--res 1001): hours of work if the check came after it.
    "groundtruth": (["groundtruth", "blazed", "--quiet", "--out", "{out}.exr"], "trainer.cli_support.load_heightfield",
                    False),
    "groundtruth preview": (["groundtruth", "blazed", "--quiet", "--out", "ok.exr", "--preview", "{out}.png"],
                            "trainer.cli_support.load_heightfield", False),
    "heightfield convert": (["heightfield", "convert", "blazed", "--out", "{out}.npz"],
                            "trainer.heightfield_cli.load_heightfield", False),
    "heightfield convert preview": (["heightfield", "convert", "blazed", "--out", "ok.npz", "--preview", "{out}.png"],
                                    "trainer.heightfield_cli.load_heightfield", False),
    "heightfield preview": (["heightfield", "preview", "blazed", "--out", "{out}.png"],
                            "trainer.heightfield_cli.load_heightfield", False),
    "train": (["train", "{volume}", "--quiet", "--out", "{out}"], "gratnet.volume.read_volume", True),
    "evaluate": (["evaluate", "{model}", "--quiet", "--out", "{out}"], "gratnet.modelfile.load_model", True),
    "bench": (["bench", "--quiet", "--out", "{out}"], "viewer.catalog.resolve_material", True),
    "view screenshots": (["view", "--screenshot-dir", "{out}", "--max-frames", "1"],
                         "viewer.catalog.resolve_material", True),
    "mitsuba-render": ([*MITSUBA, "--out", "{out}.png"], "gratnet.modelfile.load_model", False),
    "mitsuba-render exr": ([*MITSUBA, "--out", "{out}.exr"], "gratnet.modelfile.load_model", False),
}

WHERE_NEEDLES = {"parent is a file": "a-file is a file, not a folder", "in /proc": "not writable",
                 "a folder in its place": "folder"}


@pytest.mark.parametrize("where", list(WHERE_NEEDLES))
@pytest.mark.parametrize("writer", with_mitsuba_marked(list(WRITERS)))
def test_unwritable_output_is_refused_before_any_work(tmp_path, capsys, monkeypatch, model_path, writer, where):
    argv_template, heavy_step, is_folder = WRITERS[writer]

    def work_started(*arguments: object, **keywords: object) -> None:
        raise AssertionError(f"{heavy_step} ran before the output was checked")

    monkeypatch.setattr(heavy_step, work_started)
    monkeypatch.chdir(tmp_path)
    base = unwritable_targets(tmp_path)[where]
    argv = [part.format(out=base, volume=tmp_path / "v.exr", model=model_path) for part in argv_template]
    out = Path(next(part for part in argv if str(base) in part))
    if where == "a folder in its place":
        if is_folder:
            out.write_text("a file where the output folder should go")
        else:
            out.mkdir()
    code, stderr = run_cli(argv, capsys)
    needle = "it is a file, not a folder" if (where == "a folder in its place" and is_folder) else WHERE_NEEDLES[where]
    assert_one_clear_error(code, stderr, argv[0], needle, str(out))
    assert "File exists" not in stderr  # the OS's words for mkdir under a file; the cause is "Not a directory"
    assert_nothing_written(tmp_path, {"a-file", "a-folder"})


@pytest.mark.parametrize("command", with_mitsuba_marked(["render", "mitsuba-render"]))
def test_a_config_that_cannot_be_written_is_found_before_rendering(tmp_path, capsys, monkeypatch, command):
    monkeypatch.setattr("gratnet.modelfile.load_model", lambda *a, **k: pytest.fail("rendering started"))
    (tmp_path / "x.config.json").mkdir()
    code, stderr = run_cli([*(RENDER if command == "render" else MITSUBA), "--out", str(tmp_path / "x.png")], capsys)
    assert_one_clear_error(code, stderr, command, "x.config.json", "folder")
    assert_nothing_written(tmp_path, {"x.config.json"})


@pytest.mark.parametrize("name", ["", "   "])
def test_an_empty_output_name_is_refused(tmp_path, capsys, monkeypatch, name):
    monkeypatch.chdir(tmp_path)
    for argv, command in (([*RENDER, "--out", name], "render"), (["train", "v.exr", "--out", name], "train"),
                          (["bench", "--out", name], "bench"), ([*MITSUBA, "--out", name], "mitsuba-render")):
        code, stderr = run_cli(argv, capsys)
        assert_one_clear_error(code, stderr, command)
    assert_nothing_written(tmp_path, set())


def test_output_path_with_spaces_and_unicode_is_written(tmp_path, capsys):
    out = tmp_path / "a folder ä 画" / "slice one.png"
    code, stderr = run_cli([*RENDER, "--slice", "--out", str(out)], capsys)
    assert code == 0, stderr
    assert sorted(path.name for path in out.parent.iterdir()) == ["slice one.config.json", "slice one.png"]


# --------------------------------------------------------------------------------------------------
# Issue 11: outputs that belong together land together or not at all


def test_atomic_paths_rolls_back_every_output_when_one_rename_fails(tmp_path, monkeypatch):
    from gratnet import atomic

    image, config = tmp_path / "x.png", tmp_path / "x.config.json"
    image.write_text("old image")
    config.write_text("old config")
    real_replace = os.replace

    def replace(source: object, target: object) -> None:
        if Path(target) == config:
            raise OSError(28, "No space left on device")
        real_replace(source, target)

    monkeypatch.setattr(atomic.os, "replace", replace)
    with pytest.raises(atomic.GratNetError, match="x.config.json: No space left"):
        with atomic.atomic_paths(image, config) as (image_temporary, config_temporary):
            image_temporary.write_text("new image")
            config_temporary.write_text("new config")
    # The first output, already renamed, was put back; no temporary or backup is left.
    assert image.read_text() == "old image" and config.read_text() == "old config"
    assert sorted(path.name for path in tmp_path.iterdir()) == ["x.config.json", "x.png"]


def test_atomic_paths_leaves_nothing_when_the_writer_fails(tmp_path):
    from gratnet import atomic

    with pytest.raises(RuntimeError), atomic.atomic_paths(tmp_path / "a.png", tmp_path / "a.config.json") as paths:
        paths[0].write_text("half")
        raise RuntimeError("the encoder failed")
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("command", with_mitsuba_marked(["render", "mitsuba-render"]))
def test_render_leaves_no_image_when_its_config_cannot_be_written(tmp_path, capsys, monkeypatch, command):
    # The config's text fails after the image is encoded: neither lands (it used to leave the image behind).
    import gratnet.config

    def broken(*arguments: object, **keywords: object) -> str:
        raise OSError(5, "I/O error")

    monkeypatch.setattr(gratnet.config, "config_text", broken)
    argv = [*RENDER, "--slice"] if command == "render" else [*MITSUBA, "--mesh", "plane"]
    code, stderr = run_cli([*argv, "--out", str(tmp_path / "x.png")], capsys)
    assert_one_clear_error(code, stderr, command, "x.png", "I/O error")
    assert_nothing_written(tmp_path, set())


def test_heightfield_field_config_and_preview_land_together(tmp_path, capsys, monkeypatch):
    import trainer.heightfield_cli as cli_module

    def failing_preview(field: object, path: object) -> None:
        raise cli_module.GratNetError("the preview could not be drawn")

    monkeypatch.setattr(cli_module, "preview_png", failing_preview)
    code, stderr = run_cli(["heightfield", "generate", "blazed", "--out", str(tmp_path / "f.npz"), "--preview",
                            str(tmp_path / "f.png")], capsys)
    assert_one_clear_error(code, stderr, "heightfield", "preview could not be drawn")
    assert_nothing_written(tmp_path, set())


# --------------------------------------------------------------------------------------------------
# Issue 11: numbers a float32 shader cannot hold, and other bad numbers, refused with one line

NUMBERS: dict[str, tuple[list[str], str]] = {
    "render exposure 1e39": ([*RENDER, "--exposure", "1e39"], "float32"),
    "render spp 0": ([*RENDER, "--spp", "0"], "--spp"),
    "render spp -1": ([*RENDER, "--spp=-1"], "--spp"),
    "render spp 1.5": ([*RENDER, "--spp", "1.5"], "--spp"),
    "render spp huge": ([*RENDER, "--spp", "100000"], "--spp"),
    "render samples beyond int32": ([*RENDER, "--samples", "99999999999"], "integer range"),
    "render spp with --slice": ([*RENDER, "--slice", "--spp", "4"], "--spp"),
    "view spp 0": (["view", "--spp", "0"], "--spp"),
    "render exposure above the product limit": ([*RENDER, "--exposure", "1e11"], "--exposure"),
    "render exposure nan": ([*RENDER, "--exposure", "nan"], "not a number"),
    "render exposure -inf": ([*RENDER, "--exposure", "-inf"], "infinite"),
    "render exposure negative": ([*RENDER, "--exposure", "-1"], "--exposure"),
    "render exposure empty": ([*RENDER, "--exposure", ""], "expected a number"),
    "render exposure denormal": ([*RENDER, "--exposure", "1e-40"], "float32"),
    "render ior 1e39": ([*RENDER, "--ior", "1e39"], "float32"),
    "render ior 1e31": ([*RENDER, "--ior", "1e31"], "--ior"),
    "render ior negative": ([*RENDER, "--ior", "-1.5"], "--ior"),
    "render fov 1e39": ([*RENDER, "--fov", "1e39"], "float32"),
    "render fov 180": ([*RENDER, "--fov", "180"], "field of view"),
    "render light 1e39": ([*RENDER, "--light", "1e39,0"], "float32"),
    "render light 1e30": ([*RENDER, "--light", "1e30,0"], "--light"),
    "render light nan": ([*RENDER, "--light", "nan,0"], "not a number"),
    "render light one value": ([*RENDER, "--light", "45"], "θ,φ"),
    "render light empty": ([*RENDER, "--light", ""], "θ,φ"),
    "render camera distance 0": ([*RENDER, "--camera", "0,-90,45"], "--camera"),
    "render camera distance 1e30": ([*RENDER, "--camera", "1e30,-90,45"], "--camera"),
    "render camera elevation 91": ([*RENDER, "--camera", "0.2,-90,91"], "elevation"),
    "render point light at the origin": ([*RENDER, "--point-light", "0,0,0"], "--point-light"),
    "render point light 1e30": ([*RENDER, "--point-light", "0,0,1e30"], "--point-light"),
    "render point light inf": ([*RENDER, "--point-light", "0,inf,1"], "infinite"),
    "render size 0": (["render", "--size", "0,8"], "--size"),
    "render size 1e9": (["render", "--size", "1e9,8"], "--size"),
    "render size fraction": (["render", "--size", "8.5,8"], "--size"),
    "view exposure 1e39": (["view", "--exposure", "1e39"], "float32"),
    "view ior 1e39": (["view", "--ior", "1e39"], "float32"),
    "view ior out of range": (["view", "--ior", "1e31"], "--ior"),
    "view exposure above the product limit": (["view", "--exposure", "1e11"], "--exposure"),
    "view camera distance 1e30": (["view", "--camera", "1e30,0,45"], "--camera"),
    "view max frames 1e10": (["view", "--max-frames", "10000000000"], "integer range"),
    "brdfslice size 1e6": (["brdfslice", "blazed", "--size", "1000000"], "--size"),
    "brdfslice size beyond int32": (["brdfslice", "blazed", "--size", "10000000000"], "integer range"),
    "brdfslice sigma 1e39": (["brdfslice", "blazed", "--sigma-s", "1e39"], "float32"),
    "brdfslice sigma 0": (["brdfslice", "blazed", "--sigma-s", "0"], "--sigma-s"),
    "brdfslice dx nan": (["brdfslice", "blazed", "--dx-um", "nan"], "not a number"),
    "brdfslice dx denormal": (["brdfslice", "blazed", "--dx-um", "1e-45"], "float32"),
    "brdfslice exposure 1e39": (["brdfslice", "blazed", "--exposure", "1e39"], "float32"),
    "brdfslice ior 1e39": (["brdfslice", "blazed", "--ior", "1e39"], "float32"),
    "brdfslice wavelength step 1e-9": (["brdfslice", "blazed", "--wavelength-step-nm", "1e-9"], "wavelength"),
    "brdfslice grid samples 1e9": (["brdfslice", "blazed", "--max-grid-samples", "1000000000"], "grid"),
    "brdfslice tolerance 2": (["brdfslice", "blazed", "--tolerance", "2"], "tolerance"),
    "groundtruth res 1e9": (["groundtruth", "blazed", "--res", "1000000000"], "--res"),
    "groundtruth res and slices too large together": (["groundtruth", "blazed", "--res", "4001", "--slices", "1001"],
                                                      "GB"),
    "groundtruth slices 0": (["groundtruth", "blazed", "--slices", "0"], "--slices"),
    "groundtruth preview slice out of range": (["groundtruth", "blazed", "--preview", "p.png", "--preview-slice",
                                                "11"], "--preview-slice"),
    "groundtruth preview exposure negative": (["groundtruth", "blazed", "--preview", "p.png", "--exposure", "-1"],
                                              "--exposure"),
    "heightfield size 1e30": (["heightfield", "generate", "blazed", "--size-um", "1e30"], "samples per side"),
    "heightfield dx 1e39": (["heightfield", "generate", "blazed", "--dx-um", "1e39"], "float32"),
    "heightfield scratches 1e9": (["heightfield", "generate", "scratches", "--count", "1000000000"], "count"),
    "train learning rate nan": (["train", "v.exr", "--learning-rate", "nan"], "not a number"),
    "train epochs beyond int32": (["train", "v.exr", "--epochs", "99999999999"], "integer range"),
    "evaluate size 0": (["evaluate", "m.npz", "--size", "0"], "--size"),
    "evaluate ior 1e39": (["evaluate", "m.npz", "--ior", "1e39"], "float32"),
    "evaluate no volume slice": (["evaluate", "m.npz", "--volume", "v.exr", "--volume-slices", ","], "no slice"),
    "bench exposure 1e39": (["bench", "--exposure", "1e39"], "float32"),
    # gratnet mitsuba-render: render's checks (the same functions), and its own flags'
    "mitsuba-render exposure 1e39": ([*MITSUBA, "--exposure", "1e39"], "float32"),
    "mitsuba-render exposure above the product limit": ([*MITSUBA, "--exposure", "1e11"], "--exposure"),
    "mitsuba-render exposure negative": ([*MITSUBA, "--exposure", "-1"], "--exposure"),
    "mitsuba-render ior 1e31": ([*MITSUBA, "--ior", "1e31"], "--ior"),
    "mitsuba-render ior negative": ([*MITSUBA, "--ior", "-1.5"], "--ior"),
    "mitsuba-render fov 180": ([*MITSUBA, "--fov", "180"], "field of view"),
    "mitsuba-render light 1e30": ([*MITSUBA, "--light", "1e30,0"], "--light"),
    "mitsuba-render light nan": ([*MITSUBA, "--light", "nan,0"], "not a number"),
    "mitsuba-render camera distance 0": ([*MITSUBA, "--camera", "0,-90,45"], "--camera"),
    "mitsuba-render camera elevation 91": ([*MITSUBA, "--camera", "0.2,-90,91"], "elevation"),
    "mitsuba-render point light at the origin": ([*MITSUBA, "--point-light", "0,0,0"], "--point-light"),
    "mitsuba-render point light 1e30": ([*MITSUBA, "--point-light", "0,0,1e30"], "--point-light"),
    "mitsuba-render size 0": ([*MITSUBA, "--size", "0,8"], "--size"),
    "mitsuba-render spp 0": ([*MITSUBA, "--spp", "0"], "--spp"),
    "mitsuba-render light intensity nan": ([*MITSUBA, "--light-intensity", "nan"], "not a number"),
    "mitsuba-render environment scale negative": ([*MITSUBA, "--environment-scale", "-1"], "--environment-scale"),
    "mitsuba-render environment negative": ([*MITSUBA, "--environment", "-1"], "--environment"),
    "mitsuba-render lobe 0": ([*MITSUBA, "--lobe-degrees", "0"], "--lobe-degrees"),
}


@pytest.mark.parametrize("case", with_mitsuba_marked(list(NUMBERS)))
def test_bad_number_is_one_line_before_any_work(tmp_path, capsys, monkeypatch, case):
    argv, needle = NUMBERS[case]
    monkeypatch.chdir(tmp_path)
    for heavy_step in ("gratnet.modelfile.load_model", "trainer.cli_support.load_heightfield",
                       "gratnet.volume.read_volume", "trainer.heightfield_cli.save_heightfield"):
        monkeypatch.setattr(heavy_step, lambda *a, **k: pytest.fail("work started before the numbers were checked"))
    out = {"train": "run", "evaluate": "report", "bench": "bench", "view": None}.get(argv[0], "out.png")
    if argv[0] == "groundtruth":
        out = "v.exr"
    if argv[0] == "heightfield":
        out = "f.npz"
    code, stderr = run_cli([*argv, *(["--out", out] if out else []), *(["--max-frames", "1"] if out is None else [])],
                           capsys)
    assert_one_clear_error(code, stderr, argv[0], needle)
    assert_nothing_written(tmp_path, set())


# --------------------------------------------------------------------------------------------------
# Issue 42: --quality chooses between a shipped material's points (viewer.catalog); --preset fast is a recipe


#: A shipped material without a fast point, and a model file (which has no points).
_ONE = next(name for name in shipped_materials() if FAST not in material_points(name))
_FILE = str(ASSETS / _ONE / "model.npz")
# (argv without --out, the words the one line must hold)
QUALITY: dict[str, tuple[list[str], str]] = {
    "render fast, no fast point": ([*RENDER, "--material", _ONE, "--quality", "fast"], f"{_ONE} has no fast point"),
    "render quality, model file": ([*RENDER, "--material", _FILE, "--quality", "accurate"], "is a model file"),
    "compare fast, no fast point": (["compare", _ONE, "--reference", "v.exr", "--quality", "fast"], "no fast point"),
    "compare quality, model file": (["compare", _FILE, "--reference", "v.exr", "--quality", "fast"], "a model file"),
    "mitsuba-render fast, no fast point": ([*MITSUBA, "--material", _ONE, "--quality", "fast"], "no fast point"),
    "mitsuba-render quality, model file": ([*MITSUBA, "--material", _FILE, "--quality", "fast"], "a model file"),
    "view fast, no fast point": (["view", "--material", _ONE, "--quality", "fast"], "has no fast point"),
    "view auto, model file": (["view", "--material", _FILE, "--quality", "auto"], "is a model file"),
    "train fast preset, mlp": (["train", "v.exr", "--preset", "fast", "--architecture", "mlp"], "feature-grid recipe"),
}


@pytest.mark.parametrize("case", with_mitsuba_marked(list(QUALITY)))
def test_a_quality_or_preset_that_cannot_be_had_is_one_line_before_any_work(tmp_path, capsys, monkeypatch, case):
    argv, needle = QUALITY[case]
    monkeypatch.chdir(tmp_path)
    for heavy_step in ("gratnet.modelfile.load_model", "gratnet.volume.read_volume",
                       "viewer.scene_config.load_reference"):
        monkeypatch.setattr(heavy_step, lambda *a, **k: pytest.fail("work started before --quality was checked"))
    out = {"train": ["--out", "run"], "compare": ["--out", "compare"], "view": ["--max-frames", "1"]}.get(
        argv[0], ["--out", "out.png"])
    code, stderr = run_cli([*argv, *out], capsys)
    assert_one_clear_error(code, stderr, argv[0], needle)
    assert_nothing_written(tmp_path, set())


# --------------------------------------------------------------------------------------------------
# Issue 11: negative values in comma lists parse, in both forms, in every subcommand


@pytest.mark.parametrize("form", ["separate", "equals"])
def test_negative_values_in_comma_lists_parse_everywhere(tmp_path, capsys, form):
    from gratnet.cli import build_parser

    def flag(name: str, value: str) -> list[str]:
        return [name, value] if form == "separate" else [f"{name}={value}"]

    render = build_parser(only="render").parse_args(
        ["render", "--out", "x.png", *flag("--light", "-30,0"), *flag("--point-light", "-0.1,0,0.2"),
         *flag("--camera", "0.2,-90,-45"), *flag("--exposure", "-0")])
    assert (render.light_text, render.point_light_text, render.camera_text) == ("-30,0", "-0.1,0,0.2", "0.2,-90,-45")
    from viewer.render_cli import resolve_config

    config = resolve_config(render)
    assert (config.light_theta_degrees, config.point_light, config.camera_elevation_degrees) == (
        -30.0, (-0.1, 0.0, 0.2), -45.0)
    assert str(config.exposure) == "0.0"  # -0 is 0
    view = build_parser(only="view").parse_args(["view", *flag("--light", "-30,-90"), *flag("--camera", "0.2,-10,-20")])
    assert (view.light_text, view.camera_text) == ("-30,-90", "0.2,-10,-20")
    brdfslice = build_parser(only="brdfslice").parse_args(["brdfslice", "blazed", "--out", "s.png",
                                                           *flag("--light", "30,-45")])
    assert brdfslice.light == (30.0, -45.0)
    evaluate = build_parser(only="evaluate").parse_args(["evaluate", "m.npz", "--out", "r",
                                                         *flag("--volume-slices", "-1,2")])
    assert evaluate.volume_slices == "-1,2"
    # A negative θ is parsed, then refused by brdfslice's own rule (θ in [0, 90)), with one line.
    code, stderr = run_cli(["brdfslice", "blazed", "--out", str(tmp_path / "s.png"), *flag("--light", "-30,0")],
                           capsys)
    assert_one_clear_error(code, stderr, "brdfslice", "light θ")


def test_render_with_negative_light_and_point_light_writes_images(tmp_path, capsys):
    for argv in (["--light", "-30,0"], ["--light=-30,0"], ["--point-light", "-0.1,0,0.2"]):
        out = tmp_path / f"x{len(list(tmp_path.iterdir()))}.png"
        code, stderr = run_cli([*RENDER, *argv, "--out", str(out)], capsys)
        assert code == 0 and out.is_file(), stderr


def test_argparse_errors_are_one_line_without_a_usage_dump(capsys):
    cases = [
        (["render"], "gratnet render: error: ", "--out"),
        (["render", "--bogus", "--out", "x.png"], "gratnet: error: ", "--bogus"),
        (["groundtruth", "blazed", "--out", "v.exr", "--sampling", "x"], "gratnet groundtruth: error: ", "choice"),
        (["heightfield", "generate", "blazed", "--out", "f.npz", "--dx-um", "abc"], "gratnet heightfield: error: ",
         "--dx-um"),
    ]
    for argv, prefix, needle in cases:
        code, stderr = run_cli(argv, capsys)
        assert code == 2 and len(stderr.strip().splitlines()) == 1, stderr
        assert stderr.startswith(prefix) and needle in stderr and "usage:" not in stderr, stderr


# --------------------------------------------------------------------------------------------------
# Issue 11: --quiet everywhere (one meaning), and --help with typical values and no internal names

# mitsuba-render's parser needs no Mitsuba (it is imported when rendering starts): no skip here.
SUBCOMMANDS = ["render", "view", "brdfslice", "groundtruth", "train", "evaluate", "bench", "mitsuba-render",
               "heightfield generate blazed", "heightfield convert", "heightfield preview", "heightfield"]
LONG_RUNNING = ["render", "view", "brdfslice", "groundtruth", "train", "evaluate", "bench", "mitsuba-render"]


def _help(command: str, capsys: pytest.CaptureFixture[str]) -> str:
    from gratnet.cli import main as gratnet

    assert gratnet([*command.split(), "--help"]) == 0
    return capsys.readouterr().out


@pytest.mark.parametrize("command", LONG_RUNNING)
def test_every_long_running_subcommand_takes_quiet_with_one_meaning(capsys, command):
    from gratnet.config import QUIET_HELP

    text = " ".join(_help(command, capsys).split())
    assert f"--quiet {QUIET_HELP}" in text


@pytest.mark.parametrize("command", SUBCOMMANDS)
def test_help_names_no_internal_module_and_gives_typical_use(capsys, command):
    import re

    text = _help(command, capsys)
    assert not re.search(r"\b(gratnet|viewer|trainer|shaders)\.[a-z_]+", text), text
    assert not re.search(r"\b[A-Z][a-z]+(Config|Options|Params):", text), text  # dataclass names as group titles
    if command in LONG_RUNNING or command == "heightfield":
        assert "typical use:" in text


def test_quiet_silences_progress_but_not_errors(tmp_path, capsys):
    field = tmp_path / "f.npz"
    assert main(["heightfield", "generate", "blazed", "--out", str(field)]) == 0
    capsys.readouterr()
    # The generated field is too coarse for 380 nm and gets resampled: a preparation message on stderr without
    # --quiet, none with it; errors are still shown.
    argv = ["brdfslice", str(field), "--size", "8", "--sigma-s", "1", "--wavelength-step-nm", "200"]
    assert main([*argv, "--out", str(tmp_path / "a.png")]) == 0
    assert "resampled" in capsys.readouterr().err
    assert main([*argv, "--quiet", "--out", str(tmp_path / "b.png")]) == 0
    assert capsys.readouterr().err == ""
    code, stderr = run_cli([*argv, "--quiet", "--out", str(tmp_path / "a.png" / "x.png")], capsys)
    assert_one_clear_error(code, stderr, "brdfslice", "a.png is a file, not a folder")


# --------------------------------------------------------------------------------------------------
# Issue 11: IOR near 1 through the real CLI: exact Fresnel ratio in the rendered image


@pytest.mark.parametrize("ior", [float(np.float32(1 + 1e-5)), float(np.float32(1 - 1e-5)), 1.0, 1e-30, 1e30])
def test_rendered_fresnel_ratio_is_exact_for_ior_near_one_and_extreme(tmp_path, capsys, ior):
    # The same BRDF slice with and without Fresnel: per pixel the ratio is (R/R0)² at the half-vector, from
    # the analytic (float64) form; before the fix it was 12–57 % off within 1e-5 of 1.
    import OpenEXR

    from gratnet.brdf import direction, fresnel_ratio, slice_view_directions

    size, theta, phi = 24, 40.0, 30.0
    images = []
    for name, flags in (("with.exr", ["--ior", repr(ior)]), ("without.exr", ["--no-fresnel"])):
        out = tmp_path / name
        code, stderr = run_cli([*RENDER, "--slice", "--size", f"{size},{size}", "--light", f"{theta},{phi}",
                                "--exposure", "1", *flags, "--out", str(out)], capsys)
        assert code == 0, stderr
        with OpenEXR.File(str(out), separate_channels=True) as exr:
            channels = exr.channels()
            images.append(np.stack([channels[c].pixels for c in "RGB"], -1).astype(np.float64))
    with_fresnel, without = images
    views, inside = slice_view_directions(size)
    light = direction(theta, phi)
    key = light + views
    cos_half = np.sqrt(np.clip(0.25 * np.sum(key * key, -1), 0, 1))
    expected = fresnel_ratio(cos_half, ior) ** 2
    lit = inside & np.all(np.abs(without) > 1e-6 * np.abs(without).max(), axis=-1)
    assert np.count_nonzero(lit) > size * size // 3
    np.testing.assert_allclose(with_fresnel[lit], without[lit] * expected[lit][:, None], rtol=2e-4)


def test_view_reads_model_and_mesh_before_opening_a_window(tmp_path, capsys):
    # Without this the window (or the no-display message) came first and a bad file surfaced later.
    (tmp_path / "bad.npz").write_bytes(b"not a model")
    (tmp_path / "bad.obj").write_bytes(bytes(range(256)) * 8)
    for argv, needle in ((["--material", str(tmp_path / "bad.npz")], "not a GratNet model"),
                         (["--mesh", str(tmp_path / "bad.obj")], "OBJ")):
        code, stderr = run_cli(["view", *argv, "--max-frames", "1", "--screenshot-dir", str(tmp_path)], capsys)
        assert_one_clear_error(code, stderr, "view", needle)


def test_resume_without_a_checkpoint_is_refused(tmp_path, capsys, volume_bytes):
    volume = tmp_path / "v.exr"
    volume.write_bytes(volume_bytes)
    code, stderr = run_cli(["train", str(volume), "--out", str(tmp_path / "run"), "--resume", "--quiet"], capsys)
    assert_one_clear_error(code, stderr, "train", "checkpoint.pt")
    assert_nothing_written(tmp_path, {"v.exr"})
