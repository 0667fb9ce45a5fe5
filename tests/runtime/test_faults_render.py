"""``gratnet render`` under faults (issue 36): Ctrl-C answered within a second, sizes it cannot render refused.

- Ctrl-C: a real ``gratnet render`` process (the forward path, the deferred path, a BRDF slice) is sent SIGINT
  while it renders; it exits with status 130 within 1.5 s, its stderr shows one line (the progress bar, cleared,
  aside) and the folder holds no file (no image, no config, no temporary). This needs a renderer slow enough to
  be caught rendering (Mesa llvmpipe): where the render ends first, the test is skipped.
- The work behind it (viewer.pacing): a render drawn in many small bands or pieces equals the render drawn in
  one, bit for bit, on both mesh paths and for slices.
- Ctrl-C inside a shader's compile is raised once the program is made (a KeyboardInterrupt inside moderngl's
  program creation crashed the process).
- ``--size``: a size beyond the GL limits, the driver's largest render target or the memory available is
  refused in one line naming the largest size that fits, before any work, and nothing is written.
"""

from __future__ import annotations

import os
import select
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

import viewer.context
import viewer.render_cli
from gratnet.cli import main
from scripts.fault_injection import visible_lines
from tests.helpers import REPO, random_model
from viewer.antialias import sample_offsets
from viewer.camera import Camera, Light
from viewer.meshes import compact_disc, sphere
from viewer.pacing import Pacer

#: The longest a render may take to stop after SIGINT (seconds; the issue asks for 1 s, this allows for a busy CI).
STOP_WITHIN = 1.5
CAMERA = Camera(distance=0.25, azimuth_deg=-90.0, elevation_deg=50.0)
LIGHT = Light.directional(40.0, 80.0)


# -------------------------------------------------------------------------------------------------
# Ctrl-C in a real process


def _interrupted(folder: Path, arguments: list[str]) -> tuple[int, float, str]:
    """Run ``gratnet render ARGUMENTS`` in ``folder``, send SIGINT once it renders (its progress bar shows, 2 s
    into the render), and return its exit status, the seconds from the signal to its exit and its stderr. Skips
    the test when the render ends before it can be interrupted (a fast GPU)."""
    environment = {**os.environ, "PYTHONPATH": os.pathsep.join(filter(None, [str(REPO), os.environ.get("PYTHONPATH")]))}
    process = subprocess.Popen([sys.executable, "-c", "import sys\nfrom gratnet.cli import main\nsys.exit(main())",
                                "render", *arguments], cwd=folder, env=environment, stdout=subprocess.PIPE,
                               stderr=subprocess.PIPE)
    assert process.stderr is not None
    stderr = b""
    try:
        deadline = time.monotonic() + 120.0
        while b"%|" not in stderr and process.poll() is None and time.monotonic() < deadline:
            if select.select([process.stderr], [], [], 1.0)[0]:
                stderr += os.read(process.stderr.fileno(), 65536)
        if process.poll() is not None:
            pytest.skip("the render ended before it could be interrupted (a renderer faster than llvmpipe)")
        sent = time.monotonic()
        process.send_signal(signal.SIGINT)
        _, rest = process.communicate(timeout=60)
        stopped = time.monotonic() - sent
    finally:
        if process.poll() is None:
            process.kill()
            process.communicate()
    return process.returncode, stopped, (stderr + rest).decode("utf-8", "replace")


# Wall-clock targets: beside a second worker's GL tests the exit took 2.1 s here (and 3–9 s at 1374b1d under
# two busy loops), so they run alone with the other timing tests.
@pytest.mark.timing
@pytest.mark.parametrize(("path", "size"), [("forward", "512,512"), ("deferred", "768,768")])
def test_ctrl_c_stops_a_mesh_render_within_a_second_and_writes_nothing(tmp_path, path, size):
    """The progress bar shows after 2 s; SIGINT then: exit 130 in time, one line, no file (texture weights: no
    baked shader's long first compile)."""
    code, stopped, stderr = _interrupted(tmp_path, ["--material", "paper-cd", "--mesh", "cd", "--size", size,
                                                    "--spp", "2", "--weights-path", "texture", "--render-path",
                                                    path, "--out", "x.png"])
    assert code == 130, stderr
    assert stopped < STOP_WITHIN, f"{stopped:.2f} s from SIGINT to exit"
    assert visible_lines(stderr) == ["gratnet render: interrupted; nothing was written"], stderr
    assert sorted(os.listdir(tmp_path)) == []


@pytest.mark.timing
def test_ctrl_c_stops_a_slice_render_within_a_second_and_writes_nothing(tmp_path):
    code, stopped, stderr = _interrupted(tmp_path, ["--material", "paper-cd", "--slice", "--size", "640,640",
                                                    "--weights-path", "texture", "--out", "s.exr"])
    assert code == 130, stderr
    assert stopped < STOP_WITHIN, f"{stopped:.2f} s from SIGINT to exit"
    assert visible_lines(stderr) == ["gratnet render: interrupted; nothing was written"], stderr
    assert sorted(os.listdir(tmp_path)) == []


@pytest.mark.parametrize("quiet", [False, True])
def test_the_progress_bar_shows_on_long_renders_and_quiet_hides_it(tmp_path, capsys, monkeypatch, quiet):
    """With the delay at 0 every render is "long": the bar is drawn on stderr and cleared at the end (no line
    left); --quiet: stderr stays empty. The image is written either way."""
    monkeypatch.setattr(viewer.render_cli, "PROGRESS_DELAY", 0.0)
    assert main(["render", "--material", "blazed", "--mesh", "cd", "--size", "96,64", "--weights-path", "texture",
                 "--render-path", "forward", "--out", str(tmp_path / "x.png"), *(["--quiet"] if quiet else [])]) == 0
    stderr = capsys.readouterr().err
    if quiet:
        assert stderr == ""
    else:
        assert "gratnet render:   0%|" in stderr and "%|█" in stderr
        assert visible_lines(stderr) == []
    assert sorted(os.listdir(tmp_path)) == ["x.config.json", "x.png"]


def test_ctrl_c_while_writing_leaves_nothing_and_after_writing_says_so(tmp_path, capsys, monkeypatch):
    """Ctrl-C inside the writer (between the image's temporary and the config's): nothing lands, no temporary;
    Ctrl-C after the files landed: the line says they were written."""
    import gratnet.config

    arguments = ["render", "--material", "blazed", "--mesh", "plane", "--size", "16,16", "--weights-path", "texture",
                 "--quiet", "--out", str(tmp_path / "x.png")]

    def interrupt(*_arguments: object, **_options: object) -> str:
        raise KeyboardInterrupt

    with monkeypatch.context() as patch:
        patch.setattr(gratnet.config, "config_text", interrupt)
        assert main(arguments) == 130
    assert capsys.readouterr().err == "gratnet render: interrupted; nothing was written\n"
    assert sorted(os.listdir(tmp_path)) == []
    with monkeypatch.context() as patch:
        patch.setattr(viewer.render_cli, "warn_if_black", interrupt)
        assert main(arguments) == 130
    assert capsys.readouterr().err == (f"gratnet render: interrupted; {tmp_path / 'x.png'} and its config were "
                                       f"written before it\n")
    assert sorted(os.listdir(tmp_path)) == ["x.config.json", "x.png"]


def test_ctrl_c_during_a_shader_compile_is_raised_once_the_program_is_made(ctx, monkeypatch):
    """moderngl's program creation calls back into Python after the link: a KeyboardInterrupt raised there
    crashed the process (segmentation fault, Ctrl-C during a baked shader's compile). The compile holds SIGINT
    and raises it once the program exists (and its GL object is left to the context's release)."""
    from viewer.glsl import compile_program

    made: list[object] = []
    real = type(ctx).program

    def program(self: object, *arguments: object, **options: object) -> object:
        os.kill(os.getpid(), signal.SIGINT)  # Python's handler runs at the next bytecode: here, unless held
        time.sleep(0.05)
        made.append(real(self, *arguments, **options))
        return made[-1]

    monkeypatch.setattr(type(ctx), "program", program)
    with pytest.raises(KeyboardInterrupt):
        compile_program(ctx, "accumulate", {})
    assert len(made) == 1
    made[0].release()  # type: ignore[attr-defined]


# -------------------------------------------------------------------------------------------------
# Many small pieces = one piece, bit for bit


@pytest.fixture(scope="module")
def model():
    return random_model([163, 16, 8, 3], activation="silu", scheme="simple-max", seed=4)


@pytest.fixture(scope="module")
def scenes(ctx, model) -> Iterator[dict[str, object]]:
    from viewer.scene import SceneRenderer

    made = {path: SceneRenderer(ctx, model, weights_path="texture", render_path=path)
            for path in ("forward", "deferred")}
    yield made
    for scene in made.values():
        scene.release()


def _one_piece(ctx: object) -> Pacer:
    return Pacer(ctx, first_cost=1e12)  # type: ignore[arg-type]


def _slivers(ctx: object) -> Pacer:
    return Pacer(ctx, first_cost=1.0, seconds=1e-9)  # type: ignore[arg-type]


def _set_pacers(scene: object, make: object) -> None:
    scene.forward.depth_pacer = make(scene.ctx)  # type: ignore[attr-defined, operator]
    scene.forward.shade_pacer = make(scene.ctx)  # type: ignore[attr-defined, operator]
    for name in ("gbuffer_pacer", "compact_pacer", "shade_pacer", "resolve_pacer"):
        setattr(scene.deferred, name, make(scene.ctx))  # type: ignore[attr-defined, operator]
    scene.shading.slice_pacer = make(scene.ctx)  # type: ignore[attr-defined, operator]


@pytest.mark.parametrize("samples", [1, 3])
@pytest.mark.parametrize(("path", "depth_prepass"), [("forward", True), ("forward", False), ("deferred", True)])
def test_a_render_in_slivers_equals_the_render_in_one_piece(scenes, path, depth_prepass, samples):
    """Pieces of one 64×4 block (the least), bands of 4 rows (8 for the compaction and the resolve) and list
    pieces of 256 entries against one piece each: the same float32 image, coverage, sums and work counters; the
    CD disc and a sphere (overdraw without the depth pre-pass)."""
    scene = scenes[path]
    offsets = sample_offsets(samples)
    images, counters = [], []
    for make in (_one_piece, _slivers):
        _set_pacers(scene, make)
        statistics: dict[str, int] = {}
        for mesh in (compact_disc(), sphere()):
            images.append(scene.render_rgba(mesh, CAMERA, LIGHT, (61, 47), 3.0, depth_prepass=depth_prepass,
                                            statistics=statistics, offsets_px=offsets))
            counters.append(dict(statistics))
    pacer = scene.forward.shade_pacer if path == "forward" else scene.deferred.shade_pacer
    assert pacer.pieces_done > 4  # the slivers were slivers
    for one, many in zip(images[:2], images[2:], strict=True):
        assert one[..., 3].any()
        np.testing.assert_array_equal(many, one)
    assert counters[:2] == counters[2:]


def test_a_slice_in_slivers_equals_the_slice_in_one_piece(scenes):
    scene = scenes["forward"]
    reports: list[float] = []
    _set_pacers(scene, _one_piece)
    whole = scene.shading.render_brdf_slice(30.0, 10.0, 53)
    band = scene.shading.render_brdf_slice(30.0, 10.0, 53, rows=(11, 40))
    _set_pacers(scene, _slivers)
    np.testing.assert_array_equal(scene.shading.render_brdf_slice(30.0, 10.0, 53, progress=reports.append), whole)
    np.testing.assert_array_equal(scene.shading.render_brdf_slice(30.0, 10.0, 53, rows=(11, 40)), band)
    np.testing.assert_array_equal(band[11:40], whole[11:40])
    assert not band[:11].any() and not band[40:].any()
    assert len(reports) == scene.shading.slice_pacer.pieces_done - 8 > 4  # one report per band of the first slice
    assert reports == sorted(reports) and reports[-1] == pytest.approx(1.0)


class _Clock:
    """A context whose ``finish`` advances a fake clock (``time.perf_counter``) by the seconds of the piece drawn."""

    def __init__(self, monkeypatch: pytest.MonkeyPatch, seconds_per_unit: np.ndarray) -> None:
        self.now = 0.0
        self.piece = (0, 0)
        self.seconds_per_unit = seconds_per_unit
        monkeypatch.setattr(time, "perf_counter", lambda: self.now)

    def finish(self) -> None:
        self.now += float(self.seconds_per_unit[self.piece[0]:self.piece[1]].sum())


def _paced(clock: _Clock, costs: np.ndarray | None) -> tuple[list[tuple[int, int]], list[float]]:
    """The pieces of 1000 units a pacer aiming at 0.2 s makes on ``clock``, and their seconds."""
    pacer = Pacer(clock, first_cost=1.0, seconds=0.2)  # type: ignore[arg-type]
    pieces = []
    for piece in pacer.pieces(1000, costs):
        clock.piece = piece
        pieces.append(piece)
    return pieces, [float(clock.seconds_per_unit[start:end].sum()) for start, end in pieces]


def test_pacer_pieces_tile_the_work_and_keep_to_their_time(monkeypatch):
    """400 units of background (0.5 ms each), then 600 of mesh (20 ms each). With their relative costs known the
    pieces tile 0 … 1000 and none takes more than 0.2 s (+ 1 %); a uniform guess, growing 4× a piece over cheap
    background, runs into the mesh with a piece of seconds: why the renderers weigh blocks by coverage."""
    seconds = np.where(np.arange(1000) < 400, 0.0005, 0.02)
    clock = _Clock(monkeypatch, seconds)
    pieces, times = _paced(clock, seconds / seconds.max())
    assert pieces[0][0] == 0 and pieces[-1][1] == 1000
    assert all(end == start for (_, end), (start, _) in zip(pieces, pieces[1:], strict=False))
    assert max(times) <= 0.202, times
    assert len(pieces) < 80  # not slivers: 12.2 s of work in pieces near 0.2 s
    _, blind = _paced(clock, None)
    assert max(blind) > 1.0


# -------------------------------------------------------------------------------------------------
# Sizes this machine cannot render


@pytest.fixture
def small_gl_limits(monkeypatch: pytest.MonkeyPatch) -> None:
    """Contexts whose GL_MAX_TEXTURE_SIZE is 300 (as a small GPU's)."""
    real = viewer.context.create_headless_context

    def limited(*arguments: object, **options: object) -> object:
        made = real(*arguments, **options)
        made.info["GL_MAX_TEXTURE_SIZE"] = 300
        return made

    monkeypatch.setattr(viewer.context, "create_headless_context", limited)


@pytest.mark.parametrize("flags", [["--size", "400,200"], ["--slice", "--size", "512,512"]], ids=["mesh", "slice"])
def test_a_size_beyond_the_gl_limits_is_refused_in_one_line(tmp_path, capsys, small_gl_limits, flags):
    assert main(["render", "--material", "blazed", *flags, "--out", str(tmp_path / "x.png")]) == 2
    lines = capsys.readouterr().err.splitlines()
    assert len(lines) == 1, lines
    assert lines[0].startswith(f"gratnet render: error: --size {flags[-1]} is too large for this machine: "
                               "GL_MAX_TEXTURE_SIZE is 300 here; at most ")
    assert lines[0].endswith("300,150 at this aspect ratio" if flags[0] == "--size" else "300,300 at this aspect ratio")
    assert sorted(os.listdir(tmp_path)) == []


def test_a_size_beyond_the_memory_available_is_refused_in_one_line(tmp_path, capsys, monkeypatch):
    """MemAvailable of 64 MiB: a 1024² render (about 220 bytes a pixel) is refused before any work, and the
    largest size named is one the same check passes."""
    monkeypatch.setattr(viewer.render_cli, "available_memory", lambda: 64 << 20)
    assert main(["render", "--material", "blazed", "--size", "1024,1024", "--spp", "4",
                 "--out", str(tmp_path / "x.exr")]) == 2
    (line,) = capsys.readouterr().err.splitlines()
    assert line.startswith("gratnet render: error: --size 1024,1024 is too large for this machine: the render needs "
                           "about ")
    assert " GiB of memory and 0.1 GiB is available; at most " in line
    side = int(line.rsplit("at most ", 1)[1].split(",")[0])
    assert 400 < side < 600
    assert sorted(os.listdir(tmp_path)) == []


def test_the_issues_12000_square_is_refused_on_llvmpipe(ctx, tmp_path, capsys):
    """12000² RGBA32F (2.1 GiB) is more than llvmpipe allocates for one texture (about 1.5 GiB): one line, not
    the old traceback (INCOMPLETE_ATTACHMENT)."""
    from viewer.renderer import is_software_rasterizer

    if not is_software_rasterizer(ctx):
        pytest.skip("a GPU may render 12000² (minutes of work): the refusal is llvmpipe's")
    assert main(["render", "--material", "blazed", "--size", "12000,12000", "--out", str(tmp_path / "x.png")]) == 2
    (line,) = capsys.readouterr().err.splitlines()
    assert line.startswith("gratnet render: error: --size 12000,12000 is too large for this machine: ")
    assert line.endswith(" at this aspect ratio")
    assert sorted(os.listdir(tmp_path)) == []
