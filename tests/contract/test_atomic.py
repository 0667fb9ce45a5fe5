"""gratnet.atomic's temporaries name their writer, and killed writers' temporaries are removed (issue 36).

A kill during a write leaves its hidden temporary (nothing reads it, but a volume's is up to 0.5 GB). The next
write into the same folder removes those of this host whose process is gone, and nothing else.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from gratnet import atomic


def _dead_pid() -> int:
    """The PID of a process that has ended and been reaped."""
    child = subprocess.Popen([sys.executable, "-c", "pass"])
    child.wait()
    return child.pid


def _stale_name(stem: str, pid: int, suffix: str = ".exr") -> str:
    return f".{stem}.{atomic.host_tag()}-{pid}-abcd_123.tmp{suffix}"


def test_the_temporary_names_its_writer(tmp_path: Path) -> None:
    seen: list[str] = []
    with atomic.atomic_path(tmp_path / "volume.config.json") as temporary:
        seen.append(temporary.name)
        temporary.write_text("{}")
    match = atomic.TEMPORARY_NAME.match(seen[0])
    assert match is not None, seen[0]
    assert int(match["pid"]) == os.getpid() and match["host"] == atomic.host_tag()
    assert seen[0].startswith(".volume.config.") and seen[0].endswith(".tmp.json")
    assert sorted(path.name for path in tmp_path.iterdir()) == ["volume.config.json"]


def test_a_write_removes_dead_writers_temporaries_and_nothing_else(tmp_path: Path) -> None:
    dead = _dead_pid()
    other_host = "000000" if atomic.host_tag() != "000000" else "ffffff"
    stale = [_stale_name("volume", dead), _stale_name("volume.config", dead, ".json"),
             f".volume.exr.{atomic.host_tag()}-{dead}.backup", _stale_name("other", dead, "")]
    kept = [
        _stale_name("volume", os.getpid()),  # a live writer (this process)
        _stale_name("volume", os.getppid(), ".png"),  # another live one
        f".volume.{other_host}-{dead}-abcd_123.tmp.exr",  # another host's: its processes are not visible here
        f".volume.{dead}.tmp.exr",  # not our pattern (no host)
        ".volume.x1y2z3a4.tmp.exr",  # the old unnamed pattern: the writer is unknown
        "volume.exr", "notes.txt", f"{atomic.host_tag()}-{dead}-abcd_123.tmp.exr",  # not hidden
    ]
    for name in stale + kept:
        (tmp_path / name).write_bytes(b"x")
    (tmp_path / _stale_name("folder", dead)).mkdir()  # a folder of that name is not a temporary
    atomic.write_text_atomic(tmp_path / "result.json", "{}")
    left = {path.name for path in tmp_path.iterdir()}
    assert not left & set(stale), left & set(stale)
    assert left == {*kept, _stale_name("folder", dead), "result.json"}


def test_only_the_target_folder_is_cleaned(tmp_path: Path) -> None:
    dead = _dead_pid()
    elsewhere = tmp_path / "other"
    elsewhere.mkdir()
    (elsewhere / _stale_name("volume", dead)).write_bytes(b"x")
    atomic.write_text_atomic(tmp_path / "out" / "result.json", "{}")
    assert (elsewhere / _stale_name("volume", dead)).exists()


@pytest.mark.skipif(sys.platform != "linux", reason="kills a child process (POSIX signals)")
def test_a_killed_writers_temporary_is_removed_by_the_next_write(tmp_path: Path) -> None:
    """A real writer killed (SIGKILL) inside atomic_path: its temporary is left; the next write removes it."""
    script = ("import sys, time\nfrom gratnet.atomic import atomic_path\n"
              "with atomic_path(sys.argv[1]) as temporary:\n"
              "    temporary.write_bytes(b'half')\n    print(temporary, flush=True)\n    time.sleep(60)\n")
    writer = subprocess.Popen([sys.executable, "-c", script, str(tmp_path / "volume.exr")], stdout=subprocess.PIPE,
                              text=True)
    try:
        left = Path(writer.stdout.readline().strip())  # type: ignore[union-attr]
        assert left.exists()
        atomic.write_text_atomic(tmp_path / "other.json", "{}")  # the writer is alive: kept
        assert left.exists()
    finally:
        writer.send_signal(signal.SIGKILL)
        writer.wait()
    deadline = time.monotonic() + 5.0
    while atomic.process_alive(writer.pid) and time.monotonic() < deadline:  # reaped already; a PID reuse is unlikely
        time.sleep(0.05)
    assert left.exists()
    atomic.write_text_atomic(tmp_path / "volume.exr", "{}")
    assert sorted(path.name for path in tmp_path.iterdir()) == ["other.json", "volume.exr"]


def test_a_cache_entry_is_not_an_output(tmp_path: Path) -> None:
    """An interrupted command's line names the outputs it kept (atomic.WRITTEN); a cache entry it wrote on the way
    (the importance table, the bounds, the ground-truth slices) is none of them."""
    before = list(atomic.WRITTEN)
    with atomic.atomic_path(tmp_path / "cache.npz", output=False) as temporary:
        temporary.write_bytes(b"cached")
    assert (tmp_path / "cache.npz").read_bytes() == b"cached" and atomic.WRITTEN == before
    atomic.write_text_atomic(tmp_path / "out.txt", "output")
    assert atomic.WRITTEN == [*before, tmp_path / "out.txt"]
