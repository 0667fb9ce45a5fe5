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
recorded per phase: ``max_frame_s``, ``frame_work_summary_s``, ``frames_over_150ms``. With ``--inject`` a child
process moves the real X pointer through XTest (libXtst) in a left-button drag over the picture every
``--inject-interval-s`` (±50 % jitter), and each motion's latency is reported (``input_latency_s``, with its
summary overall and per phase): from the motion's time stamp (taken just before it is sent) to the swap of the
first frame whose *picture* reflects it (:func:`analysis.input_latency.match_inputs`: the pointer column each
frame's drag saw says which motions it consumed; the state of the picture on show says which frame's input it
reflects). A motion consumed while the picture could not follow (a shader or a mesh not ready) waits for the
picture that does. ``--default-view`` starts at the material's default view on the mesh (what ``gratnet view``
shows). The load average at the start and the end is in the report: on a shared 2-core machine it decides the
numbers.

``--environment SPEC`` (issue 43) opens the viewer under that environment light (``gratnet view --environment``:
the light off, the exposure from the first picture under it) and adds a phase, "environment", between the launch
and the interaction: frames until the picture on show is rendered with the environment
(``environment_picture_s``, from ``--launched-at``; before it the scene shows without the environment while the
compile child warms the variant and builds the importance table). ``environment_samples_at_end``: the passes the
still view had accumulated when the session ended.

The X screen must hold the window (``-screen 0 WxHx24``; ``xvfb-run``'s default screen is 640×480 at 8 bits):
the drag stays inside the picture and the screen. Examples (an empty shader cache: the first compile, as a
new user sees it):

    MESA_SHADER_CACHE_DIR=$(mktemp -d) xvfb-run -s "-screen 0 1024x768x24" \\
        python benchmarks/viewer_latency.py --material blazed --mesh plane --switch-to cd --inject
    xvfb-run -a -s "-screen 0 1280x1024x24" python benchmarks/viewer_latency.py --material paper-cd --mesh cd \\
        --size 512,512 --default-view --switch-to cd --inject
    MESA_SHADER_CACHE_DIR=$(mktemp -d) XDG_CACHE_HOME=$(mktemp -d) xvfb-run -a -s "-screen 0 1280x1024x24" \
        python benchmarks/viewer_latency.py --material paper-cd --mesh cd --size 512,512 --default-view \
        --environment sky --switch-to paper-cd --inject
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
from collections.abc import Sequence  # noqa: E402
from typing import Any  # noqa: E402

from analysis.input_latency import FrameRecord, match_inputs  # noqa: E402


def _injector(x0: int, y0: int, span: int, interval: float, seed: int) -> int:
    """Child mode: press the left button at (x0, y0) (screen pixels), then move by 2 pixels every
    ~``interval`` seconds, right until ``x0 + span``, then left back to ``x0``, and so on (the caller keeps
    that range inside the picture and the screen); after every 20th motion a pause of 0.5 s, the button held
    (a hand that stops; the turns fall in these pauses, so no frame sees a motion and its reverse). Prints
    ``TIME X`` for each motion, TIME taken just before the motion is sent (``time.perf_counter()``, the
    parent's clock) and X the pointer's new screen column; releases the button on stdin EOF."""
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
    steps = max(1, span // 2)
    moved = offset = 0
    while True:
        pause = 0.5 if moved and moved % 20 == 0 else 0.0
        ready, _, _ = select.select([sys.stdin], [], [], pause + interval * rng.uniform(0.5, 1.5))
        if ready and not sys.stdin.readline():
            break
        offset += 2 if (moved // steps) % 2 == 0 else -2
        moved += 1
        stamp = time.perf_counter()  # before the event exists: no frame can have seen it earlier
        xtst.XTestFakeMotionEvent(display, -1, x0 + offset, y0, 0)
        x11.XFlush(display)
        print(f"{stamp:.6f} {x0 + offset}", flush=True)
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
        self.records: list[FrameRecord] = []
        self.injected: list[tuple[float, float]] = []  # (time stamp, screen column) per motion
        self.injector: subprocess.Popen[str] | None = None
        self._pending = ""
        self._pointer_x: float | None = None  # the pointer's screen column at the frame's last drag
        #: render key → the index of the frame whose input (or switch) made that state (the latest one).
        self._state_frame: dict[tuple[Any, ...], int] = {}
        self.baked_at: float | None = None  # when the baked program first rendered the state on show
        self.view_exact_at: float | None = None  # when no default view was pending any more (after a start)
        original = self.app.orbit

        def orbit(dx: float, dy: float, *args: Any, **kwargs: Any) -> bool:
            changed = original(dx, dy, *args, **kwargs)
            import glfw
            from imgui_bundle import imgui

            window_x, _ = glfw.get_window_pos(self.window.handle)
            self._pointer_x = window_x + float(imgui.get_io().mouse_pos.x)
            self._state_frame[self.app.render_key()] = len(self.records)
            return changed

        self.app.orbit = orbit  # records where the pointer was (the work itself is unchanged)

    def frame(self) -> None:
        window, app = self.window, self.app
        self._pointer_x = None
        window.frame()
        swapped = time.perf_counter()
        index = len(self.records)
        self._state_frame.setdefault(app.render_key(), index)  # a state made without a drag (a switch)
        shown = None if app.image is None else self._state_frame.get(app.image.key)
        self.records.append(FrameRecord(swapped, self._pointer_x, shown))
        self.frames.append({"phase": self.phase, "work_s": app.stats.last_frame_s, "swapped": swapped,
                            "renders": app.stats.renders, "kind": app.stats.last_kind,
                            "render_s": app.stats.last_render_s})
        self._read_injector()
        if self.baked_at is None and app.weights_path_in_use() == "baked":
            self.baked_at = swapped
        if self.view_exact_at is None and not app.default_view_stage:
            self.view_exact_at = swapped

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
        screen_width = _screen_width()
        x0 = x + ax + aw // 4
        span = max(2, min(200, x + ax + aw - 4 - x0, (screen_width or 1 << 30) - 4 - x0))
        command = [sys.executable, __file__, "--injector", str(x0), str(y + ay + ah // 2), str(span), str(interval)]
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

    def matched(self) -> dict[str, Any]:
        """:func:`match_inputs` over the session."""
        return match_inputs(self.injected, self.records)


def _screen_width() -> int | None:
    """The X screen's width in pixels (None: unknown)."""
    try:
        x11 = ctypes.CDLL("libX11.so.6")
    except OSError:
        return None
    x11.XOpenDisplay.restype = ctypes.c_void_p
    x11.XOpenDisplay.argtypes = [ctypes.c_char_p]
    x11.XDefaultScreen.argtypes = [ctypes.c_void_p]
    x11.XDisplayWidth.argtypes = [ctypes.c_void_p, ctypes.c_int]
    x11.XCloseDisplay.argtypes = [ctypes.c_void_p]
    display = x11.XOpenDisplay(None)
    if not display:
        return None
    try:
        return int(x11.XDisplayWidth(display, x11.XDefaultScreen(display)))
    finally:
        x11.XCloseDisplay(display)


def _summary(values: Sequence[float]) -> dict[str, float | int | None]:
    """Count, median, 90th percentile and maximum (seconds, rounded)."""
    if not values:
        return {"count": 0, "median": None, "p90": None, "max": None}
    ordered = sorted(values)

    def at(fraction: float) -> float:
        return round(ordered[min(len(ordered) - 1, int(fraction * len(ordered)))], 4)

    return {"count": len(ordered), "median": at(0.5), "p90": at(0.9), "max": round(ordered[-1], 4)}


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if argv and argv[0] == "--injector":
        return _injector(int(argv[1]), int(argv[2]), int(argv[3]), float(argv[4]), seed=1)
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
    parser.add_argument("--environment", default=None, metavar="SPEC",
                        help="open the viewer under this environment light (gratnet view --environment)")
    parser.add_argument("--default-view", action="store_true",
                        help="open the window as gratnet view does, at the material's default view on the mesh "
                        "(default: the fixed view of issue 11's measurements: camera 0.15 m, light 30°)")
    arguments = parser.parse_args(argv)

    from viewer.state import ViewerState
    from viewer.window import ViewerWindow

    width, height = (int(v) for v in arguments.size.split(","))
    report: dict[str, Any] = {"material": arguments.material, "mesh": arguments.mesh, "size": [width, height],
                              "default_view": arguments.default_view, "environment": arguments.environment,
                              "shader_cache": os.environ.get("MESA_SHADER_CACHE_DIR", "default"),
                              "load_average_at_start": [round(value, 2) for value in os.getloadavg()]}
    constructed = time.perf_counter()
    if arguments.default_view:  # what `gratnet view --material M --mesh MESH --size W,H` opens
        from gratnet.cli import build_parser
        from viewer.view_cli import open_window

        lighting = [] if arguments.environment is None else ["--environment", arguments.environment]
        command = build_parser(only="view").parse_args(
            ["view", "--material", arguments.material, "--mesh", arguments.mesh, "--size", arguments.size, *lighting])
        window = open_window(command, background=arguments.background)
    else:
        state = ViewerState(material=arguments.material, mesh=arguments.mesh, camera_distance=0.15, light_theta=30.0)
        if arguments.environment is not None:  # as gratnet view --environment: the light off, the exposure found
            state = ViewerState(material=arguments.material, mesh=arguments.mesh, camera_distance=0.15,
                                light_theta=30.0, light_intensity=0.0, environment=arguments.environment)
        window = ViewerWindow(state, (width, height), background=arguments.background,
                              auto_exposure=arguments.environment is not None)
    report["window_open_s"] = time.perf_counter() - constructed  # the constructor (blocks only when not background)
    report["window_shown_s"] = time.perf_counter() - arguments.launched_at  # the panel is on screen from here
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

        if arguments.environment is not None:
            session.phase = "environment"
            took = session.run_until(lambda: app.environment_live() and app.image is not None
                                     and app.image.key == app.render_key(), arguments.timeout_s)
            report["environment_picture_s"] = None if took is None else time.perf_counter() - arguments.launched_at
            report["environment_exposure"] = app.state.exposure

        session.phase = "interact"
        session.run_until(lambda: False, arguments.interact_s)
        exact = session.view_exact_at
        report["start_view_exact_s"] = None if exact is None else exact - arguments.launched_at

        session.phase = "material switch"
        switched = time.perf_counter()
        app.switch(material=arguments.switch_to)

        def on_show(stages: tuple[str, ...]) -> bool:  # the new material's picture, at a view of these stages
            image = app.image
            return (image is not None and image.key[0] == arguments.switch_to and image.key == app.render_key()
                    and app.default_view_stage in stages)

        report["switch_picture_s"] = session.run_until(
            lambda: app.image is not None and app.image.key[0] == arguments.switch_to, arguments.timeout_s)
        # A picture of the new material at a view handed over (a quick guess or the exact defaults), then at the
        # exact defaults (None: not within the time limit, or the drag kept the whole view).
        for name, stages in (("switch_usable_view_s", ("refining", "")), ("switch_exact_view_s", ("",))):
            took = session.run_until(lambda stages=stages: on_show(stages), arguments.timeout_s)
            report[name] = None if took is None else time.perf_counter() - switched
        report["switch_view_after"] = {name: getattr(app.state, name) for name in
                                       ("light_theta", "light_phi", "camera_distance", "camera_elevation", "exposure")}
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
        if arguments.environment is not None:  # the slice shows none: back to the mesh, a few seconds still
            app.switch(slice_mode=False)
            session.phase = "environment still"
            session.run_until(lambda: False, 5.0)
            report["environment_samples_at_end"] = app.samples
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
    matched = session.matched()
    latencies: list[float | None] = matched["latency_s"]
    report["input_events"] = len(latencies)
    report["input_latency_s"] = [None if value is None else round(value, 4) for value in latencies]
    report["input_unanswered"] = latencies.count(None)
    report["input_negative"] = matched["negative"]  # 0 unless the matching is wrong
    report["input_unmatched_drags"] = matched["unmatched_drags"]
    report["input_latency_summary_s"] = _summary([value for value in latencies if value is not None])
    by_phase: dict[str, list[float]] = {}
    for value, frame in zip(latencies, matched["answered_by"], strict=True):
        if value is not None and frame is not None:
            by_phase.setdefault(session.frames[frame]["phase"], []).append(value)
    report["input_latency_by_phase_s"] = {phase: _summary(values) for phase, values in by_phase.items()}
    answered = [value for value in latencies if value is not None]
    report["max_input_latency_s"] = max(answered) if answered else None
    applied = [value for value in matched["applied_s"] if value is not None]
    report["input_applied_summary_s"] = _summary(applied)  # to the frame that applied it, picture or not
    works = [f["work_s"] for f in session.frames]
    report["frame_work_summary_s"] = _summary(works)
    report["frames_over_150ms"] = sum(1 for value in works if value > 0.150)
    report["load_average_at_end"] = [round(value, 2) for value in os.getloadavg()]
    print(json.dumps(report))
    return 0


if __name__ == "__main__":
    sys.exit(main())
