"""Ctrl-C within a second, even inside a long C call that holds the GIL (issue 36).

Python runs a SIGINT handler only between bytecodes, in the main thread. moderngl holds the GIL through each
GL call, and on a CPU rasterizer a shader's first compile or first draw is one such call of 10–40 s (a baked
network on llvmpipe with a cold Mesa cache): no Python code runs in *any* thread of the process meanwhile, so
neither the handler nor an in-process watchdog thread can answer the signal.

So the ``gratnet`` command runs under a small supervisor: :func:`supervise` forks before any heavy import; the
child runs the command, the parent waits for it and exits with its status. The parent takes the termination
signals (SIGINT, SIGTERM, SIGHUP, SIGQUIT) and passes on those sent to it alone (a terminal's Ctrl-C already
reached the whole process group). The child tells the parent which of gratnet.atomic's temporaries are pending
and, from its SIGINT handler, that it answers the signal. It normally does so at once and ends by itself (its
own line, exit 130, after its own cleanup: a sweep leaves its Ray instance, whose watchdog kills it). If
instead its handler has not run :data:`GRACE` seconds after a SIGINT, its main thread is inside a call that
will not return soon — one that holds the GIL (a shader compile) or one that releases it (a long numpy or
torch operation: other threads run, but Python runs signal handlers only in the main thread, between
bytecodes): the parent kills the child (SIGKILL), removes its pending temporaries, prints the one line and
exits 130. A ``kill -9`` of the parent takes the child with it (``PR_SET_PDEATHSIG``).

Linux only (``PR_SET_PDEATHSIG``); elsewhere, with ``GRATNET_NO_SUPERVISOR=1``, or when threads already run
(forking them is unsafe), the command runs in the one process as before.
"""

from __future__ import annotations

import contextlib
import ctypes
import os
import signal
import sys
import threading
import time
import types

__all__ = ["GRACE", "POLL", "SIGNALS", "done", "pending", "supervise", "written"]

#: Seconds after a SIGINT without the child's handler running before the child counts as stuck in a long call.
GRACE = 0.5
#: Seconds between the supervisor's looks at the child.
POLL = 0.1
#: The signals the supervisor takes and passes on to the command.
SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP, signal.SIGQUIT)
#: ``si_code`` of a signal the kernel sent (a terminal's Ctrl-C, a hangup): the whole process group has it.
_SI_KERNEL = 0x80
_PR_SET_PDEATHSIG = 1

#: In the supervised child: the pipe's write end to the supervisor (its messages), else None.
_channel: int | None = None


def pending(path: str | os.PathLike[str], added: bool) -> None:
    """Tell the supervisor, if any, that ``path`` (a temporary of gratnet.atomic) now exists (``added``) or is
    gone (renamed onto its target, or removed): it removes those still pending if it must kill the command."""
    _tell(b"+" if added else b"-", path)


def written(path: str | os.PathLike[str]) -> None:
    """Tell the supervisor, if any, that an output is complete (its line then says that finished files are kept)."""
    _tell(b"=", path)


def done(status: int) -> None:
    """In the supervised child, once the command has returned ``status``: stdout and stderr are flushed, and SIGINT
    is ignored from now on. The supervisor exits with ``status``: at once, ending the interpreter's teardown
    (1–2 s with torch loaded on a busy CPU), if a SIGINT came before or comes during it."""
    if _channel is None:
        return
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    with contextlib.suppress(OSError, ValueError):  # the supervisor may end the teardown: nothing may be lost
        sys.stdout.flush()
        sys.stderr.flush()
    _tell(b"#" + str(int(status)).encode())


def _forked() -> None:
    """In a process forked by the command (multiprocessing's fork): not the command, so no messages from it."""
    global _channel
    _channel = None
    if signal.getsignal(signal.SIGINT) is _answered:
        signal.signal(signal.SIGINT, signal.default_int_handler)


def _unraisable(unraisable: sys.UnraisableHookArgs) -> None:
    """``sys.unraisablehook`` of the child: a KeyboardInterrupt raised inside a weakref callback or a ``__del__``
    (Ctrl-C during a garbage collection) cannot propagate, so Python printed a traceback and went on, and the
    command ran to its end (seen in gratnet train's report). Instead the signal is sent again, to be raised where
    the command can answer it: a little later, from a thread (sent from here, it would be raised here, in the hook,
    and be lost the same way; if it lands in a callback again, this repeats)."""
    if isinstance(unraisable.exc_value, KeyboardInterrupt):
        later = threading.Timer(0.02, os.kill, (os.getpid(), signal.SIGINT))
        later.daemon = True
        later.start()
        return
    sys.__unraisablehook__(unraisable)


def _answered(number: int, frame: types.FrameType | None) -> None:
    """The child's SIGINT handler: Python's (KeyboardInterrupt), after telling the supervisor that the command
    answers the signal itself (it then leaves the command to its own cleanup, however long, and its own line)."""
    _tell(b"!")
    signal.default_int_handler(number, frame)


def _tell(kind: bytes, path: str | os.PathLike[str] | None = None) -> None:
    if _channel is None:
        return
    message = kind + (os.fsencode(os.path.abspath(path)) if path is not None else b"") + b"\0"
    if len(message) <= 4096:  # PIPE_BUF: one write, never interleaved with another message
        with contextlib.suppress(OSError):  # the supervisor is gone, or its pipe is full: nothing to do
            os.write(_channel, message)


def _enabled() -> bool:
    return (sys.platform.startswith("linux") and hasattr(os, "fork") and not os.environ.get("GRATNET_NO_SUPERVISOR")
            and threading.active_count() == 1)


def supervise(command: str) -> int | None:
    """Fork the command under a supervisor (see the module docstring). Returns None in the child, which goes on
    with the command (and when no supervisor is used); in the parent, the command's exit status once it ended
    (a signal's death as 128 + the signal's number). ``command``: ``gratnet SUBCOMMAND``, for the line printed
    when the supervisor has to stop a stuck child."""
    global _channel
    if not _enabled():
        return None
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        prctl = libc.prctl
    except (OSError, AttributeError):
        return None
    taken = [number for number in SIGNALS if signal.getsignal(number) is not signal.SIG_IGN]
    reader, writer = os.pipe()
    os.set_blocking(writer, False)  # a message is dropped rather than block the command on a busy supervisor
    parent = os.getpid()
    sys.stdout.flush()
    sys.stderr.flush()
    before = signal.pthread_sigmask(signal.SIG_BLOCK, [*taken, signal.SIGCHLD])  # no signal lost around the fork
    child = os.fork()
    if child == 0:
        os.close(reader)
        prctl(_PR_SET_PDEATHSIG, signal.SIGKILL, 0, 0, 0)
        if os.getppid() != parent:  # the supervisor died before the line above
            os._exit(128 + signal.SIGKILL)
        signal.pthread_sigmask(signal.SIG_SETMASK, before)
        _channel = writer
        if signal.getsignal(signal.SIGINT) is signal.default_int_handler:
            signal.signal(signal.SIGINT, _answered)
            sys.unraisablehook = _unraisable
        os.register_at_fork(after_in_child=_forked)
        return None
    os.close(writer)
    # The signals stay blocked here to the end: one pending when the child ends (a second Ctrl-C) must not
    # become a KeyboardInterrupt in the supervisor.
    return _wait(child, reader, taken, command)


def _wait(child: int, reader: int, taken: list[signal.Signals], command: str) -> int:
    """The supervisor's loop: pass signals on, read the child's messages, stop it if it is stuck after a SIGINT;
    the child's exit status."""
    os.set_blocking(reader, False)
    temporaries: set[bytes] = set()
    finished = False
    buffer = b""
    interrupted_at: float | None = None  # the last SIGINT's arrival
    answered = False  # whether the child's Python handler ran since then
    returned: int | None = None  # the command's status, once it has returned (then only teardown is left)
    while True:
        info = signal.sigtimedwait([*taken, signal.SIGCHLD], POLL / 2)
        now = time.monotonic()
        # Only a signal it waited for: after SIGSTOP and SIGCONT of this process (kill -STOP, a shell's Ctrl-Z and
        # fg) CPython's sigtimedwait can return a record of garbage (seen: si_signo −713092144), which passed on
        # would end the supervisor with EINVAL and the command with it.
        if info is not None and info.si_signo in taken:
            if info.si_code != _SI_KERNEL:  # sent to this process alone: the child has not seen it
                with contextlib.suppress(ProcessLookupError):
                    os.kill(child, info.si_signo)
            if info.si_signo == signal.SIGINT:
                interrupted_at, answered = now, False
        with contextlib.suppress(BlockingIOError):
            while chunk := os.read(reader, 65536):
                buffer += chunk
        *messages, buffer = buffer.split(b"\0")
        for message in messages:
            if message[:1] == b"+":
                temporaries.add(message[1:])
            elif message[:1] == b"-":
                temporaries.discard(message[1:])
            elif message[:1] == b"=":
                finished = True
            elif message[:1] == b"!":
                answered = True
            elif message[:1] == b"#" and message[1:].isdigit():
                returned = int(message[1:])
        if returned is not None and interrupted_at is not None:
            # Ctrl-C, and the command has returned (its outputs and its line are out): only the interpreter's
            # teardown is left (1–2 s with torch loaded, on a busy CPU), and it does nothing the user waits for.
            with contextlib.suppress(ProcessLookupError):
                os.kill(child, signal.SIGKILL)
            os.waitpid(child, 0)
            return returned
        ended, status = os.waitpid(child, os.WNOHANG)
        if ended:
            if os.WIFEXITED(status):
                return os.WEXITSTATUS(status)
            return returned if returned is not None else 128 + os.WTERMSIG(status)
        if returned is None and interrupted_at is not None and not answered and now - interrupted_at > GRACE:
            return _stop(child, temporaries, finished, command)


def _stop(child: int, temporaries: set[bytes], finished: bool, command: str) -> int:
    """Kill the stuck child, remove its pending temporaries, say so in one line: exit status 130."""
    with contextlib.suppress(ProcessLookupError):
        os.kill(child, signal.SIGKILL)
    try:
        _, status = os.waitpid(child, 0)
    except ChildProcessError:
        status = 0
    if os.WIFEXITED(status):  # it answered by itself just before the kill (and said so): its status
        return os.WEXITSTATUS(status)
    for path in temporaries:
        with contextlib.suppress(OSError):
            os.unlink(path)
    clear = "\r\033[K" if sys.stderr.isatty() else "\r"  # over a progress bar left on the line
    outcome = "files finished before it are kept, none is half-written" if finished else "nothing was written"
    print(f"{clear}{command}: interrupted; {outcome}", file=sys.stderr, flush=True)
    return 130
