"""Height-field files: reading .npy/.npz, Gwyddion .gsf, PNG and EXR images; writing .npz and .gsf; previews.

Heights come out in µm with a square sample spacing ``dx_um`` (µm). Image files carry no physical
scale, so they need ``LoadOptions.dx_um`` (sample spacing) and ``LoadOptions.height_scale_um`` (the
height of image value 1.0, i.e. white). Loaded heights are kept as stored (not shifted to start at 0).
Names (generators, the paper's datasets) are resolved above this, by :func:`trainer.loaders.load_heightfield`.
"""

from __future__ import annotations

import dataclasses
import math
import os
import zipfile
import zlib
from pathlib import Path

import numpy as np

from gratnet.atomic import atomic_path
from gratnet.config import config_field
from gratnet.errors import GratNetError
from gratnet.figures import save_figure
from trainer.heightfield import HeightField

IMAGE_SUFFIXES = (".png", ".exr")
SUFFIXES = (".npy", ".npz", ".gsf", *IMAGE_SUFFIXES)
# Rec. 709 luminance weights, applied to the stored code values: height maps hold linear codes.
LUMINANCE_WEIGHTS = (0.2126, 0.7152, 0.0722)
GSF_MAGIC = b"Gwyddion Simple Field 1.0\n"
# Length units accepted in .gsf headers, in µm per unit.
GSF_UNITS_UM = {"m": 1e6, "mm": 1e3, "um": 1.0, "µm": 1.0, "μm": 1.0, "nm": 1e-3, "pm": 1e-6, "A": 1e-4, "Å": 1e-4}
# Relative difference between x and y sample spacings treated as square pixels.
SQUARE_TOLERANCE = 1e-6


@dataclasses.dataclass(frozen=True)
class LoadOptions:
    """How to read a height-field file (images carry no physical scale: give it here)."""

    dx_um: float | None = config_field(
        None, "sample spacing (µm); needed for .npy, .png and .exr; overrides the spacing stored in .npz/.gsf",
        flag="--dx-um",
    )
    height_scale_um: float | None = config_field(
        None, "height (µm) of image value 1.0 (white in 8/16-bit PNG); needed for .png and .exr",
        flag="--height-scale-um",
    )
    channel: str = config_field(
        "luminance", "image channel: 'luminance' (Rec. 709 of R,G,B; or the grey / Y / only channel) or a "
        "channel name (R, G, B, A; any EXR channel)", flag="--channel",
    )

    def __post_init__(self) -> None:
        for name in ("dx_um", "height_scale_um"):
            value = getattr(self, name)
            if value is None:
                continue
            if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
                raise GratNetError(f"{name} must be a number of µm, got {value!r}")
            if not (math.isfinite(value) and value > 0):
                raise GratNetError(f"{name} must be a positive number of µm, got {value!r}")
            object.__setattr__(self, name, float(value))
        if not isinstance(self.channel, str) or not self.channel:
            raise GratNetError(f"channel must be a non-empty name, got {self.channel!r}")


def read_heightfield_file(path: str | os.PathLike[str], options: LoadOptions | None = None) -> HeightField:
    """Read the height-field file at ``path`` (.npy, .npz, .gsf, .png, .exr; heights and spacing in µm)."""
    path = Path(path)
    options = options or LoadOptions()
    if not path.exists():
        raise GratNetError(f"no such file: {path}")
    if path.is_dir():
        raise GratNetError(f"{path} is a folder, not a height-field file")
    suffix = path.suffix.lower()
    readers = {".npy": _read_npy, ".npz": _read_npz, ".gsf": _read_gsf, ".png": _read_png, ".exr": _read_exr}
    if suffix not in readers:
        raise GratNetError(f"{path}: unknown height-field format {suffix or '(no extension)'!r}; "
                           f"supported: {', '.join(SUFFIXES)} or a generator name")
    try:
        if path.stat().st_size == 0:
            raise GratNetError(f"{path} is empty")
        return readers[suffix](path, options)
    except OSError as error:
        raise GratNetError(f"cannot read {path}: {error.strerror or error}") from error


def _needs_dx(path: Path, options: LoadOptions, how: str) -> float:
    if options.dx_um is None:
        raise GratNetError(f"{path}: the sample spacing is unknown; give it with --dx-um (µm){how}")
    return options.dx_um


# ---------------------------------------------------------------------------------------------------
# NumPy


def _read_npy(path: Path, options: LoadOptions) -> HeightField:
    dx = _needs_dx(path, options, " or save the field as .npz with a dx_um entry")
    try:
        heights = np.load(path, allow_pickle=False)
    except (ValueError, EOFError) as error:
        raise GratNetError(f"{path}: not a readable .npy array ({error})") from error
    if not isinstance(heights, np.ndarray):  # np.load also opens .npz archives
        heights.close()
        raise GratNetError(f"{path}: holds a .npz archive, not a .npy array; rename it to .npz")
    return HeightField(heights, dx, f"file:{path}")


def _read_npz(path: Path, options: LoadOptions) -> HeightField:
    with open(path, "rb") as handle:
        if handle.read(2) != b"PK":  # zip magic: np.load would otherwise try other formats
            raise GratNetError(f"{path}: not a .npz (zip) archive")
    try:
        with np.load(path, allow_pickle=False) as archive:
            keys = list(archive.keys())
            if "heights_um" not in keys:
                raise GratNetError(f"{path}: no 'heights_um' array (µm) in the archive; it holds {keys}")
            heights = archive["heights_um"]
            stored_dx = np.asarray(archive["dx_um"]) if "dx_um" in keys else None
            stored_source = str(archive["source"]) if "source" in keys else None
    except (ValueError, EOFError, zipfile.BadZipFile, zlib.error) as error:
        raise GratNetError(f"{path}: not a readable .npz archive ({error})") from error
    if options.dx_um is not None:
        dx = options.dx_um
    elif stored_dx is not None:
        if stored_dx.size != 1:
            raise GratNetError(f"{path}: dx_um must be a single number (µm), got shape {stored_dx.shape}")
        try:
            dx = float(stored_dx.reshape(()))
        except (TypeError, ValueError):  # a string or other non-number stored as dx_um
            raise GratNetError(f"{path}: dx_um must be a number (µm), got {stored_dx.reshape(()).item()!r}") from None
    else:
        dx = _needs_dx(path, options, " or store a dx_um entry in the archive")
    source = f"file:{path}" + (f" ({stored_source})" if stored_source else "")
    return HeightField(heights, dx, source)


def save_heightfield(path: str | os.PathLike[str], field: HeightField) -> None:
    """Save ``field`` atomically as .npz (heights_um float64, dx_um, source) or as .gsf."""
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix == ".gsf":
        write_gsf(path, field)
        return
    if suffix != ".npz":
        raise GratNetError(f"{path}: height fields are saved as .npz or .gsf, not {suffix or '(no extension)'!r}")
    with atomic_path(path) as temporary, open(temporary, "wb") as handle:
        np.savez_compressed(
            handle, heights_um=np.asarray(field.heights_um, np.float64), dx_um=np.float64(field.dx_um),
            source=np.str_(field.source),
        )


# ---------------------------------------------------------------------------------------------------
# Gwyddion Simple Field


def _gsf_unit(path: Path, header: dict[str, str], key: str) -> float:
    """µm per unit of header entry ``key`` (metres when absent or empty)."""
    unit = header.get(key, "").strip() or "m"
    if unit not in GSF_UNITS_UM:
        raise GratNetError(f"{path}: unsupported {key} {unit!r}; supported: {', '.join(GSF_UNITS_UM)}")
    return GSF_UNITS_UM[unit]


def _gsf_number(path: Path, header: dict[str, str], key: str, kind: type) -> float | None:
    if key not in header:
        return None
    try:
        value = kind(header[key])
    except ValueError:
        raise GratNetError(f"{path}: header entry {key} = {header[key]!r} is not a valid number") from None
    if not (math.isfinite(value) and value > 0):
        raise GratNetError(f"{path}: header entry {key} must be positive, got {header[key]!r}")
    return value


def _read_gsf(path: Path, options: LoadOptions) -> HeightField:
    data = path.read_bytes()
    if not data.startswith(GSF_MAGIC):
        raise GratNetError(f"{path}: not a Gwyddion Simple Field file (the first line must be "
                           f"'Gwyddion Simple Field 1.0')")
    end = data.find(b"\0")
    if end < 0:
        raise GratNetError(f"{path}: the header has no NUL terminator (truncated file?)")
    header: dict[str, str] = {}
    for line in data[len(GSF_MAGIC):end].decode("utf-8", errors="replace").splitlines():
        if not line.strip():
            continue
        name, equals, value = line.partition("=")
        if not equals:
            raise GratNetError(f"{path}: malformed header line {line.strip()!r} (expected 'Name = Value')")
        header[name.strip()] = value.strip()
    columns = _gsf_number(path, header, "XRes", int)
    rows = _gsf_number(path, header, "YRes", int)
    if columns is None or rows is None:
        raise GratNetError(f"{path}: the header must give XRes and YRes (samples per row and rows)")
    columns, rows = int(columns), int(rows)
    # One to four NULs end the header so that the data start at a multiple of 4 bytes.
    start = (end // 4 + 1) * 4
    expected = rows * columns * 4
    available = len(data) - start
    if available != expected:
        state = "truncated" if available < expected else "longer than its header says"
        raise GratNetError(f"{path}: file {state}: XRes × YRes = {columns} × {rows} needs {expected} data bytes, "
                           f"found {max(available, 0)}")
    z_scale = _gsf_unit(path, header, "ZUnits")
    heights = np.frombuffer(data, "<f4", rows * columns, start).reshape(rows, columns).astype(np.float64) * z_scale
    source = f"file:{path}"
    if options.dx_um is not None:
        return HeightField(heights, options.dx_um, source)
    lateral = _gsf_unit(path, header, "XYUnits")
    x_real = _gsf_number(path, header, "XReal", float)
    y_real = _gsf_number(path, header, "YReal", float)
    # A single given extent is taken to imply square pixels.
    if x_real is not None:
        dx = x_real * lateral / columns
    elif y_real is not None:
        dx = y_real * lateral / rows
    else:
        dx = _needs_dx(path, options, " (the header gives no XReal/YReal)")
    dy = y_real * lateral / rows if y_real is not None else dx
    if abs(dx - dy) > SQUARE_TOLERANCE * max(dx, dy):
        heights, source = _square_pixels(heights, dx, dy, source)
    return HeightField(heights, min(dx, dy), source)


def _square_pixels(heights: np.ndarray, dx: float, dy: float, source: str) -> tuple[np.ndarray, str]:
    """Resample the coarser axis (cubic spline) to the finer spacing, keeping the lateral extent."""
    from scipy import ndimage

    spacing = min(dx, dy)
    rows, columns = heights.shape
    new_rows = max(2, round(rows * dy / spacing))
    new_columns = max(2, round(columns * dx / spacing))
    # Sample centres of the new grid in old-sample units (centred on the same extent).
    y = ((np.arange(new_rows) - (new_rows - 1) / 2) * spacing + rows * dy / 2) / dy - 0.5
    x = ((np.arange(new_columns) - (new_columns - 1) / 2) * spacing + columns * dx / 2) / dx - 0.5
    grid_y, grid_x = np.meshgrid(y, x, indexing="ij")
    resampled = ndimage.map_coordinates(heights, [grid_y, grid_x], order=3, mode="nearest")
    note = f" [non-square pixels {dx:.4g} × {dy:.4g} µm resampled to square {spacing:.4g} µm]"
    return resampled, source + note


def write_gsf(path: str | os.PathLike[str], field: HeightField) -> None:
    """Write ``field`` atomically as a Gwyddion Simple Field file (lengths and heights in metres)."""
    path = Path(path)
    rows, columns = field.shape
    title = field.source.replace("\n", " ").replace("\0", " ")
    lines = [
        "Gwyddion Simple Field 1.0",
        f"XRes = {columns}",
        f"YRes = {rows}",
        f"XReal = {columns * field.dx_um * 1e-6!r}",
        f"YReal = {rows * field.dx_um * 1e-6!r}",
        "XYUnits = m",
        "ZUnits = m",
        f"Title = {title}",
    ]
    header = ("\n".join(lines) + "\n").encode("utf-8")
    header += b"\0" * (4 - len(header) % 4)
    with atomic_path(path) as temporary:
        temporary.write_bytes(header + (field.heights_um * 1e-6).astype("<f4").tobytes())


# ---------------------------------------------------------------------------------------------------
# Images


def _image_scale(path: Path, options: LoadOptions) -> tuple[float, float]:
    """(dx in µm, height in µm of value 1.0), both required for images."""
    dx, scale = options.dx_um, options.height_scale_um
    if dx is None or scale is None:
        missing = [flag for flag, value in (("--dx-um", dx), ("--height-scale-um", scale)) if value is None]
        raise GratNetError(f"{path}: an image has no physical scale; give {' and '.join(missing)} "
                           f"(sample spacing in µm; height in µm of value 1.0 / white)")
    return dx, scale


def _pick_channel(path: Path, channels: dict[str, np.ndarray], wanted: str) -> np.ndarray:
    """The channel ``wanted`` ('luminance' or a name) from named channel arrays."""
    if wanted.lower() == "luminance":
        for name in ("Y", "L"):
            if name in channels:
                return channels[name]
        if all(name in channels for name in "RGB"):
            red, green, blue = (weight * channels[name] for weight, name in zip(LUMINANCE_WEIGHTS, "RGB", strict=True))
            return red + green + blue
        if len(channels) == 1:
            return next(iter(channels.values()))
        raise GratNetError(f"{path}: cannot form a luminance from channels {sorted(channels)}; "
                           f"pick one with --channel")
    if wanted not in channels:
        raise GratNetError(f"{path}: no channel {wanted!r}; it has {sorted(channels)} (or use 'luminance')")
    return channels[wanted]


def _read_png(path: Path, options: LoadOptions) -> HeightField:
    # pypng keeps every bit depth (Pillow cuts 16-bit colour and grey+alpha PNGs to 8 bits).
    import png

    dx, scale = _image_scale(path, options)
    try:
        columns, rows, row_iterator, info = png.Reader(filename=str(path)).asDirect()
        pixels = np.vstack([np.asarray(row, dtype=np.float64) for row in row_iterator])
    except (png.Error, OSError, ValueError, EOFError, zlib.error) as error:
        raise GratNetError(f"{path}: not a readable PNG image ({error})") from error
    planes = int(info["planes"])
    if pixels.shape != (rows, columns * planes):
        raise GratNetError(f"{path}: truncated PNG data ({pixels.shape[0]} of {rows} rows)")
    pixels = pixels.reshape(rows, columns, planes) / float(2 ** int(info["bitdepth"]) - 1)
    names = ("L" if info["greyscale"] else "RGB") + ("A" if info["alpha"] else "")
    channels = {name: pixels[..., index] for index, name in enumerate(names)}
    if "L" in channels:  # a grey image answers for any of R, G, B
        channels.update({name: channels["L"] for name in "RGB"})
    wanted = options.channel if options.channel.lower() == "luminance" else options.channel.upper()
    values = _pick_channel(path, channels, wanted)
    return HeightField(values * scale, dx, f"file:{path} [{options.channel}, 1.0 = {scale:g} µm]")


def _read_exr(path: Path, options: LoadOptions) -> HeightField:
    import OpenEXR

    dx, scale = _image_scale(path, options)
    try:
        with OpenEXR.File(str(path), separate_channels=True) as exr:
            channels = {name: np.asarray(channel.pixels, np.float64) for name, channel in exr.channels().items()}
    except (RuntimeError, OSError, ValueError, TypeError) as error:
        raise GratNetError(f"{path}: not a readable OpenEXR image ({error})") from error
    if not channels:
        raise GratNetError(f"{path}: the EXR image has no channels")
    values = _pick_channel(path, channels, options.channel)
    return HeightField(values * scale, dx, f"file:{path} [{options.channel}, 1.0 = {scale:g} µm]")


# ---------------------------------------------------------------------------------------------------
# Preview


def preview_png(field: HeightField, path: str | os.PathLike[str]) -> None:
    """Write a colour-mapped PNG of ``field`` atomically: axes in µm, colour bar of heights in µm."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    path = Path(path)
    if path.suffix.lower() != ".png":
        raise GratNetError(f"{path}: previews are written as .png")
    width, height = field.size_um
    half = field.dx_um / 2  # samples sit at ix·dx: pixel edges half a sample either side
    figure = Figure(figsize=(6.4, 5.2), dpi=100, layout="constrained")
    FigureCanvasAgg(figure)
    axes = figure.add_subplot()
    image = axes.imshow(field.heights_um, cmap="viridis", extent=(-half, width - half, height - half, -half))
    figure.colorbar(image, ax=axes, label="height (µm)")
    axes.set_xlabel("x (µm)")
    axes.set_ylabel("y (µm)")
    title = field.source if len(field.source) <= 90 else field.source[:87] + "…"
    axes.set_title(title, fontsize=7)
    save_figure(figure, path)
