"""Atomic file output, and output paths checked before any work is done.

- :func:`check_output_file` / :func:`check_output_folder`: refuse, with one line, an output that
  cannot be written (a component of its path is a file, it is a folder where a file is wanted, the
  folder is read-only, the name is too long) *before* a long computation. They really probe: a
  temporary file is created and removed in the deepest existing folder, because permission bits
  say nothing when running as root (CI does).
- :func:`atomic_paths`: several outputs that belong together (an image and its ``.config.json``)
  land together or not at all: every temporary is written first, then all are renamed; if a rename
  fails, the ones already renamed are rolled back (an existing output is restored where the file
  system allows a hard link).
- :func:`atomic_path`: the one-file case. Nothing is ever half-written: on an exception (or
  Ctrl-C) the temporary file is removed and the target is left untouched.
- A kill (SIGKILL, the OOM killer) runs no cleanup, so a temporary's name says who wrote it:
  ``.NAME.HOST-PID-RANDOM.tmp.EXT`` (HOST: a short hash of the host name; backups of replaced outputs:
  ``.NAME.EXT.HOST-PID.backup``). Before each write, a folder's temporaries of this host whose process
  is gone are removed (:func:`remove_stale_temporaries`): a killed volume write leaves up to 0.5 GB.
  Another host's are never touched (its processes cannot be seen from here: a sweep's shared folder).
"""

from __future__ import annotations

import contextlib
import hashlib
import os
import re
import socket
import stat
import tempfile
from collections.abc import Callable, Iterator
from pathlib import Path

from gratnet import interrupts
from gratnet.errors import GratNetError

#: Longest file name (bytes) that the usual file systems accept.
_NAME_MAX = 255

#: Every output this process has completed, in order (an interrupted command's line names what it kept).
WRITTEN: list[Path] = []

#: Our temporaries and backups: ``.NAME.HOST-PID-RANDOM.tmp.EXT`` and ``.NAME.EXT.HOST-PID.backup`` (HOST: 6 hex
#: digits; RANDOM: mkstemp's 8 characters; EXT: the target's suffix, at most 20 characters with its dot).
TEMPORARY_NAME = re.compile(r"^\..+\.(?P<host>[0-9a-f]{6})-(?P<pid>[0-9]+)"
                            r"(?:-[a-z0-9_]{8}\.tmp(?:\.[^/]{0,19})?|\.backup)$")


def host_tag() -> str:
    """This host's 6 hex digits in temporary names (a hash: host names may hold any character)."""
    return hashlib.sha1(socket.gethostname().encode("utf-8", "replace")).hexdigest()[:6]


def _writer_tag() -> str:
    """``HOST-PID`` of this process (read on each call: a forked child has its own PID)."""
    return f"{host_tag()}-{os.getpid()}"


def process_alive(pid: int) -> bool:
    """Whether a process ``pid`` exists on this host (another user's counts: EPERM)."""
    if pid <= 0:
        return True  # not a PID we wrote: leave its file alone
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except OSError:  # EPERM: it exists; anything else: do not guess
        return True
    return True


def remove_stale_temporaries(folder: str | os.PathLike[str]) -> list[Path]:
    """Remove ``folder``'s temporaries and backups (:data:`TEMPORARY_NAME`) written on this host by processes that
    are gone (killed during a write); the paths removed. Nothing else is touched: other names, other hosts'
    temporaries, those of live processes (a reused PID keeps a stale one until that process ends too)."""
    removed: list[Path] = []
    host = host_tag()
    try:
        entries = list(os.scandir(folder))
    except OSError:
        return removed
    for entry in entries:
        match = TEMPORARY_NAME.match(entry.name) if entry.name.startswith(".") else None
        if match is None or match["host"] != host or process_alive(int(match["pid"])):
            continue
        try:
            if not entry.is_file(follow_symlinks=False):
                continue
            os.unlink(entry.path)
        except OSError:  # gone already (another writer cleaned it), or not ours to remove
            continue
        removed.append(Path(entry.path))
    return removed


def _make_temporary(folder: Path, target: Path) -> str:
    """A new empty file in ``folder`` named ``.STEM.HOST-PID-RANDOM.tmp.EXT`` (:data:`TEMPORARY_NAME`), kept to
    :data:`_NAME_MAX` bytes; its path. Raises OSError."""
    stem = target.stem[:100]
    while len(os.fsencode(stem)) > 150:  # a stem of many-byte characters
        stem = stem[:-1]
    handle, name = tempfile.mkstemp(prefix=f".{stem}.{_writer_tag()}-", suffix=f".tmp{target.suffix[:20]}",
                                    dir=folder)
    os.close(handle)
    return name


def _blocking_file(target: Path) -> Path | None:
    """The first component of ``target``'s parent folders that exists but is not a folder, if any."""
    for ancestor in reversed(target.parents):
        if ancestor.is_dir():
            continue
        if ancestor.exists() or ancestor.is_symlink():
            return ancestor
        return None  # missing from here on: it will be created
    return None


def _reason(target: Path, error: OSError | None = None) -> str:
    """Why ``target`` cannot be written, in words (the OS error's own words are often misleading:
    mkdir under a file says "File exists", where the cause is "Not a directory")."""
    blocker = _blocking_file(target)
    if blocker is not None:
        return f"{blocker} is a file, not a folder"
    if target.is_dir():
        return "it is a folder, not a file"
    if error is not None:
        return str(error.strerror or error)
    return "unknown reason"


def _deepest_existing_folder(target: Path) -> Path:
    """The deepest folder on ``target``'s path that exists (``target`` itself excluded)."""
    for ancestor in target.parents:
        if ancestor.is_dir():
            return ancestor
    return Path(".")


def _probe(folder: Path, target: Path, flag: str) -> None:
    """Create and remove a temporary file in ``folder`` named like :func:`atomic_path`'s temporaries."""
    try:
        name = _make_temporary(folder, target)
    except (OSError, UnicodeError, ValueError) as error:
        detail = error.strerror if isinstance(error, OSError) and error.strerror else str(error)
        raise GratNetError(f"cannot write {flag} {target}: the folder {folder} is not writable ({detail})") from None
    with contextlib.suppress(OSError):
        os.unlink(name)


def _check_names(given: str | os.PathLike[str], flag: str) -> Path:
    """``given`` as a Path, refused if empty or blank (Path('') would quietly mean the working folder)."""
    if not os.fspath(given).strip():
        raise GratNetError(f"{flag} is empty; give a path")
    target = Path(given)
    for part in target.parts:
        try:
            encoded = os.fsencode(part)
        except UnicodeError:
            raise GratNetError(f"{flag} {target!s}: the name {part!r} cannot be encoded for this file system") from None
        if b"\0" in encoded:
            raise GratNetError(f"{flag} {target!r} contains a NUL character")
        if len(encoded) > _NAME_MAX - 40:  # room for the temporary name's prefix and suffix
            raise GratNetError(f"{flag} {target}: the name {part[:40]}… is too long ({len(encoded)} bytes)")
    return target


def check_output_file(target: str | os.PathLike[str], flag: str = "--out") -> Path:
    """Refuse ``target`` (one GratNetError) unless a file can be written there; nothing is created.

    Checks: the name is not empty and not too long; no component of its folder is a file; it is not
    itself a folder or a special file (a device, a pipe); the deepest existing folder on its path
    accepts a new file (probed, not read from permission bits). Missing folders are created later
    by the writer.
    """
    target = _check_names(target, flag)
    blocker = _blocking_file(target)
    if blocker is not None:
        raise GratNetError(f"cannot write {flag} {target}: {blocker} is a file, not a folder")
    if target.is_dir():
        raise GratNetError(f"cannot write {flag} {target}: it is a folder; give a file name inside it")
    if target.exists() or target.is_symlink():
        mode = os.lstat(target).st_mode
        if not (stat.S_ISREG(mode) or stat.S_ISLNK(mode)):
            raise GratNetError(f"cannot write {flag} {target}: it exists and is not a regular file")
    _probe(_deepest_existing_folder(target), target, flag)
    return target


def check_output_folder(folder: str | os.PathLike[str], flag: str = "--out") -> Path:
    """Refuse ``folder`` (one GratNetError) unless files can be written in it; nothing is created.

    It may be missing (the writer creates it) but not a file, and no component of its path may be a file.
    """
    folder = _check_names(folder, flag)
    blocker = _blocking_file(folder)
    if blocker is not None:
        raise GratNetError(f"cannot write {flag} {folder}: {blocker} is a file, not a folder")
    if folder.exists() and not folder.is_dir():
        raise GratNetError(f"cannot write {flag} {folder}: it is a file, not a folder")
    _probe(folder if folder.is_dir() else _deepest_existing_folder(folder), folder / "probe", flag)
    return folder


def make_folder(folder: str | os.PathLike[str]) -> Path:
    """Create ``folder`` (and its parents) if needed; one GratNetError when that is impossible."""
    folder = Path(folder)
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as error:  # a file in its place or on its path, a read-only or virtual file system
        blocker = folder if folder.exists() and not folder.is_dir() else _blocking_file(folder)
        reason = f"{blocker} is a file, not a folder" if blocker is not None else error.strerror or str(error)
        raise GratNetError(f"cannot create the output folder {folder}: {reason}") from error
    return folder


def _temporary_beside(target: Path) -> Path:
    """A new empty file in ``target``'s folder (created if needed), keeping ``target``'s suffix so that
    writers choosing a format by extension (Pillow, OpenEXR) still work. Killed writers' temporaries in that
    folder are removed first."""
    folder = target.parent
    try:
        folder.mkdir(parents=True, exist_ok=True)
        remove_stale_temporaries(folder)
        name = _make_temporary(folder, target)
    except OSError as error:
        raise GratNetError(f"cannot write {target}: {_reason(target, error)}") from error
    interrupts.pending(name, added=True)  # a supervisor that must kill a stuck command removes it
    # mkstemp makes the file private (0600); give it the permissions a plain open() would.
    umask = os.umask(0)
    os.umask(umask)
    os.chmod(name, 0o666 & ~umask)
    return Path(name)


def _commit(targets: list[Path], temporaries: list[Path]) -> None:
    """Rename every temporary onto its target; on a failure undo the renames already done."""
    backups: list[Path | None] = []
    try:
        for target in targets:
            backup = None
            if target.is_file():  # keep the old output reachable until every new one is in place
                backup = target.with_name(f".{target.name[:100]}.{_writer_tag()}.backup")
                with contextlib.suppress(OSError):
                    os.unlink(backup)
                try:
                    os.link(target, backup)
                except OSError:
                    backup = None  # no hard links here: the old file cannot be restored
            backups.append(backup)
        done = 0
        try:
            for target, temporary in zip(targets, temporaries, strict=True):
                try:
                    os.replace(temporary, target)
                except OSError as error:
                    raise GratNetError(f"cannot write {target}: {_reason(target, error)}") from error
                done += 1
        except BaseException:
            for target, backup in zip(targets[:done], backups[:done], strict=True):
                with contextlib.suppress(OSError):
                    if backup is not None:
                        os.replace(backup, target)
                    else:
                        os.unlink(target)
            raise
    finally:
        for backup in backups:
            if backup is not None:
                with contextlib.suppress(OSError):
                    os.unlink(backup)


@contextlib.contextmanager
def atomic_paths(*targets: str | os.PathLike[str], output: bool = True) -> Iterator[tuple[Path, ...]]:
    """Yield one temporary path per target (same folder, same suffix); on success rename them all.

    On an exception nothing new is left: every temporary is removed, and targets already renamed
    are put back as they were. ``output`` False: a cache entry, not the command's output (an interrupted
    command's line does not name it: :data:`WRITTEN`).
    """
    paths = [Path(target) for target in targets]
    if len({os.path.abspath(path) for path in paths}) != len(paths):
        raise GratNetError(f"two outputs share one path: {', '.join(map(str, paths))}")
    temporaries: list[Path] = []
    try:
        for path in paths:
            temporaries.append(_temporary_beside(path))
        try:
            yield tuple(temporaries)
        except OSError as error:  # the writer failed, e.g. the disk is full
            names = " and ".join(map(str, paths))
            raise GratNetError(f"cannot write {names}: {error.strerror or error}") from error
        _commit(paths, temporaries)
        for path in paths if output else ():
            WRITTEN.append(path)
            interrupts.written(path)
    finally:
        for temporary in temporaries:
            with contextlib.suppress(OSError):
                temporary.unlink()
            interrupts.pending(temporary, added=False)


@contextlib.contextmanager
def atomic_path(target: str | os.PathLike[str], output: bool = True) -> Iterator[Path]:
    """Yield a temporary path in the target's folder; rename it onto ``target`` on success (``output``: as
    :func:`atomic_paths`)."""
    with atomic_paths(target, output=output) as (temporary,):
        yield temporary


def write_bytes_atomic(target: str | os.PathLike[str], data: bytes) -> None:
    """Write ``data`` to ``target`` atomically."""
    with atomic_path(target) as temporary:
        temporary.write_bytes(data)


def write_text_atomic(target: str | os.PathLike[str], text: str) -> None:
    """Write UTF-8 ``text`` to ``target`` atomically."""
    write_bytes_atomic(target, text.encode("utf-8"))


def cache_folder(*parts: str) -> Path:
    """GratNet's folder for caches that can be rebuilt (``$XDG_CACHE_HOME/gratnet``, else ``~/.cache/gratnet``),
    joined with ``parts``; nothing is created."""
    base = os.environ.get("XDG_CACHE_HOME")
    return (Path(base) if base else Path.home() / ".cache").joinpath("gratnet", *parts)


def atomic_folder(out: str | os.PathLike[str], write: Callable[[Path], None], flag: str = "--out") -> None:
    """Run ``write(folder)`` on a new hidden temporary folder beside ``out``, then rename it onto ``out`` (an empty
    folder there is replaced): a folder of outputs lands whole or not at all. On any failure the temporary folder is
    removed and ``out`` is left as it was; an OSError becomes one GratNetError naming ``flag``."""
    import shutil

    out = Path(out)
    parent = make_folder(out.parent if str(out.parent) else Path("."))
    temporary = Path(tempfile.mkdtemp(prefix=f".{out.name[:100]}.{host_tag()}-{os.getpid()}-", suffix=".tmp",
                                      dir=parent))
    try:
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(temporary, 0o777 & ~umask)  # mkdtemp's folder is private (0700); an output folder is not
        write(temporary)
        try:
            os.rename(temporary, out)  # atomic; replaces an empty folder, fails on a non-empty one
        except OSError as error:
            raise GratNetError(f"cannot write {flag} {out}: {error.strerror or error}") from error
    except OSError as error:  # the disk is full, …
        raise GratNetError(f"cannot write {flag} {out}: {error.strerror or error}") from error
    finally:
        if temporary.exists():
            shutil.rmtree(temporary, ignore_errors=True)
    WRITTEN.append(out)
