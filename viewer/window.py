"""The viewer's window: glfw, imgui and the EGL/GL glue, around :class:`~viewer.app.ViewerApp`.

:class:`ViewerWindow` opens the window (OpenGL 4.3 core), wraps its context with
:func:`viewer.context.context_from_current`, draws the panel (material, mesh, light, camera, exposure,
Fresnel/IOR, BRDF-slice mode, frame times, screenshot), turns mouse drags and the wheel into camera moves,
and shows :attr:`ViewerApp.image` as an imgui image. No input is lost: the frame that releases the button
still applies the drag's last motion (a flick between two slow frames orbits). The panel keeps a fixed
number of lines for its status (what compiles, the last message), so that nothing moves under the pointer,
and fits a 512-pixel-high window. The state, the scheduling and every render are the
app's (:mod:`viewer.app`): this module only draws and forwards input. glfw and imgui are imported only
here, and only when a window is made (``imgui_bundle`` first: glfw then loads imgui_bundle's GLFW library,
so both sides share one GLFW).
"""

from __future__ import annotations

import contextlib
import ctypes
import gc
import importlib
import time
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any

import numpy as np

from gratnet.errors import GratNetError
from gratnet.quality import AUTO
from viewer.app import ViewerApp
from viewer.environment_view import ENVIRONMENT_SAMPLES
from viewer.reference_view import SHADINGS
from viewer.scheduling import ResolutionPolicy
from viewer.screenshot import next_screenshot_path, save_screenshot
from viewer.state import SLIDERS, ViewerState

__all__ = ["ViewerWindow"]

_GL_READ_FRAMEBUFFER = 0x8CA8
_GL_BACK = 0x0405
_GL_PACK_ALIGNMENT = 0x0D05
_GL_RGB = 0x1907
_GL_UNSIGNED_BYTE = 0x1401


class ViewerWindow:
    """A glfw window (OpenGL 4.3 core) with the imgui panel on the left and the picture on the right.

    Args:
        state: the initial view.
        size: the render area ``(width, height)``; the window adds the panel's width.
        policy, clock: as :class:`ViewerApp`.
        screenshot_dir: where the Screenshot button writes ``gratnet-view-NNN.png``.
        idle_wait_s: how long a frame with nothing to render waits for input (``wait_events_timeout``);
            0 polls (tests).
        extra_meshes, weights_path, background: as :class:`ViewerApp` (here ``background`` is on by
            default: the window opens, shows its panel and handles input at once, whatever compiles).
        visible: show the window (tests under Xvfb may hide it; rendering is the same).
        max_samples: as :class:`ViewerApp` (progressive anti-aliasing; here 16 by default).
        worker: a compile child started earlier for ``state`` (``SceneSupply.start_worker``; ``gratnet view``
            starts it first thing), adopted (closed if the window cannot open); else the window starts one.
        refine_view: as :class:`ViewerApp` (the fields of ``state`` that are a guess at the default view).
        environments, environment_samples, auto_exposure: as :class:`ViewerApp` (environment light: the panel then
            has an environment chooser, its rotation and scale, and the light's intensity).

    Raises:
        GratNetError: no display, or no OpenGL 4.3 core context for a window.
    """

    PANEL_WIDTH = 300
    #: The panel's choices of samples per pixel accumulated while the view stands still.
    SAMPLE_CHOICES = (1, 4, 16, 64)
    #: … and of passes under an environment (its noise needs many).
    ENVIRONMENT_SAMPLE_CHOICES = (16, 64, 256, 1024, 4096)

    def __init__(self, state: ViewerState | None = None, size: tuple[int, int] = (512, 512),
                 policy: ResolutionPolicy | None = None, clock: Callable[[], float] = time.perf_counter,
                 screenshot_dir: str | Path = ".", idle_wait_s: float = 0.25, extra_meshes: Iterable[str] = (),
                 weights_path: str = "auto", background: bool = True,
                 visible: bool = True, title: str = "GratNet viewer", max_samples: int = 16,
                 render_path: str = "auto", reference: Any = None, worker: Any = None,
                 refine_view: Iterable[str] = (), quality: str = AUTO, environments: Iterable[str] = (),
                 environment_samples: int = ENVIRONMENT_SAMPLES, auto_exposure: bool = False) -> None:
        from viewer.context import context_from_current
        from viewer.scene_supply import SceneSupply
        from viewer.surface import check_size

        width, height = check_size(size)
        # The compile child first: its Python start-up and the quick shader overlap the window's set-up.
        if background and worker is None:
            with contextlib.suppress(GratNetError):  # a bad material is reported by ViewerApp below
                start = state or ViewerState()
                warmed = start.environment if start.has_environment else next(iter(environments), None)
                worker = SceneSupply.start_worker(start, weights_path, render_path, warmed)
        glfw, imgui = self._glfw, self._imgui = _shell_modules()
        self.screenshot_dir = Path(screenshot_dir)
        self.idle_wait_s = float(idle_wait_s)
        self.frames = 0
        self.gl_errors: list[str] = []
        self.last_capture: np.ndarray | None = None
        self.last_screenshot: Path | None = None
        self._texture: Any = None
        self._texture_version = -1
        self._texture_uv = (1.0, 1.0)  # the picture's corner in the (padded) texture
        self._window: Any = None
        self._imgui_ready = False
        self._app: ViewerApp | None = None
        self._closed = False
        self._first_frame = False
        #: ``time.perf_counter()`` after the swap of the first frame that showed a picture.
        self.first_picture_at: float | None = None
        #: Where the panel's controls start (window pixels from the top, by name) in the last frame, and
        #: ``end``, where its last line ends.
        self.panel_layout: dict[str, float] = {}

        # A headless renderer's EGL context may be current on this thread: unbind it for the window's
        # lifetime (restored by close()), or making the window's GLX context current kills the process.
        self._egl = _CurrentEGLContext()
        reporting = glfw.ERROR_REPORTING
        glfw.ERROR_REPORTING = "ignore"  # failures are reported below, as one GratNetError line
        try:
            if not glfw.init():
                self._egl.restore()
                if worker is not None:
                    worker.close()
                raise GratNetError(
                    f"no display for the viewer window ({_glfw_error(glfw)}); run it on a desktop session, or "
                    "under a virtual X server (xvfb-run gratnet view …), or write images with gratnet render"
                )
            glfw.window_hint(glfw.CONTEXT_VERSION_MAJOR, 4)
            glfw.window_hint(glfw.CONTEXT_VERSION_MINOR, 3)
            glfw.window_hint(glfw.OPENGL_PROFILE, glfw.OPENGL_CORE_PROFILE)
            glfw.window_hint(glfw.OPENGL_FORWARD_COMPAT, True)
            glfw.window_hint(glfw.VISIBLE, False)  # shown after the first frame (see below)
            self._window = glfw.create_window(self.PANEL_WIDTH + width, height, title, None, None)
            if not self._window:
                error = _glfw_error(glfw)
                glfw.terminate()
                self._egl.restore()
                if worker is not None:
                    worker.close()
                raise GratNetError(f"cannot open an OpenGL 4.3 core window ({error}); the viewer needs OpenGL 4.3")
        finally:
            glfw.ERROR_REPORTING = reporting
        try:
            glfw.make_context_current(self._window)
            glfw.swap_interval(1)
            self.ctx = context_from_current()
            imgui.create_context()
            imgui.get_io().set_ini_filename(None)  # no imgui.ini in the working folder
            imgui.style_colors_dark()
            address = ctypes.cast(self._window, ctypes.c_void_p).value
            imgui.backends.glfw_init_for_opengl(address, True)
            imgui.backends.opengl3_init("#version 410 core")
            self._imgui_ready = True
            self._gl = _GLFunctions(glfw)
            self._texture = self._picture_texture(1, 1)  # drawn by the first frame: see there
            self._app = ViewerApp(self.ctx, state, self._area_pixels(), policy, clock, extra_meshes, weights_path,
                                  background, worker, max_samples, render_path, reference, refine_view, quality,
                                  environments=environments, environment_samples=environment_samples,
                                  auto_exposure=auto_exposure)
            worker = None  # the app owns it now
            # The first frame compiles imgui's own shaders and, drawing the 1×1 picture texture, their variant
            # for its format (0.3–0.5 s on llvmpipe with an empty shader cache): drawn while the window is
            # unmapped, no input can wait for it; then the panel appears at once.
            self._first_frame = True
            self.frame()
            self._first_frame = False
            # Python's cyclic GC paused 60–380 ms at a time over the ~1e6 objects imgui (and colour-science, which
            # the window no longer imports: viewer.srgb) made: frozen out of every later collection.
            gc.freeze()
            if visible:
                glfw.show_window(self._window)
        except BaseException:
            if worker is not None:
                worker.close()
            self.close()
            raise

    @property
    def app(self) -> ViewerApp:
        assert self._app is not None
        return self._app

    @property
    def handle(self) -> Any:
        """The glfw window."""
        return self._window

    # -- geometry ----------------------------------------------------------------------------------

    def _scale(self) -> float:
        window_width, _ = self._glfw.get_window_size(self._window)
        framebuffer_width, _ = self._glfw.get_framebuffer_size(self._window)
        return framebuffer_width / window_width if window_width else 1.0

    def _area_pixels(self) -> tuple[int, int]:
        """The render area in framebuffer pixels (the window minus the panel)."""
        width, height = self._glfw.get_framebuffer_size(self._window)
        panel = round(self.PANEL_WIDTH * self._scale())
        return max(1, width - panel), max(1, height)

    def render_area(self) -> tuple[int, int, int, int]:
        """``(x, y, width, height)`` of the picture in framebuffer pixels, y from the top."""
        app = self.app
        area_w, area_h = self._area_pixels()
        full_w, full_h = app.full_size()
        panel = self._framebuffer_size()[0] - area_w
        return panel + (area_w - full_w) // 2, (area_h - full_h) // 2, full_w, full_h

    def _framebuffer_size(self) -> tuple[int, int]:
        width, height = self._glfw.get_framebuffer_size(self._window)
        return int(width), int(height)

    # -- the frame ---------------------------------------------------------------------------------

    def should_close(self) -> bool:
        return self._closed or bool(self._glfw.window_should_close(self._window))

    def frame(self, capture: bool = False) -> bool:
        """Wait for input (or for due work), handle it (the panel's widgets and the mouse change the
        state), render what the state then needs (:meth:`ViewerApp.frame`: one preview or one band at
        most, never a compile), draw the panel and the picture, swap: an input is on screen in the frame
        that handled it. With ``capture`` the window's pixels are read (glReadPixels) into
        :attr:`last_capture` before the swap. Returns False once the window was asked to close."""
        glfw, imgui = self._glfw, self._imgui
        if self.should_close():
            return False
        app = self.app
        wait = app.next_work_in()
        wait = self.idle_wait_s if wait is None else min(wait, self.idle_wait_s)
        if wait > 0:
            glfw.wait_events_timeout(wait)  # sleep until input (or until the preview is due for refinement)
        else:
            glfw.poll_events()
        started = time.perf_counter()  # the frame's work starts when the wait ends
        if 0 in self._framebuffer_size():  # minimized: nothing to draw into
            if self.idle_wait_s > 0:
                glfw.wait_events_timeout(self.idle_wait_s)
            return not self.should_close()
        app.set_size(self._area_pixels())

        imgui.backends.opengl3_new_frame()
        imgui.backends.glfw_new_frame()
        imgui.new_frame()
        self._picture_input()
        self._panel()
        app.frame()
        self._upload()
        self._picture()
        imgui.render()

        self.ctx.screen.use()
        self.ctx.clear(0.06, 0.06, 0.07, 1.0)
        imgui.backends.opengl3_render_draw_data(imgui.get_draw_data())
        error = self.ctx.error
        if error != "GL_NO_ERROR":
            self.gl_errors.append(f"frame {self.frames}: {error}")
        if capture:
            self.last_capture = self.read_pixels()
        glfw.swap_buffers(self._window)
        self.frames += 1
        app.stats.last_frame_s = time.perf_counter() - started
        if self.first_picture_at is None and app.image is not None:
            self.first_picture_at = time.perf_counter()
        return True

    def run(self, max_frames: int = 0) -> int:
        """Frames until the window closes (or ``max_frames`` frames when > 0); returns the frame count."""
        count = 0
        while (max_frames <= 0 or count < max_frames) and self.frame():
            count += 1
        return count

    def read_pixels(self) -> np.ndarray:
        """The window's back buffer as ``uint8`` ``(H, W, 3)``, row 0 at the top (glReadPixels)."""
        width, height = self._framebuffer_size()
        return self._gl.read_back_buffer(width, height)

    def _upload(self) -> None:
        image = self.app.image
        if image is None or image.version == self._texture_version:
            return
        height, width = image.pixels.shape[:2]
        size = (_power_of_two(width), _power_of_two(height))
        if self._texture is None or self._texture.size != size:
            if self._texture is not None:
                self._texture.release()
            self._texture = self._picture_texture(*size)
        # Edge rows and columns repeated into the padding: linear filtering at the border reads the picture.
        padded = np.pad(image.pixels, ((0, size[1] - height), (0, size[0] - width), (0, 0)), mode="edge")
        self._texture.write(np.ascontiguousarray(padded).tobytes(), alignment=1)
        self._texture_uv = (width / size[0], height / size[1])
        self._texture_version = image.version

    def _picture_input(self) -> None:
        """The render area's input: mouse drag (orbit) and wheel (zoom)."""
        imgui, app = self._imgui, self.app
        display = imgui.get_io().display_size
        x0 = self.PANEL_WIDTH
        imgui.set_next_window_pos(imgui.ImVec2(x0, 0), imgui.Cond_.always)
        imgui.set_next_window_size(imgui.ImVec2(max(1.0, display.x - x0), max(1.0, display.y)), imgui.Cond_.always)
        flags = (imgui.WindowFlags_.no_decoration | imgui.WindowFlags_.no_move | imgui.WindowFlags_.no_background
                 | imgui.WindowFlags_.no_bring_to_front_on_focus | imgui.WindowFlags_.no_saved_settings
                 | imgui.WindowFlags_.no_scroll_with_mouse)
        imgui.push_style_var(imgui.StyleVar_.window_padding, imgui.ImVec2(0, 0))
        imgui.begin("##picture", None, flags)
        imgui.pop_style_var()
        area = imgui.ImVec2(max(1.0, display.x - x0), max(1.0, display.y))
        imgui.invisible_button("##orbit", area)
        # The frame that releases the button still applies its motion: a quick flick (press, motion and
        # release between two slow frames) orbits like a slow drag (issue 35; imgui processes the motion and
        # the release in one frame, and the item is no longer active then).
        if imgui.is_item_active() or imgui.is_item_deactivated():
            delta = imgui.get_io().mouse_delta
            if delta.x or delta.y:
                app.orbit(delta.x, delta.y)
        if imgui.is_item_hovered():
            wheel = imgui.get_io().mouse_wheel
            if wheel:
                app.zoom(wheel)
        imgui.end()

    def _picture_texture(self, width: int, height: int) -> Any:
        """An RGB8 texture, linear filtering. Power-of-two sizes only: llvmpipe compiles a new variant of
        imgui's shader for a non-power-of-two texture (~0.15 s, seen as a stalled frame at the first
        picture); the first frame (hidden) compiles the one variant used."""
        import moderngl

        texture = self.ctx.texture((width, height), 3, dtype="f1", alignment=1)
        texture.filter = (moderngl.LINEAR, moderngl.LINEAR)
        return texture

    def _picture(self) -> None:
        """The picture (stretched from a preview), drawn under the widgets."""
        imgui, app = self._imgui, self.app
        if self._texture is not None and (app.image is not None or self._first_frame):
            scale = self._scale()
            ax, ay, aw, ah = self.render_area()
            p0 = imgui.ImVec2(ax / scale, ay / scale)
            p1 = imgui.ImVec2((ax + aw) / scale, (ay + ah) / scale)
            # The background list: not clipped to the window's inner rectangle (its border would be).
            imgui.get_background_draw_list().add_image(imgui.ImTextureRef(self._texture.glo), p0, p1,
                                                       imgui.ImVec2(0, 0), imgui.ImVec2(*self._texture_uv))

    #: Lines of text the panel keeps for what is compiling or loading and for the last message, whether or not
    #: there is any: a line that comes or goes never moves the controls under the pointer (issue 35).
    STATUS_LINES = 3

    def _mark(self, name: str) -> None:
        """Record where the next widget starts (:attr:`panel_layout`, window pixels from the top)."""
        self.panel_layout[name] = float(self._imgui.get_cursor_screen_pos().y)

    def _status(self) -> None:
        """The status region: a fixed number of lines (wrapped, scrolling if longer) with what is compiling or
        loading (amber) and the last message (a screenshot written, a material refused)."""
        imgui, app = self._imgui, self.app
        height = self.STATUS_LINES * imgui.get_text_line_height_with_spacing()
        imgui.begin_child("##status", imgui.ImVec2(0, height), 0, imgui.WindowFlags_.no_background)
        status = app.status
        if status:  # the reason the picture is old or absent
            imgui.push_style_color(imgui.Col_.text, imgui.ImVec4(1.0, 0.8, 0.3, 1.0))
            imgui.text_wrapped(status)
            imgui.pop_style_color()
        if app.message:
            imgui.text_wrapped(app.message)
        imgui.end_child()

    def _panel(self) -> None:
        """The panel: the status region, then every control at a fixed place; it fits a 512-pixel-high window
        (tests/runtime/test_viewer_window.py)."""
        imgui, app = self._imgui, self.app
        state = app.state
        display = imgui.get_io().display_size
        imgui.set_next_window_pos(imgui.ImVec2(0, 0), imgui.Cond_.always)
        imgui.set_next_window_size(imgui.ImVec2(self.PANEL_WIDTH, max(1.0, display.y)), imgui.Cond_.always)
        imgui.begin("GratNet", None, imgui.WindowFlags_.no_move | imgui.WindowFlags_.no_resize
                    | imgui.WindowFlags_.no_collapse | imgui.WindowFlags_.no_saved_settings)
        imgui.push_item_width(150)
        self._status()
        imgui.separator()

        self._mark("material")
        materials = app.materials()
        if state.material not in materials:
            materials.append(state.material)
        changed, index = imgui.combo("material", materials.index(state.material), materials)
        if changed:
            app.switch(material=materials[index])
        changed, index = imgui.combo("mesh", app.meshes.index(state.mesh), app.meshes)
        if changed:
            app.switch(mesh=app.meshes[index])
        changed, value = imgui.checkbox("BRDF slice", state.slice_mode)
        if changed:
            app.switch(slice_mode=value)
        imgui.same_line()
        if imgui.button("default view"):  # the light, camera and exposure that show this material's diffraction
            app.switch()
        imgui.same_line()
        self._mark("Screenshot")
        if imgui.button("Screenshot"):
            self.screenshot()
        if app.reference is not None:  # gratnet view --reference: network, its ground truth, or FLIP between them
            imgui.begin_disabled(not app.reference_available())
            for shading in SHADINGS:
                if imgui.radio_button(shading, state.shading == shading):
                    app.set(shading=shading)
                imgui.same_line()
            imgui.new_line()
            imgui.end_disabled()
            flip = app.flip_mean
            imgui.text(f"mean FLIP {flip:.4f} (covered pixels)" if flip is not None else
                       f"ground truth: {app.reference.loaded.material}'s volume")

        imgui.separator_text("light")
        self._mark("light_theta")
        self._slider("light_theta")
        self._slider("light_phi")
        imgui.separator_text("camera (drag: orbit, wheel: zoom)")
        imgui.begin_disabled(state.slice_mode)
        self._slider("camera_azimuth")
        self._slider("camera_elevation")
        self._slider("camera_distance")
        imgui.end_disabled()
        imgui.separator_text("display")
        self._slider("exposure")
        # Progressive anti-aliasing while the view stands still (1: off); the count shows under "performance".
        # Under an environment: its passes (the estimator's noise needs many).
        cap = app.sample_cap
        choices = sorted({*(self.ENVIRONMENT_SAMPLE_CHOICES if app.environment_live() else self.SAMPLE_CHOICES), cap})
        changed, index = imgui.combo("samples (still)", choices.index(cap), [str(c) for c in choices])
        if changed:
            app.set_max_samples(choices[index])
        changed, value = imgui.checkbox("Fresnel", state.fresnel)
        if changed:
            app.set(fresnel=value)
        imgui.same_line()
        imgui.begin_disabled(not state.fresnel)
        imgui.push_item_width(110)
        self._mark("ior")
        self._slider("ior")
        imgui.pop_item_width()
        imgui.end_disabled()

        if app.environments:  # gratnet view --environment: the chooser, its turn and factor, the light's intensity
            imgui.separator_text("environment")
            self._mark("environment")
            spec = state.environment if state.environment in app.environments else "none"
            names = [Path(choice).name if ("/" in choice or "\\" in choice) else choice for choice in app.environments]
            changed, index = imgui.combo("environment", app.environments.index(spec), names)
            if changed:
                app.set(environment=app.environments[index])
            imgui.begin_disabled(not state.has_environment)
            self._slider("environment_rotation")
            self._slider("environment_scale")
            imgui.end_disabled()
            self._slider("light_intensity")

        imgui.separator_text("performance")
        self._mark("performance")
        for line in self._performance_lines():
            imgui.text(line)
        self._mark("end")
        imgui.pop_item_width()
        imgui.end()

    def _performance_lines(self) -> list[str]:
        """The panel's performance figures, four lines at most (the panel fits a 512-pixel window)."""
        app = self.app
        stats, image, state = app.stats, app.image, app.state
        width, height = stats.last_render_size
        lines = [f"frame {stats.last_frame_s * 1000:.0f} ms; render {stats.last_render_s * 1000:.0f} ms at "
                 f"{width}×{height}"]
        parts = []
        if stats.last_preview_s is not None:
            pw, ph = stats.last_preview_size
            parts.append(f"preview {stats.last_preview_s * 1000:.0f} ms at {pw}×{ph}")
        if stats.last_full_s is not None:
            parts.append(f"full {stats.last_full_s:.1f} s")
        if parts:
            lines.append("; ".join(parts))
        if image is not None:
            progress = "complete" if image.complete else f"refining {image.progress:.0%}"
            samples = "" if state.slice_mode else f", {image.samples}/{app.sample_cap} samples"
            lines.append(f"{image.full_size[0]}×{image.full_size[1]}: {progress}{samples}")
        in_use = app.weights_path_in_use()
        lines.append(f"{in_use} weights, {stats.renders} renders" if in_use else f"{stats.renders} renders")
        return lines

    def screenshot(self) -> Path | None:
        """The Screenshot button: the full-resolution picture to ``screenshot_dir/gratnet-view-NNN.png``
        (and its ``.config.json``), written atomically; the outcome is shown in the panel."""
        app = self.app
        try:
            self.last_screenshot = save_screenshot(app, next_screenshot_path(self.screenshot_dir))
        except GratNetError as error:
            app.message = str(error)
            return None
        app.message = f"wrote {self.last_screenshot}"
        return self.last_screenshot

    def _slider(self, name: str) -> None:
        imgui, app = self._imgui, self.app
        slider = SLIDERS[name]
        flags = imgui.SliderFlags_.logarithmic if slider.log else 0
        changed, value = imgui.slider_float(slider.label, float(getattr(app.state, name)), slider.minimum,
                                            slider.maximum, slider.format, flags)
        if changed:
            app.set(**{name: value})

    # -- teardown ----------------------------------------------------------------------------------

    def close(self) -> None:
        """Free everything: the app's GL objects, imgui, the window, GLFW."""
        if self._closed:
            return
        self._closed = True
        glfw, imgui = self._glfw, self._imgui
        if self._app is not None:
            self._app.release()
        if self._texture is not None:
            self._texture.release()
        if self._imgui_ready:
            imgui.backends.opengl3_shutdown()
            imgui.backends.glfw_shutdown()
            imgui.destroy_context()
        if self._window:
            glfw.destroy_window(self._window)
        glfw.terminate()
        self._egl.restore()

    def __enter__(self) -> ViewerWindow:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()


def _power_of_two(value: int) -> int:
    """The smallest power of two ≥ ``value``."""
    return 1 << max(0, int(value) - 1).bit_length()


def _shell_modules() -> tuple[Any, Any]:
    """``(glfw, imgui)``: imgui_bundle first, so that glfw loads imgui_bundle's GLFW library (one GLFW for
    both the window and imgui's glfw backend)."""
    from imgui_bundle import imgui

    glfw = importlib.import_module("glfw")
    return glfw, imgui


def _glfw_error(glfw: Any) -> str:
    code, description = glfw.get_error()
    if not code:
        return "unknown GLFW error"
    text = description.decode(errors="replace") if isinstance(description, bytes) else str(description)
    return " ".join(text.split())


class _CurrentEGLContext:
    """Unbinds the EGL context current on this thread, if any, and binds it again on :meth:`restore`.

    libglvnd lets a thread have a current context of one API at a time: while an EGL context is current
    (a headless :func:`viewer.context.create_headless_context` in the same process, e.g. in a test run),
    glXMakeCurrent fails with BadAccess, and Xlib's default error handler then exits the process.
    """

    _EGL_DRAW, _EGL_READ = 0x3059, 0x305A

    def __init__(self) -> None:
        self._saved: tuple[Any, ...] | None = None
        try:
            egl = ctypes.CDLL("libEGL.so.1")
        except OSError:  # no EGL (or not Linux): nothing can be current
            return
        pointer = ctypes.c_void_p
        egl.eglGetCurrentContext.restype = pointer
        egl.eglGetCurrentDisplay.restype = pointer
        egl.eglGetCurrentSurface.restype = pointer
        egl.eglGetCurrentSurface.argtypes = [ctypes.c_int]
        egl.eglMakeCurrent.argtypes = [pointer, pointer, pointer, pointer]
        egl.eglMakeCurrent.restype = ctypes.c_uint
        context = egl.eglGetCurrentContext()
        if not context:
            return
        display = egl.eglGetCurrentDisplay()
        draw, read = egl.eglGetCurrentSurface(self._EGL_DRAW), egl.eglGetCurrentSurface(self._EGL_READ)
        if egl.eglMakeCurrent(display, None, None, None):
            self._saved = (egl, display, draw, read, context)

    def restore(self) -> None:
        if self._saved is not None:
            egl, display, draw, read, context = self._saved
            self._saved = None
            egl.eglMakeCurrent(display, draw, read, context)


class _GLFunctions:
    """The few raw GL calls the shell needs (glReadPixels of the default framebuffer's back buffer;
    moderngl's screen.read selects GL_COLOR_ATTACHMENT0, an error on the default framebuffer)."""

    def __init__(self, glfw: Any) -> None:
        def load(name: str, *arguments: Any) -> Any:
            address = glfw.get_proc_address(name)
            if not address:
                raise GratNetError(f"OpenGL function {name} is missing")
            return ctypes.CFUNCTYPE(None, *arguments)(address)

        uint, int_ = ctypes.c_uint, ctypes.c_int
        self.bind_framebuffer = load("glBindFramebuffer", uint, uint)
        self.read_buffer = load("glReadBuffer", uint)
        self.pixel_store = load("glPixelStorei", uint, int_)
        self.read_pixels = load("glReadPixels", int_, int_, int_, int_, uint, uint, ctypes.c_void_p)

    def read_back_buffer(self, width: int, height: int) -> np.ndarray:
        pixels = np.empty((height, width, 3), dtype=np.uint8)
        self.bind_framebuffer(_GL_READ_FRAMEBUFFER, 0)
        self.read_buffer(_GL_BACK)
        self.pixel_store(_GL_PACK_ALIGNMENT, 1)
        self.read_pixels(0, 0, width, height, _GL_RGB, _GL_UNSIGNED_BYTE, pixels.ctypes.data)
        return np.ascontiguousarray(pixels[::-1])
