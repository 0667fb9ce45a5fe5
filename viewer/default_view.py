"""The viewer's default view, worked out off the window's thread (the algorithm is viewer.defaults').

When the viewer switches material, mesh or BRDF-slice mode (``ViewerApp.switch``), the new pair's light,
camera and exposure — the values ``gratnet view`` and ``gratnet render`` start with
(:func:`viewer.defaults.resolve_defaults`) — are asked for here: :class:`DefaultViewRequests` computes them
in one worker process beside the scene supply's compile child (:mod:`viewer.scene_supply`), and hands them
over once ready unless the user moved the view first. No GL, no imgui.
"""

from __future__ import annotations

import os
from typing import Any

from gratnet.errors import GratNetError
from viewer.defaults import FOV_DEGREES, resolve_defaults

__all__ = ["DEFAULTS_WORKER_NICENESS", "VIEW_FIELDS", "DefaultViewRequests", "state_defaults"]


def state_defaults(material: str, mesh: str, slice_mode: bool = False, fov_degrees: float = FOV_DEGREES,
                   ior: float | None = 1.5) -> dict[str, float]:
    """The viewer's fields for :func:`resolve_defaults` (``ViewerState`` names), for the viewer to apply when
    the material or the mesh changes: ``ViewerApp.set(**state_defaults(...))``."""
    defaults = resolve_defaults(material, mesh, slice_mode, fov_degrees, ior)
    return {"light_theta": defaults.light_theta_degrees, "light_phi": defaults.light_phi_degrees,
            "camera_distance": defaults.camera_distance, "camera_azimuth": defaults.camera_azimuth_degrees,
            "camera_elevation": defaults.camera_elevation_degrees, "exposure": defaults.exposure}


#: Niceness of the viewer's default-view worker process (os.nice increment).
DEFAULTS_WORKER_NICENESS = 19
#: The viewer fields a default view sets (ViewerState names).
VIEW_FIELDS = ("light_theta", "light_phi", "camera_distance", "camera_azimuth", "camera_elevation", "exposure")


class DefaultViewRequests:
    """The viewer's default view for its material, mesh and mode, worked out off the window's thread.

    :func:`state_defaults` costs about 0.5 s of numpy the first time for a pair (cached after), far over a
    frame's budget; with ``background`` it runs in one worker process (started at the first request) and
    :meth:`take` hands the result over once it is ready. A process, not a thread: on a thread its numpy
    calls held the GIL for long enough to stretch the window's frames to 0.3 s (measured with
    benchmarks/viewer_latency.py). A result is dropped when the user has moved the light, camera or
    exposure, or switched again, since it was asked for: their choice wins.
    """

    def __init__(self, background: bool) -> None:
        self._background = background
        self._executor: Any = None  # concurrent.futures.ProcessPoolExecutor, made at the first request
        self._pending: tuple[Any, tuple[Any, ...], Any] | None = None  # (future or result, asked-for key, view)

    @staticmethod
    def _key(state: Any) -> tuple[Any, ...]:
        return state.material, state.mesh, state.slice_mode, state.fov, state.effective_ior

    @staticmethod
    def _view(state: Any) -> tuple[float, ...]:
        return tuple(getattr(state, name) for name in VIEW_FIELDS)

    def request(self, state: Any) -> None:
        """Ask for the default view of ``state``'s material, mesh and mode (replaces an earlier request)."""
        key = self._key(state)
        if not self._background:
            try:
                result: Any = state_defaults(*key)
            except GratNetError:
                result = None
        else:
            if self._executor is None:
                import multiprocessing
                from concurrent.futures import ProcessPoolExecutor

                # spawn: a forked copy of a process holding a GL context and threads is not safe. Niceness 19:
                # at the window's priority (or at 10) its numpy took enough of 2 busy cores to stretch the
                # window's frames to 0.2–1.1 s (tests/test_viewer.py test_window_never_blocks failed 3 of 4
                # runs beside a low-priority job); at 19 it passed 4 of 4 there, using what the window leaves.
                self._executor = ProcessPoolExecutor(1, mp_context=multiprocessing.get_context("spawn"),
                                                     initializer=os.nice, initargs=(DEFAULTS_WORKER_NICENESS,))
            result = self._executor.submit(state_defaults, *key)
        self._pending = (result, key, self._view(state))

    @property
    def pending(self) -> bool:
        """Whether a request is still being worked out."""
        return self._pending is not None and hasattr(self._pending[0], "done") and not self._pending[0].done()

    def take(self, state: Any) -> dict[str, float] | None:
        """The ``ViewerApp.set(**changes)`` for the last request once it is ready and still wanted, else ``None``."""
        if self._pending is None:
            return None
        result, key, view = self._pending
        if hasattr(result, "done"):
            if not result.done():
                return None
            try:
                result = result.result()
            except Exception:  # noqa: BLE001 - any failure (also a lost worker) only means no default view
                result = None  # the viewer reports an unusable material or mesh itself
        self._pending = None
        if result is None or self._key(state) != key or self._view(state) != view:
            return None
        return result

    def release(self) -> None:
        """Stop the worker process (a computation under way finishes in the background and is dropped)."""
        if self._executor is not None:
            self._executor.shutdown(wait=False, cancel_futures=True)
            self._executor = None
        self._pending = None
