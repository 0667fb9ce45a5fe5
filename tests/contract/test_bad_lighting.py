"""Bad lighting input (issue 43): the light's intensity, the environment light and the seed, in ``gratnet render``
and ``gratnet mitsuba-render`` (the same flags, checked by the same function: viewer.scene_config.check_lighting).
Each is one line and exit status 2 before any model is read or GL work starts, and nothing is written."""

from __future__ import annotations

import pytest

from tests.helpers import assert_nothing_written, assert_one_clear_error, run_cli

RENDER = ["render", "--size", "8,8", "--weights-path", "texture", "--quiet"]
MITSUBA = ["mitsuba-render", "--size", "8,8", "--spp", "1", "--quiet"]

needs_mitsuba = pytest.mark.skipif(__import__("importlib").util.find_spec("mitsuba") is None,
                                   reason="the mitsuba extra is not installed (pip install -e '.[mitsuba]')")

CASES: dict[str, tuple[list[str], str]] = {
    "mitsuba-render seed negative": ([*MITSUBA, "--seed", "-1"], "--seed"),
    "mitsuba-render light intensity negative": ([*MITSUBA, "--light-intensity", "-1"], "--light-intensity"),
    # gratnet render's environment light (issue 43): the same flags and checks as mitsuba-render's
    "render environment unknown": ([*RENDER, "--environment", "cloudy"], "--environment"),
    "render environment negative": ([*RENDER, "--environment", "-1"], "--environment"),
    "render environment nan": ([*RENDER, "--environment", "nan,1,1"], "--environment"),
    "render environment missing file": ([*RENDER, "--environment", "missing.exr"], "missing.exr"),
    "render environment scale negative": ([*RENDER, "--environment", "sky", "--environment-scale", "-1"],
                                          "--environment-scale"),
    "render environment rotation inf": ([*RENDER, "--environment", "sky", "--environment-rotation", "inf"],
                                        "--environment-rotation"),
    "render environment with slice": ([*RENDER, "--environment", "sky", "--slice"], "--slice"),
    "render environment skip dark": ([*RENDER, "--environment", "studio", "--skip-dark"], "--skip-dark"),
    "render environment spp 0": ([*RENDER, "--environment", "studio", "--spp", "0"], "--spp"),
    "render seed negative": ([*RENDER, "--environment", "studio", "--seed", "-1"], "--seed"),
    "render light intensity negative": ([*RENDER, "--light-intensity", "-1"], "--light-intensity"),
    "render environment sampling unknown": ([*RENDER, "--environment", "sky", "--environment-sampling", "uniform"],
                                            "--environment-sampling"),
    # Area lights (gratnet.area_lights): degenerate, unknown, malformed, too many, and --slice, which refuses them.
    "render area light unknown kind": ([*RENDER, "--area-light", "disc:0,0,1,0.1,1"], "--area-light"),
    "render area light no kind": ([*RENDER, "--area-light", "0,0,1,0.1,1"], "KIND:NUMBERS"),
    "render area light count": ([*RENDER, "--area-light", "sphere:0,0,1,0.1"], "sphere"),
    "render area light zero radius": ([*RENDER, "--area-light", "sphere:0,0,1,0,1"], "radius"),
    "render area light zero normal": ([*RENDER, "--area-light", "rect:0,0,1,0,0,0,1,1,1"], "normal"),
    "render area light zero width": ([*RENDER, "--area-light", "rect:0,0,1,0,0,-1,0,1,1"], "width"),
    "render area light negative radiance": ([*RENDER, "--area-light", "rect:0,0,1,0,0,-1,1,1,-1"], "radiance"),
    "render area light zero radiance": ([*RENDER, "--area-light", "sphere:0,0,1,0.1,0,0,0"], "radiance"),
    "render area light nan": ([*RENDER, "--area-light", "sphere:nan,0,1,0.1,1"], "--area-light"),
    "render area light far": ([*RENDER, "--area-light", "sphere:1e9,0,1,0.1,1"], "centre"),
    "render area light too many": ([*RENDER, *(["--area-light", "sphere:0,0,1,0.1,1"] * 9)], "at most 8"),
    "render area light slice": ([*RENDER, "--area-light", "sphere:0,0,1,0.1,1", "--slice"], "--slice"),
    "mitsuba-render area light zero radius": ([*MITSUBA, "--area-light", "sphere:0,0,1,0,1"], "radius"),
}


@pytest.mark.parametrize("case", [pytest.param(case, marks=needs_mitsuba) if case.startswith("mitsuba") else case
                                  for case in CASES])
def test_bad_lighting_is_one_line_before_any_work(tmp_path, capsys, monkeypatch, case):
    argv, needle = CASES[case]
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr("gratnet.modelfile.load_model",
                        lambda *a, **k: pytest.fail("work started before the lighting was checked"))
    code, stderr = run_cli([*argv, "--out", "out.png"], capsys)
    assert_one_clear_error(code, stderr, argv[0], needle)
    assert_nothing_written(tmp_path, set())


@pytest.mark.parametrize(("flags", "needle"), [
    (["--area-light", "sphere:0,0,1,0,1"], "radius"),
    (["--area-light", "sphere:0,0,1,0.1,1", "--render-path", "deferred", "--environment", "-1"], "environment"),
])
def test_the_viewer_refuses_bad_area_lights_in_one_line(tmp_path, capsys, monkeypatch, flags, needle):
    """gratnet view: a bad area light, or a bad environment beside one on the deferred path, is one line before any
    window."""
    monkeypatch.chdir(tmp_path)
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    code, stderr = run_cli(["view", *flags, "--max-frames", "1"], capsys)
    assert_one_clear_error(code, stderr, "view", needle)
    assert_nothing_written(tmp_path, set())


def test_a_bad_map_file_is_one_line(tmp_path, capsys, monkeypatch):
    """A map that is not twice as wide as high and one with a NaN texel: refused in one line."""
    import numpy as np

    from gratnet.environment import read_radiance_map

    monkeypatch.chdir(tmp_path)
    import OpenEXR

    def write(name: str, pixels: np.ndarray) -> str:
        header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
        channels = {name: np.ascontiguousarray(pixels[..., k]) for k, name in enumerate("RGB")}
        with OpenEXR.File(header, channels) as exr:
            exr.write(str(tmp_path / name))
        return name

    square = write("square.exr", np.ones((8, 8, 3), np.float32))
    broken = np.ones((8, 16, 3), np.float32)
    broken[3, 5, 1] = np.nan
    nan = write("nan.exr", broken)
    read_radiance_map(write("fine.exr", np.ones((8, 16, 3), np.float32)))  # the writer makes readable maps
    before = {path.name for path in tmp_path.iterdir()}
    for name, needle in ((square, "twice as wide as high"), (nan, "row 3, column 5")):
        code, stderr = run_cli([*RENDER, "--environment", name, "--out", "out.png"], capsys)
        assert_one_clear_error(code, stderr, "render", needle)
    assert_nothing_written(tmp_path, before)
