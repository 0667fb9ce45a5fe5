"""The Mitsuba plugin as its users meet it (issues 35 and 36): material names, paths relative to the scene
file, the warning for a mesh without UVs, one-line errors, and Ctrl-C in ``gratnet mitsuba-render``.

- names: ``filename`` takes what ``gratnet render --material`` takes (shipped names, files);
- paths: a scene file in another folder names a model relative to itself (Mitsuba's file resolver);
- no UVs: one warning per mesh, on the ``gratnet.mitsuba`` logger, also seen by a plain Mitsuba script;
- errors: one line, the plugin's own, also out of Mitsuba's wrapping (``runtime.plugin_errors``) and from the
  command (exit 2);
- Ctrl-C: ``gratnet mitsuba-render`` stops within a second or two, exit 130, one line, nothing written.
"""

from __future__ import annotations

import logging
import os
import shutil
import signal
import subprocess
import sys
import textwrap
import threading
import time
from pathlib import Path

import pytest

from tests.helpers import REPO

pytest.importorskip("mitsuba", reason="the mitsuba extra is not installed")

from gratnet.errors import GratNetError  # noqa: E402
from mitsuba_plugin.bsdf import PROPERTIES, plugin_message  # noqa: E402
from mitsuba_plugin.runtime import llvm_usable, plugin_errors, set_variant  # noqa: E402
from viewer.catalog import ASSETS, shipped_materials  # noqa: E402

GRATNET = Path(sys.executable).parent / "gratnet"

#: A 0.1 m quad facing +z, with and without texture coordinates.
QUAD_WITH_UVS = ("v -0.05 -0.05 0\nv 0.05 -0.05 0\nv 0.05 0.05 0\nv -0.05 0.05 0\nvt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\n"
                 "vn 0 0 1\nf 1/1/1 2/2/1 3/3/1 4/4/1\n")
QUAD_WITHOUT_UVS = "v -0.05 -0.05 0\nv 0.05 -0.05 0\nv 0.05 0.05 0\nv -0.05 0.05 0\nvn 0 0 1\nf 1//1 2//1 3//1 4//1\n"


def _scene_xml(material: str, mesh: str = "") -> str:
    shape = f'<shape type="obj"><string name="filename" value="{mesh}"/>' if mesh else '<shape type="rectangle">'
    return textwrap.dedent(f"""\
        <scene version="3.0.0">
          <integrator type="direct"/>
          <sensor type="perspective">
            <transform name="to_world"><lookat origin="0, 0, 0.3" target="0, 0, 0" up="0, 1, 0"/></transform>
            <film type="hdrfilm"><integer name="width" value="4"/><integer name="height" value="4"/></film>
          </sensor>
          <emitter type="constant"/>
          {shape}<bsdf type="gratnet"><string name="filename" value="{material}"/></bsdf></shape>
        </scene>
        """)


# ------------------------------------------------------------------------------------------------
# names and paths


@pytest.mark.parametrize("name", ["cd", "paper-cd"])
def test_shipped_names_are_accepted(name: str) -> None:
    mi = set_variant("scalar_rgb")
    bsdf = mi.load_dict({"type": "gratnet", "filename": name})
    assert bsdf.model_path == ASSETS / name / "model.npz"


def test_a_scene_file_names_a_model_relative_to_itself(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A scene in scenes/ names models/mine.npz relative to its own folder; the current directory is elsewhere
    (neither the repository nor the scene's folder), so only the scene's folder can find it."""
    mi = set_variant("scalar_rgb")
    (tmp_path / "scenes" / "models").mkdir(parents=True)
    shutil.copy(ASSETS / "cd" / "model.npz", tmp_path / "scenes" / "models" / "mine.npz")
    (tmp_path / "scenes" / "scene.xml").write_text(_scene_xml("models/mine.npz"))
    (tmp_path / "elsewhere").mkdir()
    monkeypatch.chdir(tmp_path / "elsewhere")
    scene = mi.load_file(str(tmp_path / "scenes" / "scene.xml"))
    (shape,) = scene.shapes()
    assert Path(shape.bsdf().model_path) == tmp_path / "scenes" / "models" / "mine.npz"
    # Outside that scene the folder is not searched: the same relative name is not found, and the message
    # says where it looked.
    with pytest.raises(GratNetError) as caught, plugin_errors():
        mi.load_dict({"type": "gratnet", "filename": "models/mine.npz"})
    message = str(caught.value)
    assert message.startswith("gratnet BSDF: model file 'models/mine.npz' not found (looked in ")
    assert str(tmp_path / "elsewhere") in message and "\n" not in message


def test_a_path_relative_to_the_current_directory_still_works(monkeypatch: pytest.MonkeyPatch) -> None:
    mi = set_variant("scalar_rgb")
    monkeypatch.chdir(REPO)
    bsdf = mi.load_dict({"type": "gratnet", "filename": "assets/cd/model.npz"})
    assert Path(bsdf.model_path).resolve() == ASSETS / "cd" / "model.npz"


# ------------------------------------------------------------------------------------------------
# a mesh without UVs


def _render_quads(mi: object, objs: dict[str, Path], tangent_attribute: str = "") -> None:
    """The quads side by side (x = 0, 0.12, …), all with one shared gratnet BSDF, rendered twice."""
    shapes = {name: {"type": "obj", "filename": str(obj), "bsdf": {"type": "ref", "id": "material"},
                     "to_world": mi.ScalarTransform4f().translate([0.12 * index, 0.0, 0.0])}
              for index, (name, obj) in enumerate(objs.items())}
    middle = 0.06 * (len(objs) - 1)
    scene = mi.load_dict({
        "type": "scene", "integrator": {"type": "direct"}, "light": {"type": "constant"},
        "material": {"type": "gratnet", "filename": "cd", "tangent_attribute": tangent_attribute},
        "sensor": {"type": "perspective", "to_world": mi.ScalarTransform4f().look_at(
            origin=[middle, 0, 0.3], target=[middle, 0, 0], up=[0, 1, 0]), "fov": 60,
                   "film": {"type": "hdrfilm", "width": 8, "height": 4}}, **shapes})
    for _ in range(2):  # two renders: still one warning per mesh
        image = mi.render(scene, spp=1)
    import numpy as np

    columns = np.any(np.asarray(image) != 0, axis=(0, 2))
    assert columns[:3].any() and columns[-3:].any()  # each quad was hit


@pytest.mark.parametrize("variant", ["scalar_rgb", pytest.param("llvm_ad_rgb", marks=pytest.mark.skipif(
    not llvm_usable(), reason="Dr.Jit finds no LLVM ≥ 18"))])
def test_a_mesh_without_uvs_warns_once(tmp_path: Path, caplog: pytest.LogCaptureFixture, variant: str) -> None:
    """Two quads share one BSDF (so in llvm_ad_rgb one call sees lanes of both): only the one without UVs warns,
    once over two renders."""
    mi = set_variant(variant)
    (tmp_path / "bare.obj").write_text(QUAD_WITHOUT_UVS)
    (tmp_path / "mapped.obj").write_text(QUAD_WITH_UVS)
    with caplog.at_level(logging.WARNING, logger="gratnet.mitsuba"):
        _render_quads(mi, {"mapped": tmp_path / "mapped.obj"})
        assert not caplog.records  # UVs: Mitsuba's tangent is ∂p/∂u, no warning
        _render_quads(mi, {"mapped": tmp_path / "mapped.obj", "bare": tmp_path / "bare.obj"},
                      tangent_attribute="vertex_tangent")
    warnings = [record.getMessage() for record in caplog.records]
    assert len(warnings) == 1, warnings
    assert "mesh 'bare' has no UV coordinates and no 'vertex_tangent' attribute" in warnings[0]
    assert "direction of the diffraction, is arbitrary" in warnings[0]


def test_a_plain_mitsuba_script_sees_the_warning(tmp_path: Path) -> None:
    """No logging set up, no gratnet command: the warning still reaches stderr, once."""
    (tmp_path / "bare.obj").write_text(QUAD_WITHOUT_UVS)
    script = textwrap.dedent(f"""\
        import mitsuba as mi
        mi.set_variant("scalar_rgb")
        import mitsuba_plugin.runtime
        mitsuba_plugin.runtime.set_variant("scalar_rgb")
        scene = mi.load_file({str(tmp_path / "scene.xml")!r})
        mi.render(scene, spp=1)
        mi.render(scene, spp=1)
        """)
    (tmp_path / "scene.xml").write_text(_scene_xml("paper-cd", "bare.obj"))
    done = subprocess.run([sys.executable, "-c", script], cwd=tmp_path, capture_output=True, text=True, timeout=120,
                          env={**os.environ, "PYTHONPATH": str(REPO)})
    assert done.returncode == 0, done.stderr
    lines = [line for line in done.stderr.splitlines() if "UV" in line]
    assert len(lines) == 1 and lines[0].startswith("gratnet BSDF: mesh 'bare.obj' has no UV coordinates"), \
        done.stderr


def test_mitsuba_render_warns_for_an_obj_without_uvs(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    from gratnet.cli import main

    (tmp_path / "bare.obj").write_text(QUAD_WITHOUT_UVS)
    status = main(["mitsuba-render", "--material", "cd", "--mesh", str(tmp_path / "bare.obj"), "--size", "6,4",
                   "--spp", "1", "--quiet", "--out", str(tmp_path / "x.png")])
    error = capsys.readouterr().err
    assert status == 0, error
    lines = [line for line in error.splitlines() if "UV" in line]
    assert lines == [lines[0]] and lines[0].startswith("gratnet mitsuba-render: mesh 'bare.obj' has no UV "
                                                       "coordinates: its tangent"), error


# ------------------------------------------------------------------------------------------------
# errors


@pytest.mark.parametrize(("properties", "expected"), [
    ({"filename": "no-such-material"},
     "gratnet BSDF: unknown material 'no-such-material': neither a shipped material (choose "
     + ", ".join(shipped_materials()) + ") nor a model file (looked in "),
    ({"filename": "/no/such/model.npz"}, "gratnet BSDF: model file '/no/such/model.npz' not found"),
    ({"filename": ""}, "gratnet BSDF: give the material as the 'filename' property: a shipped name (blazed, "),
    ({"filename": "cd", "ior": "abc"}, "gratnet BSDF: property 'ior' must be a number"),
    ({"filename": "cd", "iorr": 1.5}, "gratnet BSDF: unknown property 'iorr'; the gratnet BSDF takes "
     + ", ".join(PROPERTIES)),
    ({"filename": "cd", "lobe_degrees": 0.0}, "gratnet BSDF: lobe_degrees must be in (0, 90], got 0.0"),
    ({"filename": "cd", "ior": -3.0}, "gratnet BSDF: ior must be 0 (no Fresnel) or a refractive index"),
], ids=["unknown name", "missing file", "no filename", "ior not a number", "unknown property", "bad lobe",
        "bad ior"])
def test_plugin_errors_are_one_plain_line(properties: dict[str, object], expected: str) -> None:
    mi = set_variant("scalar_rgb")
    with pytest.raises(RuntimeError) as wrapped:  # what a plain Mitsuba script gets
        mi.load_dict({"type": "gratnet", **properties})
    assert "failed to instantiate" in str(wrapped.value)
    assert str(wrapped.value).rstrip().splitlines()[-1].startswith("GratNetError: " + expected)  # its last line
    message = plugin_message(wrapped.value)
    assert message is not None and message.startswith(expected) and "\n" not in message
    with pytest.raises(GratNetError) as caught, plugin_errors():
        mi.load_dict({"type": "gratnet", **properties})
    assert str(caught.value) == message


def test_other_mitsuba_errors_pass_plugin_errors_unchanged() -> None:
    mi = set_variant("scalar_rgb")
    with pytest.raises(RuntimeError, match="no-such-plugin"), plugin_errors():
        mi.load_dict({"type": "no-such-plugin"})


def test_mitsuba_render_prints_only_the_plugins_message(tmp_path: Path, capsys: pytest.CaptureFixture,
                                                        monkeypatch: pytest.MonkeyPatch) -> None:
    """An error the command's own checks let through (here: a scene entry the plugin refuses) is the
    plugin's one line, exit 2, nothing written."""
    from gratnet.cli import main
    from mitsuba_plugin import scene as mitsuba_scene

    original = mitsuba_scene.bsdf_dict
    monkeypatch.setattr(mitsuba_scene, "bsdf_dict", lambda *args, **kwargs: {**original(*args, **kwargs),
                                                                            "lobe_degrees": 120.0})
    out = tmp_path / "x.png"
    status = main(["mitsuba-render", "--material", "cd", "--mesh", "plane", "--size", "4,4", "--spp", "1",
                   "--variant", "scalar_rgb", "--quiet", "--out", str(out)])
    error = capsys.readouterr().err
    assert status == 2
    assert error == "gratnet mitsuba-render: error: gratnet BSDF: lobe_degrees must be in (0, 90], got 120.0\n"
    assert not out.exists()


# ------------------------------------------------------------------------------------------------
# Ctrl-C


@pytest.mark.parametrize("variant", [pytest.param("llvm_ad_rgb", marks=pytest.mark.skipif(
    not llvm_usable(), reason="Dr.Jit finds no LLVM ≥ 18")), "scalar_rgb"])
def test_ctrl_c_stops_the_render_at_once_with_one_line(tmp_path: Path, variant: str) -> None:
    """SIGINT half a second into the first pass (of ~10 spp, seconds long): exit 130 within 2 s, stderr the
    one "interrupted" line once the progress bar is cleared, no image, no config, no temporary file."""
    out_dir = tmp_path / "out"
    out_dir.mkdir()
    process = subprocess.Popen(
        [str(GRATNET), "mitsuba-render", "--material", "paper-cd", "--mesh", "cd", "--size", "256,192", "--spp",
         "256", "--variant", variant, "--out", str(out_dir / "mi.png")],
        cwd=tmp_path, stdout=subprocess.PIPE, stderr=subprocess.PIPE, env={**os.environ, "PYTHONPATH": str(REPO)})
    stderr = bytearray()
    bar_seen = threading.Event()

    def read() -> None:
        while chunk := process.stderr.read1(4096):
            stderr.extend(chunk)
            if b"mitsuba-render (" in stderr:
                bar_seen.set()

    reader = threading.Thread(target=read, daemon=True)
    reader.start()
    try:
        assert bar_seen.wait(120), stderr.decode()
        time.sleep(0.5)
        assert process.poll() is None, "the render ended before the signal"
        process.send_signal(signal.SIGINT)
        sent = time.monotonic()
        status = process.wait(timeout=10)
        seconds = time.monotonic() - sent
    finally:
        if process.poll() is None:
            process.kill()
    reader.join(5)
    stdout = process.stdout.read()
    print(f"{variant}: exit {status} {seconds:.3f} s after SIGINT")
    assert status == 130
    assert seconds < 2.0
    visible = [line.rsplit("\r", 1)[-1].strip() for line in stderr.decode().split("\n")]  # a terminal's view
    assert [line for line in visible if line] == ["gratnet mitsuba-render: interrupted; no output was written"], \
        stderr.decode()
    assert stdout == b""
    assert list(out_dir.iterdir()) == []
