"""The viewer's renderers and meshes for the material on show: ready at once, or later without blocking.

:class:`SceneSupply` hands :class:`~viewer.app.ViewerApp` a :class:`~viewer.scene.SceneRenderer` and the
uploaded mesh for a :class:`~viewer.state.ViewerState`, in one of two modes:

- blocking (``background=False``; scripts and headless tests): everything is loaded and compiled when
  first asked for, as ``gratnet render`` does.
- background (``background=True``; the window): nothing slow runs on the caller's thread.
  :class:`~viewer.compile_worker.CompileWorker` compiles the material's programs in a child process
  (warming Mesa's disk shader cache), the quick texture path first and, where ``auto`` picks the baked
  path, the baked one after it; :meth:`poll` then links each warm program in the window's context (a
  cache hit, one step per call) and the faster path takes over as soon as it is linked. Meshes are built
  on a thread. Until a renderer is ready :meth:`scene` returns ``None`` and :meth:`status` says what is
  being waited for ("compiling the shader for cd… 12 s"). (colour-science is not needed: the window's
  display conversion is :mod:`viewer.srgb`'s.)

Environment light (``gratnet view --environment``; ``environment`` set): the child also warms the ``environment``
group (the surface program's ``ENVIRONMENT`` variant on the window's render path: on a CPU rasterizer the deferred
path's G-buffer with it and the ``TINT`` kernel, beside the network kernel the ``surface`` group compiled already),
then builds the material's importance table into its disk cache. Until this supply reads that table
(:meth:`poll`, once the child reports it), environment passes sample with :func:`gratnet.importance.flat_table`:
unbiased, only noisier. A state with an environment renders with it only once that group is linked and
drawn here (:meth:`SceneSupply.environment_live`); until then :meth:`SceneSupply.scene` hands the ``surface``
group's renderer, the caller shows the scene without the environment, and :meth:`SceneSupply.status` says so.

Rendering only: no glfw, no imgui.

Never blocking (issue 11; measured in docs/benchmarks.md "Viewer: a window that never blocks"): the window
never compiles a shader that has not been compiled already. :class:`~viewer.scene_supply.SceneSupply`
(background mode, the window's default) has a child process (:mod:`viewer.compile_worker`) compile each
material's programs on its own EGL context, which fills Mesa's disk shader cache; the window then links
the same program text as a cache hit, one short step per frame. The quick texture path (about a second
to compile) gives the first picture; on a CPU rasterizer the faster baked program (25–60 s to compile)
takes over when its compile is done; while idle, a child at a low priority warms the other shipped
materials' quick programs, so that a switch to one links them at once. Until then the panel's status line
says what is compiling ("compiling the shader for cd… 12 s") and the picture on show stays. Meshes are
built on a thread, the first frame (imgui's own shaders) is drawn before the window is shown, and a
switch's (or a start's) default view is guessed in a worker process and refined in another
(:mod:`viewer.default_view`; a new picture waits up to 2 s for the guess). Each frame's work, the figure the
panel shows as "frame", is its events, panel, at most one preview or band, and drawing; the idle wait for
input is not counted.
"""

from __future__ import annotations

from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor
from typing import Any

from gratnet.errors import GratNetError
from viewer.catalog import build_mesh, check_mesh_spec, resolve_material
from viewer.compile_worker import (
    ENVIRONMENT_GROUP,
    GROUPS,
    IMPORTANCE,
    CompileWorker,
    shader_cache_enabled,
    warm_group,
    window_render_path,
)

__all__ = ["PREVIEW_MESHES", "SceneSupply", "load_material"]


def _preview_disc() -> Any:
    from viewer.meshes import compact_disc

    return compact_disc(segments=64, rings=1)


def _preview_sphere() -> Any:
    from viewer.meshes import sphere

    return sphere(segments=32, rings=16)


#: Coarser tessellations of the built-in meshes for previews. llvmpipe shades whole pixel blocks per
#: triangle, so on the forward path at 1/4–1/8 resolution the 4096-triangle disc costs 2–3× a 128-triangle
#: one; the outline and the interpolated tangents differ invisibly at preview resolution. Full-resolution
#: pictures always use ``build_mesh`` (the meshes of ``gratnet render``).
PREVIEW_MESHES: dict[str, Callable[[], Any]] = {"cd": _preview_disc, "sphere": _preview_sphere}

#: Weights paths from slowest to fastest to draw on a CPU rasterizer (the later one takes over).
_SPEED_ORDER = ("texture", "baked")
#: Niceness of the child that warms the other shipped materials' quick programs while the window is idle.
PREFETCH_NICENESS = 15


_LOADED: dict[tuple[str, int, int], Any] = {}  # (model file, mtime, size) -> ModelFile, for this process


def load_material(material: str) -> Any:
    """The ``ModelFile`` of a shipped material or a model-file path, read once per process (and again when the
    file changes): ``gratnet view`` checks it before its window opens, and the window's supply renders it (a
    feature-grid model's arrays take 0.3–0.6 s to decompress, twice that on a busy machine)."""
    import os

    from gratnet.modelfile import load_model

    path = resolve_material(material)
    try:
        status = os.stat(path)
    except OSError:
        return load_model(path)  # its own error
    key = (str(path), status.st_mtime_ns, status.st_size)
    if key not in _LOADED:
        _LOADED[key] = load_model(path)
    return _LOADED[key]


class SceneSupply:
    """Renderers and meshes for the viewer (see the module docstring).

    Args:
        ctx: the window's (or a headless) OpenGL ≥ 4.3 context; every GL call is made on its thread.
        weights_path: ``auto``, ``texture`` or ``baked`` (:func:`viewer.renderer.choose_weights_path`).
        background: compile and load off the caller's thread (see the module docstring).
        worker: a child already warming the first material's programs (:meth:`start_worker`, called
            before the window and its context exist, so that the compile starts at once); adopted when the
            first material selected is its model, else stopped.
        environment: an environment spec (``gratnet view --environment``; ``None``: none): every material's
            child also warms the ``environment`` group, drawn with this environment (see the module docstring).
    """

    def __init__(self, ctx: Any, weights_path: str = "auto", background: bool = False,
                 worker: CompileWorker | None = None, render_path: str = "auto",
                 environment: str | None = None) -> None:
        from viewer.renderer import WEIGHTS_PATHS
        from viewer.scene import check_render_path

        if weights_path not in WEIGHTS_PATHS:
            raise GratNetError(f"weights path must be one of {', '.join(WEIGHTS_PATHS)}, got {weights_path!r}")
        self.ctx = ctx
        self.weights_path = weights_path
        #: ``--render-path``: ``auto`` takes the cached verdict (forward until the compile child measured it).
        self.render_path = check_render_path(render_path)
        self.background = background
        #: The environment the ``environment`` group is warmed with (None: that group is never warmed or used).
        self.environment = environment
        #: The Environment of this window's first draw of the ``environment`` group (loaded from ``environment``
        #: there when None; the viewer hands its own, already read, so that no frame reads a map).
        self.warm_environment: Any = None
        #: Problems found in the background (a mesh that failed to load, a failed child), for the panel.
        self.errors: dict[str, str] = {}
        self._models: dict[str, Any] = {}
        self._material: str | None = None
        self._paths: tuple[str, ...] = ()  # the material's weights paths, slowest first
        self._scenes: dict[str, Any] = {}  # weights path -> SceneRenderer of _material
        self._importance_looked: set[str] = set()  # weights paths whose scene looked for the child's table
        self._linked: set[tuple[str, str]] = set()  # (path, group) linked in this context
        #: (path, group) → the link steps still to run (:meth:`_link`, one per frame in the background).
        self._pending_links: dict[tuple[str, str], list[Callable[[], object]]] = {}
        self._active: set[tuple[str, str]] = set()  # ... and drawn once: ready to render
        self._worker: CompileWorker | None = None
        self._prestarted = worker
        #: (model file, weights path, group) that a child of this session has warmed: linked here from Mesa's
        #: cache at once, without waiting for a new child (a switch to a prefetched material).
        self._warm: set[tuple[str, str, str]] = set()
        #: While the window is idle, one child at a time warms the next shipped material's quick (texture)
        #: programs, so that a switch to it shows a picture in a few frames instead of after a compile.
        self._prefetch: CompileWorker | None = None
        self._prefetched: set[str] = set()  # materials a prefetch child was started for
        self._meshes: dict[str, Any] = {}  # mesh key -> Mesh, or Future of one
        self._buffers: dict[tuple[str, str], Any] = {}  # (path, mesh key) -> MeshBuffers
        self._executor = ThreadPoolExecutor(1, thread_name_prefix="gratnet-mesh") if background else None

    @staticmethod
    def start_worker(state: Any, weights_path: str = "auto", render_path: str = "auto",
                     environment: str | None = None) -> CompileWorker | None:
        """A child warming ``state``'s material (``None`` when Mesa's shader cache is off), started before
        any context exists: the quick texture path first, then what ``weights_path`` picks there; with
        ``environment`` the ``environment`` group too."""
        if not shader_cache_enabled():
            return None
        paths = ("texture", weights_path) if weights_path == "auto" else (weights_path,)
        return CompileWorker(resolve_material(state.material), paths, _worker_groups(state, environment),
                             state.material, render_path=render_path, environment=environment)

    # -- checks (cheap, on the caller's thread) ----------------------------------------------------

    def model(self, material: str) -> Any:
        """The material's model (:func:`load_material`: read once per process)."""
        if material not in self._models:
            self._models[material] = load_material(material)
        return self._models[material]

    def check(self, state: Any) -> None:
        """Raise GratNetError if ``state``'s material or mesh cannot be used; in blocking mode also load
        and compile everything it needs now."""
        self.model(state.material)
        check_mesh_spec(state.mesh)
        if not self.background:
            self.scene(state)

    # -- progress (never blocks in background mode) ------------------------------------------------

    def _select(self, state: Any) -> None:
        """Hold the scenes of ``state.material`` (dropping another material's) and start its worker."""
        if state.material == self._material:
            return
        self._release_scenes()
        self._stop_prefetch()  # the CPU goes to the switch
        self._material = state.material
        model = self.model(state.material)
        from viewer.renderer import choose_weights_path

        target = choose_weights_path(self.ctx, model, self.weights_path)
        quick_first = self.background and self.weights_path == "auto" and target != "texture"
        self._paths = ("texture", target) if quick_first else (target,)
        if not self.background:
            return
        prestarted, self._prestarted = self._prestarted, None
        if shader_cache_enabled():
            model_path = resolve_material(state.material)
            if prestarted is not None and prestarted.model_path == model_path:
                self._worker, prestarted = prestarted, None
            else:
                groups = _worker_groups(state, self.environment)
                # The window is on screen: the child yields the CPU to it (the first child, started before
                # the window shows, runs at full priority).
                self._worker = CompileWorker(model_path, self._paths, groups, state.material, niceness=5,
                                             render_path=self.render_path, environment=self.environment)
        if prestarted is not None:
            prestarted.close()
        if self._worker is None:  # a child's compile would not spare ours: the first path only, compiled here
            self._paths = self._paths[:1]

    def _ready(self, path: str, group: str) -> bool:
        """Whether the program group can be linked here without a long compile."""
        if not self.background:
            return True
        if self._material is not None and (str(resolve_material(self._material)), path, group) in self._warm:
            return True
        if self._worker is None:  # no disk cache, or the child failed: the first path, compiled here
            return path == self._paths[0]
        return (path, group) in self._worker.ready

    def poll(self, state: Any, idle: bool = True) -> str | None:
        """Advance the background work by one GL step if one is due, each a cache hit: ``"linked"`` (a
        program linked; the baked one takes 0.11–0.15 s), ``"drawn"`` (its first 1×1 draw) or ``"took
        over"`` (that, and a faster path now renders ``state``); ``None``: nothing was due. Steps towards a
        faster path while a picture is already on show wait for ``idle`` (no input lately): an input that
        arrives during such a link is then unlikely."""
        self._select(state)
        if not self.background:
            return None
        worker = self._worker
        if worker is not None:
            self._note_warm(worker)
            if worker.error is not None and "worker" not in self.errors:
                self.errors["worker"] = f"the background compile failed ({worker.error}); compiling in the window"
                self._worker = None  # fall back: the first path, compiled here (and the table built here)
                self._paths = self._paths[:1]
                worker.close()
                for scene in self._scenes.values():
                    scene.provisional_importance = False
            elif worker.finished and not worker.running:  # its context chose otherwise: keep what it made
                made = tuple(path for path in self._paths if any((path, g) in worker.ready for g in worker.groups))
                self._paths = made or self._paths[:1]
        self._find_importance()
        self._collect_meshes()
        self._advance_prefetch(_group(state, self.environment), idle)
        for group in self._groups(state):
            best = self._best_active(group)
            for path in reversed(self._paths):
                if best is not None and (not idle or _SPEED_ORDER.index(path) <= _SPEED_ORDER.index(best)):
                    break
                if not self._ready(path, group):
                    continue
                if (path, group) not in self._linked:
                    self._link(path, group, every_step=False)
                    return "linked"
                self._first_draw(path, group)
                return "took over" if best is not None else "drawn"
            if best is not None:  # the group on show needs no fallback
                break
        return None

    def _groups(self, state: Any) -> tuple[str, ...]:
        """The program groups that can render ``state``, the one it wants first: an environment state falls
        back to ``surface`` (the scene without the environment) until its own group is ready."""
        group = _group(state, self.environment)
        return (group, "surface") if group == ENVIRONMENT_GROUP else (group,)

    def _best_for(self, state: Any) -> str | None:
        """The fastest active path of the first of :meth:`_groups` that has one."""
        for group in self._groups(state):
            best = self._best_active(group)
            if best is not None:
                return best
        return None

    def environment_live(self, state: Any) -> bool:
        """Whether ``state`` renders with its environment now: it has one, the supply warms environments, and the
        ``environment`` group is ready (else :meth:`scene` is the scene without the environment). In blocking
        mode :meth:`scene` links that group when first asked."""
        if _group(state, self.environment) != ENVIRONMENT_GROUP:
            return False
        return not self.background or (state.material == self._material
                                       and self._best_active(ENVIRONMENT_GROUP) is not None)

    def _note_warm(self, worker: CompileWorker) -> None:
        """Read ``worker``'s reports; what it warmed is linked from the cache from now on."""
        worker.poll()
        self._warm.update((str(worker.model_path), path, group) for path, group in worker.ready)

    def _advance_prefetch(self, group: str, idle: bool) -> None:
        """Prefetch (see ``_prefetch``): read the running child's reports, stop it when done, and start the next
        one while the window is idle and its own material's child has finished."""
        prefetch = self._prefetch
        if prefetch is not None:
            self._note_warm(prefetch)
            if not prefetch.running:
                self._stop_prefetch()
            return
        if not idle or (self._worker is not None and self._worker.running) or not shader_cache_enabled():
            return
        from viewer.catalog import shipped_materials

        for material in shipped_materials():
            if material == self._material or material in self._prefetched:
                continue
            self._prefetched.add(material)
            model_path = resolve_material(material)
            if (str(model_path), "texture", group) in self._warm:
                continue
            self._prefetch = CompileWorker(model_path, ("texture",), (group,), material, niceness=PREFETCH_NICENESS,
                                           render_path=self.render_path)
            return

    def _stop_prefetch(self) -> None:
        if self._prefetch is not None:
            self._note_warm(self._prefetch)
            self._prefetch.close()
            self._prefetch = None

    @property
    def warm(self) -> frozenset[tuple[str, str, str]]:
        """``(model file, weights path, group)`` that children of this session have warmed (prefetch included)."""
        return frozenset(self._warm)

    def step_due(self, state: Any, idle: bool = True) -> bool:
        """Whether :meth:`poll` (with the same ``idle``) has a GL step to do for ``state`` right now."""
        if not self.background or state.material != self._material:
            return False
        if self._worker is not None:
            self._worker.poll()
        for group in self._groups(state):
            best = self._best_active(group)
            for path in reversed(self._paths):
                if best is not None and (not idle or _SPEED_ORDER.index(path) <= _SPEED_ORDER.index(best)):
                    break
                if self._ready(path, group):
                    return True
            if best is not None:
                break
        return False

    def pending(self, state: Any) -> bool:
        """Whether something is still on its way for ``state`` (so the caller should poll again soon)."""
        if not self.background:
            return False
        key = _mesh_key(state.mesh, False)
        if not state.slice_mode and isinstance(self._meshes.get(key), Future):
            return True
        group = _group(state, self.environment)
        return state.material != self._material or self._best_active(group) != self._paths[-1]

    def status(self, state: Any) -> str:
        """A line for the panel: what is being compiled or loaded for ``state`` (empty when nothing is).
        Three dots, not an ellipsis: imgui's default font has no U+2026."""
        if not self.background or state.material != self._material:
            return ""
        worker = self._worker
        elapsed = f"{worker.elapsed():.0f} s" if worker is not None else ""
        group = _group(state, self.environment)
        best = self._best_active(group)
        if best is None and group == ENVIRONMENT_GROUP and self._best_active("surface") is not None:
            return (f"compiling the environment light for {state.material}... {elapsed} (showing it without the "
                    "environment)")
        if best is None:
            return f"compiling the shader for {state.material}... {elapsed}".rstrip()
        if best != self._paths[-1]:
            faster = self._paths[-1]
            return f"compiling the faster ({faster}) shader for {state.material}... {elapsed} (showing the {best} path)"
        if not state.slice_mode and isinstance(self._meshes.get(_mesh_key(state.mesh, False)), Future):
            return f"loading the mesh {state.mesh}..."
        return ""

    @property
    def worker(self) -> CompileWorker | None:
        """The compile child of the current material (its ``seconds`` and ``ready_at`` time each program), or
        ``None`` when the programs compile in this process."""
        return self._worker

    def weights_path_in_use(self, state: Any) -> str | None:
        """The weights path that renders ``state`` now (``None``: nothing ready yet)."""
        if state.material != self._material:
            return None
        return self._best_for(state)

    def _best_active(self, group: str) -> str | None:
        for path in reversed(self._paths):
            if (path, group) in self._active:
                return path
        return None

    def _scene_for(self, path: str) -> Any:
        from viewer.renderer import is_software_rasterizer
        from viewer.scene import SceneRenderer

        if path not in self._scenes:
            source = self._worker.baked_source if (self._worker is not None and path == "baked") else None
            scene = SceneRenderer(self.ctx, self.model(self._material or ""), weights_path=path,
                                  baked_source=source,
                                  render_path=window_render_path(self.render_path, is_software_rasterizer(self.ctx)),
                                  measure_render_path=False)
            # The window never builds the importance table (seconds of numpy) while a child does: until then the
            # passes sample with the flat table (each pass unbiased; _find_importance swaps the table in).
            scene.provisional_importance = self.background and self._worker is not None
            self._scenes[path] = scene
        return self._scenes[path]

    def _find_importance(self) -> None:
        """Once the child reported the material's importance table (``ready PATH importance``), each scene reads it
        from the disk cache (milliseconds), once."""
        worker = self._worker
        if worker is None or not any(group == IMPORTANCE for _, group in worker.ready):
            return
        for path, scene in self._scenes.items():
            if path not in self._importance_looked:
                self._importance_looked.add(path)
                scene.importance_table_ready()

    def _link_steps(self, path: str, group: str) -> list[Callable[[], object]]:
        """The programs ``group`` needs on ``path``, one callable each (each one link from Mesa's cache)."""
        scene = self._scene_for(path)
        network = scene.network
        if group == "slice":
            return [lambda: network.program("brdf_slice")]
        steps: list[Callable[[], object]] = [lambda: network.program("surface")]  # the mesh buffers bind to it
        if scene.render_path == "deferred":  # the window's path on a CPU, or the cached verdict on a GPU
            return steps + scene.deferred.compile_steps(tinted=group == ENVIRONMENT_GROUP)
        if group == ENVIRONMENT_GROUP:  # sampled light on the forward path (the importance table: poll's)
            from viewer.environment_light import ENVIRONMENT_DEFINES

            return [*steps, lambda: network.variant_program("surface", ENVIRONMENT_DEFINES),
                    lambda: network.depth_only_program("surface")]
        return [*steps, lambda: network.depth_only_program("surface")]  # the forward path's depth pre-pass

    def _link(self, path: str, group: str, every_step: bool = True) -> bool:
        """Link ``group``'s programs on ``path``: all of them, or with ``every_step`` False the next one only
        (one per frame keeps the window's frames short). Returns whether all are linked now."""
        pending = self._pending_links.setdefault((path, group), self._link_steps(path, group))
        while pending:
            pending.pop(0)()
            if not every_step:
                break
        if pending:
            return False
        del self._pending_links[(path, group)]
        self._linked.add((path, group))
        return True

    def _first_draw(self, path: str, group: str) -> None:
        environment = None
        if group == ENVIRONMENT_GROUP:  # drawn with the environment the child drew (the same texture formats)
            if self.warm_environment is None:
                from gratnet.environment import load_environment

                self.warm_environment = load_environment(self.environment or "1")
            environment = self.warm_environment
        # llvmpipe compiles (here: loads) the draw code at the first draw
        warm_group(self._scenes[path], group, environment=environment)
        self._active.add((path, group))

    # -- what renders ------------------------------------------------------------------------------

    def scene(self, state: Any, preview: bool = False) -> tuple[Any, Any] | None:
        """``(SceneRenderer, MeshBuffers or None in slice mode)`` for ``state`` (with ``preview``: the mesh's
        coarser preview tessellation where it has one), or ``None`` while they are not ready (background)."""
        self._select(state)
        group = _group(state, self.environment)
        if not self.background and (self._paths[-1], group) not in self._active:
            self._link(self._paths[-1], group)
            self._first_draw(self._paths[-1], group)
        path = self._best_for(state)
        if path is None:
            return None
        scene = self._scenes[path]
        if state.slice_mode:
            return scene, None
        key = _mesh_key(state.mesh, preview)
        mesh = self._mesh(key)
        if mesh is None:
            if not preview:
                return None
            key = _mesh_key(state.mesh, False)  # no preview tessellation yet: the full mesh will do
            mesh = self._mesh(key)
            if mesh is None:
                return None
        if (path, key) not in self._buffers:
            self._buffers[(path, key)] = scene.upload(mesh)
        return scene, self._buffers[(path, key)]

    def scene_ready(self, state: Any, preview: bool = True) -> bool:
        """Whether :meth:`scene` (with ``preview``) has something for ``state`` now (always, when not in
        the background). Asks for both tessellations of the mesh, so that the full one is built meanwhile."""
        if not self.background:
            return True
        if state.material != self._material or self._best_for(state) is None:
            return False
        if state.slice_mode:
            return True
        full = self._mesh(state.mesh) is not None
        return full or (preview and self._mesh(_mesh_key(state.mesh, True)) is not None)

    def _mesh(self, key: str) -> Any:
        """The CPU mesh for ``key`` (built now in blocking mode; on the thread in background mode)."""
        entry = self._meshes.get(key)
        if entry is None:
            build = _mesh_builder(key)
            if self._executor is None:
                entry = self._meshes[key] = build()
            else:
                entry = self._meshes[key] = self._executor.submit(build)
        if isinstance(entry, Future):
            if not entry.done():
                return None
            entry = self._collect(key, entry)
        return entry

    def _collect(self, key: str, future: Future) -> Any:
        try:
            mesh = self._meshes[key] = future.result()
        except GratNetError as error:
            del self._meshes[key]
            self.errors[f"mesh {key}"] = str(error)
            return None
        return mesh

    def _collect_meshes(self) -> None:
        for key, entry in list(self._meshes.items()):
            if isinstance(entry, Future) and entry.done():
                self._collect(key, entry)

    def mesh_error(self, spec: str) -> str | None:
        """The error of a mesh that failed to load in the background (taken: reported once)."""
        return self.errors.pop(f"mesh {spec}", None) or self.errors.pop(f"mesh {spec} (preview)", None)

    # -- teardown ----------------------------------------------------------------------------------

    def _release_scenes(self) -> None:
        if self._worker is not None:
            self._worker.close()
            self._worker = None
        for buffers in self._buffers.values():
            buffers.release()
        self._buffers.clear()
        for scene in self._scenes.values():
            scene.release()
        self._scenes.clear()
        self._importance_looked.clear()
        self._linked.clear()
        self._pending_links.clear()
        self._active.clear()
        self._material = None

    def release(self) -> None:
        """Stop the workers and free the GL objects (the context belongs to the caller)."""
        self._stop_prefetch()
        self._release_scenes()
        if self._prestarted is not None:
            self._prestarted.close()
            self._prestarted = None
        if self._executor is not None:
            self._executor.shutdown(wait=False, cancel_futures=True)


def _group(state: Any, environment: str | None = None) -> str:
    """The program group that renders ``state`` (``environment``: the supply warms environments)."""
    if state.slice_mode:
        return "slice"
    sampled = getattr(state, "has_sampled_light", getattr(state, "has_environment", False))  # or area lights
    return ENVIRONMENT_GROUP if environment is not None and sampled else "surface"


def _worker_groups(state: Any, environment: str | None) -> tuple[str, ...]:
    """The groups a material's child warms, the one on show first; the environment variant right after the
    surface group (the scene without the environment shows first, while the variant compiles)."""
    if state.slice_mode:
        return ("slice", "surface", ENVIRONMENT_GROUP) if environment is not None else ("slice", "surface")
    return ("surface", ENVIRONMENT_GROUP, "slice") if environment is not None else GROUPS


def _mesh_key(spec: str, preview: bool) -> str:
    return f"{spec} (preview)" if preview and spec in PREVIEW_MESHES else spec


def _mesh_builder(key: str) -> Callable[[], Any]:
    if key.endswith(" (preview)"):
        return PREVIEW_MESHES[key.removesuffix(" (preview)")]
    return lambda: build_mesh(key)
