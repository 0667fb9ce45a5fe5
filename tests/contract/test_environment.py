"""The environment-map contract (gratnet/environment.py, issue 43), analytically and in numpy:

- frame: map coordinates ↔ directions round trip, the documented axes (x = 0 along +y, row 0 at +z), rotation;
- lookup: texel (r, c) met exactly at x = (c + ½)/W, y = r/(H − 1); horizontal wrap; constant maps stay constant;
- distribution: the solid-angle pdf integrates to 1 over the sphere (a θ-φ grid and uniform Monte Carlo), the
  samples' histogram matches it (χ²), sample's pdf equals pdf, and every lit direction has pdf > 0;
- specs and files: every bad input is one GratNetError line before any pixel is read, nothing is written; a
  Radiance .hdr (flat and run-length encoded) decodes; the shipped maps load within their budget.

Mitsuba's own ``envmap.eval`` against :meth:`Environment.radiance`: tests/runtime/test_mitsuba_environment.py.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from gratnet.environment import (
    CONSTANT_SHAPE,
    ENVIRONMENTS_FOLDER,
    MAX_HEIGHT,
    Environment,
    load_environment,
    read_radiance_map,
    texel_coordinates,
)
from gratnet.errors import GratNetError


def _random_map(height: int = 8, seed: int = 0) -> np.ndarray:
    return np.random.default_rng(seed).random((height, 2 * height, 3)).astype(np.float32)


def _unit(rng: np.random.Generator, count: int) -> np.ndarray:
    values = rng.normal(size=(count, 3))
    return values / np.linalg.norm(values, axis=1, keepdims=True)


def _rz(degrees: float) -> np.ndarray:
    c, s = math.cos(math.radians(degrees)), math.sin(math.radians(degrees))
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _write_exr(path: Path, values: np.ndarray) -> None:
    import OpenEXR

    with OpenEXR.File({"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage},
                      {"RGB": values.astype(np.float32)}) as exr:
        exr.write(str(path))


def _rgbe(values: np.ndarray) -> np.ndarray:
    """Float RGB → RGBE bytes (Walter's float2rgbe)."""
    largest = values.max(axis=-1)
    mantissa, exponent = np.frexp(largest)
    scale = np.where(largest > 1e-32, mantissa * 256.0 / np.where(largest > 0, largest, 1.0), 0.0)
    result = np.zeros((*values.shape[:-1], 4), np.uint8)
    result[..., :3] = np.floor(values * scale[..., None]).astype(np.uint8)
    result[..., 3] = np.where(largest > 1e-32, exponent + 128, 0)
    return result


def _run_length(line: np.ndarray) -> bytes:
    """One channel of a scanline in Radiance's new-style RLE: runs (128 + n, byte) of 3 … 127 equal bytes,
    literals (n, bytes…) of 1 … 128."""
    out, index, size = bytearray(), 0, len(line)
    while index < size:
        run = 1
        while index + run < size and run < 127 and line[index + run] == line[index]:
            run += 1
        if run >= 3:
            out += bytes([128 + run, int(line[index])])
            index += run
            continue
        start = index
        while index < size and index - start < 128 and not (
                index + 2 < size and line[index] == line[index + 1] == line[index + 2]):
            index += 1
        out += bytes([index - start, *(int(v) for v in line[start:index])])
    return bytes(out)


def _write_hdr(path: Path, values: np.ndarray, *, encoded: bool) -> np.ndarray:
    """A Radiance file (flat, or new-style RLE); returns the values its RGBE bytes stand for."""
    rgbe = _rgbe(values)
    height, width = values.shape[:2]
    body = bytearray()
    for row in rgbe:
        if encoded:
            body += bytes([2, 2, width >> 8, width & 255])
            for channel in range(4):
                body += _run_length(row[:, channel])
        else:
            body += row.tobytes()
    path.write_bytes(f"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\nEXPOSURE=1\n\n-Y {height} +X {width}\n".encode()
                     + bytes(body))
    exponent = rgbe[..., 3].astype(np.int32)
    return rgbe[..., :3] * np.where(exponent > 0, np.ldexp(1.0, exponent - 136), 0.0)[..., None]


# ----------------------------------------------------------------------------------------------
# Frame and lookup


@pytest.mark.parametrize("rotation", [0.0, 90.0, 37.5, -200.0])
def test_directions_and_map_coordinates_round_trip(rotation: float) -> None:
    environment = Environment("test", _random_map(), rotation_degrees=rotation)
    directions = _unit(np.random.default_rng(1), 2000)
    x, y = environment.map_coordinates(directions)
    assert np.all((x >= 0.0) & (x < 1.0) & (y >= 0.0) & (y <= 1.0))
    np.testing.assert_allclose(environment.directions(x, y), directions, atol=1e-12)
    grid_x, grid_y = np.meshgrid(np.linspace(0.0, 0.999, 37), np.linspace(0.01, 0.99, 23))
    back_x, back_y = environment.map_coordinates(environment.directions(grid_x, grid_y))
    np.testing.assert_allclose(back_x, grid_x, atol=1e-12)
    np.testing.assert_allclose(back_y, grid_y, atol=1e-12)


def test_axes_are_as_documented() -> None:
    """x = 0 looks along +y, x = 0.25 along +x; y = 0 is +z (zenith), y = 1 is −z; φ = 90° − 360°·x + ρ."""
    environment = Environment("test", _random_map())
    x, y = environment.map_coordinates(np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0],
                                                 [0.0, 0.0, -1.0], [0.0, -1.0, 0.0]]))
    np.testing.assert_allclose(x[:2], [0.0, 0.25], atol=1e-15)
    np.testing.assert_allclose(x[4], 0.5, atol=1e-15)
    np.testing.assert_allclose(y, [0.5, 0.5, 0.0, 1.0, 0.5], atol=1e-15)
    rotated = Environment("test", _random_map(), rotation_degrees=30.0)
    phi = math.radians(90.0 - 360.0 * 0.1 + 30.0)
    np.testing.assert_allclose(rotated.directions(0.1, 0.5), [math.cos(phi), math.sin(phi), 0.0], atol=1e-12)


def test_texels_are_met_exactly_at_their_coordinates_and_columns_wrap() -> None:
    values = _random_map(8, seed=2).astype(np.float64)  # (expected values in float64, as radiance computes)
    environment = Environment("test", values, scale=2.0)
    height, width = environment.shape
    x, y = texel_coordinates(height, width)
    # Rows 1 … H − 2 (the pole rows are met only in the limit: every azimuth meets at a pole).
    inner = environment.radiance(environment.directions(x[1:-1], y[1:-1]))
    np.testing.assert_allclose(inner, 2.0 * values[1:-1], rtol=1e-12, atol=1e-12)
    near_zenith = environment.radiance(environment.directions(x[0], 1e-9))
    np.testing.assert_allclose(near_zenith, 2.0 * values[0], rtol=1e-6)
    # x = 0 lies halfway between the last column's centre and the first's: their mean (wrap).
    row = 3
    got = environment.radiance(environment.directions(0.0, row / (height - 1)))
    np.testing.assert_allclose(got, values[row, 0] + values[row, -1], rtol=1e-12)  # 2 × mean
    # Rows are corner-aligned: halfway between rows r and r + 1 vertically at a column centre.
    got = environment.radiance(environment.directions((5 + 0.5) / width, (row + 0.5) / (height - 1)))
    np.testing.assert_allclose(got, values[row, 5] + values[row + 1, 5], rtol=1e-12)
    # The nadir (y = 1) is the last row (Mitsuba would wrap to row 0 there: documented).
    # (0, −0, −1): x = ½, halfway between the centres of columns W/2 − 1 and W/2.
    np.testing.assert_allclose(environment.radiance([0.0, -1e-300, -1.0]),
                               values[-1, width // 2 - 1] + values[-1, width // 2], rtol=1e-12)


def test_rotation_turns_features_about_plus_z() -> None:
    values = np.full((16, 32, 3), 0.1, np.float32)
    values[5, 7] = (10.0, 20.0, 30.0)
    plain = Environment("test", values)
    directions = _unit(np.random.default_rng(3), 500)
    for rotation in (0.0, 90.0, 33.0, -120.0):
        turned = Environment("test", values, rotation_degrees=rotation)
        moved = directions @ _rz(rotation).T
        np.testing.assert_allclose(turned.radiance(moved), plain.radiance(directions), rtol=1e-9, atol=1e-12)
        np.testing.assert_allclose(turned.pdf(moved), plain.pdf(directions), rtol=1e-9)
    # The bright texel's direction turns by +90° in azimuth: +x goes to +y.
    x, y = texel_coordinates(16, 32)
    before = plain.directions(x[5, 7], y[5, 7])
    after = Environment("test", values, rotation_degrees=90.0).directions(x[5, 7], y[5, 7])
    np.testing.assert_allclose(after, [-before[1], before[0], before[2]], atol=1e-15)


def test_a_constant_environment_is_constant_and_uniformly_sampled() -> None:
    environment = load_environment("0.5,0.25,2", rotation_degrees=17.0, scale=3.0)
    assert environment is not None and environment.name == "constant"
    assert environment.shape == CONSTANT_SHAPE
    directions = _unit(np.random.default_rng(4), 3000)
    np.testing.assert_allclose(environment.radiance(directions), np.broadcast_to([1.5, 0.75, 6.0], (3000, 3)),
                               rtol=1e-12)
    grey = load_environment("0.2")
    assert grey is not None
    np.testing.assert_allclose(grey.radiance(directions), 0.2, rtol=1e-7)  # the float32 of 0.2
    np.testing.assert_allclose(np.mean(grey.pdf(directions)) * 4.0 * math.pi, 1.0, atol=0.03)
    assert load_environment("0") is None and load_environment("0,0,0") is None and load_environment(" None ") is None


# ----------------------------------------------------------------------------------------------
# Distribution


def _peaked_environment() -> Environment:
    values = np.full((16, 32, 3), 0.02, np.float32)
    values[3, 10] = (50.0, 40.0, 30.0)  # a sun
    values[12, 31] = (0.0, 5.0, 0.0)  # green only, on the wrap column
    values[0, :] = (2.0, 2.0, 2.0)  # a bright zenith row
    return Environment("peaked", values, rotation_degrees=25.0, scale=0.5)


def test_pdf_integrates_to_one_over_the_sphere() -> None:
    environment = _peaked_environment()
    rows, columns = 900, 1800  # midpoint rule in θ, φ: 30 × 56 points per distribution cell
    theta = (np.arange(rows) + 0.5) * math.pi / rows
    phi = (np.arange(columns) + 0.5) * 2.0 * math.pi / columns
    t, p = np.meshgrid(theta, phi, indexing="ij")
    directions = np.stack([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)], axis=-1)
    weights = np.sin(t) * (math.pi / rows) * (2.0 * math.pi / columns)
    assert np.sum(environment.pdf(directions) * weights) == pytest.approx(1.0, abs=2e-3)
    uniform = _unit(np.random.default_rng(5), 400_000)
    assert np.mean(environment.pdf(uniform)) * 4.0 * math.pi == pytest.approx(1.0, abs=0.03)


def test_samples_follow_the_pdf() -> None:
    from scipy import stats

    environment = _peaked_environment()
    rng = np.random.default_rng(6)
    count = 300_000
    directions, pdf = environment.sample(rng.random(count), rng.random(count))
    np.testing.assert_allclose(np.linalg.norm(directions, axis=1), 1.0, atol=1e-12)
    inside = np.isfinite(pdf) & (pdf > 0.0)
    assert inside.all()
    np.testing.assert_allclose(pdf, environment.pdf(directions), rtol=1e-6)
    # Histogram over a 12 × 24 grid in (θ, φ) against the pdf integrated over each bin (midpoint rule in θ, φ:
    # pdf · sin θ stays bounded at the poles, where the pdf alone does not).
    bins_theta, bins_phi = 12, 24
    theta_edges = np.linspace(0.0, math.pi, bins_theta + 1)
    phi_edges = np.linspace(-math.pi, math.pi, bins_phi + 1)
    observed, _, _ = np.histogram2d(np.arccos(np.clip(directions[:, 2], -1.0, 1.0)),
                                    np.arctan2(directions[:, 1], directions[:, 0]), bins=(theta_edges, phi_edges))
    fine = 40  # points per bin and axis
    theta = (np.arange(bins_theta * fine) + 0.5) / (bins_theta * fine) * math.pi
    phi = (np.arange(bins_phi * fine) + 0.5) / (bins_phi * fine) * 2.0 * math.pi - math.pi
    tt, pp = np.meshgrid(theta, phi, indexing="ij")
    density = environment.pdf(np.stack([np.sin(tt) * np.cos(pp), np.sin(tt) * np.sin(pp), np.cos(tt)], axis=-1))
    cell = (math.pi / (bins_theta * fine)) * (2.0 * math.pi / (bins_phi * fine))
    expected = (density * np.sin(tt)).reshape(bins_theta, fine, bins_phi, fine).sum(axis=(1, 3)) * cell * count
    assert expected.sum() == pytest.approx(count, rel=5e-3)
    keep = expected > 5.0
    chi2 = np.sum((observed[keep] - expected[keep]) ** 2 / expected[keep])
    assert stats.chi2.sf(chi2, int(keep.sum()) - 1) > 1e-4, chi2


def test_every_direction_that_can_be_lit_has_a_positive_pdf() -> None:
    """One texel lit on black: wherever the bilinear radiance is > 0, the pdf is > 0 (the max-weight rule)."""
    for row, column in ((0, 0), (4, 13), (7, 15), (6, 0)):
        values = np.zeros((8, 16, 3), np.float32)
        values[row, column, 2] = 1.0  # blue only: its luminance is small, but positive
        environment = Environment("single", values, rotation_degrees=10.0)
        directions = _unit(np.random.default_rng(row * 16 + column), 100_000)
        lit = environment.radiance(directions)[:, 2] > 0.0
        assert lit.sum() > 50
        assert np.all(environment.pdf(directions)[lit] > 0.0)


# ----------------------------------------------------------------------------------------------
# Specs and files


def test_shipped_maps_load_within_their_budget() -> None:
    for name in ("sky", "studio"):
        path = ENVIRONMENTS_FOLDER / f"{name}.exr"
        assert path.stat().st_size <= 400_000
        environment = load_environment(name.upper(), rotation_degrees=10.0)
        assert environment is not None and environment.name == name
        values = environment.radiance_map
        height, width = environment.shape
        assert width == 2 * height and 4 <= height <= 1024
        assert values.dtype == np.float32 and np.all(np.isfinite(values)) and values.min() >= 0.0
        assert "make_environments.py" in environment.source and "\n" not in environment.source
        environment.distribution()
    sky = load_environment("sky")
    assert sky is not None
    row, column = np.unravel_index(np.argmax(sky.radiance_map[..., 1]), sky.shape)
    x, y = texel_coordinates(*sky.shape)
    sun = sky.directions(x[row, column], y[row, column])
    assert 35.0 <= math.degrees(math.asin(sun[2])) <= 45.0  # the sun's elevation
    assert np.all(sky.radiance_map[-1] > 0.0)  # a lit ground below the horizon


def test_exr_and_hdr_files_load(tmp_path: Path) -> None:
    values = _random_map(8, seed=7) * 3.0
    _write_exr(tmp_path / "map.exr", values)
    environment = load_environment(str(tmp_path / "map.exr"), rotation_degrees=5.0, scale=2.0)
    assert environment is not None and environment.scale == 2.0 and environment.rotation_degrees == 5.0
    np.testing.assert_array_equal(environment.radiance_map, values)
    runs = np.repeat(_random_map(8, seed=8)[:, ::4], 4, axis=1) * 100.0  # runs of 4 equal texels, literals between
    runs[:, 1::8] *= 0.5
    for encoded in (False, True):
        path = tmp_path / f"map{int(encoded)}.hdr"
        expected = _write_hdr(path, runs, encoded=encoded)
        read, source = read_radiance_map(path)
        np.testing.assert_allclose(read, expected, rtol=1e-7)
        assert np.all(np.abs(read - runs) <= runs.max(axis=-1, keepdims=True) / 64)  # 8 bits of the largest
        assert str(path) in source
    assert len(_run_length(_rgbe(runs)[0, :, 3])) < 16  # the encoded file did use runs


def _bad(tmp_path: Path) -> dict[str, tuple[str, dict[str, float], str]]:
    """name → (spec, keywords, expected part of the message), the files written into ``tmp_path``."""
    values = _random_map(8)
    cases: dict[str, tuple[str, dict[str, float], str]] = {}
    for name, texel, value in (("nan", (2, 5, 1), np.nan), ("inf", (0, 3, 0), np.inf), ("negative", (7, 1, 2), -1.0)):
        bad = values.copy()
        bad[texel] = value
        bad[7, 15, 0] = value  # a later one: the first is named
        _write_exr(tmp_path / f"{name}.exr", bad)
        row, column, channel = texel
        cases[name] = (str(tmp_path / f"{name}.exr"), {}, f"at row {row}, column {column}, channel {'RGB'[channel]}")
    _write_exr(tmp_path / "wide.exr", np.ones((8, 24, 3)))
    cases["aspect"] = (str(tmp_path / "wide.exr"), {}, "twice as wide as high, got 24×8")
    _write_exr(tmp_path / "small.exr", np.ones((2, 4, 3)))
    cases["small"] = (str(tmp_path / "small.exr"), {}, "at least 8×4")
    _write_exr(tmp_path / "zero.exr", np.zeros((8, 16, 3)))
    cases["all zero"] = (str(tmp_path / "zero.exr"), {}, "all 0")
    (tmp_path / "huge.hdr").write_bytes(b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y 5000 +X 10000\n\x02\x02")
    cases["too large"] = (str(tmp_path / "huge.hdr"), {}, f"at most {2 * MAX_HEIGHT}×{MAX_HEIGHT}")
    (tmp_path / "short.hdr").write_bytes(b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y 8 +X 16\n\x02\x02\x00\x10\x81")
    cases["truncated hdr"] = (str(tmp_path / "short.hdr"), {}, "truncated or corrupt")
    (tmp_path / "xyz.hdr").write_bytes(b"#?RADIANCE\nFORMAT=32-bit_rle_xyze\n\n-Y 8 +X 16\n")
    cases["xyze"] = (str(tmp_path / "xyz.hdr"), {}, "only 32-bit_rle_rgbe")
    (tmp_path / "flipped.hdr").write_bytes(b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n+Y 8 +X 16\n")
    cases["orientation"] = (str(tmp_path / "flipped.hdr"), {}, "-Y HEIGHT +X WIDTH")
    (tmp_path / "text.hdr").write_text("hello\n")
    cases["not hdr"] = (str(tmp_path / "text.hdr"), {}, "not a Radiance .hdr file")
    (tmp_path / "text.exr").write_text("hello\n")
    cases["not exr"] = (str(tmp_path / "text.exr"), {}, "not an OpenEXR file")
    (tmp_path / "cut.exr").write_bytes((tmp_path / "nan.exr").read_bytes()[:300])
    cases["truncated exr"] = (str(tmp_path / "cut.exr"), {}, "cut.exr")
    (tmp_path / "folder.exr").mkdir()
    cases["folder"] = (str(tmp_path / "folder.exr"), {}, "is not a regular file")
    cases["missing"] = (str(tmp_path / "missing.exr"), {}, "does not exist")
    cases["png"] = (str(tmp_path / "map.png"), {}, "expects none, sky, studio")
    cases["word"] = ("skyy", {}, "expects none, sky, studio")
    cases["negative radiance"] = ("-1", {}, "expects none")
    cases["two numbers"] = ("1,2", {}, "expects none")
    cases["nan radiance"] = ("nan", {}, "expects none")
    cases["rotation"] = ("sky", {"rotation_degrees": math.inf}, "rotation must be a finite")
    cases["scale"] = ("1", {"scale": -1.0}, "scale must be a finite number ≥ 0")
    cases["scale nan"] = ("none", {"scale": math.nan}, "scale must be a finite number ≥ 0")
    return cases


def test_bad_input_is_one_line_and_writes_nothing(tmp_path: Path) -> None:
    cases = _bad(tmp_path)
    before = sorted(p.name for p in tmp_path.iterdir())
    for name, (spec, keywords, expected) in cases.items():
        with pytest.raises(GratNetError) as caught:
            load_environment(spec, keywords.get("rotation_degrees", 0.0), keywords.get("scale", 1.0))
        message = str(caught.value)
        assert expected in message and "\n" not in message, (name, message)
    assert sorted(p.name for p in tmp_path.iterdir()) == before


def test_an_environment_checks_its_own_map() -> None:
    with pytest.raises(GratNetError, match=r"\(H, W, 3\)"):
        Environment("x", np.ones((8, 16)))
    with pytest.raises(GratNetError, match="finite and ≥ 0"):
        Environment("x", np.full((8, 16, 3), np.nan))
    environment = Environment("x", np.ones((8, 16, 3)), scale=0.0)  # scale 0: dark, still sampled
    assert environment.radiance([0.0, 0.0, 1.0]).max() == 0.0
    assert environment.sample(0.5, 0.5)[1] > 0.0
    with pytest.raises(ValueError):
        environment.radiance_map[0, 0, 0] = 2.0  # read-only


def test_a_too_large_exr_is_refused_from_its_header_alone(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    import OpenEXR

    import gratnet.environment as environment_module

    _write_exr(tmp_path / "map.exr", np.ones((8, 16, 3)))
    monkeypatch.setattr(environment_module, "MAX_HEIGHT", 4)  # so that a small file stands for a huge one
    opened: list[bool] = []
    original = OpenEXR.File

    def spy(*arguments: object, header_only: bool = False, **keywords: object) -> object:
        opened.append(header_only)
        return original(*arguments, header_only=header_only, **keywords)

    monkeypatch.setattr(OpenEXR, "File", spy)
    with pytest.raises(GratNetError, match="at most 8×4"):
        load_environment(str(tmp_path / "map.exr"))
    assert opened == [True]  # the header only: no pixel was decoded


@pytest.mark.parametrize(("spec", "phi"), [("sky", 30.0), ("studio", -120.0), ("sky", 179.0)])
def test_the_default_turn_puts_the_brightest_direction_at_the_lights_azimuth(spec, phi):
    """``--environment-rotation`` left out: the environment turns so that its sun (key softbox) stands at the
    azimuth of the light that shows the material's diffraction; a given rotation stands as it is."""
    from viewer.scene_config import RenderConfig, environment_of, environment_rotation

    config = RenderConfig(environment=spec, light_phi_degrees=phi)
    turned = environment_of(config)
    assert turned.rotation_degrees == environment_rotation(config)
    height, width = turned.shape
    texel = 360.0 / width
    difference = (turned.brightest_azimuth_degrees() - phi + 180.0) % 360.0 - 180.0
    assert abs(difference) <= texel
    given = RenderConfig(environment=spec, light_phi_degrees=phi, environment_rotation=12.5)
    assert environment_rotation(given) == 12.5 and environment_of(given).rotation_degrees == 12.5
    assert environment_rotation(RenderConfig(environment="none", light_phi_degrees=phi)) == 0.0
