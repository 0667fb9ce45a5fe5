"""The interactive viewer (viewer.app, ``gratnet view``).

- App logic on a headless EGL context (no display needed): the resolution policy (reduced while the state
  moves, full resolution once it settles), "nothing changed → nothing rendered", banded refinement equal
  to one full render, screenshots.
- The real window under Xvfb (a virtual X server started on a free display number for this module, always
  stopped): glfw + OpenGL 4.3 core + imgui; the window is read back with glReadPixels, a slider is moved,
  the mouse is synthesised through imgui's glfw backend, and the OpenGL error flag is checked every frame.
  Skips with the reason when Xvfb is not installed (apt-get install xvfb; scripts/setup.sh installs it).

Renders are tiny (≤ 160×120, plane or sphere) with the shipped blazed model: the CPU rasterizer is slow.
"""

from __future__ import annotations

import ctypes
import json
import os
import subprocess
import sys
import time
import warnings
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from gratnet.cli import main
from gratnet.errors import GratNetError
from tests.helpers import ASSETS, PLANE, REPO, FakeClock
from viewer.app import ViewerApp
from viewer.meshes import plane
from viewer.scheduling import ResolutionPolicy
from viewer.screenshot import drive_slider, next_screenshot_path, save_screenshot
from viewer.state import SLIDERS, ViewerState

BLAZED = ASSETS / "blazed" / "model.npz"
EXPOSURE = PLANE.exposure


def run_until_complete(target: object, limit: int = 200) -> int:
    """Call ``target.frame()`` until the app's picture is complete and current; return the frame count."""
    app = target.app if hasattr(target, "app") else target
    for count in range(1, limit + 1):
        target.frame()
        if app.next_work_in() is None:
            return count
    raise AssertionError(f"the picture was not complete after {limit} frames")


# --------------------------------------------------------------------------------------------------
# App logic (headless)


@pytest.fixture
def app(ctx) -> Iterator[ViewerApp]:
    clock = FakeClock()
    viewer = ViewerApp(ctx, PLANE, size=(64, 48), clock=clock)
    viewer.clock_control = clock  # type: ignore[attr-defined]
    yield viewer
    viewer.release()


def test_resolution_policy_chooses_the_reduction_and_the_band_height():
    policy = ResolutionPolicy(interactive_budget_s=0.05, refine_budget_s=0.1, factors=(2, 4, 8), default_factor=4,
                              band_multiple=4)
    assert policy.reduced_factor(None) == 4
    assert policy.reduced_factor(0.1) == 2  # 0.1 s / 4 ≤ 0.05
    assert policy.reduced_factor(0.5) == 4  # 0.5 / 16 ≤ 0.05
    assert policy.reduced_factor(3.0) == 8  # 3 / 64 ≤ 0.05
    assert policy.reduced_factor(100.0) == 8  # over budget even at 1/8: the largest reduction
    assert policy.band_rows(np.full(100, 0.01)) == 8  # 10 fit: a multiple of 4
    assert policy.band_rows(np.full(100, 0.5)) == 4  # over budget: still 4 rows
    assert policy.band_rows(np.array([0.5, 0.01])) == 2  # … or what is left
    assert policy.band_rows(np.full(5, 0.001)) == 5
    assert policy.band_rows(np.full(100, 0.01), multiple=1) == 10  # the deferred path's bands: any height
    first = ResolutionPolicy()  # nothing measured yet: the first preview has at most 1024 pixels
    assert first.reduced_factor(None, (512, 512)) == 16 and first.reduced_factor(None, (64, 48)) == 2
    assert first.reduced_factor(None, (4096, 4096)) == 32  # … or the largest reduction


def test_reduced_while_moving_full_when_idle_and_nothing_rerendered(app):
    clock = app.clock_control
    assert app.frame() is True  # the first frame: a reduced preview
    image = app.image
    assert image.rendered_size[0] < 64 and image.rendered_size[1] < 48 and not image.complete
    assert app.stats.renders == app.stats.preview_renders == 1
    assert app.frame() is False and app.stats.renders == 1  # still "moving": nothing new to render

    # A slider dragged: one reduced render per new value, no refinement while it moves.
    for step, theta in enumerate((32.0, 34.0, 36.0)):
        clock.advance(0.05)
        assert drive_slider(app, "light_theta", [theta]) == 1
        assert app.moving and app.stats.preview_renders == 2 + step and app.stats.refine_renders == 0
        assert app.image.rendered_size[0] < 64 and not app.image.complete
    assert app.next_work_in() == pytest.approx(app.policy.idle_seconds)

    # Input stops: after idle_seconds the picture is refined to full resolution.
    clock.advance(app.policy.idle_seconds)
    assert app.next_work_in() == 0.0
    frames = run_until_complete(app)
    assert app.image.complete and app.image.full_size == (64, 48) and app.image.pixels.shape == (48, 64, 3)
    assert app.image.rendered_size == (64, 48) and app.stats.refine_renders == frames
    assert app.image.key == app.render_key()

    # Nothing changed: nothing is rendered, however many frames.
    renders, version = app.stats.renders, app.image.version
    for _ in range(5):
        clock.advance(1.0)
        assert app.frame() is False
    assert app.stats.renders == renders and app.image.version == version
    assert app.set(light_theta=36.0) is False  # the same value is no change
    assert app.frame() is False and app.stats.renders == renders

    # A change after that: a reduced preview again.
    assert app.set(exposure=2 * EXPOSURE) is True
    assert app.frame() is True and app.stats.renders == renders + 1 and not app.image.complete


def test_a_resize_is_a_change(app):
    app.frame()
    app.clock_control.advance(1.0)
    run_until_complete(app)
    renders = app.stats.renders
    assert app.set_size((40, 30)) is True
    assert app.frame() is True and app.stats.renders == renders + 1 and app.image.full_size == (40, 30)


def test_banded_refinement_equals_one_full_render(ctx):
    policy = ResolutionPolicy(refine_budget_s=1e-9, band_multiple=1)  # one row per band: the most bands
    clock = FakeClock()
    with_bands = ViewerApp(ctx, dataclass_replace(PLANE, mesh="sphere", camera_distance=0.2, camera_elevation=30.0,
                                                  light_theta=50.0, light_phi=-60.0, exposure=2000.0),
                           size=(48, 40), policy=policy, clock=clock)
    try:
        with_bands.frame()
        clock.advance(1.0)
        frames = run_until_complete(with_bands)
        assert frames == 40  # one band per row
        banded = with_bands.image.pixels
        with_bands.image = None  # forget the cache: render_full renders the whole picture in one call
        single = with_bands.render_full()
    finally:
        with_bands.release()
    assert np.count_nonzero(single) > 20  # the comparison is not between two black pictures
    levels = np.abs(banded.astype(int) - single.astype(int)).max(axis=2)
    assert np.mean(levels > 1) <= 0.002, f"{np.count_nonzero(levels > 1)} pixels differ"


#: A sphere view whose outline and highlights change across sub-pixel offsets (anti-aliasing tests).
SPHERE = ViewerState(mesh="sphere", camera_distance=0.2, camera_elevation=30.0, light_theta=50.0, light_phi=-60.0,
                     exposure=2000.0)


def _reference_render(viewer: ViewerApp, samples: int) -> np.ndarray:
    """SceneRenderer's own ``samples``-sample render of the viewer's view, on the viewer's renderer and mesh."""
    renderer, buffers = viewer.supply.scene(viewer.state, preview=False)
    state = viewer.state
    return renderer.render(buffers, state.camera(), state.light(), viewer.full_size(), state.exposure,
                           state.effective_ior, samples=samples)


@pytest.mark.parametrize("budget", [1e3, 1e-9], ids=["one band per sample", "one row per band"])
def test_progressive_antialiasing_equals_the_k_sample_render_and_restarts_on_a_change(ctx, budget):
    from viewer.scene import SceneRenderer

    clock = FakeClock()
    cap = 3 if budget > 1 else 2
    viewer = ViewerApp(ctx, SPHERE, size=(48, 40), clock=clock, max_samples=cap,
                       policy=ResolutionPolicy(refine_budget_s=budget, band_multiple=1))
    try:
        viewer.frame()
        clock.advance(1.0)
        while not viewer.image.complete:  # the refinement: sample 0, the pixel centre
            viewer.frame()
        assert viewer.samples == viewer.image.samples == 1
        single = viewer.accumulated_xyz()
        frames = 0
        while viewer.next_work_in() == 0.0:  # still frames: one sample (or a band of one) each
            assert viewer.frame() is True and viewer.image.complete
            frames += 1
            if budget > 1:
                assert viewer.samples == viewer.image.samples == 1 + frames  # one sample per still frame
        assert frames == (cap - 1) * (1 if budget > 1 else 40) and viewer.samples == cap
        assert viewer.frame() is False and viewer.next_work_in() is None  # at the cap: nothing more
        accumulated, reference = viewer.accumulated_xyz(), _reference_render(viewer, cap)
        scale = float(np.abs(reference).max())
        assert scale > 0 and np.abs(accumulated - single).max() > 1e-3 * scale  # the samples changed pixels
        levels = np.abs(viewer.image.pixels.astype(int) - SceneRenderer.display_srgb8(reference).astype(int))
        # The deferred path rasterizes N samples as N stacked viewports: a sample's varyings are interpolated at
        # other window coordinates than in a one-sample render (float32 rounding, amplified at sharp highlights).
        deferred = viewer.supply.scene(viewer.state, preview=False)[0].render_path == "deferred"
        if budget > 1 and not deferred:  # the same matrices as SceneRenderer's: float32 rounding only
            np.testing.assert_allclose(accumulated, reference, rtol=1e-5, atol=1e-6 * scale)
            assert levels.max() <= 1
        else:  # a band's clip-space crop rounds vertex positions differently (as the refinement's bands)
            close = np.isclose(accumulated, reference, rtol=1e-3, atol=1e-5 * scale).all(axis=2)
            assert np.mean(~close) <= 0.01, f"{np.count_nonzero(~close)} pixels differ"
            assert np.mean(levels.max(axis=2) > 1) <= 0.002

        # A higher cap continues from the samples there; a change of the view starts from 1 sample again.
        assert viewer.set_max_samples(cap + 1) is True and viewer.next_work_in() == 0.0
        assert viewer.set(exposure=SPHERE.exposure * 2) is True
        assert viewer.frame() is True and not viewer.image.complete and viewer.image.samples == 1
        assert viewer.samples == 1 and viewer.accumulated_xyz() is None
        with pytest.raises(GratNetError, match="samples per pixel"):
            viewer.set_max_samples(0)
    finally:
        viewer.release()


def test_screenshot_of_an_accumulated_view_records_its_samples(ctx, tmp_path):
    clock = FakeClock()
    viewer = ViewerApp(ctx, SPHERE, size=(32, 24), clock=clock, max_samples=2,
                       policy=ResolutionPolicy(refine_budget_s=1e3))
    try:
        viewer.frame()
        clock.advance(1.0)
        run_until_complete(viewer)
        assert viewer.samples == 2
        path = save_screenshot(viewer, tmp_path / "shot.png")
    finally:
        viewer.release()
    config = json.loads(path.with_name("shot.config.json").read_text())["render"]
    assert config["spp"] == 2 and config["width"] == 32


def dataclass_replace(state: ViewerState, **changes: object) -> ViewerState:
    import dataclasses

    return dataclasses.replace(state, **changes)


def test_slice_mode_refines_by_doubling_the_resolution(ctx):
    clock = FakeClock()
    # At 48² the pixel centres miss the blazed grating's diffraction lines (≈0.004 wide in v): an
    # accurate model's slice is nearly black at the usual exposure, so light up its tails instead.
    viewer = ViewerApp(ctx, dataclass_replace(PLANE, slice_mode=True, exposure=1e7), size=(64, 48), clock=clock,
                       policy=ResolutionPolicy(factors=(4,), default_factor=4))
    try:
        viewer.frame()
        assert viewer.full_size() == (48, 48) and viewer.image.rendered_size == (12, 12)
        clock.advance(1.0)
        sizes = []
        while viewer.next_work_in() is not None:
            viewer.frame()
            if not sizes or sizes[-1] != viewer.image.rendered_size:  # a level may take several bands
                sizes.append(viewer.image.rendered_size)
        assert sizes == [(24, 24), (48, 48)] and viewer.image.complete
        assert np.count_nonzero(viewer.image.pixels.max(axis=2) > 16) > 5
    finally:
        viewer.release()


def test_state_changes_are_checked_and_clamped(app):
    assert app.set(light_theta=500.0) and app.state.light_theta == SLIDERS["light_theta"].maximum
    assert app.set(material="no-such-material") is False
    assert "unknown material" in app.message and app.state.material == "blazed"
    assert app.set(mesh="missing.obj") is False and "does not exist" in app.message
    with pytest.raises(GratNetError, match="unknown viewer setting"):
        app.set(colour="red")
    with pytest.raises(GratNetError, match="finite"):
        app.set(exposure=float("nan"))
    with pytest.raises(GratNetError, match="unknown slider"):
        drive_slider(app, "brightness", [1.0])
    azimuth, distance = app.state.camera_azimuth, app.state.camera_distance
    assert app.orbit(10.0, 0.0) and app.state.camera_azimuth == pytest.approx(azimuth - 4.0)
    assert app.zoom(1.0) and app.state.camera_distance == pytest.approx(distance * 0.9)
    assert app.set(slice_mode=True) and app.orbit(0.0, 10.0)  # in slice mode a drag moves the light
    assert app.state.light_theta == pytest.approx(SLIDERS["light_theta"].maximum - 4.0)


def test_a_switch_brings_the_default_view_of_the_new_material_and_mesh(app):
    """The panel's material / mesh / slice choices go through switch(): the new pair's default view, the
    one gratnet view and gratnet render start with (viewer.default_view.state_defaults)."""
    from viewer.default_view import VIEW_FIELDS, state_defaults

    assert app.switch(material="cd", mesh="sphere")
    wanted = state_defaults("cd", "sphere", False, app.state.fov, app.state.effective_ior)
    assert {name: getattr(app.state, name) for name in VIEW_FIELDS} == pytest.approx(
        {name: SLIDERS[name].clamp(value) for name, value in wanted.items()})
    app.set(exposure=app.state.exposure * 3.0)
    assert app.switch() is False  # "default view": the same pair's defaults again
    assert app.state.exposure == pytest.approx(SLIDERS["exposure"].clamp(wanted["exposure"]))
    assert app.switch(material="no-such-material") is False and "unknown material" in app.message
    with pytest.raises(GratNetError, match="switch"):
        app.switch(exposure=1.0)


def test_a_default_view_worked_out_in_the_background_yields_to_the_user(tmp_path, monkeypatch):
    """In the window's background mode the defaults come from a worker process (a quick guess from a thread
    first); a user who moves the light, camera or exposure before they arrive keeps that choice, and the other
    fields still come (tests/runtime/test_viewer_default_view.py has the rest)."""
    from viewer.default_view import DefaultViewRequests, state_defaults

    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))  # nothing remembered: the worker computes
    requests = DefaultViewRequests(background=True)
    try:
        state = ViewerState(material="blazed", mesh="plane")
        exact = state_defaults("blazed", "plane", False, state.fov, state.effective_ior)
        (tmp_path / "gratnet" / "default_views.json").unlink()  # forget what state_defaults remembered
        requests.request(state)
        deadline = time.monotonic() + 60.0
        handed = {}
        while (requests.pending or handed != exact) and time.monotonic() < deadline:
            handed.update(requests.take(state) or {})
            time.sleep(0.01)
        assert handed == exact
        assert requests.take(state) is None  # handed over once
        (tmp_path / "gratnet" / "default_views.json").unlink()
        requests.request(state)
        moved = ViewerState(material="blazed", mesh="plane", light_theta=state.light_theta + 5.0)
        handed = {}
        while (requests.pending or not handed) and time.monotonic() < deadline:
            handed.update(requests.take(moved) or {})
            time.sleep(0.01)
        assert set(handed) == {"camera_distance", "camera_azimuth", "camera_elevation", "exposure"}  # not the light
    finally:
        requests.release()


def test_screenshot_is_full_resolution_png_with_its_render_config(app, tmp_path):
    app.frame()  # only a preview so far: the screenshot renders the full picture itself
    path = save_screenshot(app, next_screenshot_path(tmp_path))
    assert path == tmp_path / "gratnet-view-001.png"
    assert next_screenshot_path(tmp_path).name == "gratnet-view-002.png"
    image = np.asarray(Image.open(path))
    assert image.shape == (48, 64, 3) and np.count_nonzero(image.max(axis=2) > 16) > 5
    np.testing.assert_array_equal(image, app.image.pixels)
    config = json.loads((tmp_path / "gratnet-view-001.config.json").read_text())
    assert config["render"]["mesh"] == "plane" and config["render"]["width"] == 64
    assert config["render"]["exposure"] == EXPOSURE and config["model_file"].endswith("model.npz")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["gratnet-view-001.config.json", "gratnet-view-001.png"]
    with pytest.raises(GratNetError, match=".png"):
        save_screenshot(app, tmp_path / "x.jpg")


# --------------------------------------------------------------------------------------------------
# The real window under Xvfb (the xvfb and display fixtures: conftest.py)


@pytest.fixture
def window(display, tmp_path) -> Iterator[object]:
    from viewer.window import ViewerWindow

    clock = FakeClock()
    # Compiling in the window's thread (background=False): these tests count frames and renders; the
    # background mode, the window's default, is tested with real time in test_window_never_blocks.
    with ViewerWindow(PLANE, size=(160, 120), clock=clock, idle_wait_s=0.0, screenshot_dir=tmp_path,
                      background=False) as viewer:
        viewer.clock_control = clock  # type: ignore[attr-defined]
        yield viewer


def picture(window, capture: np.ndarray) -> np.ndarray:
    x, y, width, height = window.render_area()
    return capture[y:y + height, x:x + width]


def test_window_shows_panel_and_picture_and_a_slider_changes_the_picture(window):
    assert window.ctx.version_code >= 430
    window.frame()
    window.clock_control.advance(1.0)
    run_until_complete(window)
    window.frame(capture=True)
    before = window.last_capture
    assert before.shape == (120, window.PANEL_WIDTH + 160, 3)
    assert window.render_area() == (window.PANEL_WIDTH, 0, 160, 120)
    region = picture(window, before)
    lit = np.count_nonzero(region.max(axis=2) > 40)
    assert lit >= 20, "the picture is blank"
    np.testing.assert_array_equal(region, window.app.image.pixels)  # shown 1:1 at full resolution
    panel = before[:, :window.PANEL_WIDTH]
    assert len(np.unique(panel.reshape(-1, 3), axis=0)) > 10  # imgui drew its widgets

    renders = window.app.stats.renders
    drive_slider(window, "light_theta", [32.0, 36.0, 40.0])  # as a dragged slider: a frame per value
    assert window.app.stats.preview_renders >= 4 and window.app.stats.renders == renders + 3
    window.frame(capture=True)
    moving = picture(window, window.last_capture)
    assert not np.array_equal(moving, region)
    window.clock_control.advance(1.0)
    run_until_complete(window)
    window.frame(capture=True)
    after = picture(window, window.last_capture)
    assert np.mean(np.any(after != region, axis=2)) > 0.002, "moving the light did not change the picture"
    assert np.count_nonzero(after.max(axis=2) > 40) >= 20
    np.testing.assert_array_equal(after, window.app.image.pixels)
    assert window.gl_errors == []


def test_window_frames_without_changes_render_nothing(window):
    window.frame()
    window.clock_control.advance(1.0)
    run_until_complete(window)
    renders = window.app.stats.renders
    for _ in range(5):
        window.clock_control.advance(0.5)
        window.frame()
    assert window.app.stats.renders == renders
    assert window.gl_errors == []


def test_window_mouse_drag_orbits_and_wheel_zooms(window):
    """Mouse input synthesised through imgui's glfw backend callbacks (the path real events take)."""
    from imgui_bundle import imgui

    window.frame()
    address = ctypes.cast(window.handle, ctypes.c_void_p).value
    backends = imgui.backends
    x, y = window.PANEL_WIDTH + 80.0, 60.0
    backends.glfw_cursor_enter_callback(address, 1)
    backends.glfw_cursor_pos_callback(address, x, y)
    window.frame()
    azimuth, elevation = window.app.state.camera_azimuth, window.app.state.camera_elevation
    backends.glfw_mouse_button_callback(address, 0, 1, 0)  # left button pressed
    window.frame()
    for step in range(1, 4):
        backends.glfw_cursor_pos_callback(address, x + 10.0 * step, y + 5.0 * step)
        window.frame()
    backends.glfw_mouse_button_callback(address, 0, 0, 0)  # released
    window.frame()
    assert window.app.state.camera_azimuth == pytest.approx(azimuth - 30.0 * 0.4)
    assert window.app.state.camera_elevation == pytest.approx(elevation + 15.0 * 0.4)

    distance = window.app.state.camera_distance
    backends.glfw_scroll_callback(address, 0.0, 1.0)
    window.frame()
    assert window.app.state.camera_distance == pytest.approx(distance * 0.9)

    # Over the panel the wheel scrolls the panel, not the camera.
    backends.glfw_cursor_pos_callback(address, 50.0, 60.0)
    window.frame()
    backends.glfw_scroll_callback(address, 0.0, 1.0)
    window.frame()
    assert window.app.state.camera_distance == pytest.approx(distance * 0.9)
    assert window.gl_errors == []


def test_window_screenshot_button_writes_the_full_picture(window, tmp_path):
    window.frame()  # a preview on show: the screenshot renders the full picture
    path = window.screenshot()
    assert path == tmp_path / "gratnet-view-001.png" and window.app.message == f"wrote {path}"
    assert np.asarray(Image.open(path)).shape == (120, 160, 3)
    assert (tmp_path / "gratnet-view-001.config.json").is_file()
    window.screenshot_dir = tmp_path / "a-file"
    window.screenshot_dir.write_text("")
    assert window.screenshot() is None and "cannot write" in window.app.message  # shown, not raised
    window.frame()
    assert window.gl_errors == []


def test_a_headless_context_and_a_window_in_one_process(display):
    """A current EGL context (a headless renderer) must not stop the window's GLX context from becoming
    current (libglvnd: one API per thread; Xlib would exit the process), and works again afterwards."""
    from gratnet.modelfile import load_model
    from viewer.context import create_headless_context
    from viewer.scene import SceneRenderer
    from viewer.window import ViewerWindow

    headless = create_headless_context()
    try:
        with ViewerWindow(PLANE, size=(32, 24), idle_wait_s=0.0) as viewer:
            viewer.frame()
            assert viewer.gl_errors == []
        with SceneRenderer(headless, load_model(BLAZED)) as scene:
            xyz = scene.render(plane(), PLANE.camera(), PLANE.light(), (16, 16), EXPOSURE)
        assert np.isfinite(xyz).all() and xyz.max() > 0 and headless.error == "GL_NO_ERROR"
    finally:
        headless.release()


def _tiny_model_file(path: Path) -> Path:
    """A random 73-16-12-3 SiLU net: its baked program compiles in seconds, so the test sees it take over."""
    from gratnet.encoding import EncodingSpec, RangeSpec
    from gratnet.modelfile import ModelFile, save_model

    spec = EncodingSpec.for_grid(65, 5, frequencies=6, t_frequencies=2)
    sizes = [spec.features, 16, 12, 3]
    rng = np.random.default_rng(3)
    pairs = zip(sizes[:-1], sizes[1:], strict=True)
    weights = [rng.normal(0.0, np.sqrt(2.0 / a), (b, a)).astype(np.float32) for a, b in pairs]
    biases = [rng.normal(0.0, 0.3, b).astype(np.float32) for b in sizes[1:]]
    save_model(path, ModelFile(layer_sizes=sizes, weights=weights, biases=biases, activation="silu",
                               output_activation="clamp", encoding=spec, range=RangeSpec(), scheme="simple-max",
                               metadata={"volume": {"resolution": 65, "slices": 5}}))
    return path


@pytest.mark.timing
def test_window_never_blocks(display, tmp_path):
    """Issue 11's targets on the real window (background compile, the default) under Xvfb, with an EMPTY
    Mesa shader cache (a fresh MESA_SHADER_CACHE_DIR for the viewer process and its compile child):

    - the first picture is on screen ≤ 5 s after the process was started (imports included);
    - no frame's work (from the end of the wait for input to the swap: events, panel, render, draw) takes
      more than 150 ms: while the baked shader compiles, across a material switch, while the faster baked
      program takes over, and across the switch to the BRDF slice;
    - real pointer events (XTest: a left-button drag over the picture, one motion every ~0.15 s, from
      another process with its own time stamps) are each applied in a frame swapped ≤ 150 ms later, and shown
      in a picture swapped ≤ 150 ms later where no shader compile holds the picture back (not at the launch or
      right after the switch: there the picture follows once the new program is linked).

    benchmarks/viewer_latency.py drives the session (also the measurement in docs/benchmarks.md). It
    launches on the shipped blazed model (28k MACs: its baked compile takes 25 s+, and runs on) and
    switches to a tiny net whose baked program compiles in seconds, so that its takeover is seen too.
    """
    import ctypes.util

    if int(os.environ.get("PYTEST_XDIST_WORKER_COUNT", "1")) > 1:
        # Measured: beside another worker's GL tests on 2 cores, frames reached 0.16–0.32 s and the first
        # picture 4–6.7 s (the CPU, not the viewer): scripts/test.sh runs the timing tests alone.
        pytest.skip("wall-clock targets: run alone (pytest -m timing -n 0), not beside other xdist workers")
    repository = REPO
    inject = ctypes.util.find_library("Xtst") is not None
    environment = {**os.environ, "DISPLAY": display, "MESA_SHADER_CACHE_DIR": str(tmp_path / "mesa-cache"),
                   "PYTHONPATH": os.pathsep.join([str(repository), os.environ.get("PYTHONPATH", "")])}
    for name in ("MESA_SHADER_CACHE_DISABLE", "MESA_GLSL_CACHE_DISABLE", "WAYLAND_DISPLAY"):
        environment.pop(name, None)
    command = [sys.executable, str(repository / "benchmarks" / "viewer_latency.py"), "--material", "blazed",
               "--mesh", "plane", "--switch-to", str(_tiny_model_file(tmp_path / "tiny.npz")), "--takeover",
               "--timeout-s", "120", *(["--inject"] if inject else [])]
    launched = time.perf_counter()  # CLOCK_MONOTONIC: the same clock in the child
    result = subprocess.run([*command, "--launched-at", repr(launched)], env=environment, capture_output=True,
                            text=True, timeout=600, cwd=tmp_path)
    assert result.returncode == 0, result.stderr[-2000:]
    report = json.loads(result.stdout.strip().splitlines()[-1])
    summary = json.dumps({k: v for k, v in report.items() if k != "input_latency_s"})
    assert report["gl_errors"] == [], summary
    assert report["first_picture_s"] is not None and report["first_picture_s"] <= 5.0, summary
    assert report["weights_path_first"] == "texture", summary  # the quick path shows the first picture
    assert report["switch_picture_s"] is not None and report["takeover_s"] is not None, summary
    assert report["slice_picture_s"] is not None, summary
    assert set(report["phases"]) == {"launch", "interact", "material switch", "slice switch"}, summary
    assert report["max_frame_s"] <= 0.150, summary
    if inject:
        latencies = report["input_latency_s"]
        assert len(latencies) >= 20 and None not in latencies and report["input_negative"] == 0, summary
        assert report["input_applied_summary_s"]["max"] <= 0.150, summary  # every motion applied in a frame ≤ 150 ms
        for phase in ("interact", "slice switch"):  # … and on screen, where no shader compile holds the picture
            assert report["input_latency_by_phase_s"][phase]["max"] <= 0.150, summary
    else:
        warnings.warn("libXtst is missing (apt-get install libxtst6): real pointer events were not injected",
                      stacklevel=1)


def test_gratnet_view_runs_frames_and_exits(display, tmp_path):
    assert main(["view", "--mesh", "sphere", "--size", "64,48", "--max-frames", "3",
                 "--screenshot-dir", str(tmp_path)]) == 0


def test_gratnet_view_bad_input_is_one_line_before_any_window(display, capsys):
    assert main(["view", "--material", "no-such-material"]) == 2
    assert main(["view", "--mesh", "cube.stl"]) == 2
    assert main(["view", "--size", "0,10"]) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 3 and all(line.startswith("gratnet view: error:") for line in lines)


def test_gratnet_view_without_a_display_is_one_line_and_exit_2(monkeypatch, capsys):
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    assert main(["view", "--mesh", "plane", "--size", "32,32", "--max-frames", "1"]) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and "no display" in lines[0] and "xvfb-run" in lines[0]


def test_gratnet_view_flags_make_the_starting_state():
    from gratnet.cli import build_parser
    from viewer.view_cli import starting_state

    arguments = build_parser(only="view").parse_args(
        ["view", "--mesh", "sphere", "--light", "35,-60", "--camera", "0.3,10,20", "--exposure", "7", "--ior", "0",
         "--slice"])
    state = starting_state(arguments)
    assert (state.mesh, state.light_theta, state.light_phi, state.camera_distance, state.camera_azimuth,
            state.camera_elevation, state.exposure, state.slice_mode) == ("sphere", 35, -60, 0.3, 10, 20, 7, True)
    assert state.fresnel is False  # --ior 0: no Fresnel, as in gratnet render
    with pytest.raises(GratNetError, match="ior"):
        starting_state(build_parser(only="view").parse_args(["view", "--ior", "1e31"]))
    with pytest.raises(GratNetError, match="--light"):
        starting_state(build_parser(only="view").parse_args(["view", "--light", "45"]))


def test_setup_installs_xvfb():
    setup = (REPO / "scripts" / "setup.sh").read_text()
    assert "xvfb" in setup.split("debian_packages=(")[1].split(")")[0]


def test_rendering_modules_never_import_glfw_or_imgui():
    code = ("import sys, viewer.app, viewer.scene, viewer.renderer, viewer.context, viewer.view_cli, "
            "viewer.scene_supply, viewer.compile_worker; "
            "print(sorted(m for m in ('glfw', 'imgui_bundle') if m in sys.modules))")
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                            cwd=REPO, check=True)
    assert result.stdout.strip() == "[]"
