"""Ground-truth volumes: the diffraction lobe sampled on a (w, v*, u*) grid, stored as OpenEXR.

A *volume* holds ``S`` slices of ``R x R`` CIE XYZ samples of the D65-normalised reflectance ``F``
(dimensionless; a flat mirror's specular peak has ``Y = 1``). Slice ``s`` is one value of the
third coordinate (``w``, or the normalised ``t_s = s / (S - 1)``, see the metadata); within a slice,
row ``i`` is the ``v*`` grid index and column ``j`` the ``u*`` grid index, both ascending over
``volume_axes(R) = linspace(-2, 2, R)`` (both ends included).

File layout (a contract; also documented in ``docs/formats.md``):

* one OpenEXR **multi-part** file, one scanline part per slice, named ``slice_00``, ``slice_01``, ...
  (zero-padded to at least two digits; more digits when ``S > 100``);
* each part is ``R x R`` pixels with data window ``(0, 0) - (R-1, R-1)`` and three 32-bit ``FLOAT``
  channels ``X``, ``Y``, ``Z``, ZIP-compressed (lossless);
* EXR row ``i`` (``y = i``, counted from the top as EXR does) is ``v*`` index ``i``: row 0 is
  ``v* = -2``. Column ``j`` is ``u*`` index ``j``: column 0 is ``u* = -2``. There is no flip: the
  array ``xyz[s, i, j]`` is exactly pixel ``(x=j, y=i)`` of part ``s``;
* every part's header carries ``gratnet_format = "gratnet-volume"``, ``gratnet_format_version``,
  ``gratnet_slice_index``, ``gratnet_slice_count``, ``gratnet_pixels_crc32`` (CRC-32 of the part's
  pixels, checked on read), the whole metadata dict as one JSON string ``gratnet_metadata`` (the
  source of truth when reading) and, for display with ``exrheader``, every metadata entry again as
  its own attribute ``gratnet_<key>``.

This module is runtime-side: it must not import torch.
"""

from __future__ import annotations

import contextlib
import io
import json
import os
import re
import sys
import tempfile
import zlib
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import OpenEXR

from gratnet.atomic import atomic_path
from gratnet.errors import GratNetError, read_magic
from gratnet.jsontext import strict_json

__all__ = [
    "FORMAT_NAME",
    "FORMAT_VERSION",
    "Volume",
    "VolumeHeader",
    "read_volume",
    "read_volume_header",
    "volume_axes",
    "write_volume",
]

FORMAT_NAME = "gratnet-volume"
FORMAT_VERSION = 1

#: Extent of the u* and v* grid axes: samples run from ``-AXIS_LIMIT`` to ``+AXIS_LIMIT``.
AXIS_LIMIT = 2.0

CHANNELS = ("X", "Y", "Z")

_ATTRIBUTE_PREFIX = "gratnet_"
_FORMAT_ATTRIBUTE = "gratnet_format"
_VERSION_ATTRIBUTE = "gratnet_format_version"
_METADATA_ATTRIBUTE = "gratnet_metadata"
_SLICE_INDEX_ATTRIBUTE = "gratnet_slice_index"
_SLICE_COUNT_ATTRIBUTE = "gratnet_slice_count"
_CHECKSUM_ATTRIBUTE = "gratnet_pixels_crc32"

# Metadata keys whose ``gratnet_<key>`` attribute names the writer uses for itself.
_RESERVED_KEYS = frozenset({"metadata", "slice_index", "slice_count", "pixels_crc32"})
# Metadata keys allowed only when they repeat the format identification.
_FORMAT_KEYS = {"format": FORMAT_NAME, "format_version": FORMAT_VERSION}

_KEY_PATTERN = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")
_MAX_KEY_LENGTH = 200  # EXR attribute names may be up to 255 bytes; "gratnet_" takes 8.
_PART_NAME_PATTERN = re.compile(r"slice_(\d+)")
_INT32_MIN, _INT32_MAX = -(2**31), 2**31 - 1


@dataclass
class Volume:
    """A ground-truth volume in memory.

    Attributes:
        xyz: ``float32`` array of shape ``(S, R, R, 3)``: ``xyz[s, i, j]`` is the CIE XYZ value
            (dimensionless, D65-normalised reflectance; a flat mirror's specular peak has
            ``Y = 1``) of slice ``s`` at ``v* = axes[i]`` and ``u* = axes[j]`` with
            ``axes = volume_axes(R)`` (row = ``v*`` index ascending, column = ``u*`` index
            ascending).
        metadata: JSON-able parameters: ``str | int | float | bool | None`` values and lists of
            them (see ``docs/formats.md`` for the keys ``gratnet groundtruth`` writes).
    """

    xyz: np.ndarray
    metadata: dict[str, Any] = field(default_factory=dict)

    @property
    def slices(self) -> int:
        """Number of slices ``S`` (first axis of ``xyz``)."""
        return int(self.xyz.shape[0])

    @property
    def resolution(self) -> int:
        """Samples per side ``R`` of each slice (``xyz.shape[1] == xyz.shape[2]``)."""
        return int(self.xyz.shape[1])


def volume_axes(resolution: int) -> np.ndarray:
    """Return the ``u*`` (equally ``v*``) sample coordinates of a volume with ``resolution`` samples.

    The grid is ``np.linspace(-2, 2, R)`` (dimensionless direction-cosine differences), both ends
    included, as ``float64``. Index ``i`` of the result is row ``i`` (for ``v*``) or column ``i``
    (for ``u*``) of every slice.
    """
    if isinstance(resolution, bool) or not isinstance(resolution, (int, np.integer)):
        raise GratNetError(f"volume resolution must be an integer, got {resolution!r}")
    if resolution < 2:
        raise GratNetError(f"volume resolution must be at least 2, got {resolution}")
    return np.linspace(-AXIS_LIMIT, AXIS_LIMIT, int(resolution))


def slice_part_name(index: int, slices: int) -> str:
    """Name of the EXR part holding slice ``index`` of ``slices``: ``slice_00``, ``slice_01``, ...

    Indices are zero-padded to two digits, or to the width of ``slices - 1`` when that is wider.
    """
    width = max(2, len(str(max(slices - 1, 0))))
    return f"slice_{index:0{width}d}"


# --------------------------------------------------------------------------------------------------
# Writing
# --------------------------------------------------------------------------------------------------


def write_volume(path: str | os.PathLike[str], volume: Volume) -> None:
    """Write ``volume`` to ``path`` as a GratNet volume EXR (layout in the module docstring).

    The array is validated (4-D ``(S, R, R, 3)``, ``S >= 1``, ``R >= 2``, real, finite) and cast to
    ``float32``; the metadata must be JSON-able with string keys matching ``[A-Za-z_][A-Za-z0-9_]*``.
    The file is written atomically: on any failure nothing is left at ``path`` (an existing file
    there is untouched) and no temporary file remains.

    Raises:
        GratNetError: invalid array or metadata, or the file cannot be written.
    """
    xyz = _validated_array(volume.xyz)
    metadata_json, typed_attributes = _encode_metadata(volume.metadata)
    slices = xyz.shape[0]

    parts = []
    for index in range(slices):
        header: dict[str, Any] = {
            "compression": OpenEXR.ZIP_COMPRESSION,
            "type": OpenEXR.scanlineimage,
            _FORMAT_ATTRIBUTE: FORMAT_NAME,
            _VERSION_ATTRIBUTE: FORMAT_VERSION,
            _SLICE_INDEX_ATTRIBUTE: index,
            _SLICE_COUNT_ATTRIBUTE: slices,
            _METADATA_ATTRIBUTE: metadata_json,
            _CHECKSUM_ATTRIBUTE: _pixels_checksum(xyz[index]),
        }
        header.update(typed_attributes)
        channels = {name: np.ascontiguousarray(xyz[index, :, :, c]) for c, name in enumerate(CHANNELS)}
        parts.append(OpenEXR.Part(header, channels, slice_part_name(index, slices)))

    target = Path(path)
    with atomic_path(target) as temporary:
        try:
            OpenEXR.File(parts).write(str(temporary))
        except (RuntimeError, OSError, ValueError, TypeError) as error:
            raise GratNetError(f"cannot write volume {target}: {error}") from error


def _validated_array(xyz: object) -> np.ndarray:
    """Check the shape and values of a volume array; return it as C-contiguous ``float32``."""
    array = np.asarray(xyz)
    if array.dtype.kind not in "biuf":
        raise GratNetError(f"volume array must be real-valued numbers, got dtype {array.dtype}")
    if array.ndim != 4 or array.shape[-1] != 3:
        raise GratNetError(
            f"volume array must have shape (S, R, R, 3) (slices, v* rows, u* columns, XYZ), got {array.shape}"
        )
    slices, rows, columns, _ = array.shape
    if rows != columns:
        raise GratNetError(f"volume slices must be square (R x R), got {rows} x {columns}")
    if slices < 1:
        raise GratNetError("volume must have at least one slice")
    if rows < 2:
        raise GratNetError(f"volume resolution must be at least 2, got {rows}")
    with np.errstate(over="ignore", invalid="ignore"):
        array = np.ascontiguousarray(array, dtype=np.float32)
    finite = np.isfinite(array)
    if not finite.all():
        s, i, j, c = (int(v) for v in np.argwhere(~finite)[0])
        count = int(finite.size - np.count_nonzero(finite))
        raise GratNetError(
            f"volume array has {count} non-finite value(s) (NaN, inf, or too large for float32), "
            f"first at slice {s}, row {i}, column {j}, channel {CHANNELS[c]}: {array[s, i, j, c]}"
        )
    return array


def _pixels_checksum(slice_xyz: np.ndarray) -> str:
    """CRC-32 of one slice's pixels as 8 lower-case hex digits.

    Computed over the little-endian ``float32`` bytes of channel X, then Y, then Z, each ``R x R``
    in row-major order (row = ``v*`` index). EXR itself has no checksum, and ZIP-compressed chunks
    that do not compress are stored raw, so this is what detects flipped bits in pixel data.
    """
    crc = 0
    for c in range(len(CHANNELS)):
        plane = np.ascontiguousarray(slice_xyz[:, :, c], dtype="<f4")
        crc = zlib.crc32(plane.tobytes(), crc)
    return f"{crc:08x}"


def _encode_metadata(metadata: object) -> tuple[str, dict[str, Any]]:
    """Validate ``metadata``; return its JSON text and the per-key ``gratnet_<key>`` attributes."""
    if not isinstance(metadata, dict):
        raise GratNetError(f"volume metadata must be a dict, got {type(metadata).__name__}")
    for key in metadata:
        if not isinstance(key, str) or not _KEY_PATTERN.fullmatch(key) or len(key) > _MAX_KEY_LENGTH:
            raise GratNetError(
                f"volume metadata key {key!r} is not allowed: use letters, digits and underscores "
                f"(not starting with a digit), at most {_MAX_KEY_LENGTH} characters"
            )
        if key in _RESERVED_KEYS:
            raise GratNetError(f"volume metadata key {key!r} is reserved by the volume file format")
        if key in _FORMAT_KEYS and metadata[key] != _FORMAT_KEYS[key]:
            raise GratNetError(
                f"volume metadata {key!r} is {metadata[key]!r} but this writer writes "
                f"{_FORMAT_KEYS[key]!r}; leave it out or set it to that value"
            )
    text = strict_json(metadata, "volume metadata")
    # Round-trip so that numpy scalars etc. become plain Python values before typing attributes.
    plain = json.loads(text)
    typed = {
        _ATTRIBUTE_PREFIX + key: _typed_attribute(value)
        for key, value in plain.items()
        if key not in _FORMAT_KEYS  # written anyway as gratnet_format / gratnet_format_version
    }
    return text, typed


def _typed_attribute(value: object) -> object:
    """EXR header value for one metadata entry, for display only (the JSON copy is authoritative).

    ``str`` -> EXR ``string``; ``int`` within 32 bits -> ``int``; ``float`` -> ``double``;
    everything else (bool, None, lists, larger ints) -> its JSON text as a ``string``.
    """
    if isinstance(value, str):
        return value
    if isinstance(value, bool):
        return json.dumps(value)
    if isinstance(value, int):
        return value if _INT32_MIN <= value <= _INT32_MAX else json.dumps(value)
    if isinstance(value, float):
        # A Python float would be stored as a 32-bit EXR "float"; a 0-d float64 array is a "double".
        return np.array(value, dtype=np.float64)
    return json.dumps(value)


# --------------------------------------------------------------------------------------------------
# Reading
# --------------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class VolumeHeader:
    """What a volume file's headers say, read without decoding a pixel (:func:`read_volume_header`).

    Attributes:
        slices: ``S``, the number of slices (parts).
        resolution: ``R``, samples per side of each slice.
        metadata: the decoded ``gratnet_metadata`` JSON.
    """

    slices: int
    resolution: int
    metadata: dict[str, Any]


def read_volume_header(path: str | os.PathLike[str]) -> VolumeHeader:
    """The slice count, resolution and metadata of a GratNet volume EXR, from its headers alone: milliseconds
    even for a 250 MB volume, so that callers can check a volume (its source, its size against a memory limit)
    before reading its pixels. The pixels' checksums are checked only by :func:`read_volume`.

    Raises:
        GratNetError: as :func:`read_volume` for everything its header pass checks.
    """
    source = Path(path)
    _, names, metadata, resolution = _header_pass(source)
    return VolumeHeader(slices=len(names), resolution=resolution, metadata=metadata)


def _header_pass(source: Path) -> tuple[_OpenedFile, list[str], dict[str, Any], int]:
    """The magic number, then the headers only: the true part count (the pixel pass silently drops parts it
    cannot decode); foreign or too-new files are rejected before any pixel is decoded."""
    magic = read_magic(source, "volume file", 4)
    if magic != b"\x76\x2f\x31\x01":
        raise GratNetError(f"{source} is not an OpenEXR file (wrong magic number)")
    headers_file = _open_exr(source, header_only=True)
    names, metadata, resolution = _check_headers(source, headers_file)
    return headers_file, names, metadata, resolution


def read_volume(path: str | os.PathLike[str]) -> Volume:
    """Read a GratNet volume EXR written by :func:`write_volume`.

    Returns a :class:`Volume` whose ``xyz`` is ``float32`` ``(S, R, R, 3)`` in file order (slice
    ``s`` = part ``slice_<s>``, row = ``v*`` index ascending, column = ``u*`` index ascending) and
    whose ``metadata`` is the decoded ``gratnet_metadata`` JSON.

    Raises:
        GratNetError: the file is missing, unreadable, not an OpenEXR file, truncated or corrupt,
            not a GratNet volume, of an unsupported format version, or structurally inconsistent.
    """
    source = Path(path)
    headers_file, names, metadata, resolution = _header_pass(source)  # pass 1: headers only

    # Pass 2: pixels.
    pixels_file = _open_exr(source, header_only=False)
    parts = pixels_file.parts
    if [part.name() for part in parts] != names:
        raise GratNetError(
            f"volume file {source} is truncated or corrupt: {len(names)} slice(s) declared but "
            f"only {len(parts)} could be decoded{_library_reason(pixels_file)}"
        )
    xyz = np.empty((len(names), resolution, resolution, 3), dtype=np.float32)
    for index, part in enumerate(parts):
        for c, channel_name in enumerate(CHANNELS):
            channel = part.channels.get(channel_name)
            pixels = None if channel is None else channel.pixels
            if pixels is None or pixels.shape != (resolution, resolution):
                raise GratNetError(
                    f"volume file {source}: part {names[index]} channel {channel_name} could not be "
                    f"read as {resolution} x {resolution} pixels{_library_reason(pixels_file)}"
                )
            if pixels.dtype.kind != "f":
                raise GratNetError(
                    f"volume file {source}: part {names[index]} channel {channel_name} has pixel "
                    f"type {pixels.dtype}, expected FLOAT"
                )
            xyz[index, :, :, c] = pixels
        expected = part.header.get(_CHECKSUM_ATTRIBUTE)
        if isinstance(expected, str) and _pixels_checksum(xyz[index]) != expected.lower():
            raise GratNetError(
                f"volume file {source} is corrupt: pixel data of part {names[index]} does not match "
                f"its checksum ({_CHECKSUM_ATTRIBUTE}); regenerate or re-copy the file"
            )
    # Nothing went wrong: pass on anything the native library printed (normally nothing).
    for opened in (headers_file, pixels_file):
        if opened.messages.strip():
            sys.stderr.write(opened.messages)
    return Volume(xyz=xyz, metadata=metadata)


class _OpenedFile:
    """An ``OpenEXR.File`` plus whatever the native library printed on stderr while opening it."""

    def __init__(self, exr: Any, messages: str) -> None:
        self.exr = exr
        self.messages = messages

    @property
    def parts(self) -> list[Any]:
        return list(self.exr.parts)


def _open_exr(source: Path, *, header_only: bool) -> _OpenedFile:
    """Open ``source`` with the OpenEXR binding, turning its failures into ``GratNetError``."""
    with _captured_library_output() as captured:
        try:
            exr = OpenEXR.File(str(source), separate_channels=True, header_only=header_only)
        except Exception as error:  # the binding raises RuntimeError, but be safe
            failure: Exception | None = error
        else:
            failure = None
    messages = "".join(captured)
    if failure is not None:
        detail = _first_message(messages) or str(failure)
        raise GratNetError(
            f"cannot read volume file {source}: not a valid OpenEXR file or truncated ({detail})"
        ) from failure
    return _OpenedFile(exr, messages)


def _library_reason(opened: _OpenedFile) -> str:
    """``" (reason)"`` from the library's messages, or ``""``."""
    message = _first_message(opened.messages)
    return f" ({message})" if message else ""


def _first_message(messages: str) -> str:
    """The most specific line the library printed, without its file-name prefix.

    The core library's ``file: (EXR_ERR_...) text`` lines are preferred over the binding's generic
    ``Warning: Exception raised reading pixel data ...`` lines.
    """
    lines = [line.strip() for line in messages.splitlines() if line.strip()]
    for line in lines:
        if ": (EXR_ERR_" in line:
            return line.split(": ", 1)[1]
    return lines[0] if lines else ""


@contextlib.contextmanager
def _captured_library_output() -> Iterator[list[str]]:
    """Capture the OpenEXR library's chatter and yield a list that receives it when the block ends.

    The core C library prints diagnostics on file descriptor 2; the Python binding prints
    ``Warning: ...`` lines through Python's ``sys.stdout`` when it skips a part it cannot decode.
    Both are captured so that a bad file gives one clean ``GratNetError`` instead of a flood of
    lines. If descriptor 2 cannot be redirected, only the Python-level output is captured.
    """
    captured: list[str] = []
    python_output = io.StringIO()
    with contextlib.suppress(Exception):
        sys.stderr.flush()
    try:
        saved = os.dup(2)
    except OSError:
        saved = -1
    sink = tempfile.TemporaryFile() if saved >= 0 else None
    try:
        if sink is not None:
            os.dup2(sink.fileno(), 2)
        try:
            with contextlib.redirect_stdout(python_output):
                yield captured
        finally:
            if sink is not None:
                os.dup2(saved, 2)
                sink.seek(0)
                captured.append(sink.read().decode("utf-8", "replace"))
            captured.append(python_output.getvalue())
    finally:
        if saved >= 0:
            os.close(saved)
        if sink is not None:
            sink.close()


def _check_headers(source: Path, opened: _OpenedFile) -> tuple[list[str], dict[str, Any], int]:
    """Validate the part headers; return the part names, the metadata and the resolution ``R``."""
    parts = opened.parts
    if not parts:
        raise GratNetError(f"volume file {source} has no image parts{_library_reason(opened)}")
    first = parts[0].header
    if _FORMAT_ATTRIBUTE not in first:
        raise GratNetError(
            f"{source} is an OpenEXR file but not a GratNet volume (no '{_FORMAT_ATTRIBUTE}' header "
            f"attribute); write volumes with gratnet.volume.write_volume"
        )
    if first[_FORMAT_ATTRIBUTE] != FORMAT_NAME:
        raise GratNetError(
            f"{source} is not a GratNet volume: '{_FORMAT_ATTRIBUTE}' is "
            f"{first[_FORMAT_ATTRIBUTE]!r}, expected {FORMAT_NAME!r}"
        )
    version = first.get(_VERSION_ATTRIBUTE)
    if isinstance(version, bool) or not isinstance(version, int):
        raise GratNetError(
            f"volume file {source} has no valid '{_VERSION_ATTRIBUTE}' header attribute (got {version!r})"
        )
    if version != FORMAT_VERSION:
        newer = " (written by a newer GratNet; upgrade gratnet)" if version > FORMAT_VERSION else ""
        raise GratNetError(
            f"volume file {source} has format version {version}, but this GratNet reads only "
            f"format version {FORMAT_VERSION}{newer}"
        )

    metadata_json = first.get(_METADATA_ATTRIBUTE)
    if not isinstance(metadata_json, str):
        raise GratNetError(f"volume file {source} has no '{_METADATA_ATTRIBUTE}' header attribute")
    try:
        metadata = json.loads(metadata_json)
    except ValueError as error:
        raise GratNetError(f"volume file {source}: '{_METADATA_ATTRIBUTE}' is not valid JSON: {error}") from error
    if not isinstance(metadata, dict):
        raise GratNetError(f"volume file {source}: '{_METADATA_ATTRIBUTE}' is not a JSON object")

    declared = first.get(_SLICE_COUNT_ATTRIBUTE)
    if declared is not None and declared != len(parts):
        raise GratNetError(
            f"volume file {source} is truncated or corrupt: it declares {declared} slice(s) but "
            f"has {len(parts)} part(s)"
        )

    names: list[str] = []
    resolution = -1
    for index, part in enumerate(parts):
        name = part.name()
        header = part.header
        match = _PART_NAME_PATTERN.fullmatch(name)
        if match is None or int(match.group(1)) != index:
            raise GratNetError(
                f"volume file {source}: part {index} is named {name!r}, expected "
                f"{slice_part_name(index, len(parts))!r} (parts must be slice_00, slice_01, ... in order)"
            )
        if header.get(_SLICE_INDEX_ATTRIBUTE) != index:
            raise GratNetError(
                f"volume file {source}: part {name} has '{_SLICE_INDEX_ATTRIBUTE}' "
                f"{header.get(_SLICE_INDEX_ATTRIBUTE)!r}, expected {index}"
            )
        for attribute in (_FORMAT_ATTRIBUTE, _VERSION_ATTRIBUTE, _METADATA_ATTRIBUTE):
            if header.get(attribute) != first.get(attribute):
                raise GratNetError(
                    f"volume file {source}: part {name} disagrees with part {names[0] if names else name} "
                    f"on '{attribute}'"
                )
        storage = header.get("type", OpenEXR.scanlineimage)
        if storage not in (OpenEXR.scanlineimage, OpenEXR.tiledimage):
            raise GratNetError(f"volume file {source}: part {name} is a deep image ({storage})")
        size = _part_size(source, name, header)
        if resolution < 0:
            resolution = size
        elif size != resolution:
            raise GratNetError(
                f"volume file {source}: part {name} is {size} x {size} pixels but part {names[0]} "
                f"is {resolution} x {resolution}; all slices must be the same size"
            )
        channel_names = {channel.name for channel in header.get("channels", [])}
        missing = [c for c in CHANNELS if c not in channel_names]
        if missing:
            raise GratNetError(
                f"volume file {source}: part {name} lacks channel(s) {', '.join(missing)} "
                f"(has {', '.join(sorted(channel_names)) or 'none'}); expected X, Y, Z"
            )
        names.append(name)
    return names, metadata, resolution


def _part_size(source: Path, name: str, header: dict[str, Any]) -> int:
    """Side ``R`` of a part whose data window must be ``(0, 0) - (R-1, R-1)``."""
    window: Any = header.get("dataWindow")  # the file's: None or malformed raises below
    try:
        x0, y0 = (int(v) for v in window[0])
        x1, y1 = (int(v) for v in window[1])
    except (TypeError, ValueError, IndexError) as error:
        raise GratNetError(f"volume file {source}: part {name} has no valid data window") from error
    width, height = x1 - x0 + 1, y1 - y0 + 1
    if (x0, y0) != (0, 0) or width != height:
        raise GratNetError(
            f"volume file {source}: part {name} has data window ({x0}, {y0}) - ({x1}, {y1}); "
            f"expected (0, 0) - (R-1, R-1), a square starting at the origin"
        )
    if width < 2:
        raise GratNetError(f"volume file {source}: part {name} is {width} x {height} pixels (need R >= 2)")
    return width
