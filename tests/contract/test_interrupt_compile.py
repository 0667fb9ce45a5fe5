"""Ctrl-C within a second even inside a long C call that holds the GIL (issue 36; gratnet/interrupts.py).

A baked network's first compile and first draw on llvmpipe with a cold Mesa cache are single moderngl calls of
10–40 s that hold the GIL: before the supervisor, ``gratnet render`` answered a SIGINT there only when the call
ended (13 s after the signal, measured). Now the supervisor stops the stuck command: exit 130 within
:data:`STOP_WITHIN`, one line, no file, no process left. The supervisor is also checked alone, with a pure
Python call that holds the GIL (``sum(range(…))`` checks no signal), without GL.
"""

from __future__ import annotations

import os
import select
import signal
import subprocess
import sys
import time
import uuid
from pathlib import Path

import pytest

from tests.helpers import REPO

if str(REPO) not in sys.path:  # scripts/ is a folder of the repository, not an installed package
    sys.path.insert(0, str(REPO))

from scripts.fault_injection import TAG_VARIABLE, tagged_processes, visible_lines  # noqa: E402

#: The longest a command may take to stop after SIGINT (seconds; the issue asks for 1 s, this allows for a busy CI).
STOP_WITHIN = 1.5
#: The gratnet command as a process of its own (``main()`` with no arguments: supervised).
COMMAND = "import sys\nfrom gratnet.cli import main\nsys.exit(main())"

#: A stand-in command: supervised, then holds the GIL inside an atomic write (``gil``), or waits in Python and
#: answers Ctrl-C itself (``python``), or waits in Python without a SIGINT handler of its own (``plain``), or
#: has returned 0 and tears down (``done``).
STAND_IN = """\
import sys, time
from gratnet import atomic, interrupts
status = interrupts.supervise("gratnet stand-in")
if status is not None:
    sys.exit(status)
if sys.argv[1] == "gil":
    with atomic.atomic_path("out.bin") as temporary:
        temporary.write_bytes(b"half")
        print("ready", flush=True)
        sum(range(10**12))  # one C call: holds the GIL and checks no signal
elif sys.argv[1] == "released":  # inside C calls that release the GIL and check no signal: other threads run
    import threading
    import numpy as np
    threading.Thread(target=lambda: [time.sleep(0.01) for _ in iter(int, 1)], daemon=True).start()
    matrix = np.random.default_rng(0).random((3000, 3000))
    with atomic.atomic_path("out.bin") as temporary:
        temporary.write_bytes(b"half")
        print("ready", flush=True)
        while True:
            np.linalg.eigvals(matrix)  # one LAPACK call of ~10 s on 2 cores, the GIL released
elif sys.argv[1] == "python":
    try:
        print("ready", flush=True)
        while True:
            time.sleep(0.01)
    except KeyboardInterrupt:
        print("stand-in: interrupted by itself", file=sys.stderr)
        sys.exit(130)
elif sys.argv[1] == "fork":  # a process the command forks is not the command: it tells the supervisor nothing
    import os, signal
    pid = os.fork()
    if pid == 0:
        os._exit(0 if interrupts._channel is None and signal.getsignal(signal.SIGINT) is signal.default_int_handler
                 else 1)
    print("ready", flush=True)
    sys.exit(os.waitstatus_to_exitcode(os.waitpid(pid, 0)[1]))
elif sys.argv[1] == "callback":  # Ctrl-C inside a weakref callback (a garbage collection), then Python code
    import gc, os, signal, weakref
    class Thing:
        pass
    def hit(_reference):
        os.kill(os.getpid(), signal.SIGINT)
        time.sleep(0.05)  # the KeyboardInterrupt is raised here, where it cannot propagate
    thing = Thing()
    reference = weakref.ref(thing, hit)
    try:
        print("ready", flush=True)
        del thing
        gc.collect()
        time.sleep(5)
        print("stand-in: ran on", file=sys.stderr)
    except KeyboardInterrupt:
        print("stand-in: interrupted by itself", file=sys.stderr)
        sys.exit(130)
elif sys.argv[1] == "short":  # a command that ends by itself after a while (0)
    print("ready", flush=True)
    time.sleep(1.5)
elif sys.argv[1] == "done":
    interrupts.done(0)  # the command returned 0; what follows stands for the interpreter's teardown
    print("ready", flush=True)
    time.sleep(1.0)
else:
    print("ready", flush=True)
    time.sleep(60)
"""


def _environment(tag: str, **extra: str) -> dict[str, str]:
    return {**os.environ, TAG_VARIABLE: tag, **extra,
            "PYTHONPATH": os.pathsep.join(filter(None, [str(REPO), os.environ.get("PYTHONPATH")]))}


def _stand_in(folder: Path, mode: str) -> tuple[subprocess.Popen[bytes], str]:
    tag = uuid.uuid4().hex
    process = subprocess.Popen([sys.executable, "-c", STAND_IN, mode], cwd=folder, env=_environment(tag),
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    assert process.stdout is not None
    assert process.stdout.readline() == b"ready\n"
    return process, tag


def _stop(process: subprocess.Popen[bytes], number: int = signal.SIGINT) -> tuple[float, str]:
    """Send ``number``; the seconds until the process ended, and its stderr."""
    sent = time.monotonic()
    process.send_signal(number)
    _, stderr = process.communicate(timeout=60)
    return time.monotonic() - sent, stderr.decode("utf-8", "replace")


def _gone(tag: str, folder: Path, within: float = 2.0) -> dict[int, str]:
    """The command's processes still alive ``within`` seconds from now (none expected)."""
    deadline = time.monotonic() + within
    while (alive := tagged_processes(tag, folder)) and time.monotonic() < deadline:
        time.sleep(0.05)
    return alive


pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="the supervisor is Linux only")


@pytest.mark.parametrize("mode", ["gil", "released"])
def test_a_command_stuck_in_a_long_call_stops_within_a_second(tmp_path: Path, mode: str) -> None:
    """``gil``: a call that holds the GIL (as a cold shader compile does). ``released``: a long numpy/LAPACK call
    releases the GIL, so the command's other threads run, but its SIGINT handler waits for the main thread's call
    to end; the supervisor stops it all the same (it once waited on, fooled by a heartbeat from another thread:
    `gratnet groundtruth` ran on for over 20 s after a SIGINT)."""
    process, tag = _stand_in(tmp_path, mode)
    assert len(os.listdir(tmp_path)) == 1  # the write's temporary
    time.sleep(0.5)
    stopped, stderr = _stop(process)
    print(f"stuck in a long call ({mode}): exit {process.returncode} {stopped:.3f} s after SIGINT")
    assert process.returncode == 130, stderr
    assert stopped < STOP_WITHIN, f"{stopped:.2f} s from SIGINT to exit"
    assert visible_lines(stderr) == ["gratnet stand-in: interrupted; nothing was written"], stderr
    assert os.listdir(tmp_path) == []  # the pending temporary removed by the supervisor
    assert not _gone(tag, tmp_path)


def test_a_command_that_answers_ctrl_c_itself_is_left_to_do_so(tmp_path: Path) -> None:
    process, tag = _stand_in(tmp_path, "python")
    stopped, stderr = _stop(process)
    assert process.returncode == 130 and stopped < STOP_WITHIN
    assert visible_lines(stderr) == ["stand-in: interrupted by itself"], stderr
    assert not _gone(tag, tmp_path)


def test_signals_reach_the_command_and_its_death_is_the_exit_status(tmp_path: Path) -> None:
    """SIGTERM is passed on (the command has no handler: it dies of it, 128 + 15); a kill -9 of the supervisor
    takes the command with it."""
    process, tag = _stand_in(tmp_path, "plain")
    stopped, stderr = _stop(process, signal.SIGTERM)
    assert process.returncode == 128 + signal.SIGTERM and stopped < STOP_WITHIN, stderr
    assert not _gone(tag, tmp_path)
    process, tag = _stand_in(tmp_path, "plain")
    _stop(process, signal.SIGKILL)
    assert not _gone(tag, tmp_path), "the command outlived its supervisor's kill -9"


@pytest.mark.timing  # a wall-clock target: beside a second worker's GL tests it measured 1.9 s, at 1374b1d too
@pytest.mark.parametrize("marker", ["program 'surface' with baked weights", "deferred shading program"],
                         ids=["surface-program", "deferred-program"])
def test_ctrl_c_during_a_cold_shader_compile_stops_within_a_second(tmp_path: Path, marker: str) -> None:
    """``gratnet render --material cd`` (a baked 28k-MAC network) with an empty Mesa shader cache: SIGINT 1.5 s
    after the render says it compiles the program named by ``marker`` (a 10–25 s call on llvmpipe)."""
    work, cache = tmp_path / "work", tmp_path / "mesa-cache"
    work.mkdir()
    tag = uuid.uuid4().hex
    process = subprocess.Popen([sys.executable, "-c", COMMAND, "render", "--material", "cd", "--mesh", "sphere",
                                "--size", "160,120", "--render-path", "auto", "--out", "x.png"], cwd=work,
                               env=_environment(tag, MESA_SHADER_CACHE_DIR=str(cache)), stdout=subprocess.PIPE,
                               stderr=subprocess.PIPE)
    assert process.stderr is not None
    before = b""
    try:
        deadline = time.monotonic() + 180.0
        while marker.encode() not in before and process.poll() is None and time.monotonic() < deadline:
            if select.select([process.stderr], [], [], 1.0)[0]:
                before += os.read(process.stderr.fileno(), 65536)
        if marker.encode() not in before:
            process.kill()
            process.communicate()
            pytest.skip(f"the render never compiled {marker!r} here (a GPU, a path without it, or no GL): "
                        f"{before.decode(errors='replace').strip()[-200:]!r}")
        time.sleep(1.5)
        assert process.poll() is None, "the compile ended within 1.5 s: nothing to measure"
        stopped, after = _stop(process)
    finally:
        if process.poll() is None:
            process.kill()
            process.communicate()
    print(f"cold compile ({marker}): exit {process.returncode} {stopped:.3f} s after SIGINT")
    assert process.returncode == 130, after
    assert stopped < STOP_WITHIN, f"{stopped:.2f} s from SIGINT to exit"
    assert visible_lines(after) == ["gratnet render: interrupted; nothing was written"], after
    assert os.listdir(work) == []
    assert not _gone(tag, work)


def test_ctrl_c_after_the_command_returned_changes_nothing(tmp_path: Path) -> None:
    """A SIGINT in the interpreter's teardown (the work done, its status known): no line, the command's status."""
    process, tag = _stand_in(tmp_path, "done")
    _, stderr = _stop(process)
    assert process.returncode == 0 and visible_lines(stderr) == [], stderr
    assert not _gone(tag, tmp_path)


def test_a_process_the_command_forks_sends_the_supervisor_nothing(tmp_path: Path) -> None:
    process, _ = _stand_in(tmp_path, "fork")
    _, stderr = process.communicate(timeout=60)
    assert process.returncode == 0, stderr


def test_ctrl_c_inside_a_garbage_collection_callback_is_not_lost(tmp_path: Path) -> None:
    """Python cannot raise a KeyboardInterrupt out of a weakref callback: it printed a traceback ("Exception
    ignored") and the command went on (gratnet train ran its report to the end and exited 0). It is raised
    again where the command answers it."""
    process, tag = _stand_in(tmp_path, "callback")
    stderr = process.communicate(timeout=60)[1].decode("utf-8", "replace")
    assert process.returncode == 130, stderr
    assert visible_lines(stderr) == ["stand-in: interrupted by itself"], stderr
    assert not _gone(tag, tmp_path)


def test_a_stopped_and_continued_supervisor_keeps_its_command(tmp_path):
    """kill -STOP and -CONT of the supervisor (a shell's Ctrl-Z and fg, a pause of a long training) leave the
    command running to its own end: CPython's sigtimedwait can return a garbage record after SIGCONT, which the
    supervisor passed on as a signal and died of (EINVAL), taking the training with it (seen 2026-11-27)."""
    process, tag = _stand_in(tmp_path, "short")
    for _ in range(3):
        process.send_signal(signal.SIGSTOP)
        time.sleep(0.2)
        process.send_signal(signal.SIGCONT)
        time.sleep(0.1)
    _, stderr = process.communicate(timeout=60)
    assert process.returncode == 0, stderr.decode("utf-8", "replace")
    assert not visible_lines(stderr.decode("utf-8", "replace"))
    assert not _gone(tag, tmp_path)
