"""The viewer's default view: an instant first guess, then the exact one worked out off the window's thread.

When the viewer starts without ``--light``, ``--camera`` or ``--exposure``, or switches material, mesh or
BRDF-slice mode (``ViewerApp.switch``), it wants the new pair's light, camera and exposure — the values
``gratnet render`` starts with (:func:`viewer.defaults.resolve_defaults`). Those take about a second of numpy
plus colour-science's import (1–6 s on a busy 2-core machine), so :class:`DefaultViewRequests` hands them over
in up to three steps (issue 35: a switch showed the new material at the old light and exposure, dark, for
55–118 s):

1. **Remembered**: the exact defaults computed before for the same model file, mesh, mode, field of view and
   IOR (:func:`remembered_view`, a JSON file in ``$XDG_CACHE_HOME/gratnet/``): at once.
2. **Quick guess** (:func:`quick_view`, tenths of a second in a worker process, no colour-science): the steps of
   :mod:`viewer.defaults` on :data:`QUICK_SAMPLES` surface points instead of 4096, aiming only the material's
   brightest stored peak (``metadata["display"]``, :class:`gratnet.showcase.MaterialDisplay`; the exact
   defaults try four): the default camera at each elevation, the light that puts the peak (or 0.6 of it) at
   the point seen in the picture's centre, the exposure that puts the 99.5th percentile of the network's
   predicted brightness at display white, the candidate the display would show most coloured.
3. **Exact**: :func:`state_defaults` in another worker process (started with the requests, its imports done
   ahead), which also remembers the result for next time.

A result is handed over only where the view is as the last hand-over left it: a user who moved the light, the
camera or the exposure keeps that group of fields (the others still come: dragging the camera during a switch
keeps the camera, and the new material still gets its light and exposure); a switch drops the request. No GL,
no imgui.
"""

from __future__ import annotations

import json
import math
import os
import time
from collections.abc import Iterable
from pathlib import Path
from typing import Any

from gratnet.errors import GratNetError
from viewer.defaults import FOV_DEGREES, resolve_defaults

__all__ = ["DEFAULTS_WORKER_NICENESS", "GUESS_WAIT_S", "QUICK_SAMPLES", "QUICK_WORKER_NICENESS", "VIEW_FIELDS",
           "DefaultViewRequests", "quick_view", "remembered_view", "state_defaults", "view_cache_file"]

#: Niceness of the viewer's default-view worker process (os.nice increment). At 19 a busy machine starved it
#: for 55–118 s (issue 35); at 10 it still yields the window most of the CPU when both want it.
DEFAULTS_WORKER_NICENESS = 10
#: The viewer fields a default view sets (ViewerState names).
VIEW_FIELDS = ("light_theta", "light_phi", "camera_distance", "camera_azimuth", "camera_elevation", "exposure")
#: Fields handed over together: a user who moved one of a group (a drag moves the camera's azimuth and
#: elevation) keeps the whole group, and the other groups still come (the light and exposure of a new material).
_GROUPS = (("light_theta", "light_phi"), ("camera_distance", "camera_azimuth", "camera_elevation"), ("exposure",))
_GROUP_OF = {name: group for group in _GROUPS for name in group}
#: How long the viewer holds a new picture back for the quick guess (seconds from the first picture held):
#: rather than show the material at a view about to change (the old light and exposure after a switch, the
#: fallback view at a start).
GUESS_WAIT_S = 2.0
#: Niceness of the quick guess's worker: below the window and a new material's compile child (5), above the
#: exact defaults' worker.
QUICK_WORKER_NICENESS = 5
#: Surface points of the quick guess's exposure (viewer.defaults uses 4096).
QUICK_SAMPLES = 384
_CACHE_VERSION = 1
_CACHE_ENTRIES = 256  # the remembered views kept (the oldest go first)


def view_cache_file() -> Path:
    """The remembered exact default views: ``$XDG_CACHE_HOME/gratnet/default_views.json`` (else
    ``~/.cache/gratnet/default_views.json``)."""
    from gratnet.atomic import cache_folder

    return cache_folder("default_views.json")


def _cache_key(material: str, mesh: str, slice_mode: bool, fov_degrees: float, ior: float | None) -> str | None:
    """What a default view depends on: the model file (path, modification time, size), the mesh (an .obj file's
    too), the mode, the field of view and the IOR; ``None`` when a file cannot be read."""
    from viewer.catalog import MESHES, resolve_material

    try:
        model = resolve_material(material)
        stat = os.stat(model)
        mesh_part = "slice" if slice_mode else mesh
        if not slice_mode and mesh not in MESHES:
            path = Path(mesh).expanduser().resolve()
            mesh_stat = os.stat(path)
            mesh_part = f"{path}|{mesh_stat.st_mtime_ns}|{mesh_stat.st_size}"
    except (OSError, GratNetError):
        return None
    return (f"v{_CACHE_VERSION}|{Path(model).resolve()}|{stat.st_mtime_ns}|{stat.st_size}|{mesh_part}|"
            f"{float(fov_degrees)!r}|{ior!r}")


def _read_cache() -> dict[str, Any]:
    try:
        entries = json.loads(view_cache_file().read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return {}
    return entries if isinstance(entries, dict) else {}


def remembered_view(material: str, mesh: str, slice_mode: bool = False, fov_degrees: float = FOV_DEGREES,
                    ior: float | None = 1.5) -> dict[str, float] | None:
    """The exact default view computed before for this pair (:func:`state_defaults` remembers each), or
    ``None``."""
    key = _cache_key(material, mesh, slice_mode, fov_degrees, ior)
    entry = _read_cache().get(key) if key is not None else None
    if not isinstance(entry, dict) or set(entry) != set(VIEW_FIELDS):
        return None
    values = {name: entry[name] for name in VIEW_FIELDS}
    if not all(isinstance(value, (int, float)) and math.isfinite(value) for value in values.values()):
        return None
    return {name: float(value) for name, value in values.items()}


def _remember(key: str | None, view: dict[str, float]) -> None:
    """Add ``view`` under ``key``, atomically; a cache that cannot be written only costs a later computation."""
    if key is None:
        return
    from gratnet.atomic import write_text_atomic

    entries = _read_cache()
    entries.pop(key, None)
    entries[key] = view
    while len(entries) > _CACHE_ENTRIES:
        entries.pop(next(iter(entries)))
    try:
        view_cache_file().parent.mkdir(parents=True, exist_ok=True)
        write_text_atomic(view_cache_file(), json.dumps(entries, indent=1) + "\n")
    except (OSError, GratNetError):
        pass


def state_defaults(material: str, mesh: str, slice_mode: bool = False, fov_degrees: float = FOV_DEGREES,
                   ior: float | None = 1.5) -> dict[str, float]:
    """The viewer's fields for :func:`resolve_defaults` (``ViewerState`` names), for the viewer to apply when
    the material or the mesh changes: ``ViewerApp.set(**state_defaults(...))``. Remembered for
    :func:`remembered_view`."""
    defaults = resolve_defaults(material, mesh, slice_mode, fov_degrees, ior)
    view = {"light_theta": defaults.light_theta_degrees, "light_phi": defaults.light_phi_degrees,
            "camera_distance": defaults.camera_distance, "camera_azimuth": defaults.camera_azimuth_degrees,
            "camera_elevation": defaults.camera_elevation_degrees, "exposure": defaults.exposure}
    _remember(_cache_key(material, mesh, slice_mode, fov_degrees, ior), view)
    return view


def _colour(model: Any, light: Any, view: Any, ior: float | None) -> Any:
    """Unexposed linear sRGB of A · XYZ ``(N, 3)`` for unit ``light`` and ``view`` directions ``(N, 3)`` in the
    tangent frame (0 where either is below the surface)."""
    import numpy as np

    from gratnet.brdf import a_term
    from gratnet.modelfile import evaluate_keys
    from viewer.srgb import linear_srgb

    key = -(light + view)
    lit = (light[:, 2] > 0.0) & (view[:, 2] > 0.0)
    colour = np.zeros((len(view), 3))
    if np.any(lit):
        xyz = evaluate_keys(model, key[lit, 0], key[lit, 1], key[lit, 2])
        colour[lit] = linear_srgb(xyz) * a_term(light[lit], view[lit], ior)[:, None]
    return colour


def quick_view(model: Any, mesh: Any, slice_mode: bool = False, fov_degrees: float = FOV_DEGREES,
               ior: float | None = 1.5) -> dict[str, float] | None:
    """The instant first guess at the default view of ``model`` (a ``ModelFile``) on ``mesh`` (a ``Mesh``; not
    read in slice mode), from the display analysis the model file stores; ``None`` when it stores none (then
    only the exact defaults will do). See the module docstring."""
    import numpy as np

    from gratnet.brdf import direction, slice_view_directions
    from gratnet.showcase import DISPLAY_KEY, MaterialDisplay
    from viewer.camera import Camera
    from viewer.defaults import (
        AIM_FRACTIONS,
        CAMERA_AZIMUTH_DEGREES,
        CAMERA_ELEVATIONS_DEGREES,
        FALLBACK,
        SCORE_TIE,
        SLICE_LIGHT_DEGREES,
        aim_light,
        display_score,
        framing_distance,
        light_angles,
        predicted_exposure,
        significant,
        surface_samples,
    )

    metadata = model.metadata if isinstance(model.metadata, dict) else {}
    display = MaterialDisplay.from_json(metadata.get(DISPLAY_KEY))
    if display is None:
        return None
    u, v = display.peak_keys_uv[0]
    if slice_mode:  # viewer.defaults.slice_defaults on a coarser grid of view directions
        phi = FALLBACK.light_phi_degrees
        if math.hypot(u, v) > 1e-9:  # the light opposite the brightest peak: the peak near the slice's centre
            phi = round(math.degrees(math.atan2(-v, -u)), 1) + 0.0
        views, inside = slice_view_directions(24)
        views = views[inside]
        light = np.broadcast_to(direction(SLICE_LIGHT_DEGREES, phi), views.shape)
        colour = _colour(model, light, views, ior)
        exposure = predicted_exposure(colour.max(axis=1).clip(0.0), np.ones(len(views)), display.exposure)
        return {"light_theta": SLICE_LIGHT_DEGREES, "light_phi": phi, "camera_distance": FALLBACK.camera_distance,
                "camera_azimuth": FALLBACK.camera_azimuth_degrees,
                "camera_elevation": FALLBACK.camera_elevation_degrees, "exposure": significant(exposure)}
    samples = surface_samples(mesh, QUICK_SAMPLES)
    distance = round(framing_distance(mesh, fov_degrees), 3)
    positions = samples["positions"]
    frames = np.stack([samples["tangents"], samples["bitangents"], samples["normals"]], axis=1)  # (N, 3 axes, 3)
    best: tuple[float, dict[str, float]] | None = None
    for elevation in CAMERA_ELEVATIONS_DEGREES:  # the brightest peak only (viewer.defaults tries four)
        camera = Camera(distance, CAMERA_AZIMUTH_DEGREES, elevation, fov_deg=fov_degrees)
        clip = np.concatenate([positions, np.ones((len(positions), 1))], axis=1) @ camera.view_projection(1.0)
        with np.errstate(divide="ignore", invalid="ignore"):
            ndc = clip[:, :2] / clip[:, 3:4]
        to_eye = camera.eye()[None, :] - positions
        distances = np.linalg.norm(to_eye, axis=1)
        view = np.einsum("nij,nj->ni", frames, to_eye / np.maximum(distances, 1e-30)[:, None])
        visible = (view[:, 2] > 0.0) & (clip[:, 3] > 0.0) & np.all(np.abs(ndc) <= 1.0, axis=1)
        if not np.any(visible):
            continue
        centre = int(np.flatnonzero(visible)[np.argmin(np.sum(np.square(ndc[visible]), axis=1))])
        weights = view[visible, 2] * samples["area"][visible] / np.square(distances[visible])
        for fraction in AIM_FRACTIONS:
            world = aim_light((fraction * u, fraction * v), view[centre], samples, centre)
            if world is None:
                continue
            colour = _colour(model, np.einsum("nij,j->ni", frames[visible], world), view[visible], ior)
            exposure = predicted_exposure(colour.max(axis=1).clip(0.0), weights, display.exposure)
            score = display_score(colour, weights, exposure)  # solid angles shown coloured (same field for all)
            if best is None or score > best[0] + SCORE_TIE:
                theta, phi = light_angles(world)
                best = (score, {"light_theta": theta, "light_phi": phi, "camera_distance": distance,
                                "camera_azimuth": CAMERA_AZIMUTH_DEGREES, "camera_elevation": elevation,
                                "exposure": significant(exposure)})
    if best is not None:
        return best[1]
    return {"light_theta": FALLBACK.light_theta_degrees, "light_phi": FALLBACK.light_phi_degrees,
            "camera_distance": distance, "camera_azimuth": CAMERA_AZIMUTH_DEGREES,
            "camera_elevation": FALLBACK.camera_elevation_degrees, "exposure": significant(display.exposure)}


def _quick_view_of(material: str, mesh: str, slice_mode: bool, fov_degrees: float,
                   ior: float | None) -> dict[str, float] | None:
    """:func:`quick_view` by names (the model file and the mesh read here; the quick worker's task)."""
    from gratnet.modelfile import load_model
    from viewer.catalog import build_mesh, resolve_material

    model = load_model(resolve_material(material))
    return quick_view(model, None if slice_mode else build_mesh(mesh), slice_mode, fov_degrees, ior)


def _warm_imports(niceness: int, exact: bool) -> None:
    """A worker's initializer: its niceness, and the imports of its tasks ahead of a request (colour-science for
    the exact defaults; the quick guess needs none)."""
    if niceness > 0:
        os.nice(niceness)
    import gratnet.modelfile  # noqa: F401
    import viewer.catalog  # noqa: F401
    import viewer.defaults  # noqa: F401

    if exact:
        import numpy as np

        import gratnet.display

        gratnet.display.xyz_to_linear_srgb(np.zeros((1, 3)))  # colour-science's import


def _pool(niceness: int, exact: bool) -> Any:
    """A one-process pool, spawned (a forked copy of a process holding a GL context and threads is not safe), at
    ``niceness``, its imports done ahead (:func:`_warm_imports`)."""
    import multiprocessing

    return multiprocessing.get_context("spawn").Pool(1, initializer=_warm_imports, initargs=(niceness, exact))


class DefaultViewRequests:
    """The viewer's default view for its material, mesh and mode: remembered, guessed, then exact (see the
    module docstring).

    With ``background`` the exact defaults come from one worker process (spawned, at
    :data:`DEFAULTS_WORKER_NICENESS`) and the quick guess from another (at :data:`QUICK_WORKER_NICENESS`),
    both started by :meth:`start` or the first request with their imports done ahead; without, the exact
    defaults are computed in :meth:`request` itself. :meth:`take` hands over whatever has arrived (the best
    of it), once each. Processes, not threads: on a thread the exact defaults' numpy held the GIL long enough to
    stretch the window's frames to 0.3 s, and the quick guess of a feature-grid model (paper-scratches: 1.4 s
    of numpy on a busy machine) stretched one to 1.27 s (benchmarks/viewer_latency.py).
    """

    def __init__(self, background: bool) -> None:
        self._background = background
        self._pool: Any = None  # multiprocessing.pool.Pool of the exact defaults, made by start()
        self._quick_pool: Any = None  # … of the quick guesses
        self._key: tuple[Any, ...] | None = None  # the pair asked for
        self._fields: tuple[str, ...] = VIEW_FIELDS  # the fields the request may set
        self._view: tuple[float, ...] | None = None  # the view the last hand-over left (the user's since)
        self._quick: Any = None  # AsyncResult or result of the quick guess
        self._exact: Any = None  # AsyncResult or result of the exact defaults
        self._held_since: float | None = None  # time.monotonic() when a picture was first held for the guess

    @staticmethod
    def _state_key(state: Any) -> tuple[Any, ...]:
        return state.material, state.mesh, state.slice_mode, state.fov, state.effective_ior

    @staticmethod
    def _state_view(state: Any) -> tuple[float, ...]:
        return tuple(getattr(state, name) for name in VIEW_FIELDS)

    def start(self) -> None:
        """Start the worker process and its imports now (background mode), so that a later request only computes."""
        if not self._background:
            return
        if self._quick_pool is None:
            self._quick_pool = _pool(QUICK_WORKER_NICENESS, exact=False)
        if self._pool is None:
            self._pool = _pool(DEFAULTS_WORKER_NICENESS, exact=True)

    def request(self, state: Any, fields: Iterable[str] = VIEW_FIELDS) -> None:
        """Ask for the default view of ``state``'s material, mesh and mode (replaces an earlier request); only
        ``fields`` (:data:`VIEW_FIELDS` names) are handed over (``gratnet view`` keeps the flags it was given)."""
        key = self._state_key(state)
        self._key, self._fields, self._view = key, tuple(name for name in VIEW_FIELDS if name in set(fields)), \
            self._state_view(state)
        self._quick = self._exact = None
        self._held_since = None
        remembered = remembered_view(*key)
        if remembered is not None:
            self._exact = remembered
            return
        if not self._background:
            try:
                self._exact = state_defaults(*key)
            except GratNetError:
                self._exact = None
            return
        for name in ("_quick_pool", "_pool"):  # a computation of an earlier request still running: stopped
            if self._running(self._quick if name == "_quick_pool" else self._exact):
                getattr(self, name).terminate()
                setattr(self, name, None)
        self.start()
        self._quick = self._quick_pool.apply_async(_quick_view_of, key)
        self._exact = self._pool.apply_async(state_defaults, key)

    @staticmethod
    def _running(entry: Any) -> bool:
        return hasattr(entry, "ready") and not entry.ready()

    @property
    def pending(self) -> bool:
        """Whether a result of the last request is still to come or to be taken (the caller polls :meth:`take`)."""
        return self._key is not None and (self._quick is not None or self._exact is not None)

    @property
    def stage(self) -> str:
        """``guessing`` (nothing handed over yet), ``refining`` (the quick guess is on show, the exact defaults
        still being worked out) or an empty string (nothing pending)."""
        if not self.pending:
            return ""
        return "guessing" if self._quick is not None else "refining"

    @staticmethod
    def _result(entry: Any) -> Any:
        """A finished computation's result (None on any failure), a plain result as it is, None while running."""
        if not hasattr(entry, "ready"):
            return entry
        if not entry.ready():
            return None
        try:
            return entry.get(0)
        except Exception:  # noqa: BLE001 - any failure (also a lost worker) only means no default view
            return None  # the viewer reports an unusable material or mesh itself

    def hold(self) -> bool:
        """Whether the caller, about to render a new picture, should hold it back: the quick guess is still on
        its way, for at most :data:`GUESS_WAIT_S` from the first picture held."""
        if self.stage != "guessing":
            return False
        now = time.monotonic()
        if self._held_since is None:
            self._held_since = now
        return now - self._held_since < GUESS_WAIT_S

    def take(self, state: Any) -> dict[str, float] | None:
        """The ``ViewerApp.set(**changes)`` for the last request once something better than what was handed over
        has arrived and the view is still as that hand-over left it, else ``None``; then :meth:`applied`."""
        if self._key is None:
            return None
        if self._state_key(state) != self._key:
            self.forget()  # switched again
            return None
        view = self._state_view(state)
        if view != self._view:  # the user moved the light, the camera or the exposure: their choice wins there
            moved = {name for name, now, before in zip(VIEW_FIELDS, view, self._view or view, strict=True)
                     if now != before}
            self._fields = tuple(name for name in self._fields
                                 if not any(other in moved for other in _GROUP_OF[name]))
            self._view = view
            if not self._fields:
                self.forget()
                return None
        if self._exact is not None and not self._running(self._exact):
            exact = self._result(self._exact)
            self.forget()  # the last hand-over of this request
            return None if exact is None else {name: exact[name] for name in self._fields}
        if self._quick is not None and not self._running(self._quick):
            quick, self._quick = self._result(self._quick), None
            if quick is not None:
                return {name: quick[name] for name in self._fields}
        if self._exact is None and self._quick is None:
            self.forget()  # nothing more will come
        return None

    def applied(self, state: Any) -> None:
        """The view after the caller applied :meth:`take`'s changes (clamped to the sliders): later results are
        handed over only while the view stays so."""
        if self._key is not None:
            self._view = self._state_view(state)

    def forget(self) -> None:
        """Drop the request (its results, when they come, are not handed over)."""
        self._key = None
        self._quick = self._exact = None

    def release(self) -> None:
        """Stop the worker processes at once (a computation under way is dropped)."""
        for pool in (self._pool, self._quick_pool):
            if pool is not None:
                pool.terminate()  # at once: closing the window must not wait for a computation under way
        self._pool = self._quick_pool = None
        self.forget()
