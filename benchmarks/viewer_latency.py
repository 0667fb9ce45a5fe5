"""How long the viewer window takes to show a first picture, and how long each of its frames blocks input.

Drives the real window (``viewer.window.ViewerWindow``, needs an X display, e.g. Xvfb) through a scripted
session and prints one JSON object:

1. launch with ``--material`` on ``--mesh``; ``first_picture_s``: seconds from ``--launched-at`` (the
   caller's ``time.perf_counter()`` just before it started this process; default: this script's start)
   to the swap of the first frame that shows a picture;
2. ``--interact-s`` seconds of frames while the background compile runs;
3. a material switch to ``--switch-to`` (as the panel's combo does: ``app.switch``, which also brings that
   material's default view), frames until its picture is on show and, with ``--takeover``, until the
   faster (baked) path renders it;
4. a switch to the BRDF slice, frames until the slice is on show.

Every frame's work (``stats.last_frame_s``: from the end of the wait for input to the buffer swap) is
recorded per phase: ``max_frame_s``. With ``--inject`` a child process moves the real X pointer through
XTest (libXtst) in a left-button drag over the picture every ``--inject-interval-s`` (±50 % jitter), and
each motion's latency (its time stamp to the swap of the frame that applied it) is reported:
``input_latency_s``. Example (an empty shader cache: the first compile, as a new user sees it):

    MESA_SHADER_CACHE_DIR=$(mktemp -d) xvfb-run -s "-screen 0 1024x768x24" \\
        python benchmarks/viewer_latency.py --material blazed --mesh plane --switch-to cd --inject
"""

from __future__ import annotations

import time

_STARTED = time.perf_counter()

import argparse  # noqa: E402 - the start time is taken before the imports
import ctypes  # noqa: E402
import json  # noqa: E402
import os  # noqa: E402
import random  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
from pathlib import Path  # noqa: E402
from typing import Any  # noqa: E402


def _injector(x0: int, y0: int, interval: float, seed: int) -> int:
    """Child mode: press the left button at (x0, y0) (screen pixels), then move by 2 pixels every
    ~``interval`` seconds, right for 100 motions, then left for 100, and so on (the screen has an edge);
    after every 20th motion a pause of 0.5 s, the button held (a hand that stops; the turns fall in these
    pauses, so no frame sees a motion and its reverse). Prints ``TIME TOTAL`` after each motion is
    flushed, TOTAL the pixels moved so far; releases the button on stdin EOF."""
    import select

    x11 = ctypes.CDLL("libX11.so.6")
    xtst = ctypes.CDLL("libXtst.so.6")
    x11.XOpenDisplay.restype = ctypes.c_void_p
    x11.XOpenDisplay.argtypes = [ctypes.c_char_p]
    x11.XFlush.argtypes = [ctypes.c_void_p]
    x11.XCloseDisplay.argtypes = [ctypes.c_void_p]
    xtst.XTestFakeMotionEvent.argtypes = [ctypes.c_void_p, ctypes.c_int, ctypes.c_int, ctypes.c_int, ctypes.c_ulong]
    xtst.XTestFakeButtonEvent.argtypes = [ctypes.c_void_p, ctypes.c_uint, ctypes.c_int, ctypes.c_ulong]
    display = x11.XOpenDisplay(None)
    if not display:
        print("injector: cannot open the display", file=sys.stderr)
        return 2
    rng = random.Random(seed)
    xtst.XTestFakeMotionEvent(display, -1, x0, y0, 0)
    x11.XFlush(display)
    time.sleep(0.2)
    xtst.XTestFakeButtonEvent(display, 1, 1, 0)
    x11.XFlush(display)
    print("pressed", flush=True)
    moved = offset = 0
    while True:
        pause = 0.5 if moved and moved % 40 == 0 else 0.0
        ready, _, _ = select.select([sys.stdin], [], [], pause + interval * rng.uniform(0.5, 1.5))
        if ready and not sys.stdin.readline():
            break
        offset += 2 if (moved // 200) % 2 == 0 else -2
        moved += 2
        xtst.XTestFakeMotionEvent(display, -1, x0 + offset, y0, 0)
        x11.XFlush(display)
        print(f"{time.perf_counter():.6f} {moved}", flush=True)
    xtst.XTestFakeButtonEvent(display, 1, 0, 0)
    x11.XFlush(display)
    x11.XCloseDisplay(display)
    return 0


class Session:
    """The window, its per-frame records and the injector's reports."""

    def __init__(self, window: Any, launched_at: float) -> None:
        self.window = window
        self.app = window.app
        self.launched_at = launched_at
        self.phase = "launch"
        self.frames: list[dict[str, Any]] = []
        self.orbit_dx = 0.0  # pixels of drag the app has applied (|dx| summed: the drag turns)
        self.injected: list[tuple[float, float]] = []  # (time, total dx) per motion
        self.injector: subprocess.Popen[str] | None = None
        self._pending = ""
        self.baked_at: float | None = None  # when the baked program first rendered the state on show
        original = self.app.orbit

        def orbit(dx: float, dy: float, *args: Any, **kwargs: Any) -> bool:
            self.orbit_dx += abs(dx)
            return original(dx, dy, *args, **kwargs)

        self.app.orbit = orbit  # counts the drag the app receives (the work itself is unchanged)

    def frame(self) -> None:
        window = self.window
        window.frame()
        swapped = time.perf_counter()
        self.frames.append({"phase": self.phase, "work_s": self.app.stats.last_frame_s, "swapped": swapped,
                            "orbit_dx": self.orbit_dx, "renders": self.app.stats.renders,
                            "kind": self.app.stats.last_kind, "render_s": self.app.stats.last_render_s})
        self._read_injector()
        if self.baked_at is None and self.app.weights_path_in_use() == "baked":
            self.baked_at = swapped

    def run_until(self, condition: Any, timeout: float) -> float | None:
        """Frames until ``condition()``; the seconds it took (None: timed out)."""
        started = time.perf_counter()
        while time.perf_counter() - started < timeout:
            self.frame()
            if condition():
                return time.perf_counter() - started
        return None

    def start_injector(self, interval: float) -> None:
        window = self.window
        import glfw

        x, y = glfw.get_window_pos(window.handle)
        ax, ay, aw, ah = window.render_area()
        command = [sys.executable, __file__, "--injector", str(x + ax + aw // 4), str(y + ay + ah // 2),
                   str(interval)]
        self.injector = subprocess.Popen(command, stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
        assert self.injector.stdout is not None
        os.set_blocking(self.injector.stdout.fileno(), False)

    def _read_injector(self) -> None:
        if self.injector is None or self.injector.stdout is None:
            return
        try:
            chunk = self.injector.stdout.read()
        except (BlockingIOError, TypeError):
            chunk = None
        if chunk:
            self._pending += chunk
        *lines, self._pending = self._pending.split("\n")
        for line in lines:
            words = line.split()
            if len(words) == 2:
                self.injected.append((float(words[0]), float(words[1])))

    def stop_injector(self) -> None:
        if self.injector is not None:
            assert self.injector.stdin is not None
            self.injector.stdin.close()
            self.injector.wait(timeout=10)
            self._read_injector()

    def latencies(self) -> list[float | None]:
        """Per injected motion: seconds from its time stamp to the swap of the first frame whose state
        includes it (None: never applied)."""
        result: list[float | None] = []
        for stamp, total in self.injected:
            answered = next((f["swapped"] for f in self.frames if f["orbit_dx"] >= total - 1e-6), None)
            result.append(None if answered is None else answered - stamp)
        return result


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if argv and argv[0] == "--injector":
        return _injector(int(argv[1]), int(argv[2]), float(argv[3]), seed=1)
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--material", default="blazed")
    parser.add_argument("--mesh", default="plane")
    parser.add_argument("--size", default="160,120", help="render area W,H (pixels)")
    parser.add_argument("--switch-to", default="cd", help="the material switched to in phase 3")
    parser.add_argument("--takeover", action="store_true", help="phase 3 waits until the baked path renders")
    parser.add_argument("--interact-s", type=float, default=4.0)
    parser.add_argument("--inject", action="store_true", help="drag with real X pointer events (XTest)")
    parser.add_argument("--inject-interval-s", type=float, default=0.15)
    parser.add_argument("--timeout-s", type=float, default=120.0, help="limit of each phase")
    parser.add_argument("--launched-at", type=float, default=_STARTED)
    parser.add_argument("--background", action=argparse.BooleanOptionalAction, default=True)
    arguments = parser.parse_args(argv)

    from viewer.state import ViewerState
    from viewer.window import ViewerWindow

    width, height = (int(v) for v in arguments.size.split(","))
    state = ViewerState(material=arguments.material, mesh=arguments.mesh, camera_distance=0.15, light_theta=30.0)
    report: dict[str, Any] = {"material": arguments.material, "mesh": arguments.mesh, "size": [width, height],
                              "shader_cache": os.environ.get("MESA_SHADER_CACHE_DIR", "default")}
    constructed = time.perf_counter()
    window = ViewerWindow(state, (width, height), background=arguments.background)
    report["window_open_s"] = time.perf_counter() - constructed  # the constructor (blocks only when not background)
    session = Session(window, arguments.launched_at)
    app = window.app
    try:
        if arguments.inject:
            session.start_injector(arguments.inject_interval_s)
        took = session.run_until(lambda: app.image is not None, arguments.timeout_s)
        first = window.first_picture_at
        report["first_picture_s"] = None if took is None or first is None else first - arguments.launched_at
        report["weights_path_first"] = app.weights_path_in_use()
        worker = app.supply.worker  # the child's own timings, for the report
        report["worker_s"] = {} if worker is None else {" ".join(k): round(v, 3) for k, v in worker.seconds.items()}
        report["worker_started_s"] = None if worker is None else round(worker.started - arguments.launched_at, 3)
        report["worker_ready_at_s"] = {} if worker is None else {
            " ".join(k): round(v - arguments.launched_at, 3) for k, v in worker.ready_at.items()}
        ready_at = app.supply.display_ready_at
        report["display_import_done_s"] = None if ready_at is None else round(ready_at - arguments.launched_at, 3)

        session.phase = "interact"
        session.run_until(lambda: False, arguments.interact_s)

        session.phase = "material switch"
        app.switch(material=arguments.switch_to)
        report["switch_picture_s"] = session.run_until(
            lambda: app.image is not None and app.image.key[0] == arguments.switch_to, arguments.timeout_s)
        if arguments.takeover:
            report["takeover_s"] = session.run_until(lambda: app.weights_path_in_use() == "baked"
                                                     and app.stats.weights_path == "baked", arguments.timeout_s)

        session.phase = "slice switch"
        app.switch(slice_mode=True)
        report["slice_picture_s"] = session.run_until(
            lambda: app.image is not None and app.image.key[11] is True, arguments.timeout_s)
        session.run_until(lambda: False, 1.0)
        session.stop_injector()
        session.run_until(lambda: app.image is not None and app.image.complete, arguments.timeout_s)
        session.run_until(lambda: False, 0.5)
        report["frame_figure_at_rest_s"] = app.stats.last_frame_s  # what the panel shows as "frame"
    finally:
        if session.injector is not None and session.injector.poll() is None:
            session.injector.kill()
        report["gl_errors"] = list(window.gl_errors)
        closing = time.perf_counter()
        window.close()  # the baked compile still runs in the child: closing stops it
        report["close_s"] = time.perf_counter() - closing

    phases: dict[str, Any] = {}
    for record in session.frames:
        entry = phases.setdefault(record["phase"], {"frames": 0, "max_frame_s": 0.0})
        entry["frames"] += 1
        entry["max_frame_s"] = max(entry["max_frame_s"], record["work_s"])
    report["phases"] = phases
    report["baked_takes_over_at_s"] = None if session.baked_at is None else session.baked_at - arguments.launched_at
    report["slowest_frames"] = [  # the five slowest: when (seconds after launch), how long, what ran
        {"at_s": round(f["swapped"] - arguments.launched_at, 3), "work_s": round(f["work_s"], 4), "phase": f["phase"],
         "rendered": f["kind"] if f["renders"] > (session.frames[k - 1]["renders"] if k else 0) else "",
         "render_s": round(f["render_s"], 4)}
        for k, f in sorted(enumerate(session.frames), key=lambda item: -item[1]["work_s"])[:5]]
    report["max_frame_s"] = max(entry["max_frame_s"] for entry in phases.values())
    if os.environ.get("VIEWER_LATENCY_FRAMES"):  # every frame, for a closer look
        report["frames"] = [{"at_s": round(f["swapped"] - arguments.launched_at, 3), "work_s": round(f["work_s"], 4),
                             "kind": f["kind"], "render_s": round(f["render_s"], 4)} for f in session.frames]
    latencies = session.latencies()
    report["input_events"] = len(latencies)
    report["input_latency_s"] = [None if value is None else round(value, 4) for value in latencies]
    answered = [value for value in latencies if value is not None]
    report["max_input_latency_s"] = max(answered) if answered else None
    print(json.dumps(report))
    return 0


if __name__ == "__main__":
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
    sys.exit(main())
