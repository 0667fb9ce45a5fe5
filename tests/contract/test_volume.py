"""Tests for gratnet.volume: the ground-truth volume EXR format (see docs/formats.md)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import OpenEXR
import pytest

import gratnet.volume as volume_module
from gratnet.errors import GratNetError
from gratnet.volume import (
    FORMAT_NAME,
    FORMAT_VERSION,
    Volume,
    read_volume,
    volume_axes,
    write_volume,
)

METADATA = {
    "format": FORMAT_NAME,
    "format_version": FORMAT_VERSION,
    "scheme": "regular",
    "resolution": 9,
    "slices": 3,
    "slice_t": [0.0, 0.5, 1.0],
    "slice_w": [0.1, None, 0.30000000000000004],
    "sigma_s_um": 12.345678901234567,
    "repeat": "periodic",
    "wavelengths_nm": [380.0, 385.5],
    "grid_samples": [64, 64],
    "observer": "CIE 1931 2 Degree Standard Observer",
    "flag": True,
    "big": 2**40,
    "unicode": "µm ✓",
}


def random_volume(slices: int = 3, resolution: int = 9, seed: int = 0) -> Volume:
    rng = np.random.default_rng(seed)
    xyz = rng.standard_normal((slices, resolution, resolution, 3)).astype(np.float32)
    xyz[0, 0, 0] = [0.0, -0.0, np.float32(1e-40)]  # zero, negative zero, subnormal
    xyz[-1, -1, -1] = np.finfo(np.float32).max
    return Volume(xyz=xyz, metadata=dict(METADATA))


def leftovers(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir())


def write_plain_exr(path: Path, header: dict, names: list[str], size: int = 4) -> None:
    parts = [OpenEXR.Part(dict(header), {c: np.zeros((size, size), np.float32) for c in "XYZ"}, name) for name in names]
    OpenEXR.File(parts).write(str(path))


def gratnet_header(version: int = FORMAT_VERSION, slices: int = 1) -> dict:
    return {
        "compression": OpenEXR.ZIP_COMPRESSION,
        "type": OpenEXR.scanlineimage,
        "gratnet_format": FORMAT_NAME,
        "gratnet_format_version": version,
        "gratnet_slice_index": 0,
        "gratnet_slice_count": slices,
        "gratnet_metadata": "{}",
    }


# --- round trip and layout -----------------------------------------------------------------------


def test_round_trip_is_bit_exact(tmp_path):
    volume = random_volume()
    path = tmp_path / "gt.exr"
    write_volume(path, volume)
    back = read_volume(path)

    assert back.xyz.dtype == np.float32
    assert back.xyz.shape == (3, 9, 9, 3)
    assert back.slices == 3 and back.resolution == 9
    assert np.array_equal(back.xyz.view(np.uint32), volume.xyz.view(np.uint32))
    assert back.metadata == METADATA
    assert list(back.metadata) == list(METADATA)
    assert leftovers(tmp_path) == ["gt.exr"]


def test_accepts_str_path_and_float64_input(tmp_path):
    xyz = np.linspace(0, 1, 2 * 4 * 4 * 3).reshape(2, 4, 4, 3)  # float64
    write_volume(str(tmp_path / "a.exr"), Volume(xyz=xyz, metadata={}))
    back = read_volume(str(tmp_path / "a.exr"))
    assert np.array_equal(back.xyz, xyz.astype(np.float32))
    assert back.metadata == {}


def test_file_layout_parts_channels_and_attributes(tmp_path):
    path = tmp_path / "gt.exr"
    write_volume(path, random_volume())
    exr = OpenEXR.File(str(path), separate_channels=True)
    assert [part.name() for part in exr.parts] == ["slice_00", "slice_01", "slice_02"]
    for index, part in enumerate(exr.parts):
        header = part.header
        assert header["compression"] == OpenEXR.ZIP_COMPRESSION
        assert header["type"] == OpenEXR.scanlineimage
        lo, hi = header["dataWindow"]
        assert list(lo) == [0, 0] and list(hi) == [8, 8]
        assert sorted(part.channels) == ["X", "Y", "Z"]
        for channel in part.channels.values():
            assert channel.type() == OpenEXR.FLOAT
            assert channel.pixels.dtype == np.float32
        assert header["gratnet_format"] == FORMAT_NAME
        assert header["gratnet_format_version"] == FORMAT_VERSION
        assert header["gratnet_slice_index"] == index
        assert header["gratnet_slice_count"] == 3
        assert json.loads(header["gratnet_metadata"]) == METADATA
        # Per-key typed copies, for exrheader.
        assert header["gratnet_scheme"] == "regular"
        assert header["gratnet_resolution"] == 9
        assert float(np.asarray(header["gratnet_sigma_s_um"]).ravel()[0]) == METADATA["sigma_s_um"]
        assert json.loads(header["gratnet_slice_w"]) == METADATA["slice_w"]
        assert json.loads(header["gratnet_grid_samples"]) == [64, 64]
        assert header["gratnet_flag"] == "true"
        assert header["gratnet_big"] == str(2**40)
        assert header["gratnet_unicode"] == "µm ✓"


def test_typed_float_attribute_is_double(tmp_path):
    path = tmp_path / "gt.exr"
    write_volume(path, random_volume())
    data = path.read_bytes()
    start = data.index(b"gratnet_sigma_s_um\0") + len("gratnet_sigma_s_um\0")
    assert data[start : data.index(b"\0", start)] == b"double"


def test_orientation_marker_stays_in_place(tmp_path):
    xyz = np.zeros((3, 5, 5, 3), np.float32)
    xyz[1, 1, 2] = [1.0, 2.0, 3.0]  # slice 1, row (v* index) 1, column (u* index) 2
    path = tmp_path / "marker.exr"
    write_volume(path, Volume(xyz=xyz, metadata={}))

    back = read_volume(path)
    assert np.argwhere(back.xyz[..., 1] != 0).tolist() == [[1, 1, 2]]
    assert back.xyz[1, 1, 2].tolist() == [1.0, 2.0, 3.0]

    # In the raw EXR: part slice_01, pixel array [y=1, x=2], no flip.
    exr = OpenEXR.File(str(path), separate_channels=True)
    pixels = exr.parts[1].channels["Y"].pixels
    assert np.argwhere(pixels != 0).tolist() == [[1, 2]]
    assert not exr.parts[0].channels["Y"].pixels.any()


def test_volume_axes():
    axes = volume_axes(9)
    assert axes.shape == (9,)
    assert axes[0] == -2.0 and axes[-1] == 2.0 and axes[4] == 0.0
    assert np.allclose(np.diff(axes), 0.5)
    with pytest.raises(GratNetError):
        volume_axes(1)
    with pytest.raises(GratNetError):
        volume_axes(2.5)


def test_part_names_widen_beyond_100_slices(tmp_path):
    xyz = np.zeros((101, 2, 2, 3), np.float32)
    xyz[:, 0, 0, 0] = np.arange(101)
    path = tmp_path / "many.exr"
    write_volume(path, Volume(xyz=xyz, metadata={}))
    names = [part.name() for part in OpenEXR.File(str(path), header_only=True).parts]
    assert names[0] == "slice_000" and names[-1] == "slice_100"
    assert np.array_equal(read_volume(path).xyz, xyz)

    assert volume_module.slice_part_name(99, 100) == "slice_99"


def test_single_slice(tmp_path):
    volume = random_volume(slices=1, resolution=2)
    write_volume(tmp_path / "one.exr", volume)
    assert np.array_equal(read_volume(tmp_path / "one.exr").xyz, volume.xyz)


def test_one_call_from_another_process(tmp_path):
    path = tmp_path / "gt.exr"
    write_volume(path, random_volume())
    code = (
        "import sys, gratnet.volume as v; vol = v.read_volume(sys.argv[1]); "
        "print(vol.xyz.shape, vol.metadata['scheme']); "
        "assert 'torch' not in sys.modules"
    )
    result = subprocess.run([sys.executable, "-c", code, str(path)], capture_output=True, text=True, check=True)
    assert result.stdout.strip() == "(3, 9, 9, 3) regular"


# --- writing: validation and atomicity ------------------------------------------------------------


@pytest.mark.parametrize(
    "xyz",
    [
        np.zeros((3, 9, 9), np.float32),  # 3-D
        np.zeros((3, 9, 9, 4), np.float32),  # 4 channels
        np.zeros((3, 9, 8, 3), np.float32),  # not square
        np.zeros((0, 9, 9, 3), np.float32),  # no slices
        np.zeros((3, 1, 1, 3), np.float32),  # R < 2
        np.full((2, 3, 3, 3), np.nan),  # NaN
        np.full((2, 3, 3, 3), np.inf),  # inf
        np.full((2, 3, 3, 3), 1e300),  # overflows float32
        np.zeros((2, 3, 3, 3), np.complex64),  # complex
    ],
)
def test_invalid_array_writes_nothing(tmp_path, xyz):
    target = tmp_path / "bad.exr"
    with pytest.raises(GratNetError):
        write_volume(target, Volume(xyz=xyz, metadata={}))
    assert leftovers(tmp_path) == []


def test_nan_error_says_where(tmp_path):
    xyz = np.zeros((2, 3, 3, 3), np.float32)
    xyz[1, 2, 0, 1] = np.nan
    with pytest.raises(GratNetError, match=r"slice 1, row 2, column 0, channel Y"):
        write_volume(tmp_path / "bad.exr", Volume(xyz=xyz, metadata={}))


@pytest.mark.parametrize(
    "metadata",
    [
        {"sigma": float("nan")},
        {"x": object()},
        {"bad key": 1},
        {"1abc": 1},
        {3: "int key"},
        {"metadata": "reserved"},
        {"slice_index": 0},
        {"format": "something-else"},
        {"format_version": 2},
    ],
)
def test_invalid_metadata_writes_nothing(tmp_path, metadata):
    with pytest.raises(GratNetError):
        write_volume(tmp_path / "bad.exr", Volume(xyz=np.zeros((1, 2, 2, 3)), metadata=metadata))
    assert leftovers(tmp_path) == []


def test_numpy_metadata_values_become_plain(tmp_path):
    metadata = {"n": np.int64(7), "f": np.float32(0.5), "arr": np.array([1.0, 2.0])}
    write_volume(tmp_path / "a.exr", Volume(xyz=np.zeros((1, 2, 2, 3)), metadata=metadata))
    assert read_volume(tmp_path / "a.exr").metadata == {"n": 7, "f": 0.5, "arr": [1.0, 2.0]}


def test_unwritable_folder_leaves_nothing(tmp_path):
    if hasattr(os, "geteuid") and os.geteuid() == 0:
        pytest.skip("root ignores folder permissions")
    folder = tmp_path / "locked"
    folder.mkdir()
    folder.chmod(0o500)
    try:
        with pytest.raises(GratNetError):
            write_volume(folder / "gt.exr", random_volume())
        assert leftovers(folder) == []
    finally:
        folder.chmod(0o700)


def test_folder_that_is_a_file_gives_error(tmp_path):
    blocker = tmp_path / "not_a_folder"
    blocker.write_text("x")
    with pytest.raises(GratNetError):
        write_volume(blocker / "gt.exr", random_volume())
    assert leftovers(tmp_path) == ["not_a_folder"]


def test_failure_during_write_leaves_no_file_and_keeps_old_one(tmp_path, monkeypatch):
    target = tmp_path / "gt.exr"
    target.write_bytes(b"old contents")

    class FailingFile:
        def __init__(self, parts):
            self.parts = parts

        def write(self, filename):
            Path(filename).write_bytes(b"half-written")
            raise RuntimeError("disk full")

    class FakeOpenEXR:
        def __getattr__(self, name):
            return getattr(OpenEXR, name)

        File = FailingFile

    monkeypatch.setattr(volume_module, "OpenEXR", FakeOpenEXR())
    with pytest.raises(GratNetError, match="disk full"):
        write_volume(target, random_volume())
    assert leftovers(tmp_path) == ["gt.exr"]
    assert target.read_bytes() == b"old contents"


def test_overwrite_replaces_existing_volume(tmp_path):
    path = tmp_path / "gt.exr"
    write_volume(path, random_volume(seed=1))
    second = random_volume(seed=2)
    write_volume(path, second)
    assert np.array_equal(read_volume(path).xyz, second.xyz)
    assert leftovers(tmp_path) == ["gt.exr"]


# --- reading: bad files ---------------------------------------------------------------------------


def test_missing_file(tmp_path):
    with pytest.raises(GratNetError, match="does not exist"):
        read_volume(tmp_path / "nope.exr")


def test_directory_is_not_a_volume(tmp_path):
    with pytest.raises(GratNetError, match="not a regular file"):
        read_volume(tmp_path)


@pytest.mark.parametrize("content", [b"", b"v/1", b"hello, this is not an image" * 10])
def test_not_an_exr(tmp_path, content):
    path = tmp_path / "fake.exr"
    path.write_bytes(content)
    with pytest.raises(GratNetError, match="not an OpenEXR file") as info:
        read_volume(path)
    assert str(path) in str(info.value)


@pytest.mark.parametrize("fraction", [0.5, 0.01, 0.1, 0.3, 0.7, 0.9, 0.999])
def test_truncated_file(tmp_path, fraction):
    full = tmp_path / "full.exr"
    # Large enough that each part spans several compressed chunks.
    write_volume(full, random_volume(slices=3, resolution=64))
    data = full.read_bytes()
    cut = tmp_path / "cut.exr"
    cut.write_bytes(data[: int(len(data) * fraction)])
    with pytest.raises(GratNetError) as info:
        read_volume(cut)
    assert str(cut) in str(info.value)
    assert "\n" not in str(info.value)


def test_truncated_file_in_subprocess_does_not_crash(tmp_path):
    full = tmp_path / "full.exr"
    write_volume(full, random_volume(slices=3, resolution=32))
    data = full.read_bytes()
    cut = tmp_path / "cut.exr"
    cut.write_bytes(data[: len(data) // 2])
    code = (
        "import sys\nfrom gratnet.errors import GratNetError\nfrom gratnet.volume import read_volume\n"
        "try:\n    read_volume(sys.argv[1])\nexcept GratNetError as e:\n    print('ERROR', e)\n"
    )
    result = subprocess.run([sys.executable, "-c", code, str(cut)], capture_output=True, text=True)
    assert result.returncode == 0, result.stderr
    assert result.stdout.startswith("ERROR ")


def test_corrupted_bytes_give_error_not_crash(tmp_path):
    full = tmp_path / "full.exr"
    write_volume(full, random_volume(slices=2, resolution=32))
    data = bytearray(full.read_bytes())
    rng = np.random.default_rng(3)
    for position in rng.integers(len(data) // 2, len(data), 200):
        data[position] ^= 0xFF
    bad = tmp_path / "bad.exr"
    bad.write_bytes(bytes(data))
    code = (
        "import sys\nfrom gratnet.errors import GratNetError\nfrom gratnet.volume import read_volume\n"
        "try:\n    read_volume(sys.argv[1])\nexcept GratNetError as e:\n    print('ERROR', e)\n"
        "else:\n    print('READ')\n"
    )
    result = subprocess.run([sys.executable, "-c", code, str(bad)], capture_output=True, text=True)
    # Flipped bits in pixel data must never crash the interpreter, and are caught (by the EXR
    # decoder, or by the per-part CRC for chunks stored uncompressed).
    assert result.returncode == 0, result.stderr
    assert result.stdout.startswith("ERROR "), result.stdout


def test_exr_without_gratnet_format(tmp_path):
    path = tmp_path / "plain.exr"
    write_plain_exr(path, {"compression": OpenEXR.ZIP_COMPRESSION}, ["slice_00"])
    with pytest.raises(GratNetError, match="not a GratNet volume"):
        read_volume(path)


def test_single_part_rgb_exr_is_rejected(tmp_path):
    path = tmp_path / "rgb.exr"
    OpenEXR.File({}, {"RGB": np.zeros((4, 4, 3), np.float32)}).write(str(path))
    with pytest.raises(GratNetError, match="gratnet_format"):
        read_volume(path)


def test_newer_format_version(tmp_path):
    path = tmp_path / "future.exr"
    write_plain_exr(path, gratnet_header(version=999), ["slice_00"])
    with pytest.raises(GratNetError) as info:
        read_volume(path)
    message = str(info.value)
    assert "999" in message and str(FORMAT_VERSION) in message


def test_wrong_part_names(tmp_path):
    path = tmp_path / "names.exr"
    write_plain_exr(path, gratnet_header(), ["left"])
    with pytest.raises(GratNetError, match="slice_00"):
        read_volume(path)


def test_missing_part(tmp_path):
    path = tmp_path / "missing.exr"
    write_plain_exr(path, gratnet_header(slices=2), ["slice_00"])
    with pytest.raises(GratNetError, match="declares 2 slice"):
        read_volume(path)


def test_missing_channel(tmp_path):
    path = tmp_path / "channels.exr"
    part = OpenEXR.Part(gratnet_header(), {c: np.zeros((4, 4), np.float32) for c in "XY"}, "slice_00")
    OpenEXR.File([part]).write(str(path))
    with pytest.raises(GratNetError, match="lacks channel"):
        read_volume(path)


def test_mismatched_part_sizes(tmp_path):
    path = tmp_path / "sizes.exr"
    parts = []
    for index, size in enumerate((4, 5)):
        header = gratnet_header(slices=2)
        header["gratnet_slice_index"] = index
        header["displayWindow"] = (np.array([0, 0], np.int32), np.array([4, 4], np.int32))
        parts.append(OpenEXR.Part(header, {c: np.zeros((size, size), np.float32) for c in "XYZ"}, f"slice_{index:02d}"))
    OpenEXR.File(parts).write(str(path))
    with pytest.raises(GratNetError, match="same size"):
        read_volume(path)


def test_half_float_channels_are_accepted(tmp_path):
    path = tmp_path / "half.exr"
    pixels = {c: np.full((4, 4), 0.5, np.float16) for c in "XYZ"}
    OpenEXR.File([OpenEXR.Part(gratnet_header(), pixels, "slice_00")]).write(str(path))
    back = read_volume(path)
    assert back.xyz.dtype == np.float32 and np.all(back.xyz == 0.5)


def test_changed_pixel_is_detected_by_checksum(tmp_path):
    path = tmp_path / "gt.exr"
    write_volume(path, random_volume(slices=2, resolution=16))
    # Re-write the file with the same headers (checksum included) but one pixel off by one ulp.
    exr = OpenEXR.File(str(path), separate_channels=True)
    parts = []
    for part in exr.parts:
        channels = {name: channel.pixels.copy() for name, channel in part.channels.items()}
        if part.name() == "slice_01":
            channels["Z"][3, 5] = np.nextafter(channels["Z"][3, 5], np.float32(np.inf))
        header = {k: v for k, v in part.header.items() if k not in ("channels", "chunkCount", "name")}
        parts.append(OpenEXR.Part(header, channels, part.name()))
    OpenEXR.File(parts).write(str(path))
    with pytest.raises(GratNetError, match="slice_01.*checksum"):
        read_volume(path)


def test_checksum_attribute_is_written(tmp_path):
    path = tmp_path / "gt.exr"
    write_volume(path, random_volume())
    header = OpenEXR.File(str(path), header_only=True).parts[0].header
    assert len(header["gratnet_pixels_crc32"]) == 8
