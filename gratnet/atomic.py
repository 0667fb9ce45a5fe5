"""Atomic file output: write to a temporary file beside the target, then rename.

Nothing is ever half-written: on an exception (or Ctrl-C) the temporary file is removed and the
target is left untouched.
"""

from __future__ import annotations

import contextlib
import os
import tempfile
from collections.abc import Iterator
from pathlib import Path

from gratnet.errors import GratNetError


@contextlib.contextmanager
def atomic_path(target: str | os.PathLike[str]) -> Iterator[Path]:
    """Yield a temporary path in the target's folder; rename it onto ``target`` on success.

    The temporary name keeps the target's suffix so that writers choosing a format by extension
    (Pillow, OpenEXR) still work.
    """
    target = Path(target)
    folder = target.parent if str(target.parent) else Path(".")
    try:
        folder.mkdir(parents=True, exist_ok=True)
        handle, temporary_name = tempfile.mkstemp(
            prefix=f".{target.stem}.", suffix=f".tmp{target.suffix}", dir=folder
        )
    except OSError as error:
        raise GratNetError(f"cannot write {target}: {error.strerror or error}") from error
    os.close(handle)
    temporary = Path(temporary_name)
    # mkstemp makes the file private (0600); give it the permissions a plain open() would.
    umask = os.umask(0)
    os.umask(umask)
    os.chmod(temporary, 0o666 & ~umask)
    try:
        try:
            yield temporary
            os.replace(temporary, target)
        except OSError as error:  # e.g. a folder in the target's place, or the disk is full
            raise GratNetError(f"cannot write {target}: {error.strerror or error}") from error
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            temporary.unlink()
        raise


def make_folder(folder: str | os.PathLike[str]) -> Path:
    """Create ``folder`` (and its parents) if needed; one GratNetError when that is impossible."""
    folder = Path(folder)
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as error:  # a file in its place or on its path, a read-only or virtual file system
        raise GratNetError(f"cannot create the output folder {folder}: {error.strerror or error}") from error
    return folder


def write_bytes_atomic(target: str | os.PathLike[str], data: bytes) -> None:
    """Write ``data`` to ``target`` atomically."""
    with atomic_path(target) as temporary:
        temporary.write_bytes(data)


def write_text_atomic(target: str | os.PathLike[str], text: str) -> None:
    """Write UTF-8 ``text`` to ``target`` atomically."""
    write_bytes_atomic(target, text.encode("utf-8"))
