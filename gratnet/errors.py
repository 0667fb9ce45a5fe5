"""One error type for bad input: the CLI prints its message on one line and exits non-zero."""

from __future__ import annotations

import os


class GratNetError(Exception):
    """A user-facing error: bad input, unsupported file, impossible parameters.

    The message must say what is wrong and, where possible, what to do instead.
    """

    exit_code = 2


def read_magic(path: str | os.PathLike[str], what: str, size: int) -> bytes:
    """The first ``size`` bytes of an existing regular file, or one GratNetError naming ``what`` (e.g. 'model file')."""
    from pathlib import Path

    source = Path(path)
    if not source.exists():
        raise GratNetError(f"{what} {source} does not exist")
    if not source.is_file():
        raise GratNetError(f"{what} {source} is not a regular file")
    try:
        with source.open("rb") as handle:
            return handle.read(size)
    except OSError as error:
        raise GratNetError(f"cannot read {what} {source}: {error.strerror or error}") from error
