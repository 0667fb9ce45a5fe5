"""A local Ray instance that ends with the sweep that started it, however the sweep ends.

``ray.init()`` starts its processes (GCS server, raylet, dashboard and runtime-env agents, log monitor, then
the workers the raylet starts) as children that the kernel kills when the driver dies (Ray's
``PR_SET_PDEATHSIG``) — but only its direct children: measured with Ray 2.60 on Linux, a sweep killed with
SIGKILL while a volume was computed left the dashboard agent, the runtime-env agent and two starting workers
alive 10 s later, and the agents for good (they notice the raylet is gone, then hang reporting it to the dead
GCS). For SIGKILL (and the OOM killer) this module adds a watchdog, which also ends the instance of a sweep
stopped by Ctrl-C, SIGTERM or SIGHUP: at once, instead of Ray's shutdown of its processes (1–3 s; sweep.runner
only disconnects the driver then):

- before ``ray.init()``, the driver puts a token unique to this sweep in its environment
  (:data:`TOKEN_VARIABLE`); every process Ray starts inherits it, whatever its process group or session
  (and ``SPT_NOENV=1``: without it the processes that Ray retitles, ``ray::DashboardAgent`` or
  ``ray::TASK``, overwrite their ``/proc/PID/environ`` with the title, the token with it);
- a watchdog process (``python -m sweep.watchdog``, in a session of its own so that a signal to the
  terminal's process group does not take it first) blocks reading a pipe whose only writer is the driver.
  The read ends when the driver closes the pipe after ``ray.shutdown()`` (or after only disconnecting, when
  the sweep was stopped) or when the kernel closes it because the driver died; the watchdog then kills
  (SIGKILL) every process that carries the token, until none is left, and exits.

Linux only (processes are found through ``/proc/PID/environ``); elsewhere :func:`start` returns None and the
instance's cleanup is Ray's own. A sweep that joins a cluster (``--address``) starts no watchdog: the
cluster is not the sweep's, and Ray ends a dead driver's tasks itself.
"""

from __future__ import annotations

import contextlib
import os
import signal
import subprocess
import sys
import time
import uuid
from pathlib import Path

__all__ = ["TOKEN_VARIABLE", "Watchdog", "carriers", "kill_carriers", "main", "start"]

#: The environment variable whose value marks the processes of one sweep's local Ray instance.
TOKEN_VARIABLE = "GRATNET_SWEEP_INSTANCE"
#: Seconds the driver waits for the watchdog to finish after a normal end.
WAIT_SECONDS = 15.0
_PROC = Path("/proc")


def carriers(token: str, exclude: set[int] | frozenset[int] = frozenset()) -> list[int]:
    """The PIDs of the live processes whose environment holds ``TOKEN_VARIABLE=token`` (zombies hold none)."""
    needle = f"{TOKEN_VARIABLE}={token}".encode()
    found = []
    for entry in os.scandir(_PROC):
        if not entry.name.isdigit() or int(entry.name) in exclude:
            continue
        try:
            with open(os.path.join(entry.path, "environ"), "rb") as handle:
                if needle in handle.read().split(b"\0"):
                    found.append(int(entry.name))
        except OSError:  # gone meanwhile, or another user's
            continue
    return found


def kill_carriers(token: str, exclude: set[int] | frozenset[int] = frozenset(), rounds: int = 50) -> int:
    """SIGKILL every process carrying ``token`` (but ``exclude``), again until a round finds none (a raylet
    may start a worker between two rounds); returns how many were killed."""
    killed: set[int] = set()
    for _ in range(rounds):
        found = carriers(token, exclude)
        if not found:
            break
        for pid in found:
            with contextlib.suppress(ProcessLookupError, PermissionError):
                os.kill(pid, signal.SIGKILL)
                killed.add(pid)
        time.sleep(0.1)
    return len(killed)


class Watchdog:
    """The running watchdog of one local Ray instance (see the module's description)."""

    def __init__(self, token: str, process: subprocess.Popen) -> None:
        self.token = token
        self.process = process

    def close(self) -> None:
        """After ``ray.shutdown()``: let the watchdog remove what is left of the instance (all of it when the
        sweep was stopped: sweep.runner), and wait for it."""
        with contextlib.suppress(OSError):
            if self.process.stdin is not None:
                self.process.stdin.close()
        try:
            self.process.wait(timeout=WAIT_SECONDS)
        except subprocess.TimeoutExpired:
            self.process.kill()
            self.process.wait()
        if os.environ.get(TOKEN_VARIABLE) == self.token:
            del os.environ[TOKEN_VARIABLE]  # later children of this process are not the instance's


def start() -> Watchdog | None:
    """Mark this process's future children with a new token and start their watchdog (None where processes
    cannot be found by their environment: not Linux)."""
    if not (_PROC / "self" / "environ").is_file():
        return None
    token = uuid.uuid4().hex
    os.environ[TOKEN_VARIABLE] = token
    # Ray's processes retitle themselves (ray::DashboardAgent, ray::TASK), which overwrites /proc/PID/environ,
    # token included, unless SPT_NOENV is set (titles then fit in the command line's length instead).
    os.environ.setdefault("SPT_NOENV", "1")
    root = str(Path(__file__).resolve().parents[1])
    environment = {key: value for key, value in os.environ.items() if key != TOKEN_VARIABLE}  # not a carrier
    environment["PYTHONPATH"] = os.pathsep.join(filter(None, [root, os.environ.get("PYTHONPATH")]))
    process = subprocess.Popen([sys.executable, "-m", "sweep.watchdog", token, str(os.getpid())],
                               stdin=subprocess.PIPE, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                               env=environment, start_new_session=True, close_fds=True)
    return Watchdog(token, process)


def main(argv: list[str] | None = None) -> int:
    """``python -m sweep.watchdog TOKEN DRIVER_PID``: wait for the driver's end, then kill the token's
    processes."""
    token, driver = (sys.argv[1:] if argv is None else argv)[:2]
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is the driver's to handle
    with contextlib.suppress(OSError):
        while sys.stdin.buffer.read(4096):  # nothing is ever written: returns at EOF
            pass
    kill_carriers(token, exclude={os.getpid(), int(driver)})
    return 0


if __name__ == "__main__":
    sys.exit(main())
