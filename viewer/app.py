"""The interactive viewer's logic: :class:`ViewerApp`, its state and scheduling around a SceneRenderer.

Two layers, so that the logic can be tested without a display:

- :class:`ViewerApp` (this module; no glfw, no imgui; any OpenGL ≥ 4.3 context, a window's or a headless
  one): the :class:`~viewer.state.ViewerState`, the scene supply (:mod:`viewer.scene_supply`: models,
  meshes, shaders), the :class:`~viewer.scheduling.ResolutionPolicy` and the frame cache.
  :meth:`ViewerApp.frame` renders only what the state needs: nothing when the picture on show is already
  the full-resolution picture of the current state.
- :class:`~viewer.window.ViewerWindow` (:mod:`viewer.window`): the thin shell of glfw, imgui and EGL glue
  that draws the panel and the picture and turns input into :meth:`ViewerApp.set`, :meth:`ViewerApp.orbit`
  and :meth:`ViewerApp.zoom`.

Where the rest lives: the panel's sliders and the state (:mod:`viewer.state`); the resolution policy, its cost
model and how the viewer spends its frames (:mod:`viewer.scheduling`: staying responsive on a CPU rasterizer, issue
35; progressive anti-aliasing, issue 12); models, meshes and shaders, never blocking (:mod:`viewer.scene_supply`,
issue 11); a switch's default view (:mod:`viewer.default_view`); the environment light (:mod:`viewer.environment_view`,
issue 43); screenshots and slider driving (:mod:`viewer.screenshot`).

Every pixel comes from :class:`SceneRenderer` (``render_rgba`` / ``render_brdf_slice``), converted by :mod:`viewer.srgb`
(``gratnet.display``'s bytes without colour-science), so the window shows exactly what ``gratnet render`` writes.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any

import numpy as np

from gratnet.errors import GratNetError
from gratnet.quality import AUTO, FAST, VIEW_QUALITIES, check_quality
from viewer.camera import Camera, Light
from viewer.catalog import MESHES, material_point, material_points, model_label, shipped_materials
from viewer.default_view import DefaultViewRequests
from viewer.environment_view import ENVIRONMENT_SAMPLES, EnvironmentChoices, picture_exposure, warmed_spec
from viewer.reference_view import SHADINGS, LoadedReference, ReferenceView, flip_heat_map
from viewer.scheduling import (
    UNCOVERED_COST,
    Accumulation,
    BandCamera,
    Frame,
    Refinement,
    RenderStats,
    ResolutionPolicy,
    disc_coverage,
    effective_pixels,
    effective_pixels_per_row,
    first_band_margin,
    padded_size,
    reduced_size,
    upscale,
)
from viewer.srgb import display_srgb8
from viewer.state import SLIDERS, ViewerState

__all__ = ["ViewerApp"]


_FLIP_CHANNELS = 7  # FLIP mode's picture data: network XYZ, reference XYZ, coverage


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
        reference: a material's checked ground-truth volume: ``state.shading`` may then show it, or the FLIP
            heat map between it and the network, while that material is on show (:mod:`viewer.reference_view`).
        refine_view: fields of ``state`` (:data:`viewer.default_view.VIEW_FIELDS` names) that are a first guess at
            the default view (``gratnet view`` without ``--light``, ``--camera`` or ``--exposure``): the exact
            defaults replace them once worked out, unless the user moves the view first.
        quality: ``gratnet view --quality`` (gratnet.quality): which of a material's points renders it (:meth:`point`).
        environments: environment specs the viewer offers besides :data:`ENVIRONMENT_CHOICES` (``gratnet view
            --environment``'s); an environment in ``state`` or here makes the compile child warm the environment
            variant and the panel show its chooser; empty and none in ``state``: no environment light at all.
        environment_samples: passes accumulated while a view under an environment stands still.
        auto_exposure: take the exposure from the first preview under an environment (``gratnet view
            --environment`` without ``--exposure``), again after a switch of material, mesh or environment.

    Raises:
        GratNetError: the initial material or mesh cannot be loaded.
    """

    def __init__(self, ctx: Any, state: ViewerState | None = None, size: tuple[int, int] = (512, 512),
                 policy: ResolutionPolicy | None = None, clock: Callable[[], float] = time.perf_counter,
                 extra_meshes: Iterable[str] = (), weights_path: str = "auto", background: bool = False,
                 worker: Any = None, max_samples: int = 1, render_path: str = "auto",
                 reference: LoadedReference | None = None, refine_view: Iterable[str] = (),
                 quality: str = AUTO, environments: Iterable[str] = (),
                 environment_samples: int = ENVIRONMENT_SAMPLES, auto_exposure: bool = False) -> None:
        from viewer.antialias import check_samples
        from viewer.scene_supply import SceneSupply
        from viewer.surface import check_size

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
        self.quality = check_quality(quality, VIEW_QUALITIES)
        self._points: dict[str, tuple[Path, str | None]] = {}  # material -> its point on show (see point())
        self.choices = EnvironmentChoices(self.state.environment if self.state.has_environment else None,
                                          environments)
        self.environments = self.choices.specs  #: the panel's environment choices (empty: none at all)
        #: Passes accumulated while a view under an environment stands still.
        self.environment_samples = check_samples(environment_samples)
        self.auto_exposure = bool(auto_exposure)
        # The automatic exposure (auto_exposure): "preview" from the first preview under the environment, then "full"
        # from its first full-resolution pass (a 16² preview's one pass is too noisy to trust alone); "": none due.
        self._exposure_stage = "preview" if self.auto_exposure and self.state.has_sampled_light else ""
        if self._exposure_stage:
            import gratnet.showcase  # noqa: F401 - the exposure rule, imported now rather than in a frame
        warmed = warmed_spec(self.choices.warmed, self.state.area_light)
        self.supply = SceneSupply(ctx, weights_path, background, worker, render_path, environment=warmed)
        if warmed is not None:
            self.supply.warm_environment = self.choices.map(warmed)
        # A switch of material, mesh or mode brings that pair's default view (viewer.default_view): remembered, or
        # a quick guess at once and the exact one from a worker process (started now in the background mode).
        self._defaults = DefaultViewRequests(background)
        self._last_mesh = self.state.mesh  # the last mesh that loaded (restored if a newer one fails)
        # Per material and mesh: measured seconds per "effective pixel" (covered + 5 % of uncovered).
        self._seconds_per_pixel: dict[tuple[Any, ...], float] = {}
        self._coverage = np.ones(1)  # fraction of each row covered, from the last preview (top row first)
        self._seen_key: tuple[Any, ...] | None = None
        self._changed_at = -math.inf
        self._refinement: Refinement | None = None
        self._accumulation: Accumulation | None = None
        #: Progressive anti-aliasing: samples per pixel accumulated while the view stands still (1: off).
        self.max_samples = check_samples(max_samples)
        self.reference = ReferenceView(ctx, reference) if reference is not None else None
        self._flip_picture: np.ndarray | None = None  # the last complete FLIP-mode picture's data
        self._flip_mean: float | None = None
        self._version = 0
        self._released = False
        #: Whether the state changed less than ``policy.idle_seconds`` before the last :meth:`frame`.
        self.moving = False
        try:
            self._warm_up()  # fails early on a bad material or mesh
        except BaseException:
            self.supply.release()
            raise
        self._defaults.start()
        refine = tuple(refine_view)
        if refine:
            self._defaults.request(self.state, refine)
            self._take_default_view()
        if self.state.mesh not in self.meshes:
            self.meshes.append(self.state.mesh)

    # -- choices -----------------------------------------------------------------------------------

    @staticmethod
    def materials() -> list[str]:
        """Shipped materials (``assets/*/model.npz``)."""
        return shipped_materials()

    def point(self, material: str | None = None) -> tuple[Path, str | None]:
        """The model file that renders ``material`` (default: the one on show) and its point (``None``: a model
        file): under ``quality`` fast the fast point where the material has one, else the accurate one. ``auto`` is
        the accurate point: the supply holds one model's programs at a time (a switch releases them and starts a
        compile child: viewer.scene_supply), so switching points on every drag would recompile. GratNetError for
        an unknown material."""
        material = self.state.material if material is None else material
        if material not in self._points:
            try:
                fast = self.quality == FAST and FAST in material_points(material)
            except GratNetError:  # a model file: its own point
                fast = False
            self._points[material] = material_point(material, FAST if fast else None)
        return self._points[material]

    def _supplied(self, state: ViewerState) -> ViewerState:
        """``state`` as the scene supply takes it: a fast point as its model file's path (the supply renders model
        files); the state on show keeps the material's name (panel, default view, screenshot)."""
        path, quality = self.point(state.material)
        if quality != FAST:
            return state
        return dataclasses.replace(state, material=str(path))

    def set_quality(self, quality: str) -> bool:
        """Change ``quality``; the picture on show stays until the new point's is ready. Whether it changed."""
        quality = check_quality(quality, VIEW_QUALITIES)
        if quality == self.quality:
            return False
        self.quality, self._points = quality, {}
        self.supply.check(self._supplied(self.state))
        return True

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
            elif name == "environment":
                value = self.choices.check(value)
            elif name == "seed":
                from viewer.environment_light import check_seed

                value = check_seed(value)
            elif name == "shading" and value not in SHADINGS:
                raise GratNetError(f"shading must be one of {', '.join(SHADINGS)}, got {value!r}")
            setattr(new, name, value)
        if new.shading != "network" and not self.reference_available(new.material):
            if "shading" in changes:
                self.message = (f"no ground-truth volume for {new.material}: start gratnet view with --reference"
                                if self.reference is None else
                                f"the ground-truth volume is {self.reference.loaded.material}'s, not {new.material}'s")
                return False
            new.shading = "network"  # another material: its network only
        if new == self.state:
            return False
        try:
            from gratnet.brdf import check_ior

            new.camera()
            new.light()
            check_ior(new.effective_ior, "ior")
            self.supply.check(self._supplied(new))  # cheap checks (and, when not in the background, the loading itself)
        except GratNetError as error:
            self.message = str(error)
            return False
        if new.mesh not in self.meshes:
            self.meshes.append(new.mesh)
        self.message = ""
        if self.auto_exposure and new.has_environment and new.environment != self.state.environment:
            self._exposure_stage = "preview"  # another environment: its own exposure
        elif "exposure" in changes and not self._applying_view:
            self._exposure_stage = ""  # the user's exposure wins
        self.state = new
        return True

    _applying_view = False  # set while a default view or the automatic exposure is applied (not the user's)

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
            self._exposure_stage = "preview" if self.auto_exposure and self.state.has_sampled_light else ""
            self._defaults.request(self.state)
            self._take_default_view()  # remembered, or computed at once (blocking mode)
        return changed

    def _take_default_view(self) -> None:
        """Apply the requested default view's next step once it has arrived (viewer.default_view: remembered, a
        quick guess, then the exact one), unless the user moved the view since."""
        ready = self._defaults.take(self.state)
        if ready is not None:
            if self.auto_exposure and self.state.has_sampled_light and self._exposure_stage != "preview":
                ready = {name: value for name, value in ready.items() if name != "exposure"}  # the picture's stays
            self._applying_view = True
            try:
                self.set(**ready)
            finally:
                self._applying_view = False
            self._defaults.applied(self.state)

    def set_size(self, size: tuple[int, int]) -> bool:
        """Change the full render size (the window's render area); returns whether it changed."""
        from viewer.surface import check_size

        size = check_size(size)
        if size == self.size:
            return False
        self.size = size
        return True

    def set_max_samples(self, samples: int) -> bool:
        """The accumulation cap (the panel's "samples" choice; 1 … viewer.antialias.MAX_SAMPLES) of the view on
        show (:attr:`sample_cap`: ``environment_samples`` under an environment, else ``max_samples``): a still mesh
        view gains one sample per pixel at a time, band by band, up to it. Lowering it below the samples on
        show keeps them. Returns whether it changed."""
        from viewer.antialias import check_samples

        samples = check_samples(samples)
        if self.environment_live():
            changed, self.environment_samples = samples != self.environment_samples, samples
        else:
            changed, self.max_samples = samples != self.max_samples, samples
        return changed

    @property
    def sample_cap(self) -> int:
        """The samples a still view of the state on show accumulates (under an environment: its passes)."""
        return self.environment_samples if self.environment_live() else self.max_samples

    def environment_live(self, state: ViewerState | None = None) -> bool:
        """Whether ``state`` (default: the one on show) renders with its environment or area lights now: a network
        mesh view with them, the variant ready (the compile child's; until then the view shows without them)."""
        state = self.state if state is None else state
        return ((state.has_environment and bool(self.environments) or bool(state.area_light)) and not state.slice_mode
                and state.shading == "network" and self.supply.environment_live(self._supplied(state)))

    def environment(self, state: ViewerState | None = None) -> Any:
        """The :class:`gratnet.environment.Environment` of ``state`` (default: the one on show; turned and scaled) or
        ``None`` (:class:`viewer.environment_view.EnvironmentChoices`)."""
        state = self.state if state is None else state
        return (self.choices.environment(state.environment, state.environment_rotation, state.environment_scale)
                if state.has_environment else None)

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

    def _current_accumulation(self) -> Accumulation | None:
        accumulation = self._accumulation
        return accumulation if accumulation is not None and accumulation.key == self.render_key() else None

    def _accumulation_due(self) -> bool:
        """A still, complete mesh view below the sample cap, with its full-resolution mesh ready and nothing
        else on its way for it: while a faster program compiles in the background, extra samples would take
        the CPU from that compile (and each costs several times more on the slower path)."""
        accumulation = self._current_accumulation()
        return (accumulation is not None and accumulation.samples < self.sample_cap and not self.moving
                and not self.state.slice_mode and self.supply.scene_ready(self._supplied(self.state), preview=False)
                and not self.supply.pending(self._supplied(self.state)))

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

    def reference_available(self, material: str | None = None) -> bool:
        """Whether a ground-truth volume is loaded for ``material`` (default: the one on show)."""
        return self.reference is not None and self.reference.available(material or self.state.material)

    @property
    def flip_mean(self) -> float | None:
        """FLIP mode: mean LDR-FLIP between network and reference over the covered pixels of the last complete
        picture (``None`` in the other modes or before one is complete)."""
        if self._flip_mean is None and self._flip_picture is not None and self.state.shading == "flip":
            data = self._flip_picture
            self._flip_mean = flip_heat_map(data[..., :3], data[..., 3:6], data[..., 6] > 0.0)[1]
        return self._flip_mean if self.state.shading == "flip" else None

    def _picture_complete(self, xyz: np.ndarray) -> None:
        """A complete picture's data: kept for :attr:`flip_mean` in FLIP mode."""
        self._flip_picture, self._flip_mean = (xyz, None) if xyz.shape[-1] == _FLIP_CHANNELS else (None, None)

    @staticmethod
    def display_pixels(xyz: np.ndarray) -> np.ndarray:
        """8-bit display sRGB of exposed XYZ (:mod:`viewer.srgb`: ``gratnet.display``'s bytes without importing
        colour-science); FLIP-mode data (network XYZ, reference XYZ, coverage) shows as the FLIP heat map."""
        if xyz.shape[-1] == _FLIP_CHANNELS:
            return flip_heat_map(xyz[..., :3], xyz[..., 3:6])[0]
        return display_srgb8(xyz)

    def render_key(self) -> tuple[Any, ...]:
        # Another point, or the environment becoming ready: another picture.
        return (*self.state.key(), *self.full_size(), self.point()[1], self.environment_live())

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
        image, key, supplied = self.image, self.render_key(), self._supplied(self.state)
        if image is not None and image.key == key and image.complete:
            if self.supply.step_due(supplied, self._idle()) or self._accumulation_due():
                return 0.0
            return self.POLL_SECONDS if self.supply.pending(supplied) or self._defaults.pending else None
        if self.supply.step_due(supplied, self._idle()):
            return 0.0  # a warm program to link or draw: the next frame does it
        if not self.supply.scene_ready(supplied):
            return self.POLL_SECONDS  # waiting for a shader or a mesh: look again soon
        if image is None or image.key != key or key != self._seen_key:
            # A picture held back for the quick guess (frame): look again soon, not in a busy loop that takes
            # the CPU from the guess's worker and the compile child.
            return self.GUESS_POLL_SECONDS if self.default_view_stage == "guessing" else 0.0
        if not self.supply.scene_ready(supplied, preview=False):
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
        self._take_default_view()  # a default view asked for by switch() or at the start
        supplied = self._supplied(self.state)  # the state as the supply takes it: its point's model file
        step = self.supply.poll(supplied, self._idle(now))  # background: at most one GL step (a cache hit)
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
        if not self.supply.scene_ready(self._supplied(self.state)):
            return False  # the picture on show stays until the new one can be rendered
        if self._defaults.hold():
            return False  # … or until its view is known (the quick guess: tenths of a second)
        if image is None or image.key != key:
            self._refinement = None
            self._preview(key)
            return True
        if self.moving or not self.supply.scene_ready(self._supplied(self.state), preview=False):
            return False
        self._refine(key)
        return True

    #: How often the window looks at background work in progress (seconds).
    POLL_SECONDS = 0.1
    #: … and for the quick guess of a default view while a new picture waits for it.
    GUESS_POLL_SECONDS = 0.02

    def _idle(self, now: float | None = None) -> bool:
        """No state change for ``policy.idle_seconds`` (the moment for a faster program to take over)."""
        now = self.clock() if now is None else float(now)
        return self.render_key() == self._seen_key and now - self._changed_at >= self.policy.idle_seconds

    @property
    def status(self) -> str:
        """What is being compiled or loaded for the state on show ("compiling the shader for cd… 12 s"),
        or an empty string."""
        supplied = self._supplied(self.state)
        status = self.supply.status(supplied)
        if supplied.material != self.state.material:  # the supply names the point's model file
            status = status.replace(supplied.material, model_label(Path(supplied.material)))
        stage = self.default_view_stage
        if stage:
            choosing = (f"choosing a view that shows {self.state.material}..." if stage == "guessing" else
                        f"refining the view of {self.state.material}...")
            status = f"{choosing} {status}" if status else choosing
        return status

    @property
    def default_view_stage(self) -> str:
        """Where the requested default view is (:attr:`viewer.default_view.DefaultViewRequests.stage`):
        ``guessing``, ``refining`` (a quick guess on show) or an empty string (none pending)."""
        return self._defaults.stage

    def weights_path_in_use(self) -> str | None:
        """The weights path that renders the current state (``None``: none ready yet)."""
        return self.supply.weights_path_in_use(self._supplied(self.state))

    def _check_background_errors(self) -> None:
        failed = self.supply.mesh_error(self.state.mesh)
        if failed is not None:
            self.message = failed
            self.state = dataclasses.replace(self.state, mesh=self._last_mesh)
        elif not self.state.slice_mode and self.supply.weights_path_in_use(self._supplied(self.state)) is not None:
            self._last_mesh = self.state.mesh
        worker = self.supply.errors.pop("worker", None)
        if worker is not None:
            self.message = worker

    def _scene_key(self, state: ViewerState) -> tuple[Any, ...]:
        supplied = self._supplied(state)
        return (supplied.material, "slice" if state.slice_mode else state.mesh,
                self.supply.weights_path_in_use(supplied), state.shading, self.environment_live(state))

    def _timed_render(self, state: ViewerState, size: tuple[int, int], camera: Camera | None = None,
                      preview: bool = False, rows: tuple[int, int] | None = None,
                      sample: int = 0) -> tuple[np.ndarray, np.ndarray]:
        """``(exposed XYZ, coverage)`` of ``state`` at ``size`` (a mesh, or the BRDF slice: coverage 1; with
        ``rows``, only those rows of the slice), timed and counted; the time per effective pixel feeds the
        resolution policy. ``sample``: the index of the mesh render's sub-pixel offset
        (:func:`viewer.antialias.sample_offsets`; 0 = the pixel centre)."""
        supplied = self.supply.scene(self._supplied(state), preview)
        if supplied is None:
            raise GratNetError(f"the shader for {state.material} is still compiling; try again in a moment")
        renderer, buffers = supplied
        live = self.environment_live(state)
        environment, area_lights = (self.environment(state), state.area_lights()) if live else (None, ())
        light = state.light()
        if not live and state.has_sampled_light and state.light_intensity == 0.0:
            light = Light.directional(state.light_theta, state.light_phi)  # the view without it: not black
        # A band of rows keys its light samples by the whole picture's pixels (GL rows count from the bottom).
        origin = (0, camera.height - camera.row1) if isinstance(camera, BandCamera) else (0, 0)
        started = time.perf_counter()
        shading = state.shading if self.reference_available(state.material) else "network"
        truth = self.reference.scene() if shading != "network" and self.reference is not None else None
        pictures = []
        for scene in {"network": (renderer,), "reference": (truth,), "flip": (renderer, truth)}[shading]:
            if state.slice_mode:
                xyz = scene.render_brdf_slice(state.light_theta, state.light_phi, size[0], state.exposure,
                                              state.effective_ior, rows=rows)
                coverage = disc_coverage(size[0], rows)  # the network runs inside the unit disc only
                if rows is not None:
                    xyz = xyz[rows[0]:rows[1]]
            else:  # the reference draws the network's mesh buffers: the same geometry, preview or full
                target, view, keys = size, camera or state.camera(), origin
                lit, lamps = (environment, area_lights) if scene is renderer else (None, ())
                if scene.render_path == "deferred":  # power-of-two: the warm variant; the picture at its top left,
                    target, view = self._padded(view, size)  # so its pixels' keys move down by the padding rows
                    keys = (origin[0], origin[1] - (target[1] - size[1]))
                path = scene.render_path if lit is not None or lamps else None  # sampled light: the scene's path
                rgba = scene.render_rgba(buffers, view, light, target, state.exposure, state.effective_ior,
                                         first_sample=sample, environment=lit, seed=state.seed, pixel_origin=keys,
                                         area_lights=lamps, render_path=path)[:size[1], :size[0]]
                xyz, coverage = rgba[..., :3], rgba[..., 3]
            pictures.append(xyz)
        if shading == "flip":  # network XYZ, reference XYZ, coverage: _display shows the FLIP heat map
            xyz = np.concatenate([*pictures, np.broadcast_to(coverage, xyz.shape[:2])[..., None]], axis=-1)
        seconds = time.perf_counter() - started
        scene = self._scene_key(state)
        effective = effective_pixels(coverage)
        per_pixel = seconds / max(1.0, effective)
        previous = self._seconds_per_pixel.get(scene)
        # Quick to grow, slow to shrink: a render slower than predicted (a busy CPU) shrinks the next band
        # at once, so that one misprediction does not make several long frames. A render mostly of background
        # only grows it: there an uncovered pixel cost far less than UNCOVERED_COST of a covered one (the
        # deferred path skips it), and the rows of background at a picture's top once pulled the rate down to
        # a fifth, so that the first band across the mesh took 0.8–0.9 s (issue 35).
        if previous is None:
            self._seconds_per_pixel[scene] = per_pixel
        elif np.count_nonzero(coverage > 0.5) >= 0.5 * effective:
            self._seconds_per_pixel[scene] = max(per_pixel, 0.5 * (previous + per_pixel))
        else:
            self._seconds_per_pixel[scene] = max(per_pixel, previous)
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
        full = self.full_size()
        seconds_per_pixel = self._seconds_per_pixel.get(self._scene_key(self.state))
        predicted = None
        if seconds_per_pixel is not None:  # with the last preview's coverage
            covered = float(np.mean(self._coverage))
            predicted = seconds_per_pixel * full[0] * full[1] * (covered + UNCOVERED_COST * (1.0 - covered))
        elif self.environment_live():
            # Nothing measured under the environment yet: the smallest preview (a pass costs several times a
            # directionally lit render's pixels: on the forward path, paper-cd, 32² on llvmpipe: 0.23 s, 16²: 0.06 s).
            predicted = math.inf
        factor = self.policy.reduced_factor(predicted, full)
        size = reduced_size(full, factor)  # square in slice mode (full is square)
        self._accumulation = None  # a new view: its samples start again
        xyz, coverage = self._timed_render(self.state, size, preview=True)
        if self._exposure_stage == "preview" and self.environment_live():
            xyz, key = self._expose(xyz, key, final=size == full)
        self._coverage = coverage.mean(axis=1)
        self.stats.preview_renders += 1
        self.stats.last_kind = f"preview 1/{factor}"
        self.stats.last_preview_s = self.stats.last_render_s
        self.stats.last_preview_size = size
        complete = size == full
        if complete:
            self._picture_complete(xyz)
        self._publish(key, self.display_pixels(xyz), size, complete, 1.0 if complete else 0.0)

    def _expose(self, xyz: np.ndarray, key: tuple[Any, ...], final: bool) -> tuple[np.ndarray, tuple[Any, ...]]:
        """The automatic exposure under an environment from a picture (``xyz``, at the state's exposure): the first
        preview's, then (``final``) the first full-resolution pass's (:func:`viewer.environment_view.picture_exposure`).
        The picture is linear in the exposure, so it is rescaled, not rendered again. Returns it and the new state's
        key (unchanged when nothing is lit)."""
        exposure = picture_exposure(xyz, self.state.exposure)
        self._exposure_stage = "" if final else "full"
        if exposure is None:
            return xyz, key
        old = self.state.exposure
        self._applying_view = True
        try:
            changed = self.set(exposure=exposure)
        finally:
            self._applying_view = False
        if not changed:
            return xyz, key
        new_key = self.render_key()
        self._seen_key = new_key  # the same view: not a change to wait out
        return xyz * np.float32(self.state.exposure / old), new_key

    def _refine(self, key: tuple[Any, ...]) -> None:
        state, (width, height) = self.state, self.full_size()
        refinement = self._refinement
        if refinement is None or refinement.key != key:
            preview = self.image.pixels if self.image is not None else np.zeros((1, 1, 3), np.uint8)
            factor = max(1, round(width / max(1, preview.shape[1])))
            refinement = self._refinement = Refinement(
                key, preview if state.slice_mode else upscale(preview, width, height), next_factor=max(1, factor // 2))
        started = time.perf_counter()
        if state.slice_mode:  # double the resolution per level, each level in bands that fit the budget
            factor = refinement.next_factor
            side = reduced_size((width, height), factor)[0]
            if refinement.pixels.shape[0] != side:  # a new level: over the last one, upscaled
                refinement.pixels = upscale(refinement.pixels, side, side)
                refinement.next_row = 0
            row0 = refinement.next_row
            seconds_per_pixel = self._seconds_per_pixel.get(self._scene_key(state), 0.0)
            row_pixels = effective_pixels_per_row(disc_coverage(side, (row0, side)))
            row1 = min(side, row0 + self.policy.band_rows(seconds_per_pixel * row_pixels * first_band_margin(row0)))
            xyz = self._timed_render(state, (side, side), rows=(row0, row1))[0]
            refinement.pixels[row0:row1] = self.display_pixels(xyz)
            refinement.next_row = row1
            level_done = row1 == side
            if level_done:
                refinement.next_factor = max(1, factor // 2)
            done, rendered = factor == 1 and level_done, (side, side)
            progress = 1.0 if done else row1 / side / factor**2
            self.stats.last_kind = f"refine 1/{factor} rows {row0}-{row1}"
        else:  # the next band of rows at full resolution, over the upscaled preview
            row0 = refinement.next_row
            rows = self._band_rows(state, self._row_seconds(width, height)[row0:] * first_band_margin(row0))
            row1 = min(height, row0 + rows)
            band = self._band_camera(state, width, height, row0, row1)
            xyz = self._timed_render(state, (width, row1 - row0), band)[0]
            refinement.pixels[row0:row1] = self.display_pixels(xyz)
            if refinement.xyz is None:
                refinement.xyz = np.zeros((height, width, xyz.shape[-1]), dtype=np.float32)
            refinement.xyz[row0:row1] = xyz
            refinement.next_row = row1
            done, rendered, progress = row1 == height, (width, height), row1 / height
            if done and self._exposure_stage and self.environment_live():  # the exposure from all its pixels
                refinement.xyz, key = self._expose(refinement.xyz, key, final=True)
                refinement.pixels = self.display_pixels(refinement.xyz)
            if done:  # sample 0 of the progressive anti-aliasing
                self._accumulation = Accumulation(key, refinement.xyz)
                self._picture_complete(refinement.xyz)
            self.stats.last_kind = f"refine rows {row0}-{row1}"
        refinement.seconds += time.perf_counter() - started
        self.stats.refine_renders += 1
        if done:
            self.stats.last_full_s = refinement.seconds
            self._refinement = None
        self._publish(key, refinement.pixels.copy(), rendered, done, 1.0 if done else progress)

    @staticmethod
    def _padded(camera: Camera, size: tuple[int, int]) -> tuple[tuple[int, int], Camera]:
        """A render of ``size`` with ``camera`` (a band's, or a whole picture's) as a power-of-two target whose
        top-left corner holds it (:func:`viewer.scheduling.padded_size`)."""
        target = padded_size(size)
        if target == size:
            return size, camera
        if not isinstance(camera, BandCamera):  # the whole picture: a band of all its rows
            camera = BandCamera(camera.distance, camera.azimuth_deg, camera.elevation_deg, camera.target,
                                camera.fov_deg, camera.near, camera.far, full_aspect=size[0] / size[1],
                                height=size[1], row0=0, row1=size[1])
        return target, dataclasses.replace(camera, width_fraction=size[0] / target[0],
                                           height_fraction=size[1] / target[1])

    def _band_camera(self, state: ViewerState, width: int, height: int, row0: int, row1: int) -> BandCamera:
        camera = state.camera()
        return BandCamera(camera.distance, camera.azimuth_deg, camera.elevation_deg, camera.target, camera.fov_deg,
                           camera.near, camera.far, full_aspect=width / height, height=height, row0=row0, row1=row1)

    def _accumulate(self, key: tuple[Any, ...]) -> None:
        """Progressive anti-aliasing: the next band of rows of the next sample (one sub-pixel offset) of the
        still mesh view, sized to ``refine_budget_s`` like a refinement band; the rows done show the mean
        over one more sample than the rest."""
        accumulation = self._accumulation
        assert accumulation is not None and self.image is not None
        state, (width, height) = self.state, self.full_size()
        row0 = accumulation.next_row
        row1 = min(height, row0 + self._band_rows(state, self._row_seconds(width, height)[row0:]))
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
            self._picture_complete(accumulation.sums / np.float32(accumulation.samples))
        else:
            mean = (accumulation.sums[row0:row1] + xyz) / np.float32(accumulation.samples + 1)
        pixels = self.image.pixels.copy()
        pixels[row0:row1] = self.display_pixels(mean)
        self.stats.refine_renders += 1
        self.stats.last_kind = f"sample {accumulation.samples + (row1 < height)} rows {row0}-{row1}"
        self.stats.last_sample_s = time.perf_counter() - started
        self._publish(key, pixels, (width, height), True, 1.0, accumulation.samples)

    def _band_rows(self, state: ViewerState, row_seconds: np.ndarray) -> int:
        """The next mesh band's rows (:meth:`ResolutionPolicy.band_rows`): on the deferred path a power of two
        (the network runs per covered pixel, not per block of fragments, and a power-of-two band needs no
        padding: :func:`viewer.scheduling.padded_size`); elsewhere a multiple of the policy's."""
        supplied = self.supply.scene(self._supplied(state))
        deferred = supplied is not None and supplied[0].render_path == "deferred"
        return self.policy.band_rows(row_seconds, 1 if deferred else None, power_of_two=deferred)

    def _row_seconds(self, width: int, height: int) -> np.ndarray:
        """Predicted seconds of each full-resolution row, from the preview's coverage of that row."""
        seconds_per_pixel = self._seconds_per_pixel.get(self._scene_key(self.state), 0.0)
        rows = np.minimum((np.arange(height) * len(self._coverage)) // height, len(self._coverage) - 1)
        covered = self._coverage[rows]
        return seconds_per_pixel * width * (covered + UNCOVERED_COST * (1.0 - covered))

    def render_full(self) -> np.ndarray:
        """The current state's picture at full resolution in one render (display sRGB ``uint8``); the
        cached picture when it is complete and current."""
        key = self.render_key()
        if self.image is not None and self.image.key == key and self.image.complete:
            return self.image.pixels
        xyz = self._timed_render(self.state, self.full_size())[0]
        self._picture_complete(xyz)
        pixels = self.display_pixels(xyz)
        self.stats.last_kind = "full"
        self._refinement = None
        self._accumulation = None if self.state.slice_mode else Accumulation(key, np.array(xyz, dtype=np.float32))
        self._publish(key, pixels, self.full_size(), True, 1.0)
        return pixels

    def _warm_up(self) -> None:
        """Check the state's material and mesh (GratNetError if unusable). When not in the background, also
        pay the one-off costs before the first timed frame: loading, the driver's shader JIT (a 1×1 render,
        uncounted) and the import of the display conversion (colour-science, ~1 s); in the background the
        child process starts compiling now (:meth:`frame` polls it)."""
        self.supply.check(self._supplied(self.state))
        self.supply.poll(self._supplied(self.state))

    def release(self) -> None:
        """Free the GL objects and stop background work (the context belongs to the caller)."""
        if not self._released:
            if self.reference is not None:
                self.reference.release()
            self._defaults.release()
            self.supply.release()
            self._released = True


def _wrap(degrees: float) -> float:
    """An angle in [−180, 180)."""
    return (degrees + 180.0) % 360.0 - 180.0
