"""The viewer window's input and panel (issue 35), under Xvfb (conftest.py's ``xvfb``, as test_viewer.py).

- No input is lost: a quick flick (press, motion and release between two frames) orbits like a slow drag.
- The panel: every control fits a 512-pixel window (the Screenshot button included), and a status line
  appearing or going does not move the controls under the pointer.
"""

from __future__ import annotations

import ctypes

import pytest

from tests.helpers import PLANE, FakeClock

DEGREES_PER_PIXEL = 0.4


@pytest.fixture
def window(display, tmp_path):
    from viewer.window import ViewerWindow

    clock = FakeClock()
    with ViewerWindow(PLANE, size=(160, 120), clock=clock, idle_wait_s=0.0, screenshot_dir=tmp_path,
                      background=False) as viewer:
        viewer.clock_control = clock  # type: ignore[attr-defined]
        yield viewer


def _mouse(window):
    from imgui_bundle import imgui

    return imgui.backends, ctypes.cast(window.handle, ctypes.c_void_p).value


@pytest.mark.parametrize("pressed_in_its_own_frame", [True, False], ids=["press, then motion+release", "all at once"])
def test_a_flick_between_two_frames_orbits_like_a_slow_drag(window, pressed_in_its_own_frame):
    backends, address = _mouse(window)
    x, y = window.PANEL_WIDTH + 60.0, 60.0
    window.frame()
    backends.glfw_cursor_enter_callback(address, 1)
    backends.glfw_cursor_pos_callback(address, x, y)
    window.frame()
    azimuth, elevation = window.app.state.camera_azimuth, window.app.state.camera_elevation
    backends.glfw_mouse_button_callback(address, 0, 1, 0)  # pressed
    if pressed_in_its_own_frame:
        window.frame()
    backends.glfw_cursor_pos_callback(address, x + 30.0, y + 15.0)  # moved …
    backends.glfw_mouse_button_callback(address, 0, 0, 0)  # … and released before the next frame
    for _ in range(3):
        window.frame()
    assert window.app.state.camera_azimuth == pytest.approx(azimuth - 30.0 * DEGREES_PER_PIXEL)
    assert window.app.state.camera_elevation == pytest.approx(elevation + 15.0 * DEGREES_PER_PIXEL)
    # A move after the release is no drag.
    backends.glfw_cursor_pos_callback(address, x + 50.0, y + 15.0)
    window.frame()
    assert window.app.state.camera_azimuth == pytest.approx(azimuth - 30.0 * DEGREES_PER_PIXEL)
    assert window.gl_errors == []


@pytest.fixture
def tall_window(display, tmp_path):  # noqa: F811 - the display fixture imported above
    """The window of `gratnet view`'s default size: a 512-pixel-high render area."""
    from viewer.window import ViewerWindow

    clock = FakeClock()
    with ViewerWindow(PLANE, size=(64, 512), clock=clock, idle_wait_s=0.0, screenshot_dir=tmp_path,
                      background=False) as viewer:
        yield viewer


def test_every_control_fits_a_512_pixel_window_and_status_lines_move_nothing(tall_window):
    window = tall_window
    window.frame()
    window.frame()
    quiet = dict(window.panel_layout)
    assert window.app.status == "" and window.app.message == ""
    assert quiet["end"] <= 512 - 4, f"the panel's last line ends at {quiet['end']:.0f} of 512 pixels"
    assert quiet["Screenshot"] < quiet["light_theta"] < quiet["ior"] < quiet["performance"] < quiet["end"]
    window.app.message = "a message that is long enough to wrap over more than one line of the panel, " * 2
    window.frame()
    window.frame()
    assert window.panel_layout == quiet  # the status region keeps its height
    window.frame(capture=True)
    assert window.gl_errors == []
