"""A material's quality points (issue 42; gratnet.quality, viewer.catalog): ``assets/NAME/model.npz`` is the accurate
point, ``assets/NAME/fast/model.npz`` the fast one, and ``--quality`` chooses between them in ``gratnet render``,
``compare``, ``mitsuba-render`` and ``view``, recorded in the config saved beside each output.

Every test builds its own assets folder of random models (tests/helpers.py ``two_point_material``) and points
viewer.catalog at it; the renders are 16×16 on the texture weights path and the forward render path (no probe).
"""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import numpy as np
import pytest

from gratnet.cli import main
from gratnet.errors import GratNetError
from gratnet.quality import ACCURATE, DEFAULT_QUALITY, FAST, POINT_FOLDERS, QUALITIES, VIEW_QUALITIES
from tests.helpers import ASSETS, two_point_material
from viewer import catalog
from viewer.screenshot import save_screenshot

#: A view of the plane that needs no default view (nothing reads a model before the render).
SCENE = ["--mesh", "plane", "--light", "30,90", "--camera", "0.15,-90,50", "--exposure", "5000", "--size", "16,16"]
RENDER = ["render", *SCENE, "--weights-path", "texture", "--render-path", "forward", "--quiet"]


@pytest.fixture
def assets(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """An assets folder, viewer.catalog's for the test: ``duo`` (accurate and fast points), ``solo`` (accurate)."""
    root = tmp_path / "assets"
    two_point_material(root, "duo")
    two_point_material(root, "solo", fast=False)
    monkeypatch.setattr(catalog, "ASSETS", root)
    return root


def one_error_line(capsys: pytest.CaptureFixture[str], command: str) -> str:
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"gratnet {command}: error: "), lines
    return lines[0]


# --------------------------------------------------------------------------------------------------
# The names and the catalog


def test_the_quality_names_are_defined_once_and_the_default_is_accurate():
    assert QUALITIES == (FAST, ACCURATE) and set(VIEW_QUALITIES) == {*QUALITIES, "auto"}
    assert DEFAULT_QUALITY == ACCURATE and set(POINT_FOLDERS) == set(QUALITIES)
    assert POINT_FOLDERS[ACCURATE] == ""  # the accurate point is the material's own model.npz: old paths keep working


def test_a_materials_points_are_listed_fastest_first(assets):
    assert catalog.material_points("duo") == {FAST: assets / "duo" / "fast" / "model.npz",
                                              ACCURATE: assets / "duo" / "model.npz"}
    assert list(catalog.material_points("duo")) == [FAST, ACCURATE]
    assert catalog.material_points("solo") == {ACCURATE: assets / "solo" / "model.npz"}
    with pytest.raises(GratNetError, match="not a shipped material"):
        catalog.material_points(str(assets / "duo" / "model.npz"))


def test_a_point_folder_is_no_material(assets, tmp_path):
    assert catalog.shipped_materials() == ["duo", "solo"]
    assert catalog.shipped_materials(tmp_path / "none") == []
    # The real assets too: a shipped fast point never shows up as a material of its own.
    assert FAST not in catalog.shipped_materials(ASSETS)


def test_a_quality_resolves_to_its_point_and_none_to_the_accurate_one(assets):
    assert catalog.material_point("duo") == (assets / "duo" / "model.npz", ACCURATE)
    assert catalog.material_point("duo", FAST) == (assets / "duo" / "fast" / "model.npz", FAST)
    assert catalog.resolve_material("duo", ACCURATE) == assets / "duo" / "model.npz"
    assert catalog.resolve_material("solo") == assets / "solo" / "model.npz"
    # The parameter instead of the module's folder: the real assets.
    assert catalog.resolve_material("cd", assets=ASSETS) == ASSETS / "cd" / "model.npz"


def test_a_missing_point_names_the_points_the_material_has(assets):
    with pytest.raises(GratNetError) as error:
        catalog.material_point("solo", FAST)
    assert str(error.value) == "--quality fast: solo has no fast point; its points: accurate (solo/model.npz)"
    with pytest.raises(GratNetError, match="--quality must be one of fast, accurate, got 'best'"):
        catalog.material_point("duo", "best")


def test_a_quality_with_a_model_file_is_refused_and_without_one_the_file_is_taken(assets):
    path = assets / "duo" / "fast" / "model.npz"
    assert catalog.material_point(str(path)) == (path, None)
    for quality in QUALITIES:  # the default's name too: nothing given is ignored
        with pytest.raises(GratNetError, match="chooses between a shipped material's points; .* is a model file"):
            catalog.material_point(str(path), quality)
    with pytest.raises(GratNetError, match="unknown material 'nope'.*choose duo, solo"):
        catalog.material_point("nope")


def test_messages_name_a_point_by_its_material(assets):
    assert catalog.model_label(assets / "duo" / "fast" / "model.npz") == "duo (fast)"
    assert catalog.model_label(assets / "duo" / "model.npz") == "duo"
    assert catalog.model_label(Path("elsewhere") / "mine.npz") == "mine.npz"


# --------------------------------------------------------------------------------------------------
# gratnet render, compare, mitsuba-render


def render_config(out: Path) -> dict:
    return json.loads(out.with_name(out.stem + ".config.json").read_text())


def test_render_takes_the_point_asked_for_and_records_it(ctx, assets, tmp_path, capsys):
    from PIL import Image

    pictures = {}
    for quality in (None, ACCURATE, FAST):
        out = tmp_path / f"{quality}.png"
        assert main([*RENDER, "--material", "duo", *(["--quality", quality] if quality else []),
                     "--out", str(out)]) == 0
        config = render_config(out)
        point = quality or ACCURATE
        assert config["render"]["quality"] == point
        assert config["model_file"] == str(catalog.material_points("duo")[point])
        with Image.open(out) as image:
            pictures[quality] = np.asarray(image)
    assert "wrote" in capsys.readouterr().out
    np.testing.assert_array_equal(pictures[None], pictures[ACCURATE])
    assert not np.array_equal(pictures[ACCURATE], pictures[FAST])  # another network drew it
    assert pictures[FAST].max() > 0


def test_render_of_a_model_file_records_no_quality(ctx, assets, tmp_path, capsys):
    out = tmp_path / "file.png"
    path = assets / "duo" / "fast" / "model.npz"
    assert main([*RENDER, "--material", str(path), "--out", str(out)]) == 0
    config = render_config(out)
    assert config["render"]["quality"] is None and config["model_file"] == str(path)
    assert "duo (fast)" in capsys.readouterr().out


@pytest.mark.parametrize(("arguments", "needle"), [
    (["--material", "solo", "--quality", FAST], "solo has no fast point; its points: accurate (solo/model.npz)"),
    (["--material", "{model}", "--quality", ACCURATE], "is a model file"),
    (["--material", "duo", "--quality", "best"], "invalid choice: 'best'"),
])
def test_render_refuses_a_point_it_cannot_take_before_any_work(assets, tmp_path, capsys, monkeypatch, arguments,
                                                                needle):
    monkeypatch.setattr("gratnet.modelfile.load_model", lambda *a, **k: pytest.fail("a model was read"))
    argv = [part.format(model=assets / "duo" / "model.npz") for part in arguments]
    out = tmp_path / "x.png"
    assert main(["render", "--size", "8,8", *argv, "--out", str(out)]) == 2
    assert needle in one_error_line(capsys, "render")
    assert not out.exists() and not (tmp_path / "x.config.json").exists()


def test_render_of_a_reference_alone_refuses_a_quality(assets, tmp_path, capsys):
    out = tmp_path / "x.png"
    assert main(["render", "--reference", str(tmp_path / "v.exr"), "--quality", FAST, "--out", str(out)]) == 2
    assert "has no network" in one_error_line(capsys, "render")


def cd_volume(path: Path) -> Path:
    """A tiny volume claiming the shipped cd surface (that ``two_point_material``'s models claim)."""
    from gratnet.modelfile import load_model
    from gratnet.volume import Volume, write_volume

    trained = load_model(ASSETS / "cd" / "model.npz").metadata["volume"]
    values = 10.0 ** np.random.default_rng(3).uniform(-9.0, -3.0, (3, 17, 17, 3))
    write_volume(path, Volume(values.astype(np.float32), {"scheme": "simple-max", "source": trained["source"],
                                                           "sigma_s_um": trained["sigma_s_um"]}))
    return path


def test_compare_scores_the_point_asked_for_and_records_it(ctx, assets, tmp_path):
    volume = cd_volume(tmp_path / "cd.exr")
    common = ["--reference", str(volume), "--meshes", "plane", "--width", "16", "--height", "16", "--spp", "1",
              "--weights-path", "texture", "--quiet"]
    for quality in (None, FAST):
        out = tmp_path / f"compare-{quality}"
        assert main(["compare", "duo", *common, *(["--quality", quality] if quality else []),
                     "--out", str(out)]) == 0
        config = json.loads((out / "compare.config.json").read_text())
        assert config["compare"]["quality"] == (quality or ACCURATE)
        assert config["model_file"] == str(catalog.material_points("duo")[quality or ACCURATE])
        assert json.loads((out / "compare.json").read_text())["quality"] == (quality or ACCURATE)


def test_compare_refuses_a_missing_point_before_any_work(assets, tmp_path, capsys, monkeypatch):
    monkeypatch.setattr("viewer.scene_config.load_reference", lambda *a, **k: pytest.fail("the volume was read"))
    out = tmp_path / "c"
    assert main(["compare", "solo", "--reference", "v.exr", "--quality", FAST, "--out", str(out)]) == 2
    assert "solo has no fast point" in one_error_line(capsys, "compare")
    assert not out.exists()


needs_mitsuba = pytest.mark.skipif(importlib.util.find_spec("mitsuba") is None,
                                   reason="the mitsuba extra is not installed (pip install -e '.[mitsuba]')")


@needs_mitsuba
def test_mitsuba_render_takes_the_point_asked_for_and_records_it(assets, tmp_path, capsys):
    out = tmp_path / "fast.png"
    argv = ["mitsuba-render", *SCENE[:-1], "4,4", "--spp", "1", "--variant", "scalar_rgb", "--quiet"]
    assert main([*argv, "--material", "duo", "--quality", FAST, "--out", str(out)]) == 0
    config = render_config(out)
    assert config["mitsuba_render"]["quality"] == FAST
    assert config["model_file"] == str(assets / "duo" / "fast" / "model.npz")
    assert "duo (fast)" in capsys.readouterr().out
    assert main([*argv, "--material", "solo", "--quality", FAST, "--out", str(tmp_path / "x.png")]) == 2
    assert "solo has no fast point" in one_error_line(capsys, "mitsuba-render")


# --------------------------------------------------------------------------------------------------
# gratnet view and the viewer


def test_the_viewer_renders_the_point_of_its_quality(ctx, assets, tmp_path):
    import dataclasses

    from viewer.app import ViewerApp
    from viewer.state import ViewerState

    state = ViewerState(material="duo", mesh="plane", camera_distance=0.15, camera_elevation=50.0, light_theta=30.0,
                        light_phi=90.0, exposure=5000.0)
    app = ViewerApp(ctx, state, size=(16, 16), weights_path="texture", render_path="forward", quality=FAST)
    try:
        assert app.point() == (assets / "duo" / "fast" / "model.npz", FAST)
        # The supply is handed the point's model file (the state on show keeps the material's name).
        supplied = app.supply.scene(dataclasses.replace(app.state, material=str(app.point()[0])), preview=False)
        assert supplied is not None and supplied[0].model.layer_sizes[1] == 8  # the fast net's hidden width
        assert app.state.material == "duo"
        fast = app.render_full().copy()
        shot = save_screenshot(app, tmp_path / "fast.png")
        saved = json.loads(shot.with_name("fast.config.json").read_text())
        assert saved["render"]["quality"] == FAST and saved["model_file"].endswith("duo/fast/model.npz")

        assert app.set_quality(ACCURATE) and not app.set_quality(ACCURATE)
        assert app.point()[1] == ACCURATE and app.image is not None and app.image.key != app.render_key()
        assert not np.array_equal(app.render_full(), fast)
        assert app.set_quality("auto") and app.point()[1] == ACCURATE  # auto: the accurate point (for now)

        app.set_quality(FAST)
        assert app.set(material="solo") and app.point() == (assets / "solo" / "model.npz", ACCURATE)
        with pytest.raises(GratNetError, match="must be one of fast, accurate, auto"):
            app.set_quality("best")
    finally:
        app.release()


@pytest.mark.parametrize(("arguments", "needle"), [
    (["--material", "solo", "--quality", FAST], "solo has no fast point"),
    (["--material", "{model}", "--quality", "auto"], "is a model file"),
    (["--material", "{model}", "--quality", FAST], "is a model file"),
])
def test_view_refuses_a_point_it_cannot_take_before_a_window_opens(assets, tmp_path, capsys, arguments, needle):
    argv = [part.format(model=assets / "duo" / "model.npz") for part in arguments]
    assert main(["view", *argv, "--max-frames", "1", "--screenshot-dir", str(tmp_path)]) == 2
    assert needle in one_error_line(capsys, "view")


def test_view_resolves_its_quality_against_the_material(assets):
    import argparse

    from viewer.view_cli import view_point

    def point(material: str, quality: str | None) -> tuple[str, str]:
        return view_point(argparse.Namespace(material=material, quality=quality))

    assert point("duo", None) == ("auto", "duo")
    assert point("duo", FAST) == (FAST, str(assets / "duo" / "fast" / "model.npz"))
    assert point("duo", ACCURATE) == (ACCURATE, "duo")
    model = str(assets / "solo" / "model.npz")
    assert point(model, None) == ("auto", model)  # a model file without --quality: itself


def test_gratnet_view_opens_on_the_point_of_its_quality(assets, display, tmp_path, monkeypatch):
    from gratnet.cli import build_parser
    from viewer.view_cli import open_window

    monkeypatch.setenv("MESA_SHADER_CACHE_DISABLE", "1")  # no compile child: the programs compile in the window
    view = ["view", "--material", "duo", *SCENE, "--weights-path", "texture", "--render-path", "forward",
            "--screenshot-dir", str(tmp_path)]
    for given, shown in ((["--quality", FAST], FAST), ([], ACCURATE)):
        with open_window(build_parser("view").parse_args([*view, *given])) as window:
            assert window.app.point() == (catalog.material_points("duo")[shown], shown)
            for _ in range(200):  # the first picture is the point's
                window.frame()
                if window.app.image is not None:
                    break
            assert window.app.image is not None and window.app.image.key == window.app.render_key()
            assert window.gl_errors == []
