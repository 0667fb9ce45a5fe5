"""The viewer's default view after a start or a material switch (issue 35): remembered, guessed at once, then exact.

- quick_view guesses a usable view (the material lit and exposed: most of the disc visible, little saturated)
  without colour-science, from the analysis the model file stores;
- the exact defaults are remembered per model file, mesh and mode;
- a switch in the window's background mode shows the new material at the guess before the worker's exact
  defaults arrive, and those replace it (a drag keeps the camera, not the old light and exposure);
- gratnet view without --light, --camera or --exposure computes nothing before its window (the remembered
  view, or the fallback view for the window to replace), and its first picture shows the guess.
"""

from __future__ import annotations

import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from gratnet.modelfile import load_model
from tests.helpers import REPO
from viewer.catalog import build_mesh, resolve_material
from viewer.default_view import (
    VIEW_FIELDS,
    DefaultViewRequests,
    quick_view,
    remembered_view,
    state_defaults,
    view_cache_file,
)
from viewer.state import ViewerState


@pytest.fixture(autouse=True)
def empty_cache(tmp_path, monkeypatch) -> Path:
    """Nothing remembered: a cache folder of this test's own (also for the worker processes it starts)."""
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    return tmp_path / "cache"


@pytest.mark.parametrize("material", ["paper-cd", "cd"])
def test_the_quick_guess_shows_the_material_on_the_disc(ctx, material):
    from viewer.scene import SceneRenderer
    from viewer.srgb import display_srgb8

    model, mesh = load_model(resolve_material(material)), build_mesh("cd")
    view = quick_view(model, mesh)
    assert set(view) == set(VIEW_FIELDS)
    state = ViewerState(material=material, mesh="cd", **view)
    with SceneRenderer(ctx, model, weights_path="texture", render_path="deferred", measure_render_path=False) as scene:
        rgba = scene.render_rgba(mesh, state.camera(), state.light(), (48, 48), state.exposure, state.effective_ior)
    shown = display_srgb8(rgba[..., :3]).max(axis=2)[rgba[..., 3] > 0.5]
    assert shown.size > 200
    assert np.mean(shown >= 8) >= 0.5, "the guess leaves most of the disc dark"
    assert np.mean(shown >= 250) <= 0.05, "the guess saturates the disc"


def test_the_quick_guess_needs_no_colour_science():
    code = ("import sys; from gratnet.modelfile import load_model; from viewer.catalog import build_mesh, "
            "resolve_material; from viewer.default_view import quick_view; "
            "print(quick_view(load_model(resolve_material('paper-cd')), build_mesh('plane')) is not None, "
            "quick_view(load_model(resolve_material('cd')), None, slice_mode=True) is not None, "
            "'colour' in sys.modules)")
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=REPO, check=True)
    assert result.stdout.split() == ["True", "True", "False"]


def test_a_model_file_without_its_analysis_has_no_quick_guess():
    import dataclasses

    model = load_model(resolve_material("cd"))
    assert quick_view(dataclasses.replace(model, metadata={}), build_mesh("plane")) is None


def test_the_exact_defaults_are_remembered_per_model_file(empty_cache, tmp_path):
    import shutil

    assert remembered_view("cd", "plane") is None
    exact = state_defaults("cd", "plane")
    assert view_cache_file() == empty_cache / "gratnet" / "default_views.json"
    assert remembered_view("cd", "plane") == exact
    assert remembered_view("cd", "sphere") is None and remembered_view("cd", "plane", slice_mode=True) is None
    assert remembered_view("cd", "plane", ior=None) is None
    copy = tmp_path / "copy.npz"
    shutil.copyfile(resolve_material("cd"), copy)
    assert remembered_view(str(copy), "plane") is None  # another file: not the same key
    view_cache_file().write_text("{not json")
    assert remembered_view("cd", "plane") is None  # a broken cache is no cache


def test_a_remembered_view_is_handed_over_at_once():
    state = ViewerState(material="cd", mesh="plane")
    exact = state_defaults("cd", "plane", False, state.fov, state.effective_ior)
    requests = DefaultViewRequests(background=True)
    try:
        requests.request(state)
        assert requests.take(state) == exact  # no worker, no thread: from the file
        assert not requests.pending
    finally:
        requests.release()


def test_a_switch_shows_the_new_material_at_the_guess_then_at_the_exact_view(ctx):
    """The window's background mode on a headless context: after a switch from paper-cd to cd the state takes
    cd's quick guess (light and exposure, while the camera is being dragged) before the worker's exact defaults,
    which then replace the light and exposure; the old exposure never stays."""
    from viewer.app import ViewerApp

    start = ViewerState(material="paper-cd", mesh="cd", light_theta=21.8, light_phi=102.5, camera_distance=0.185,
                        camera_elevation=75.0, exposure=39.3)
    app = ViewerApp(ctx, start, size=(32, 32), background=True)
    try:
        app.switch(material="cd")
        assert app.state.material == "cd" and app.default_view_stage == "guessing"
        stages = []
        deadline = time.monotonic() + 120.0
        while app.default_view_stage and time.monotonic() < deadline:
            app.orbit(2.0, 0.0)  # a drag under way: the camera stays the user's
            app.frame()
            stages.append((app.default_view_stage, app.state.exposure, app.state.light_theta))
            time.sleep(0.02)
        assert not app.default_view_stage, "the exact default view did not arrive in 120 s"
        guessed = [(exposure, theta) for stage, exposure, theta in stages if stage == "refining"]
        assert guessed and guessed[0][0] != start.exposure  # the guess's light and exposure came first
        exact = state_defaults("cd", "cd", False, start.fov, start.effective_ior)
        assert app.state.exposure == pytest.approx(exact["exposure"])
        assert (app.state.light_theta, app.state.light_phi) == pytest.approx((exact["light_theta"],
                                                                              exact["light_phi"]))
        assert app.state.camera_azimuth != pytest.approx(exact["camera_azimuth"])  # the drag's
    finally:
        app.release()


def test_gratnet_view_leaves_the_view_to_the_window_and_keeps_the_flags_given(empty_cache):
    from gratnet.cli import build_parser
    from viewer.defaults import FALLBACK
    from viewer.view_cli import starting_view

    def start(*flags: str) -> tuple[ViewerState, tuple[str, ...]]:
        return starting_view(build_parser(only="view").parse_args(["view", "--material", "cd", "--mesh", "plane",
                                                                   *flags]))

    state, guessed = start()  # nothing computed before the window: the fallback view, all of it to work out
    assert guessed == VIEW_FIELDS and state.exposure == FALLBACK.exposure
    state, guessed = start("--exposure", "7")
    assert state.exposure == 7.0 and "exposure" not in guessed and "light_theta" in guessed
    assert start("--exposure", "7", "--light", "20,30", "--camera", "0.3,10,20")[1] == ()
    exact = state_defaults("cd", "plane")
    state, guessed = start()  # remembered: exact at once, nothing to work out
    assert guessed == () and {name: getattr(state, name) for name in VIEW_FIELDS} == pytest.approx(exact)


def test_the_first_picture_waits_for_the_guess_not_at_the_fallback_view(ctx):
    """gratnet view's window starts at the fallback view with every view field to work out: its first picture
    shows the quick guess (or the exact defaults), never the fallback view."""
    from viewer.app import ViewerApp
    from viewer.defaults import FALLBACK

    start = ViewerState(material="cd", mesh="plane", exposure=FALLBACK.exposure)
    app = ViewerApp(ctx, start, size=(16, 16), background=True, refine_view=VIEW_FIELDS)
    try:
        deadline = time.monotonic() + 120.0
        while app.image is None and time.monotonic() < deadline:
            app.frame()
            time.sleep(0.02)
        assert app.image is not None
        shown = dict(zip(("light_theta", "light_phi", "camera_azimuth", "camera_elevation", "camera_distance"),
                         app.image.key[2:7], strict=True))
        assert app.image.key[8] != FALLBACK.exposure and shown["light_theta"] != FALLBACK.light_theta_degrees
    finally:
        app.release()
