"""The viewer under an environment light (issue 43, ``gratnet view --environment``).

- The still view's accumulation of the estimator's passes equals ``SceneRenderer.render_rgba(..., samples=N,
  environment=...)`` of the same state (one band per pass), and any change starts it again.
- Never blocking: the compile child is asked for the ``environment`` group (and warms it), the window shows the
  scene without the environment until that group is ready, says so, and never compiles the variant itself.
- Bad lighting flags: one line, exit status 2, before any window.

Tiny renders with the shipped blazed model on a headless EGL context (no display needed).
"""

from __future__ import annotations

import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from gratnet.cli import main
from gratnet.errors import GratNetError
from tests.helpers import ASSETS, REPO, FakeClock
from viewer.app import ViewerApp
from viewer.scheduling import ResolutionPolicy
from viewer.state import ViewerState

BLAZED = ASSETS / "blazed" / "model.npz"
#: A sphere under the sky (the default light off, as with --environment), an exposure that shows it.
SKY = ViewerState(mesh="sphere", camera_distance=0.2, camera_elevation=30.0, light_theta=50.0, light_phi=-60.0,
                  exposure=50.0, light_intensity=0.0, environment="sky", seed=7)
VARIANT = "surface#ENVIRONMENT=1"  # ShadingPrograms.variant_program's key of the environment variant


def _assert_close_to_the_n_pass_render(accumulated: np.ndarray, reference: np.ndarray, scale: float) -> None:
    """The window's passes (one render each) against the N-pass render (on the deferred path its N G-buffers stacked
    in one texture, docs: viewer.deferred): the stacked rows' fragment positions round differently in float32, which
    moved 5 of 3,840 values by up to 5e-4 of their value (measured), and resampled sampling's sum of candidate
    weights 1 of 3,840 by 1.1e-3. Nearly every value to 1e-4, all to 1e-2: a wrong seed, pass number or pixel origin
    changes every lit pixel by far more."""
    assert np.isclose(accumulated, reference, rtol=1e-4, atol=1e-5 * scale).mean() >= 0.99
    np.testing.assert_allclose(accumulated, reference, rtol=1e-2, atol=1e-5 * scale)


def _assert_drawn_on_the_scenes_path(renderer: Any) -> None:
    """The window's passes took the scene's own render path (deferred on a CPU rasterizer): the forward path's
    environment variant was compiled only where that path is the scene's."""
    assert (VARIANT in renderer.network.compiled) == (renderer.render_path == "forward")


def _settle(viewer: ViewerApp, clock: FakeClock) -> None:
    """Frames until the full-resolution picture of the state on show is complete (its pass 0)."""
    viewer.frame()
    clock.advance(1.0)
    for _ in range(400):
        if viewer.image is not None and viewer.image.complete and viewer.image.key == viewer.render_key():
            return
        viewer.frame()
    raise AssertionError("the picture did not complete")


def test_accumulated_passes_equal_the_n_pass_render_and_restart_on_a_change(ctx):
    clock = FakeClock()
    passes = 3
    viewer = ViewerApp(ctx, SKY, size=(40, 32), clock=clock, environment_samples=passes, max_samples=2,
                       policy=ResolutionPolicy(refine_budget_s=1e3, band_multiple=1))
    try:
        assert viewer.environments[:3] == ["none", "sky", "studio"] and viewer.environment_live()
        _settle(viewer, clock)
        assert viewer.samples == 1 and viewer.sample_cap == passes  # the environment's cap, not max_samples
        frames = 0
        while viewer.next_work_in() == 0.0:
            assert viewer.frame() is True
            frames += 1
        assert frames == passes - 1 and viewer.samples == passes
        assert viewer.frame() is False and viewer.next_work_in() is None  # at the cap: nothing more
        renderer, buffers = viewer.supply.scene(viewer.state, preview=False)
        state = viewer.state
        reference = renderer.render(buffers, state.camera(), state.light(), viewer.full_size(), state.exposure,
                                    state.effective_ior, samples=passes, environment=viewer.environment(),
                                    seed=state.seed, render_path=renderer.render_path)
        accumulated = viewer.accumulated_xyz()
        scale = float(np.abs(reference).max())
        assert scale > 0
        _assert_close_to_the_n_pass_render(accumulated, reference, scale)
        _assert_drawn_on_the_scenes_path(renderer)

        # Any change starts the passes again: the camera, the environment's turn, the environment itself.
        for change in ({"camera_azimuth": state.camera_azimuth + 5.0}, {"environment_rotation": 30.0},
                       {"environment": "studio"}, {"seed": 8}, {"light_intensity": 1.0}):
            assert viewer.set(**change) is True
            assert viewer.samples == 1 and viewer.accumulated_xyz() is None
            assert viewer.frame() is True and viewer.image.samples == 1
        assert viewer.environment().name == "studio" and viewer.environment().rotation_degrees == 30.0
        # The panel's cap is the environment's while one is on show.
        assert viewer.set_max_samples(64) is True and viewer.environment_samples == 64 and viewer.max_samples == 2
    finally:
        viewer.release()


def test_area_lights_accumulate_in_the_window_as_gratnet_render_draws_them(ctx):
    """Area lights without an environment (gratnet view --area-light): the same program and estimator, its passes
    accumulated while the view stands still equal the N-pass render with the same lights and seed."""
    clock = FakeClock()
    passes = 3
    lamps = ("rect:0.1,0.05,0.25,-1,-0.5,-2.5,0.2,0.1,20", "sphere:-0.2,0.1,0.15,0.02,100")
    state = ViewerState(mesh="sphere", camera_distance=0.2, camera_elevation=30.0, light_theta=50.0,
                        light_phi=-60.0, exposure=50.0, light_intensity=0.0, area_light=lamps, seed=5)
    viewer = ViewerApp(ctx, state, size=(32, 24), clock=clock, environment_samples=passes, max_samples=2,
                       policy=ResolutionPolicy(refine_budget_s=1e3, band_multiple=1))
    try:
        assert viewer.environments == [] and viewer.environment_live() and state.has_sampled_light
        _settle(viewer, clock)
        assert viewer.sample_cap == passes
        while viewer.next_work_in() == 0.0:
            assert viewer.frame() is True
        assert viewer.samples == passes
        renderer, buffers = viewer.supply.scene(viewer.state, preview=False)
        state = viewer.state  # as shown (a remembered default view may have moved the camera)
        reference = renderer.render(buffers, state.camera(), state.light(), viewer.full_size(), state.exposure,
                                    state.effective_ior, samples=passes, seed=state.seed,
                                    area_lights=state.area_lights(), render_path=renderer.render_path)
        scale = float(np.abs(reference).max())
        assert scale > 0  # the lights light the sphere (the default light is off)
        # The window draws its passes in bands of rows paced by real time (so by the machine's load), each band
        # through its own sub-frustum: the fragments' interpolated positions, and so their keys and light
        # samples, move by float32 ulps. Where a sample grazes a rectangle's edge or a steep order, that moved a
        # few pixels by up to 4e-4 of their value under load (3 of 2,304 values, in two of seven runs). So: nearly
        # every value to 1e-4, and every one to 1e-2, far below what a wrong estimator or seed would give.
        accumulated = viewer.accumulated_xyz()
        assert np.isclose(accumulated, reference, rtol=1e-4, atol=1e-5 * scale).mean() >= 0.99
        np.testing.assert_allclose(accumulated, reference, rtol=1e-2, atol=1e-3 * scale)
        _assert_drawn_on_the_scenes_path(renderer)
        config = viewer.state.render_config(32, 24)
        assert config.area_light == lamps and config.has_sampled_light  # the screenshot's config reproduces it
    finally:
        viewer.release()


def test_banded_passes_make_the_n_pass_render(ctx):
    """One row per band: each band keys its light samples by the whole picture's pixels (render_rgba's
    pixel_origin), so the passes drawn row by row add up to the N-pass render of the whole picture."""
    clock = FakeClock()
    viewer = ViewerApp(ctx, SKY, size=(24, 16), clock=clock, environment_samples=4,
                       policy=ResolutionPolicy(refine_budget_s=1e-9, band_multiple=1))
    try:
        _settle(viewer, clock)
        while viewer.next_work_in() == 0.0:
            viewer.frame()
        assert viewer.samples == 4
        state = viewer.state
        renderer, buffers = viewer.supply.scene(state)
        reference = renderer.render(buffers, state.camera(), state.light(), viewer.full_size(), state.exposure,
                                    state.effective_ior, samples=4, environment=viewer.environment(), seed=state.seed,
                                    render_path=renderer.render_path)
        accumulated = viewer.accumulated_xyz()
        scale = float(np.abs(reference).max())
        assert scale > 0
        # A band's cropped projection rounds a pixel's surface point (and so its key) differently in float32: a few
        # pixels differ in the fourth digit, more under resampled sampling, whose candidates' weights read
        # piecewise-constant densities: a candidate on a cell's edge may change cells (measured: 14 of 1,152 values
        # beyond 1e-4, one by 4e-3 of a small value); a band with the wrong pixel origin differs everywhere.
        assert np.isclose(accumulated, reference, rtol=1e-4, atol=1e-5 * scale).mean() >= 0.95
        np.testing.assert_allclose(accumulated, reference, rtol=1e-2, atol=1e-5 * scale)
    finally:
        viewer.release()


def _frames_until(viewer: ViewerApp, clock: FakeClock, done: Any, seconds: float = 60.0) -> None:
    """Frames (the fake clock 0.3 s on each: past the idle time) until ``done()``; the mesh is built on a thread."""
    import time

    deadline = time.monotonic() + seconds
    while not done():
        assert time.monotonic() < deadline, "the viewer did not get there"
        viewer.frame()
        clock.advance(0.3)
        time.sleep(0.005)


class _FakeWorker:
    """Stands in for viewer.compile_worker.CompileWorker: records what it was asked for; the test says when a
    group is ready."""

    made: list[_FakeWorker] = []

    def __init__(self, model_path: Any, paths: Any, groups: Any, label: str = "", niceness: int = 0,
                 render_path: str = "auto", environment: str | None = None) -> None:
        self.model_path, self.paths, self.groups = Path(model_path), tuple(paths), tuple(groups)
        self.environment = environment
        self.ready: set[tuple[str, str]] = set()
        self.seconds: dict[tuple[str, str], float] = {}
        self.ready_at: dict[tuple[str, str], float] = {}
        self.error: str | None = None
        self.finished = False
        self.running = True  # no prefetch child meanwhile
        self.baked_source = None
        _FakeWorker.made.append(self)

    def poll(self) -> set[tuple[str, str]]:
        return set()

    def elapsed(self) -> float:
        return 1.0

    def close(self) -> None:
        self.running = False


@pytest.fixture
def fake_worker(monkeypatch) -> Iterator[type[_FakeWorker]]:
    import viewer.scene_supply as supply

    monkeypatch.delenv("MESA_SHADER_CACHE_DISABLE", raising=False)
    monkeypatch.delenv("MESA_GLSL_CACHE_DISABLE", raising=False)
    monkeypatch.setattr(supply, "CompileWorker", _FakeWorker)
    _FakeWorker.made = []
    yield _FakeWorker
    _FakeWorker.made = []


def test_the_window_waits_for_the_compile_child_and_shows_the_scene_without_the_environment(ctx, fake_worker,
                                                                                             tmp_path, monkeypatch):
    from gratnet.importance import clear_memory_cache, importance_cache_folder, material_table

    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))  # an empty importance cache
    clear_memory_cache()
    clock = FakeClock()
    viewer = ViewerApp(ctx, SKY, size=(32, 24), clock=clock, background=True, weights_path="texture",
                       auto_exposure=True)
    try:
        worker = fake_worker.made[0]
        assert "environment" in worker.groups and worker.environment == "sky"  # the child warms the variant
        assert worker.groups.index("surface") < worker.groups.index("environment")  # the plain scene first
        worker.ready.add(("texture", "surface"))
        _frames_until(viewer, clock, lambda: viewer.image is not None and viewer.image.complete)
        renderer = viewer.supply.scene(viewer.state)[0]
        assert viewer.image is not None and not viewer.environment_live()
        assert VARIANT not in renderer.network.compiled  # the window never compiled the variant itself
        assert "environment light" in viewer.status and "without the environment" in viewer.status
        assert viewer.image.pixels.max() > 0  # lit by the directional light meanwhile, not black
        exposure = viewer.state.exposure

        worker.ready.add(("texture", "environment"))  # the child's programs are in Mesa's cache; no table yet
        before = viewer.render_key()
        _frames_until(viewer, clock, lambda: viewer.environment_live() and viewer.image.key == viewer.render_key())
        assert viewer.environment_live()
        _assert_drawn_on_the_scenes_path(renderer)
        assert viewer.render_key() != before and viewer.image.key == viewer.render_key()
        assert "environment" not in viewer.status
        # The material's own table is the child's to build: until it reports one, the passes sample with the flat
        # table, and the window built none (the cache is still empty).
        assert renderer.importance_provisional and not importance_cache_folder().exists()
        assert renderer.environment_lighting(viewer.environment()).table.source == "flat"
        # --exposure left out: the first pictures under the sky set it (the preview's, then the full picture's)
        _frames_until(viewer, clock, lambda: viewer.image.complete and viewer.image.key == viewer.render_key())
        assert viewer.state.exposure != exposure and viewer.image.pixels.max() > 0

        material_table(renderer.model, progress=False)  # what the child does, then reports
        clear_memory_cache()  # the window reads it from the disk cache, as from the child's
        worker.ready.add(("texture", "importance"))
        _frames_until(viewer, clock, lambda: not renderer.importance_provisional)
        assert renderer.environment_lighting(viewer.environment()).table.source == "model"
    finally:
        viewer.release()


def test_without_a_compile_child_the_window_builds_the_table_itself(ctx, tmp_path, monkeypatch):
    """No shader cache, so no child to build the material's table: the window does not sample with the flat table
    for ever, it builds the table at the first pass under the environment (as it compiles everything itself)."""
    from gratnet.importance import clear_memory_cache

    monkeypatch.setenv("MESA_SHADER_CACHE_DISABLE", "1")
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    clear_memory_cache()
    clock = FakeClock()
    viewer = ViewerApp(ctx, SKY, size=(16, 12), clock=clock, background=True, weights_path="texture")
    try:
        assert viewer.supply.worker is None
        _frames_until(viewer, clock, lambda: viewer.environment_live() and viewer.image is not None
                      and viewer.image.key == viewer.render_key())
        renderer = viewer.supply.scene(viewer.state)[0]
        assert not renderer.importance_provisional
        assert renderer.environment_lighting(viewer.environment()).table.source == "model"
    finally:
        viewer.release()


def test_a_viewer_without_an_environment_warms_no_environment_group(ctx, fake_worker):
    viewer = ViewerApp(ctx, ViewerState(mesh="plane"), size=(16, 16), background=True, weights_path="texture")
    try:
        assert fake_worker.made[0].groups == ("surface", "slice") and fake_worker.made[0].environment is None
        assert viewer.environments == [] and not viewer.environment_live()
        with pytest.raises(GratNetError, match="environment must be one of none"):
            viewer.set(environment="sky")  # no environment light in this viewer: nothing warmed it
    finally:
        viewer.release()


def test_the_compile_child_warms_the_environment_group(tmp_path):
    environment = {"MESA_SHADER_CACHE_DIR": str(tmp_path / "mesa"), "XDG_CACHE_HOME": str(tmp_path / "cache")}
    import os

    result = subprocess.run(
        [sys.executable, "-m", "viewer.compile_worker", str(BLAZED), "--paths", "texture", "--groups", "environment",
         "--folder", str(tmp_path), "--environment", "studio", "--render-path", "forward"],
        capture_output=True, text=True, cwd=REPO, timeout=600, env={**os.environ, **environment})
    assert result.returncode == 0, result.stderr[-2000:]
    lines = [line.split()[:3] for line in result.stdout.splitlines()]
    # The programs first (drawn with the flat table), then the material's table, for the window to load.
    assert lines == [["ready", "texture", "environment"], ["ready", "texture", "importance"]]
    assert any((tmp_path / "cache" / "gratnet" / "importance").iterdir())


@pytest.mark.parametrize("flags, message", [
    (["--environment", "cloudy"], "--environment"),
    (["--environment", "sky", "--environment-scale", "-1"], "--environment-scale"),
    (["--environment", "sky", "--environment-spp", "0"], "--environment-spp"),
    (["--light-intensity", "nan"], "--light-intensity"),
])
def test_bad_lighting_flags_are_one_line_and_exit_2_before_any_window(flags, message, capsys, monkeypatch):
    monkeypatch.delenv("DISPLAY", raising=False)  # no window could open: the flags are refused first
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    assert main(["view", "--mesh", "plane", "--size", "32,32", "--max-frames", "1", *flags]) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("gratnet view: error:") and message in lines[0], lines


def test_the_lighting_flags_make_the_starting_state():
    from gratnet.cli import build_parser
    from viewer.view_cli import starting_state

    parse = build_parser(only="view").parse_args
    state = starting_state(parse(["view", "--mesh", "sphere", "--environment", "sky", "--environment-rotation", "90",
                                  "--environment-scale", "0.5", "--seed", "3", "--exposure", "9"]))
    assert (state.environment, state.environment_rotation, state.environment_scale, state.seed) == ("sky", 90, 0.5, 3)
    assert state.light_intensity == 0.0 and state.has_environment  # the default light is off under an environment
    plain = starting_state(parse(["view", "--mesh", "sphere", "--light-intensity", "2", "--exposure", "9"]))
    assert plain.light_intensity == 2.0 and plain.environment == "none" and not plain.has_environment
    config = state.render_config(64, 48)
    assert (config.environment, config.environment_rotation, config.light_intensity) == ("sky", 90.0, 0.0)


def test_the_window_panel_offers_the_environments(display, tmp_path):
    """The real window (Xvfb) under an environment: its panel has the chooser; choosing another environment is a
    change of the picture; no OpenGL error."""
    from viewer.window import ViewerWindow

    clock = FakeClock()
    with ViewerWindow(SKY, size=(32, 24), clock=clock, idle_wait_s=0.0, screenshot_dir=tmp_path, background=False,
                      visible=False, environments=("studio",)) as window:
        app = window.app
        for _ in range(3):
            window.frame()
            clock.advance(1.0)
        assert "environment" in window.panel_layout and app.environment_live()
        assert app.environments[:3] == ["none", "sky", "studio"]
        assert app.set(environment="none") is True and not app.environment_live()
        window.frame()
        assert app.sample_cap == app.max_samples  # without an environment: the anti-aliasing cap again
        assert app.set(environment="studio") is True and app.environment_live()
        window.frame()
        assert window.gl_errors == []
