"""The interactive viewer: a glfw window with an imgui panel around :class:`~viewer.scene.SceneRenderer`.

Two layers, so that the logic can be tested without a display:

- :class:`ViewerApp` (no glfw, no imgui; any OpenGL ≥ 4.3 context, a window's or a headless one): the
  :class:`ViewerState`, the model and mesh caches, the :class:`ResolutionPolicy`, the frame cache and the
  screenshot. :meth:`ViewerApp.frame` renders only what the state needs: nothing when the picture on
  show is already the full-resolution picture of the current state.
- :class:`ViewerWindow`: the thin shell. It opens the window (OpenGL 4.3 core), wraps its context with
  :func:`viewer.context.context_from_current`, draws the panel (material, mesh, light, camera, exposure,
  Fresnel/IOR, BRDF-slice mode, frame times, screenshot), turns mouse drags and the wheel into camera
  moves, and shows :attr:`ViewerApp.image` as an imgui image. glfw and imgui are imported only here,
  and only when a window is made (``imgui_bundle`` first: glfw then loads imgui_bundle's GLFW library,
  so both sides share one GLFW).

Never blocking (issue 11; measured in docs/benchmarks.md "Viewer: a window that never blocks"): the window
never compiles a shader that has not been compiled already. :class:`~viewer.scene_supply.SceneSupply`
(background mode, the window's default) has a child process (:mod:`viewer.compile_worker`) compile each
material's programs on its own EGL context, which fills Mesa's disk shader cache; the window then links
the same program text as a cache hit, one short step per frame. The quick texture path (about a second
to compile) gives the first picture; on a CPU rasterizer the faster baked program (25–60 s to compile)
takes over when its compile is done. Until then the panel's status line says what is compiling
("compiling the shader for cd… 12 s") and the picture on show stays. Meshes are built on a thread,
colour-science is imported on a thread, and the first frame (imgui's own shaders) is drawn before the
window is shown. Each frame's work, the figure the panel shows as "frame", is its events, panel, at most
one preview or band, and drawing; the idle wait for input is not counted.

Staying responsive on a CPU rasterizer (Mesa llvmpipe: a full 320×240 CD-disc picture takes 1–3 s):

- While the state keeps changing (a slider or the mouse moving, and for ``idle_seconds`` after the last
  change), every new state is rendered at a reduced resolution: the smallest of 1/2, 1/4, 1/8 whose
  predicted cost fits ``interactive_budget_s`` (the cost model: measured seconds per covered pixel × the
  covered pixels of the last preview). Previews of the built-in disc and sphere use coarser
  tessellations (llvmpipe's cost per triangle dominates at low resolution).
- Once the state has stood still, the full-resolution picture is built in horizontal bands (the same
  camera with clip space cropped to the band's rows: the same pixel centres as one full render), one
  band per frame sized to ``refine_budget_s``; the window keeps handling input between bands, the
  preview stays on show under the bands not yet done, and any change abandons the refinement.
  (BRDF-slice mode doubles the resolution per level up to full, each level in bands of rows that fit
  ``refine_budget_s``: a scissor box limits the slice render to the band's rows.)
- Progressive anti-aliasing (issue 12; ``max_samples``, the panel's "samples" choice): once a mesh view's
  full-resolution picture is complete and the view stands still, each further step adds the next sub-pixel
  sample (:func:`viewer.antialias.sample_offsets`, the offsets of ``gratnet render --spp``) in bands of rows
  sized like the refinement's, into float32 sums, and shows their mean, until ``max_samples`` (not while a
  faster program for the view still compiles in the background: that compile gets the CPU); any change
  of the view starts again from the 1-sample preview. Previews and refinement bands are 1 sample (the pixel
  centre), so interaction costs what it did. The mean of k samples equals ``SceneRenderer.render(...,
  samples=k)`` (tests/test_viewer.py). BRDF-slice mode stays at 1 sample.
- When the picture is complete (and has its samples) and nothing changes, nothing is rendered, and the
  window sleeps in ``glfw.wait_events_timeout`` instead of spinning.

Every pixel comes from :class:`SceneRenderer` (``render`` / ``render_brdf_slice``), converted with its
``display_srgb8`` (``gratnet.display``), so the window shows exactly what ``gratnet render`` writes.
"""

from __future__ import annotations

import contextlib
import ctypes
import dataclasses
import gc
import importlib
import math
import time
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any

import numpy as np

from gratnet.errors import GratNetError
from viewer.camera import Camera, Light
from viewer.defaults import FALLBACK, FOV_DEGREES, DefaultViewRequests
from viewer.render_cli import MESHES, RenderConfig, resolve_material, shipped_materials

__all__ = [
    "SLIDERS",
    "Frame",
    "RenderStats",
    "ResolutionPolicy",
    "Slider",
    "ViewerApp",
    "ViewerState",
    "ViewerWindow",
    "drive_slider",
]


# --------------------------------------------------------------------------------------------------
# State


@dataclasses.dataclass
class ViewerState:
    """Everything that decides the picture (world +z up, degrees, metres; as ``gratnet render``)."""

    material: str = "blazed"
    mesh: str = "cd"
    # The material-independent defaults shared with `gratnet render` (viewer.defaults.FALLBACK); `gratnet view`
    # starts from viewer.defaults.resolve_defaults for its material and mesh instead.
    light_theta: float = FALLBACK.light_theta_degrees
    light_phi: float = FALLBACK.light_phi_degrees
    camera_azimuth: float = FALLBACK.camera_azimuth_degrees
    camera_elevation: float = FALLBACK.camera_elevation_degrees
    camera_distance: float = FALLBACK.camera_distance
    fov: float = FOV_DEGREES
    exposure: float = FALLBACK.exposure
    fresnel: bool = True
    ior: float = 1.5
    slice_mode: bool = False

    def key(self) -> tuple[Any, ...]:
        """The values that decide the pixels (two states with equal keys render the same picture)."""
        return dataclasses.astuple(self)

    @property
    def effective_ior(self) -> float | None:
        return self.ior if self.fresnel and self.ior != 0 else None

    def camera(self) -> Camera:
        return Camera(self.camera_distance, self.camera_azimuth, self.camera_elevation, fov_deg=self.fov)

    def light(self) -> Light:
        return Light.directional(self.light_theta, self.light_phi)

    def render_config(self, width: int, height: int, spp: int = 1) -> RenderConfig:
        """The ``gratnet render`` config that reproduces this view at ``width`` × ``height`` with ``spp``
        samples per pixel."""
        return RenderConfig(
            material=self.material, mesh=self.mesh, light_theta_degrees=self.light_theta,
            light_phi_degrees=self.light_phi, camera_distance=self.camera_distance,
            camera_azimuth_degrees=self.camera_azimuth, camera_elevation_degrees=self.camera_elevation,
            fov_degrees=self.fov, exposure=self.exposure, width=width, height=height, ior=self.ior,
            fresnel=self.fresnel, slice=self.slice_mode, spp=spp,
        )


@dataclasses.dataclass(frozen=True)
class Slider:
    """A numeric control of the panel: state field, label, range, logarithmic or not."""

    field: str
    label: str
    minimum: float
    maximum: float
    log: bool = False
    format: str = "%.1f"

    def clamp(self, value: float) -> float:
        value = float(value)
        if not math.isfinite(value):
            raise GratNetError(f"{self.field} must be a finite number, got {value!r}")
        return min(max(value, self.minimum), self.maximum)


#: The panel's sliders, by name (the names ``drive_slider`` and ``ViewerApp.set`` accept).
SLIDERS: dict[str, Slider] = {
    slider.field: slider
    for slider in (
        Slider("light_theta", "light theta (°)", 0.0, 89.0),  # imgui's default font has no Greek
        Slider("light_phi", "light phi (°)", -180.0, 180.0),
        Slider("camera_azimuth", "azimuth (°)", -180.0, 180.0),
        Slider("camera_elevation", "elevation (°)", -89.0, 89.0),
        Slider("camera_distance", "distance (m)", 0.02, 5.0, log=True, format="%.3f"),
        Slider("exposure", "exposure", 1e-3, 1e7, log=True, format="%.4g"),
        Slider("ior", "IOR", 1.05, 3.0, format="%.2f"),  # n = 1 has no Fresnel reflection: R0 = 0
    )
}


# --------------------------------------------------------------------------------------------------
# Resolution policy


#: Cost of a pixel the mesh does not cover, relative to a covered one (the network runs only where covered).
_UNCOVERED_COST = 0.05


@dataclasses.dataclass(frozen=True)
class ResolutionPolicy:
    """When to render reduced, when and how fast to refine (see the module docstring).

    Attributes:
        idle_seconds: the state is "moving" until it has not changed for this long.
        interactive_budget_s: target time of one reduced-resolution render while moving.
        refine_budget_s: target time of the refinement work done in one frame (one band). Predictions
            were seen 1.7–2x short on a busy CPU, and a frame must stay under 150 ms (issue 11).
        factors: the allowed reductions (divisors of width and height), smallest first.
        default_factor: used before anything has been measured for a material and mesh.
        band_multiple: band heights are multiples of this (llvmpipe shades 4×4 pixel blocks, so a band of
            5 rows costs nearly as much as 8).
    """

    idle_seconds: float = 0.25
    interactive_budget_s: float = 0.05
    refine_budget_s: float = 0.05  # with the frame's other work, a 3x margin to the 150 ms target
    factors: tuple[int, ...] = (2, 4, 8)
    default_factor: int = 4
    band_multiple: int = 4

    def reduced_factor(self, full_seconds: float | None) -> int:
        """The smallest factor whose render is predicted to fit the interactive budget (else the largest),
        given the predicted time of a full-resolution render (``None``: nothing measured yet)."""
        if full_seconds is None:
            return self.default_factor
        for factor in self.factors:
            if full_seconds / factor**2 <= self.interactive_budget_s:
                return factor
        return self.factors[-1]

    def band_rows(self, row_seconds: np.ndarray) -> int:
        """Rows of the next refinement band: as many of the remaining rows (their predicted seconds, in
        order) as fit ``refine_budget_s``, rounded down to a multiple of ``band_multiple`` (at least that
        many); all the remaining rows when they fit or are fewer."""
        remaining = len(row_seconds)
        fits = int(np.searchsorted(np.cumsum(row_seconds), self.refine_budget_s, side="right"))
        if fits >= remaining:
            return max(1, remaining)
        rows = max(self.band_multiple, fits - fits % self.band_multiple)
        return max(1, min(remaining, rows))


def reduced_size(size: tuple[int, int], factor: int) -> tuple[int, int]:
    return max(1, math.ceil(size[0] / factor)), max(1, math.ceil(size[1] / factor))


# --------------------------------------------------------------------------------------------------
# Frames and statistics


@dataclasses.dataclass
class Frame:
    """The picture on show.

    Attributes:
        key: the state and size it shows (``ViewerApp.render_key``).
        pixels: display sRGB ``uint8`` ``(h, w, 3)``, row 0 at the top (``h, w`` = ``rendered_size`` for a
            preview, the full size while refining and when complete).
        full_size: ``(width, height)`` that the picture stands for (a preview is shown stretched to it).
        rendered_size: the resolution the newest pixels were computed at.
        complete: every pixel is at full resolution.
        progress: the fraction of the full-resolution picture done (1 when complete).
        version: increases whenever ``pixels`` change (the window re-uploads its texture then).
        samples: samples per pixel of the complete picture (progressive anti-aliasing: the mean of that many
            full-resolution samples; while the next one is added band by band, its rows already hold it).
    """

    key: tuple[Any, ...]
    pixels: np.ndarray
    full_size: tuple[int, int]
    rendered_size: tuple[int, int]
    complete: bool
    progress: float
    version: int
    samples: int = 1


@dataclasses.dataclass
class RenderStats:
    """Counts and times of the SceneRenderer calls (a band counts as one render)."""

    renders: int = 0
    preview_renders: int = 0
    refine_renders: int = 0
    last_kind: str = ""
    last_render_s: float = 0.0
    last_render_size: tuple[int, int] = (0, 0)
    last_preview_s: float | None = None
    last_preview_size: tuple[int, int] = (0, 0)
    last_full_s: float | None = None  # the sum of a completed refinement's renders
    last_sample_s: float | None = None  # the last band of progressive anti-aliasing (one more sample)
    #: The window's last frame from the end of its wait for input to the buffer swap: the work of the
    #: frame (events, panel, any render, drawing), not the idle wait (set by ViewerWindow).
    last_frame_s: float = 0.0
    weights_path: str = ""  # the weights path of the last render


@dataclasses.dataclass(frozen=True)
class _BandCamera(Camera):
    """The camera restricted to rows ``[row0, row1)`` of a ``height``-row image: the same pixel centres,
    rasterized into a ``row1 − row0``-row target (a crop of clip space after the projection)."""

    full_aspect: float = 1.0
    height: int = 1
    row0: int = 0
    row1: int = 1

    def view_projection(self, aspect: float) -> np.ndarray:  # noqa: ARG002 - the band's own aspect is wrong
        full = super().view_projection(self.full_aspect)
        scale = self.height / (self.row1 - self.row0)
        centre = 1.0 - (self.row0 + self.row1) / self.height  # band centre in NDC y (+1 = top row's edge)
        crop = np.eye(4, dtype=np.float64)
        crop[1, 1] = scale
        crop[3, 1] = -scale * centre  # row vectors: y' = scale · (y − centre · w)
        return np.asarray(full.astype(np.float64) @ crop, dtype=np.float32)


@dataclasses.dataclass
class _Refinement:
    key: tuple[Any, ...]
    pixels: np.ndarray
    next_row: int = 0
    next_factor: int = 1  # slice mode: the next (smaller) reduction factor
    seconds: float = 0.0
    xyz: np.ndarray | None = None  # mesh mode: the full-resolution exposed XYZ so far (float32)


@dataclasses.dataclass
class _Accumulation:
    """Progressive anti-aliasing of a still mesh view: float32 sums of the exposed XYZ of samples 0 … k−1
    (``sums``, ``k`` = ``samples``) and, for rows before ``next_row``, sample k (``partial``)."""

    key: tuple[Any, ...]
    sums: np.ndarray
    samples: int = 1
    next_row: int = 0
    partial: np.ndarray | None = None


# --------------------------------------------------------------------------------------------------
# The app (no glfw, no imgui)


class ViewerApp:
    """The viewer's logic and rendering on a caller's GL context (see the module docstring).

    Args:
        ctx: an OpenGL ≥ 4.3 moderngl context (a window's, or :func:`viewer.context.create_headless_context`).
        state: the initial view (default :class:`ViewerState`).
        size: the full render size ``(width, height)`` in pixels.
        policy: the resolution policy.
        clock: seconds, monotonic (tests pass a fake one).
        extra_meshes: mesh specs offered besides cd, sphere and plane (e.g. an .obj path).
        weights_path: ``auto``, ``texture`` or ``baked``, for every material's
            :class:`~viewer.scene.SceneRenderer` (:func:`viewer.renderer.choose_weights_path`).
        background: compile shaders and load meshes without blocking (:class:`~viewer.scene_supply.SceneSupply`;
            the window's mode): until the material's first program is ready :meth:`frame` renders nothing and
            :attr:`status` says why; with ``auto`` on a CPU rasterizer the texture path shows the first
            picture and the baked path takes over once compiled. False: load and compile on first use.
        worker: a compile child started earlier for ``state`` (:meth:`SceneSupply.start_worker`), adopted.
        max_samples: samples per pixel accumulated while a mesh view stands still (progressive
            anti-aliasing, see the module docstring; 1: off, the default here; the window's default is 16).

    Raises:
        GratNetError: the initial material or mesh cannot be loaded.
    """

    def __init__(self, ctx: Any, state: ViewerState | None = None, size: tuple[int, int] = (512, 512),
                 policy: ResolutionPolicy | None = None, clock: Callable[[], float] = time.perf_counter,
                 extra_meshes: Iterable[str] = (), weights_path: str = "auto", background: bool = False,
                 worker: Any = None, max_samples: int = 1, render_path: str = "auto") -> None:
        from viewer.antialias import check_samples
        from viewer.scene import check_size
        from viewer.scene_supply import SceneSupply

        self.ctx = ctx
        self.state = dataclasses.replace(state) if state is not None else ViewerState()
        self.size = check_size(size)
        self.policy = policy or ResolutionPolicy()
        self.clock = clock
        self.stats = RenderStats()
        self.image: Frame | None = None
        self.message = ""  # the last problem (a material or mesh that failed to load), shown in the panel
        self.meshes = list(MESHES) + [spec for spec in extra_meshes if spec not in MESHES]
        self.weights_path = weights_path
        self._supply = SceneSupply(ctx, weights_path, background, worker, render_path)
        # A switch of material, mesh or mode brings that pair's default view (viewer.defaults), worked out in a
        # worker process in the background mode.
        self._defaults = DefaultViewRequests(background)
        self._last_mesh = self.state.mesh  # the last mesh that loaded (restored if a newer one fails)
        # Per material and mesh: measured seconds per "effective pixel" (covered + 5 % of uncovered).
        self._seconds_per_pixel: dict[tuple[Any, ...], float] = {}
        self._coverage = np.ones(1)  # fraction of each row covered, from the last preview (top row first)
        self._seen_key: tuple[Any, ...] | None = None
        self._changed_at = -math.inf
        self._refinement: _Refinement | None = None
        self._accumulation: _Accumulation | None = None
        #: Progressive anti-aliasing: samples per pixel accumulated while the view stands still (1: off).
        self.max_samples = check_samples(max_samples)
        self._version = 0
        self._released = False
        #: Whether the state changed less than ``policy.idle_seconds`` before the last :meth:`frame`.
        self.moving = False
        try:
            self._warm_up()  # fails early on a bad material or mesh
        except BaseException:
            self._supply.release()
            raise
        if self.state.mesh not in self.meshes:
            self.meshes.append(self.state.mesh)

    # -- choices -----------------------------------------------------------------------------------

    @staticmethod
    def materials() -> list[str]:
        """Shipped materials (``assets/*/model.npz``)."""
        return shipped_materials()

    # -- state changes ----------------------------------------------------------------------------

    def set(self, **changes: Any) -> bool:
        """Change state fields (sliders are clamped to their ranges); a material or mesh that fails to
        load is refused with :attr:`message` set and the state left as it was. Returns whether anything
        changed."""
        new = dataclasses.replace(self.state)
        for name, value in changes.items():
            if not hasattr(new, name):
                raise GratNetError(f"unknown viewer setting {name!r}")
            if name in SLIDERS:
                value = SLIDERS[name].clamp(value)
            elif name in ("fresnel", "slice_mode"):
                value = bool(value)
            setattr(new, name, value)
        if new == self.state:
            return False
        try:
            from gratnet.brdf import check_ior

            new.camera()
            new.light()
            check_ior(new.effective_ior, "ior")
            self._supply.check(new)  # cheap checks (and, when not in the background, the loading itself)
        except GratNetError as error:
            self.message = str(error)
            return False
        if new.mesh not in self.meshes:
            self.meshes.append(new.mesh)
        self.message = ""
        self.state = new
        return True

    def switch(self, **changes: Any) -> bool:
        """The panel's material, mesh and BRDF-slice choices: :meth:`set` them, then bring the new pair's
        default view (light, camera, exposure: what ``gratnet view`` and ``gratnet render`` start with) as
        soon as it is worked out, unless the user moves those first. With no arguments: the default view
        of what is on show. Returns whether the material, mesh or mode changed."""
        unknown = set(changes) - {"material", "mesh", "slice_mode"}
        if unknown:
            raise GratNetError(f"switch() takes material, mesh and slice_mode, not {', '.join(sorted(unknown))}")
        changed = self.set(**changes) if changes else False
        if changed or not changes:
            self._defaults.request(self.state)
            if (ready := self._defaults.take(self.state)) is not None:  # computed at once (blocking mode)
                self.set(**ready)
        return changed

    def set_size(self, size: tuple[int, int]) -> bool:
        """Change the full render size (the window's render area); returns whether it changed."""
        from viewer.scene import check_size

        size = check_size(size)
        if size == self.size:
            return False
        self.size = size
        return True

    def set_max_samples(self, samples: int) -> bool:
        """The accumulation cap (the panel's "samples" choice; 1 … viewer.antialias.MAX_SAMPLES): a still mesh
        view gains one sample per pixel at a time, band by band, up to it. Lowering it below the samples on
        show keeps them. Returns whether it changed."""
        from viewer.antialias import check_samples

        samples = check_samples(samples)
        changed, self.max_samples = samples != self.max_samples, samples
        return changed

    @property
    def samples(self) -> int:
        """Samples per pixel of the complete picture on show (1 while previewing or refining)."""
        accumulation = self._current_accumulation()
        return accumulation.samples if accumulation is not None else 1

    def accumulated_xyz(self) -> np.ndarray | None:
        """The exposed XYZ mean of the :attr:`samples` complete samples of the view on show (``float32``
        ``(H, W, 3)``; the same as ``SceneRenderer.render(..., samples=k)``), or ``None`` before the first
        full-resolution picture of a mesh view."""
        accumulation = self._current_accumulation()
        if accumulation is None:
            return None
        return accumulation.sums / np.float32(accumulation.samples)

    def _current_accumulation(self) -> _Accumulation | None:
        accumulation = self._accumulation
        return accumulation if accumulation is not None and accumulation.key == self.render_key() else None

    def _accumulation_due(self) -> bool:
        """A still, complete mesh view below the sample cap, with its full-resolution mesh ready and nothing
        else on its way for it: while a faster program compiles in the background, extra samples would take
        the CPU from that compile (and each costs several times more on the slower path)."""
        accumulation = self._current_accumulation()
        return (accumulation is not None and accumulation.samples < self.max_samples and not self.moving
                and not self.state.slice_mode and self._supply.scene_ready(self.state, preview=False)
                and not self._supply.pending(self.state))

    def orbit(self, dx_pixels: float, dy_pixels: float, degrees_per_pixel: float = 0.4) -> bool:
        """A mouse drag over the picture: the camera orbits (in BRDF-slice mode the light moves)."""
        if self.state.slice_mode:
            return self.set(light_phi=_wrap(self.state.light_phi + dx_pixels * degrees_per_pixel),
                            light_theta=self.state.light_theta - dy_pixels * degrees_per_pixel)
        return self.set(camera_azimuth=_wrap(self.state.camera_azimuth - dx_pixels * degrees_per_pixel),
                        camera_elevation=self.state.camera_elevation + dy_pixels * degrees_per_pixel)

    def zoom(self, steps: float) -> bool:
        """Mouse-wheel steps: positive moves the camera closer (×0.9 of the distance per step)."""
        return self.set(camera_distance=self.state.camera_distance * 0.9 ** float(steps))

    # -- rendering ---------------------------------------------------------------------------------

    def render_key(self) -> tuple[Any, ...]:
        return (*self.state.key(), *self.full_size())

    def full_size(self) -> tuple[int, int]:
        """The full-resolution picture's size: the render size, or its largest square in slice mode."""
        if self.state.slice_mode:
            side = min(self.size)
            return side, side
        return self.size

    def next_work_in(self, now: float | None = None) -> float | None:
        """Seconds until :meth:`frame` has rendering to do: 0 now, the rest of the idle time while a
        preview waits for the state to settle, ``None`` when the picture is complete and current (the
        window then sleeps until input arrives)."""
        image, key = self.image, self.render_key()
        if image is not None and image.key == key and image.complete:
            if self._supply.step_due(self.state, self._idle()) or self._accumulation_due():
                return 0.0
            return self.POLL_SECONDS if self._supply.pending(self.state) or self._defaults.pending else None
        if self._supply.step_due(self.state, self._idle()):
            return 0.0  # a warm program to link or draw: the next frame does it
        if not self._supply.scene_ready(self.state):
            return self.POLL_SECONDS  # waiting for a shader or a mesh: look again soon
        if image is None or image.key != key or key != self._seen_key:
            return 0.0
        if not self._supply.scene_ready(self.state, preview=False):
            return self.POLL_SECONDS  # the refinement waits for the full-resolution mesh
        now = self.clock() if now is None else float(now)
        return max(0.0, self._changed_at + self.policy.idle_seconds - now)

    def frame(self, now: float | None = None) -> bool:
        """One step: render what the state needs, if anything. Returns whether :attr:`image` changed.

        - state differs from the picture on show → a reduced-resolution preview;
        - state unchanged for ``idle_seconds`` and the picture not complete → one refinement band;
        - picture complete and current → nothing.
        """
        now = self.clock() if now is None else float(now)
        if (ready := self._defaults.take(self.state)) is not None:  # a default view asked for by switch()
            self.set(**ready)
        step = self._supply.poll(self.state, self._idle(now))  # background: at most one GL step (a cache hit)
        self._check_background_errors()
        if step is not None:
            return False  # a link (0.15 s for a baked one) or a first draw: no render in the same frame
        key = self.render_key()
        if key != self._seen_key:
            self._seen_key = key
            self._changed_at = now
        self.moving = now - self._changed_at < self.policy.idle_seconds
        image = self.image
        if image is not None and image.key == key and image.complete:
            if not self._accumulation_due():
                return False
            self._accumulate(key)
            return True
        if not self._supply.scene_ready(self.state):
            return False  # the picture on show stays until the new one can be rendered
        if image is None or image.key != key:
            self._refinement = None
            self._preview(key)
            return True
        if self.moving or not self._supply.scene_ready(self.state, preview=False):
            return False
        self._refine(key)
        return True

    #: How often the window looks at background work in progress (seconds).
    POLL_SECONDS = 0.1

    def _idle(self, now: float | None = None) -> bool:
        """No state change for ``policy.idle_seconds`` (the moment for a faster program to take over)."""
        now = self.clock() if now is None else float(now)
        return self.render_key() == self._seen_key and now - self._changed_at >= self.policy.idle_seconds

    @property
    def status(self) -> str:
        """What is being compiled or loaded for the state on show ("compiling the shader for cd… 12 s"),
        or an empty string."""
        status = self._supply.status(self.state)
        if self._defaults.pending:
            choosing = f"choosing a view that shows {self.state.material}..."
            status = f"{choosing} {status}" if status else choosing
        return status

    def weights_path_in_use(self) -> str | None:
        """The weights path that renders the current state (``None``: none ready yet)."""
        return self._supply.weights_path_in_use(self.state)

    def _check_background_errors(self) -> None:
        failed = self._supply.mesh_error(self.state.mesh)
        if failed is not None:
            self.message = failed
            self.state = dataclasses.replace(self.state, mesh=self._last_mesh)
        elif not self.state.slice_mode and self._supply.weights_path_in_use(self.state) is not None:
            self._last_mesh = self.state.mesh
        worker = self._supply.errors.pop("worker", None)
        if worker is not None:
            self.message = worker

    def _scene_key(self, state: ViewerState) -> tuple[Any, ...]:
        return (state.material, "slice" if state.slice_mode else state.mesh, self._supply.weights_path_in_use(state))

    def _timed_render(self, state: ViewerState, size: tuple[int, int], camera: Camera | None = None,
                      preview: bool = False, rows: tuple[int, int] | None = None,
                      sample: int = 0) -> tuple[np.ndarray, np.ndarray]:
        """``(exposed XYZ, coverage)`` of ``state`` at ``size`` (a mesh, or the BRDF slice: coverage 1; with
        ``rows``, only those rows of the slice), timed and counted; the time per effective pixel feeds the
        resolution policy. ``sample``: the index of the mesh render's sub-pixel offset
        (:func:`viewer.antialias.sample_offsets`; 0 = the pixel centre)."""
        supplied = self._supply.scene(state, preview)
        if supplied is None:
            raise GratNetError(f"the shader for {state.material} is still compiling; try again in a moment")
        renderer, buffers = supplied
        started = time.perf_counter()
        if state.slice_mode:
            xyz = renderer.render_brdf_slice(state.light_theta, state.light_phi, size[0], state.exposure,
                                             state.effective_ior, rows=rows)
            coverage = _disc_coverage(size[0], rows)  # the network runs inside the unit disc only
            if rows is not None:
                xyz = xyz[rows[0]:rows[1]]
        else:
            rgba = renderer.render_rgba(buffers, camera or state.camera(), state.light(), size, state.exposure,
                                        state.effective_ior, first_sample=sample)
            xyz, coverage = rgba[..., :3], rgba[..., 3]
        seconds = time.perf_counter() - started
        scene = self._scene_key(state)
        sample = seconds / max(1.0, _effective_pixels(coverage))
        previous = self._seconds_per_pixel.get(scene)
        # Quick to grow, slow to shrink: a render slower than predicted (a busy CPU) shrinks the next band
        # at once, so that one misprediction does not make several long frames.
        self._seconds_per_pixel[scene] = sample if previous is None else max(sample, 0.5 * (previous + sample))
        self.stats.renders += 1
        self.stats.weights_path = renderer.network.weights_path
        self.stats.last_render_s = seconds
        self.stats.last_render_size = size
        return xyz, coverage

    def _publish(self, key: tuple[Any, ...], pixels: np.ndarray, rendered_size: tuple[int, int],
                 complete: bool, progress: float, samples: int = 1) -> None:
        self._version += 1
        self.image = Frame(key, pixels, self.full_size(), rendered_size, complete, progress, self._version, samples)

    def _preview(self, key: tuple[Any, ...]) -> None:
        from viewer.scene import SceneRenderer

        full = self.full_size()
        seconds_per_pixel = self._seconds_per_pixel.get(self._scene_key(self.state))
        predicted = None
        if seconds_per_pixel is not None:  # with the last preview's coverage
            covered = float(np.mean(self._coverage))
            predicted = seconds_per_pixel * full[0] * full[1] * (covered + _UNCOVERED_COST * (1.0 - covered))
        factor = self.policy.reduced_factor(predicted)
        size = reduced_size(full, factor)  # square in slice mode (full is square)
        self._accumulation = None  # a new view: its samples start again
        xyz, coverage = self._timed_render(self.state, size, preview=True)
        self._coverage = coverage.mean(axis=1)
        self.stats.preview_renders += 1
        self.stats.last_kind = f"preview 1/{factor}"
        self.stats.last_preview_s = self.stats.last_render_s
        self.stats.last_preview_size = size
        complete = size == full
        self._publish(key, SceneRenderer.display_srgb8(xyz), size, complete, 1.0 if complete else 0.0)

    def _refine(self, key: tuple[Any, ...]) -> None:
        from viewer.scene import SceneRenderer

        state, (width, height) = self.state, self.full_size()
        refinement = self._refinement
        if refinement is None or refinement.key != key:
            preview = self.image.pixels if self.image is not None else np.zeros((1, 1, 3), np.uint8)
            factor = max(1, round(width / max(1, preview.shape[1])))
            refinement = self._refinement = _Refinement(
                key, preview if state.slice_mode else _upscale(preview, width, height), next_factor=max(1, factor // 2))
        started = time.perf_counter()
        if state.slice_mode:  # double the resolution per level, each level in bands that fit the budget
            factor = refinement.next_factor
            side = reduced_size((width, height), factor)[0]
            if refinement.pixels.shape[0] != side:  # a new level: over the last one, upscaled
                refinement.pixels = _upscale(refinement.pixels, side, side)
                refinement.next_row = 0
            row0 = refinement.next_row
            seconds_per_pixel = self._seconds_per_pixel.get(self._scene_key(state), 0.0)
            row_pixels = _effective_pixels_per_row(_disc_coverage(side, (row0, side)))
            row1 = min(side, row0 + self.policy.band_rows(seconds_per_pixel * row_pixels * _first_band_margin(row0)))
            xyz = self._timed_render(state, (side, side), rows=(row0, row1))[0]
            refinement.pixels[row0:row1] = SceneRenderer.display_srgb8(xyz)
            refinement.next_row = row1
            level_done = row1 == side
            if level_done:
                refinement.next_factor = max(1, factor // 2)
            done, rendered = factor == 1 and level_done, (side, side)
            progress = 1.0 if done else row1 / side / factor**2
            self.stats.last_kind = f"refine 1/{factor} rows {row0}-{row1}"
        else:  # the next band of rows at full resolution, over the upscaled preview
            row0 = refinement.next_row
            rows = self.policy.band_rows(self._row_seconds(width, height)[row0:] * _first_band_margin(row0))
            row1 = min(height, row0 + rows)
            band = self._band_camera(state, width, height, row0, row1)
            xyz = self._timed_render(state, (width, row1 - row0), band)[0]
            refinement.pixels[row0:row1] = SceneRenderer.display_srgb8(xyz)
            if refinement.xyz is None:
                refinement.xyz = np.zeros((height, width, 3), dtype=np.float32)
            refinement.xyz[row0:row1] = xyz
            refinement.next_row = row1
            done, rendered, progress = row1 == height, (width, height), row1 / height
            if done:  # sample 0 of the progressive anti-aliasing
                self._accumulation = _Accumulation(key, refinement.xyz)
            self.stats.last_kind = f"refine rows {row0}-{row1}"
        refinement.seconds += time.perf_counter() - started
        self.stats.refine_renders += 1
        if done:
            self.stats.last_full_s = refinement.seconds
            self._refinement = None
        self._publish(key, refinement.pixels.copy(), rendered, done, 1.0 if done else progress)

    def _band_camera(self, state: ViewerState, width: int, height: int, row0: int, row1: int) -> _BandCamera:
        camera = state.camera()
        return _BandCamera(camera.distance, camera.azimuth_deg, camera.elevation_deg, camera.target, camera.fov_deg,
                           camera.near, camera.far, full_aspect=width / height, height=height, row0=row0, row1=row1)

    def _accumulate(self, key: tuple[Any, ...]) -> None:
        """Progressive anti-aliasing: the next band of rows of the next sample (one sub-pixel offset) of the
        still mesh view, sized to ``refine_budget_s`` like a refinement band; the rows done show the mean
        over one more sample than the rest."""
        from viewer.scene import SceneRenderer

        accumulation = self._accumulation
        assert accumulation is not None and self.image is not None
        state, (width, height) = self.state, self.full_size()
        row0 = accumulation.next_row
        row1 = min(height, row0 + self.policy.band_rows(self._row_seconds(width, height)[row0:]))
        started = time.perf_counter()
        xyz = self._timed_render(state, (width, row1 - row0), self._band_camera(state, width, height, row0, row1),
                                 sample=accumulation.samples)[0]
        if accumulation.partial is None:
            accumulation.partial = np.zeros_like(accumulation.sums)
        accumulation.partial[row0:row1] = xyz
        accumulation.next_row = row1
        if row1 == height:  # the sample is complete: into the sums (float32, as SceneRenderer's GPU sums)
            accumulation.sums += accumulation.partial
            accumulation.samples += 1
            accumulation.next_row, accumulation.partial = 0, None
            mean = accumulation.sums[row0:row1] / np.float32(accumulation.samples)
        else:
            mean = (accumulation.sums[row0:row1] + xyz) / np.float32(accumulation.samples + 1)
        pixels = self.image.pixels.copy()
        pixels[row0:row1] = SceneRenderer.display_srgb8(mean)
        self.stats.refine_renders += 1
        self.stats.last_kind = f"sample {accumulation.samples + (row1 < height)} rows {row0}-{row1}"
        self.stats.last_sample_s = time.perf_counter() - started
        self._publish(key, pixels, (width, height), True, 1.0, accumulation.samples)

    def _row_seconds(self, width: int, height: int) -> np.ndarray:
        """Predicted seconds of each full-resolution row, from the preview's coverage of that row."""
        seconds_per_pixel = self._seconds_per_pixel.get(self._scene_key(self.state), 0.0)
        rows = np.minimum((np.arange(height) * len(self._coverage)) // height, len(self._coverage) - 1)
        covered = self._coverage[rows]
        return seconds_per_pixel * width * (covered + _UNCOVERED_COST * (1.0 - covered))

    def render_full(self) -> np.ndarray:
        """The current state's picture at full resolution in one render (display sRGB ``uint8``); the
        cached picture when it is complete and current."""
        from viewer.scene import SceneRenderer

        key = self.render_key()
        if self.image is not None and self.image.key == key and self.image.complete:
            return self.image.pixels
        xyz = self._timed_render(self.state, self.full_size())[0]
        pixels = SceneRenderer.display_srgb8(xyz)
        self.stats.last_kind = "full"
        self._refinement = None
        self._accumulation = None if self.state.slice_mode else _Accumulation(key, np.array(xyz, dtype=np.float32))
        self._publish(key, pixels, self.full_size(), True, 1.0)
        return pixels

    def save_screenshot(self, path: str | Path) -> Path:
        """Write the current picture at full resolution as a display-sRGB PNG (atomically), and beside it
        ``NAME.config.json`` with the ``gratnet render`` settings that reproduce it. Returns the path."""
        from PIL import Image

        from gratnet.atomic import atomic_path
        from gratnet.config import save_config

        path = Path(path)
        if path.suffix.lower() != ".png":
            raise GratNetError(f"a screenshot is a .png file, got {path}")
        pixels = self.render_full()
        samples = self.samples
        if samples > 1:  # the complete samples only (a sample being added band by band is left out)
            from viewer.scene import SceneRenderer

            pixels = SceneRenderer.display_srgb8(self.accumulated_xyz())
        with atomic_path(path) as temporary:
            Image.fromarray(pixels).save(temporary, format="PNG")
        width, height = self.full_size()
        save_config(path, render=self.state.render_config(width, height, samples),
                    model_file=str(resolve_material(self.state.material)))
        return path

    def next_screenshot_path(self, folder: str | Path) -> Path:
        """``folder/gratnet-view-NNN.png``, the first number not taken."""
        folder = Path(folder)
        for number in range(1, 100000):
            candidate = folder / f"gratnet-view-{number:03d}.png"
            if not candidate.exists():
                return candidate
        raise GratNetError(f"no free screenshot name in {folder}")

    def _warm_up(self) -> None:
        """Check the state's material and mesh (GratNetError if unusable). When not in the background, also
        pay the one-off costs before the first timed frame: loading, the driver's shader JIT (a 1×1 render,
        uncounted) and the import of the display conversion (colour-science, ~1 s); in the background the
        child process starts compiling now (:meth:`frame` polls it)."""
        self._supply.check(self.state)
        self._supply.poll(self.state)

    def release(self) -> None:
        """Free the GL objects and stop background work (the context belongs to the caller)."""
        if not self._released:
            self._defaults.release()
            self._supply.release()
            self._released = True


def _effective_pixels(coverage: np.ndarray) -> float:
    covered = float(np.count_nonzero(coverage > 0.5))
    return covered + _UNCOVERED_COST * (coverage.size - covered)


def _first_band_margin(row0: int) -> float:
    """Prediction factor for a band: 2 for a refinement's (or a slice level's) first band, whose prediction
    comes from renders at a lower resolution only (1.7× too short once, measured on a busy machine)."""
    return 2.0 if row0 == 0 else 1.0


def _effective_pixels_per_row(coverage: np.ndarray) -> np.ndarray:
    return np.sum(np.where(coverage > 0.5, 1.0, _UNCOVERED_COST), axis=1)


def _disc_coverage(side: int, rows: tuple[int, int] | None = None) -> np.ndarray:
    """1 where a ``side``² BRDF slice's pixel centre lies inside the unit disc (where the network runs), else
    0; only ``rows`` (first, end) when given."""
    first, end = (0, side) if rows is None else rows
    centres = (np.arange(side) + 0.5) / side * 2.0 - 1.0
    y = centres[first:end, None]
    return (centres[None, :] ** 2 + y**2 <= 1.0).astype(np.float32)


def _wrap(degrees: float) -> float:
    """An angle in [−180, 180)."""
    return (degrees + 180.0) % 360.0 - 180.0


def _upscale(pixels: np.ndarray, width: int, height: int) -> np.ndarray:
    """Nearest-neighbour resize of an ``(h, w, 3)`` image to ``(height, width, 3)`` (a new array)."""
    rows = np.minimum((np.arange(height) * pixels.shape[0]) // height, pixels.shape[0] - 1)
    columns = np.minimum((np.arange(width) * pixels.shape[1]) // width, pixels.shape[1] - 1)
    return np.ascontiguousarray(pixels[rows][:, columns])


def drive_slider(target: ViewerApp | ViewerWindow, name: str, values: Iterable[float],
                 frame: bool = True) -> int:
    """Move slider ``name`` through ``values`` as a user dragging it would: set each value and, with
    ``frame``, run one frame after each (``target.frame()``: a window frame or an app step). Returns the
    number of values that changed the state."""
    app = target.app if isinstance(target, ViewerWindow) else target
    if name not in SLIDERS:
        raise GratNetError(f"unknown slider {name!r}: choose {', '.join(SLIDERS)}")
    changed = 0
    for value in values:
        changed += bool(app.set(**{name: value}))
        if frame:
            target.frame()
    return changed


# --------------------------------------------------------------------------------------------------
# The window (glfw + imgui): the only place that imports them

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

    Raises:
        GratNetError: no display, or no OpenGL 4.3 core context for a window.
    """

    PANEL_WIDTH = 300
    #: The panel's choices of samples per pixel accumulated while the view stands still.
    SAMPLE_CHOICES = (1, 4, 16, 64)

    def __init__(self, state: ViewerState | None = None, size: tuple[int, int] = (512, 512),
                 policy: ResolutionPolicy | None = None, clock: Callable[[], float] = time.perf_counter,
                 screenshot_dir: str | Path = ".", idle_wait_s: float = 0.25, extra_meshes: Iterable[str] = (),
                 weights_path: str = "auto", background: bool = True,
                 visible: bool = True, title: str = "GratNet viewer", max_samples: int = 16,
                 render_path: str = "auto") -> None:
        from viewer.context import context_from_current
        from viewer.scene import check_size
        from viewer.scene_supply import SceneSupply, start_display_import

        width, height = check_size(size)
        # The compile child first: its Python start-up and the quick shader overlap the window's set-up.
        worker = None
        if background:
            start_display_import()
            with contextlib.suppress(GratNetError):  # a bad material is reported by ViewerApp below
                worker = SceneSupply.start_worker(state or ViewerState(), weights_path, render_path)
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
                                  background, worker, max_samples, render_path)
            worker = None  # the app owns it now
            # The first frame compiles imgui's own shaders and, drawing the 1×1 picture texture, their variant
            # for its format (0.3–0.5 s on llvmpipe with an empty shader cache): drawn while the window is
            # unmapped, no input can wait for it; then the panel appears at once.
            self._first_frame = True
            self.frame()
            self._first_frame = False
            # colour-science (the display conversion) imports on a thread from the start (scene_supply:
            # 0.5–0.7 s without its plotting); C calls of an import hold the GIL for up to ~70 ms at a time,
            # which stretched frames to 145 ms: the window is shown once it is done (the compile child runs on).
            if background:
                start_display_import().join()
            # Python's cyclic GC then paused 60–380 ms at a time over the ~1e6 objects imgui and colour-science
            # made: frozen out of every later collection.
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
        if imgui.is_item_active():
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

    def _panel(self) -> None:
        imgui, app = self._imgui, self.app
        state = app.state
        display = imgui.get_io().display_size
        imgui.set_next_window_pos(imgui.ImVec2(0, 0), imgui.Cond_.always)
        imgui.set_next_window_size(imgui.ImVec2(self.PANEL_WIDTH, max(1.0, display.y)), imgui.Cond_.always)
        imgui.begin("GratNet", None, imgui.WindowFlags_.no_move | imgui.WindowFlags_.no_resize
                    | imgui.WindowFlags_.no_collapse | imgui.WindowFlags_.no_saved_settings)
        imgui.push_item_width(150)
        status = app.status
        if status:  # what is compiling or loading, at the top: the reason the picture is old or absent
            imgui.push_style_color(imgui.Col_.text, imgui.ImVec4(1.0, 0.8, 0.3, 1.0))
            imgui.text_wrapped(status)
            imgui.pop_style_color()
            imgui.separator()

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

        imgui.separator_text("light")
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
        choices = sorted({*self.SAMPLE_CHOICES, app.max_samples})
        changed, index = imgui.combo("samples (still)", choices.index(app.max_samples), [str(c) for c in choices])
        if changed:
            app.set_max_samples(choices[index])
        changed, value = imgui.checkbox("Fresnel", state.fresnel)
        if changed:
            app.set(fresnel=value)
        imgui.begin_disabled(not state.fresnel)
        self._slider("ior")
        imgui.end_disabled()

        imgui.separator_text("performance")
        stats, image = app.stats, app.image
        imgui.text(f"frame {stats.last_frame_s * 1000:.1f} ms (work, not idle)")
        in_use = app.weights_path_in_use()
        if in_use:
            imgui.text(f"weights: {in_use} path")
        width, height = stats.last_render_size
        imgui.text(f"render {stats.last_render_s * 1000:.0f} ms at {width}×{height}")
        if stats.last_preview_s is not None:
            pw, ph = stats.last_preview_size
            imgui.text(f"preview {stats.last_preview_s * 1000:.0f} ms at {pw}×{ph}")
        if stats.last_full_s is not None:
            imgui.text(f"full picture {stats.last_full_s * 1000:.0f} ms")
        if image is not None:
            status = "complete" if image.complete else f"refining {image.progress:.0%}"
            samples = "" if state.slice_mode else f", {image.samples}/{app.max_samples} samples"
            imgui.text(f"{image.full_size[0]}×{image.full_size[1]}: {status}{samples}")
        imgui.text(f"renders: {stats.renders}")

        imgui.separator()
        if imgui.button("Screenshot"):
            self.screenshot()
        if app.message:
            imgui.text_wrapped(app.message)
        imgui.pop_item_width()
        imgui.end()

    def screenshot(self) -> Path | None:
        """The Screenshot button: the full-resolution picture to ``screenshot_dir/gratnet-view-NNN.png``
        (and its ``.config.json``), written atomically; the outcome is shown in the panel."""
        app = self.app
        try:
            self.last_screenshot = app.save_screenshot(app.next_screenshot_path(self.screenshot_dir))
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
