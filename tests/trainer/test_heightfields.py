"""Height-field generators, file loaders and the ``gratnet heightfield`` command (fast: tiny patches)."""

from __future__ import annotations

import json
import math
import struct
import zlib
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from gratnet.cli import main
from gratnet.errors import GratNetError
from tests.helpers import SHARED_DATA
from trainer import generators
from trainer.heightfield import HeightField
from trainer.heightfile import LoadOptions, preview_png, save_heightfield, write_gsf
from trainer.loaders import load_heightfield

AFM_PNG = SHARED_DATA / "elaphe_guttata_afm_100x100.png"
SMALL = 6.0  # µm: patch width for quick generator tests


# --------------------------------------------------------------------------------------------------
# Generators


@pytest.mark.parametrize("name", list(generators.GENERATORS))
def test_generator_defaults_are_seeded_finite_and_start_at_zero(name):
    field = generators.generate(name, size_um=SMALL)
    again = generators.generate(name, size_um=SMALL)
    other = generators.generate(name, size_um=SMALL, seed=1)
    heights = field.heights_um
    assert np.all(np.isfinite(heights))
    assert heights.min() == 0.0
    assert field.span_um > 0
    np.testing.assert_array_equal(heights, again.heights_um)
    assert not np.array_equal(heights, other.heights_um)
    assert field.source.startswith(f"generator:{name}(") and "seed=0" in field.source and "dx_um=0.08" in field.source


@pytest.mark.parametrize("name", ["sinusoidal", "blazed", "cd", "gaussian", "snake", "scratches", "pits"])
def test_periodic_generators_tile_without_a_seam(name):
    heights = generators.generate(name, size_um=SMALL).heights_um
    for axis in (0, 1):
        seam = np.abs(np.take(heights, 0, axis) - np.take(heights, -1, axis)).max()
        assert seam <= np.abs(np.diff(heights, axis=axis)).max() + 1e-12


def test_periodic_patches_are_snapped_to_whole_periods():
    field = generators.generate("blazed", size_um=11.0)  # 4.4 periods -> 4 periods of 2.5 µm
    assert field.size_um[0] == pytest.approx(10.0)
    assert field.dx_um == pytest.approx(0.08)
    field = generators.generate("cd", size_um=5.0)  # 3.1 track pitches -> 3 of 1.6 µm
    assert field.size_um[1] == pytest.approx(4.8)


def test_sinusoid_period_and_peak_to_peak():
    field = generators.generate("sinusoidal", size_um=10.0)
    assert field.span_um == pytest.approx(0.15, abs=1e-3)
    row = field.heights_um[0] - field.heights_um[0].mean()
    spectrum = np.abs(np.fft.rfft(row))
    frequency = np.fft.rfftfreq(row.size, field.dx_um)[np.argmax(spectrum)]  # cycles per µm
    assert 1 / frequency == pytest.approx(1000 / 600, rel=1e-6)
    assert np.all(field.heights_um == field.heights_um[:1])  # grooves along y: every row the same


def test_slope_covariance_of_a_sinusoid_is_its_analytic_value():
    """h = a sin(kx): slopes a k cos(kx), variance (a k)²/2 along x, none along y; central differences see
    a k cos(kx) · sinc(k dx) exactly (the shadowing statistics, gratnet.shadowing)."""
    field = generators.generate("sinusoidal", size_um=10.0)
    amplitude, k = 0.075, 2.0 * np.pi * 0.6  # 0.15 µm peak to peak, 600 lines/mm
    sinc = np.sin(k * field.dx_um) / (k * field.dx_um)
    xx, xy, yy = field.slope_covariance()
    assert xx == pytest.approx((amplitude * k * sinc) ** 2 / 2.0, rel=2e-3)
    assert xy == pytest.approx(0.0, abs=1e-12) and yy == pytest.approx(0.0, abs=1e-12)
    rotated = HeightField(field.heights_um.T.copy(), field.dx_um)
    assert rotated.slope_covariance() == pytest.approx((yy, xy, xx), abs=1e-12)


def test_blazed_height_and_rising_along_plus_x():
    field = generators.generate("blazed", size_um=SMALL)
    step = 0.25 * field.dx_um / 2.5
    assert 0.25 - 1.01 * step <= field.span_um <= 0.25
    rises = np.diff(field.heights_um[0])
    assert np.mean(rises > 0) > 0.9
    assert np.median(rises) == pytest.approx(step, rel=1e-6)


def test_cd_pit_depth_and_tracks():
    field = generators.generate("cd", size_um=SMALL)
    assert field.span_um == pytest.approx(0.11, abs=1e-3)
    land = field.heights_um.max()
    # Between tracks (y = k·1.6 µm, rows k·20) there are no pits: all land.
    np.testing.assert_allclose(field.heights_um[::20], land, atol=1e-6)
    pit_fraction = np.mean(field.heights_um < land - 0.1)
    assert 0.05 < pit_fraction < 0.25


def test_gaussian_and_pits_spans():
    assert generators.generate("gaussian", size_um=SMALL).span_um == pytest.approx(1.0)
    pits = generators.generate("pits", size_um=5.0, radius_jitter=0.0, position_jitter=0.0)
    assert pits.span_um == pytest.approx(0.8, abs=0.01)
    flat = generators.generate("pits", size_um=5.0, radius_jitter=0.0, depth_fraction=0.5)
    assert flat.span_um == pytest.approx(0.4, abs=0.01)


def test_corner_cube_span_and_cube_face_slopes():
    field = generators.generate("corner_cube", size_um=SMALL, dx_um=0.04)
    assert field.span_um == pytest.approx(1.5, rel=0.05)
    assert field.span_um <= 1.5 + 1e-9
    gradient_y, gradient_x = np.gradient(field.heights_um, field.dx_um)
    assert np.median(np.hypot(gradient_x, gradient_y)) == pytest.approx(math.tan(math.radians(54.7356)), rel=0.01)
    taller = generators.generate("corner_cube", size_um=SMALL, max_height_um=3.0)
    assert taller.span_um == pytest.approx(3.0, rel=0.05)


def test_generate_rejects_unknown_names_and_bad_values():
    with pytest.raises(GratNetError, match="blazed, cd"):
        generators.generate("blazd")
    with pytest.raises(GratNetError, match="no parameter 'perod_um'.*period_um"):
        generators.generate("blazed", perod_um=3.0)
    with pytest.raises(GratNetError, match="period_um must be > 0"):
        generators.generate("blazed", period_um=-1.0)
    with pytest.raises(GratNetError, match="whole number"):
        generators.generate("scratches", count=2.5)
    with pytest.raises(GratNetError, match="samples per side"):
        generators.generate("gaussian", size_um=1000.0, dx_um=0.01)


# --------------------------------------------------------------------------------------------------
# Files


def test_npz_round_trip(tmp_path):
    field = generators.generate("snake", size_um=4.0)
    save_heightfield(tmp_path / "snake.npz", field)
    loaded = load_heightfield(str(tmp_path / "snake.npz"))
    np.testing.assert_array_equal(loaded.heights_um, field.heights_um)
    assert loaded.dx_um == field.dx_um
    assert field.source in loaded.source
    assert load_heightfield(tmp_path / "snake.npz", LoadOptions(dx_um=0.5)).dx_um == 0.5


def test_npy_needs_dx_and_rejects_bad_arrays(tmp_path):
    np.save(tmp_path / "h.npy", np.zeros((4, 5)))
    with pytest.raises(GratNetError, match="--dx-um"):
        load_heightfield(tmp_path / "h.npy")
    assert load_heightfield(tmp_path / "h.npy", LoadOptions(dx_um=0.1)).shape == (4, 5)
    np.savez(tmp_path / "nodx.npz", heights_um=np.zeros((4, 5)))
    with pytest.raises(GratNetError, match="--dx-um"):
        load_heightfield(tmp_path / "nodx.npz")
    bad = np.zeros((4, 5))
    bad[1, 2] = np.nan
    np.save(tmp_path / "nan.npy", bad)
    with pytest.raises(GratNetError, match="NaN"):
        load_heightfield(tmp_path / "nan.npy", LoadOptions(dx_um=0.1))
    np.save(tmp_path / "flat.npy", np.zeros(7))
    with pytest.raises(GratNetError, match="2-D"):
        load_heightfield(tmp_path / "flat.npy", LoadOptions(dx_um=0.1))


def test_unknown_empty_missing_and_generator_specs(tmp_path):
    (tmp_path / "h.tif").write_bytes(b"abc")
    with pytest.raises(GratNetError, match="unknown height-field format '.tif'"):
        load_heightfield(tmp_path / "h.tif")
    (tmp_path / "empty.npz").write_bytes(b"")
    with pytest.raises(GratNetError, match="empty"):
        load_heightfield(tmp_path / "empty.npz")
    with pytest.raises(GratNetError, match="no such file"):
        load_heightfield(tmp_path / "missing.gsf")
    with pytest.raises(GratNetError, match="neither a file nor a built-in generator"):
        load_heightfield("blazd")
    assert load_heightfield("blazed").source.startswith("generator:blazed(")


def test_gsf_round_trip(tmp_path):
    field = generators.generate("pits", size_um=5.0)
    write_gsf(tmp_path / "pits.gsf", field)
    data = (tmp_path / "pits.gsf").read_bytes()
    assert data.startswith(b"Gwyddion Simple Field 1.0\n")
    assert (len(data) - field.heights_um.size * 4) % 4 == 0
    loaded = load_heightfield(tmp_path / "pits.gsf")
    np.testing.assert_allclose(loaded.heights_um, field.heights_um, rtol=1e-6, atol=1e-9)
    assert loaded.dx_um == pytest.approx(field.dx_um, rel=1e-12)


def _gsf(header: str, values: np.ndarray) -> bytes:
    text = ("Gwyddion Simple Field 1.0\n" + header).encode()
    return text + b"\0" * (4 - len(text) % 4) + values.astype("<f4").tobytes()


def test_gsf_units_and_errors(tmp_path):
    values = np.arange(12, dtype=np.float64).reshape(3, 4) * 10  # nm
    path = tmp_path / "nm.gsf"
    path.write_bytes(_gsf("XRes = 4\nYRes = 3\nXReal = 200\nYReal = 150\nXYUnits = nm\nZUnits = nm\n", values))
    field = load_heightfield(path)
    np.testing.assert_allclose(field.heights_um, values / 1000, rtol=1e-6)
    assert field.dx_um == pytest.approx(0.05)

    path.write_bytes(_gsf("XRes = 4\nYRes = 3\nXReal = 200\nYReal = 150\nXYUnits = nm\nZUnits = nm\n", values)[:-6])
    with pytest.raises(GratNetError, match="truncated"):
        load_heightfield(path)
    path.write_bytes(_gsf("YRes = 3\nXReal = 2e-7\n", values))
    with pytest.raises(GratNetError, match="XRes"):
        load_heightfield(path)
    path.write_bytes(b"Gwyddion Simple Field 2.0\n\0\0")
    with pytest.raises(GratNetError, match="not a Gwyddion Simple Field"):
        load_heightfield(path)
    path.write_bytes(_gsf("XRes = 4\nYRes = 3\nXYUnits = furlong\nXReal = 1\n", values))
    with pytest.raises(GratNetError, match="furlong"):
        load_heightfield(path)

    # Rows twice as far apart as columns: resampled to square pixels of the finer spacing.
    path.write_bytes(_gsf("XRes = 4\nYRes = 3\nXReal = 4e-6\nYReal = 6e-6\n", np.ones((3, 4))))
    field = load_heightfield(path)
    assert field.shape == (6, 4) and field.dx_um == pytest.approx(1.0)
    assert "resampled" in field.source


def _png16(path: Path, pixels: np.ndarray, colour: int) -> None:
    """A 16-bit PNG written by hand (Pillow cannot write 16-bit colour), rows using all five filters."""
    rows, columns = pixels.shape[:2]
    raw = pixels.astype(">u2").reshape(rows, -1).view(np.uint8)
    step = raw.shape[1] // columns
    stream, prior = bytearray(), np.zeros(raw.shape[1], np.int64)
    for index, line in enumerate(raw.astype(np.int64)):
        kind = index % 5
        left = np.concatenate([np.zeros(step, np.int64), line[:-step]])
        upper_left = np.concatenate([np.zeros(step, np.int64), prior[:-step]])
        estimate = left + prior - upper_left
        near_left, near_up, near_corner = abs(estimate - left), abs(estimate - prior), abs(estimate - upper_left)
        paeth = np.where((near_left <= near_up) & (near_left <= near_corner), left,
                         np.where(near_up <= near_corner, prior, upper_left))
        predictor = [0 * line, left, prior, (left + prior) // 2, paeth][kind]
        stream += bytes([kind]) + ((line - predictor) & 255).astype(np.uint8).tobytes()
        prior = line

    def chunk(kind: bytes, body: bytes) -> bytes:
        return struct.pack(">I", len(body)) + kind + body + struct.pack(">I", zlib.crc32(kind + body))

    header = struct.pack(">IIBBBBB", columns, rows, 16, colour, 0, 0, 0)
    path.write_bytes(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", header) + chunk(b"IDAT", zlib.compress(bytes(stream)))
                     + chunk(b"IEND", b""))


def test_png_8_and_16_bit_with_scale(tmp_path):
    grey = np.array([[0, 51, 255], [102, 204, 153]], np.uint8)
    Image.fromarray(grey).save(tmp_path / "g8.png")
    options = LoadOptions(dx_um=0.1, height_scale_um=0.5)
    field = load_heightfield(tmp_path / "g8.png", options)
    np.testing.assert_allclose(field.heights_um, grey / 255 * 0.5)
    assert field.dx_um == 0.1

    Image.fromarray(np.stack([grey] * 3 + [np.full_like(grey, 255)], -1)).save(tmp_path / "rgba8.png")
    np.testing.assert_allclose(load_heightfield(tmp_path / "rgba8.png", options).heights_um, grey / 255 * 0.5)

    grey16 = np.array([[0, 1000, 65535], [30000, 40000, 50000]], np.uint16)
    Image.fromarray(grey16).save(tmp_path / "g16.png")
    np.testing.assert_allclose(load_heightfield(tmp_path / "g16.png", options).heights_um, grey16 / 65535 * 0.5)

    rng = np.random.default_rng(0)
    colour = rng.integers(0, 65536, (5, 4, 3))
    _png16(tmp_path / "rgb16.png", colour, 2)
    luminance = colour @ np.array([0.2126, 0.7152, 0.0722]) / 65535
    np.testing.assert_allclose(load_heightfield(tmp_path / "rgb16.png", options).heights_um, luminance * 0.5)
    green = load_heightfield(tmp_path / "rgb16.png", LoadOptions(dx_um=0.1, height_scale_um=1.0, channel="G"))
    np.testing.assert_allclose(green.heights_um, colour[..., 1] / 65535)

    with pytest.raises(GratNetError, match="--dx-um and --height-scale-um"):
        load_heightfield(tmp_path / "g8.png")
    (tmp_path / "cut.png").write_bytes((tmp_path / "g16.png").read_bytes()[:40])
    with pytest.raises(GratNetError, match="cut.png"):
        load_heightfield(tmp_path / "cut.png", options)


def test_exr_luminance_with_scale(tmp_path):
    import OpenEXR

    values = np.linspace(0, 1, 12, dtype=np.float32).reshape(3, 4)
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    with OpenEXR.File(header, {"Y": values}) as exr:
        exr.write(str(tmp_path / "h.exr"))
    field = load_heightfield(tmp_path / "h.exr", LoadOptions(dx_um=0.2, height_scale_um=2.0))
    np.testing.assert_allclose(field.heights_um, values * 2.0, rtol=1e-6)
    with pytest.raises(GratNetError, match="no channel 'Z'"):
        load_heightfield(tmp_path / "h.exr", LoadOptions(dx_um=0.2, height_scale_um=2.0, channel="Z"))


@pytest.mark.skipif(not AFM_PNG.exists(), reason="shared AFM example not present")
def test_shared_afm_png_loads():
    # Scale from the data README (approximate): ~0.1 µm pixels, white = 0.375 µm.
    field = load_heightfield(AFM_PNG, LoadOptions(dx_um=0.1, height_scale_um=0.375))
    assert field.shape == (100, 100)
    assert field.size_um == pytest.approx((10.0, 10.0))
    assert 0.1 < field.span_um <= 0.375


def test_preview_png(tmp_path):
    preview_png(generators.generate("corner_cube", size_um=4.0), tmp_path / "cc.png")
    with Image.open(tmp_path / "cc.png") as image:
        assert image.format == "PNG" and image.size[0] > 100


# --------------------------------------------------------------------------------------------------
# Command line


def test_cli_generate_writes_field_and_config(tmp_path, capsys):
    out = tmp_path / "blazed.npz"
    assert main(["heightfield", "generate", "blazed", "--size-um", "5", "--out", str(out)]) == 0
    field = load_heightfield(out)
    assert field.span_um == pytest.approx(0.25, abs=0.01)
    config = json.loads((tmp_path / "blazed.config.json").read_text())
    assert config["generator"] == "blazed" and config["parameters"]["period_um"] == 2.5
    assert "wrote" in capsys.readouterr().out


def test_cli_convert_preview_and_list(tmp_path, capsys):
    np.save(tmp_path / "h.npy", np.outer(np.arange(5.0), np.ones(6)))
    assert main(["heightfield", "convert", str(tmp_path / "h.npy"), "--dx-um", "0.2",
                 "--out", str(tmp_path / "h.gsf")]) == 0
    assert load_heightfield(tmp_path / "h.gsf").dx_um == pytest.approx(0.2)
    assert main(["heightfield", "preview", str(tmp_path / "h.gsf"), "--out", str(tmp_path / "p.png")]) == 0
    assert (tmp_path / "p.png").exists() and (tmp_path / "p.config.json").exists()
    assert main(["heightfield", "list"]) == 0
    assert "--max-height-um" in capsys.readouterr().out


@pytest.mark.parametrize("argv", [
    ["generate", "blazed", "--period-um", "-1", "--out", "x.npz"],
    ["convert", "missing.npy", "--out", "x.npz"],
    ["generate", "pits", "--out", "x.txt"],
])
def test_cli_bad_input_is_one_line_and_exit_2(tmp_path, capsys, monkeypatch, argv):
    monkeypatch.chdir(tmp_path)
    assert main(["heightfield", *argv]) == 2
    error = capsys.readouterr().err
    assert error.startswith("gratnet heightfield: error: ") and error.count("\n") == 1
    assert not list(tmp_path.iterdir())
