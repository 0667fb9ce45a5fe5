"""Environment light as data (issue 43): a lat-long radiance map, its lookup, its importance distribution, and the
specs that load one (``none``, ``sky``, ``studio``, a constant, an OpenEXR or Radiance .hdr file).

This module is the contract that the GL runtime's GLSL and ``gratnet mitsuba-render`` (Mitsuba 3's ``envmap``)
reproduce; tests/contract/test_environment.py and tests/runtime/test_mitsuba_environment.py tie them.

**The map.** ``radiance_map[row, column]`` is ``float32 (H, W, 3)``, ``W == 2·H``: **linear sRGB radiance**
(Rec. 709 primaries, D65 white; W·m⁻²·sr⁻¹ in relative units, times :attr:`Environment.scale`).

**Frame.** GratNet's world has +z up. The map is placed exactly as Mitsuba 3's ``envmap`` emitter with
``to_world = Rz(rotation) · Rx(+90°)`` places it (Rx(90°) turns Mitsuba's +y up into +z). For a unit world
direction ``g`` and rotation ρ (radians, about +z, counter-clockwise seen from above):

    g' = Rz(−ρ)·g = ( cos ρ·gx + sin ρ·gy,  −sin ρ·gx + cos ρ·gy,  gz )
    x  = atan2(g'x, g'y) / 2π,  then x −= floor(x)          (x ∈ [0, 1): the column axis, azimuth)
    y  = acos(clamp(g'z, −1, 1)) / π                         (y ∈ [0, 1]: the row axis, 0 = zenith +z)

and back: ``g' = (sin πy · sin 2πx, sin πy · cos 2πx, cos πy)``, ``g = Rz(ρ)·g'``. So x = 0 looks along +y
(before rotation), x = 0.25 along +x; a feature at map x has GratNet azimuth ``φ = 90° − 360°·x + ρ`` (φ from
+x towards +y, as ``--light θ,φ``), and rotating by +ρ turns the whole sky by +ρ in φ.

**Lookup** (:meth:`Environment.radiance`; Mitsuba's ``EnvironmentMapEmitter::eval_spectrum``, src/emitters/
envmap.cpp). With ``M`` the map, ``W`` its width and ``H`` its height:

    u  = x − 0.5/W;  u −= floor(u);  s = u·W                 (s ∈ [0, W))
    i0 = min(floor(s), W − 1);  fx = s − i0;  i1 = i0 + 1, or 0 when i0 + 1 == W     (horizontal wrap)
    t  = y·(H − 1)                                           (t ∈ [0, H − 1])
    j0 = min(floor(t), H − 2);  fy = t − j0;  j1 = j0 + 1                             (no clamp needed)
    L  = scale · [ (1−fy)·((1−fx)·M[j0,i0] + fx·M[j0,i1]) + fy·((1−fx)·M[j1,i0] + fx·M[j1,i1]) ]

So texel ``(r, c)`` is met exactly at ``x = (c + 0.5)/W`` (pixel centres, wrapping horizontally) and
``y = r/(H − 1)`` (row 0 *at* the zenith, row H − 1 *at* the nadir: corner-aligned vertically, unlike the
columns). In GLSL this is a GL_LINEAR texture with REPEAT along s and CLAMP_TO_EDGE along t read at
``(x, (t + 0.5)/H)``, up to the texture unit's 8-bit weights. One deliberate difference from Mitsuba: at
exactly ``y = 1`` (the nadir) Mitsuba's ``uv −= floor(uv)`` wraps y to 0 and returns the zenith row; here the
nadir row (the limit from every side).

**Distribution** (:meth:`Environment.distribution`): a :class:`gratnet.sampling2d.PiecewiseConstant2D` over the
same unit square ``(x, y)``, with ``R = H − 1`` rows and ``C = W`` columns: cell ``(j, c)`` covers
``y ∈ [j/(H−1), (j+1)/(H−1))`` (exactly the lookup's rows j, j + 1) and ``x ∈ [c/W, (c+1)/W)`` (whose lookups
read columns c − 1, c, c + 1 mod W). Its weight is

    w[j, c] = max over rows {j, j+1} and columns {c−1, c, c+1} (mod W) of Y(M[row, column]) · sin(π·(j + 0.5)/(H − 1))

with ``Y = 0.2126 R + 0.7152 G + 0.0722 B`` (float64) of the *unscaled* map (a uniform scale does not change a
normalised distribution, and scale 0 keeps one). The max makes the weight positive wherever the bilinear
radiance can be positive inside the cell, so no lit direction has density 0. The solid-angle density is
``pdf(ω) = p(x, y) / (2π² sin θ)``, ``sin θ = sqrt(gx² + gy²)`` (0 where sin θ = 0).

Standard library at import (numpy, OpenEXR and :mod:`gratnet.sampling2d` when a function runs).
"""

from __future__ import annotations

import dataclasses
import functools
import math
import re
from pathlib import Path
from typing import TYPE_CHECKING, Any

from gratnet.errors import GratNetError, read_magic

if TYPE_CHECKING:
    import numpy as np

    from gratnet.sampling2d import PiecewiseConstant2D

__all__ = ["CONSTANT_SHAPE", "ENVIRONMENTS_FOLDER", "LUMINANCE_WEIGHTS", "MAX_HEIGHT", "MIN_HEIGHT",
           "SHIPPED_ENVIRONMENTS", "Environment", "check_radiance_map", "constant_environment", "load_environment",
           "read_radiance_map", "texel_coordinates"]

#: The shipped maps (``--environment sky|studio``): ``assets/environments/NAME.exr`` (README.md there).
ENVIRONMENTS_FOLDER = Path(__file__).resolve().parents[1] / "assets" / "environments"
SHIPPED_ENVIRONMENTS = ("sky", "studio")

#: CIE Y of linear sRGB (Rec. 709 primaries, D65).
LUMINANCE_WEIGHTS = (0.2126, 0.7152, 0.0722)

#: Smallest and largest map heights (width = 2 · height). Mitsuba's envmap needs ≥ 3 rows; 4 × 8 is the least
#: that still has two rows of cells per hemisphere. 4096 × 8192 (384 MiB of float32 RGB; the distribution takes
#: about 1 GiB more while it is built) admits the common "8K" HDRIs, and W + 1 = 8193 columns of the
#: conditional CDF fit GL's minimum texture size (16384).
MIN_HEIGHT = 4
MAX_HEIGHT = 4096

#: The constant environment's map (rows, columns): enough rows for a near-uniform distribution.
CONSTANT_SHAPE = (32, 64)

_SPEC_FORMS = "none, sky, studio, a radiance ≥ 0, R,G,B (linear sRGB) or an .exr/.hdr lat-long map"


@dataclasses.dataclass(frozen=True, eq=False)
class Environment:
    """An environment light: a lat-long map of linear sRGB radiance around GratNet's world (module docstring).

    Attributes:
        name: ``sky``, ``studio``, ``constant`` or the file's path, for messages and configs.
        radiance_map: ``float32 (H, W, 3)``, W = 2H, finite, ≥ 0, not all 0: linear sRGB radiance (W·m⁻²·sr⁻¹,
            relative units) before ``scale``; read-only.
        rotation_degrees: turn of the map about world +z (degrees, counter-clockwise seen from above).
        scale: factor on the radiance (≥ 0).
        source: provenance, one line.

    Equality is identity (the map is an array); the distribution is built once, on first use.
    """

    name: str
    radiance_map: np.ndarray
    rotation_degrees: float = 0.0
    scale: float = 1.0
    source: str = ""

    def __post_init__(self) -> None:
        import numpy as np

        _check_rotation_and_scale(self.rotation_degrees, self.scale)
        values = np.array(self.radiance_map, dtype=np.float32, copy=True, order="C")
        check_radiance_map(values, self.name)
        values.setflags(write=False)
        object.__setattr__(self, "radiance_map", values)
        object.__setattr__(self, "rotation_degrees", float(self.rotation_degrees))
        object.__setattr__(self, "scale", float(self.scale))

    @property
    def shape(self) -> tuple[int, int]:
        """``(H, W)``: the map's rows and columns."""
        height, width = self.radiance_map.shape[:2]
        return int(height), int(width)

    def _rotation(self) -> tuple[float, float]:
        """(cos ρ, sin ρ); exact at multiples of 90° so that those turns move texels exactly."""
        quarter, remainder = divmod(self.rotation_degrees, 90.0)
        if remainder == 0.0:
            return ((1.0, 0.0), (0.0, 1.0), (-1.0, 0.0), (0.0, -1.0))[int(quarter) % 4]
        angle = math.radians(self.rotation_degrees)
        return math.cos(angle), math.sin(angle)

    def map_coordinates(self, directions: object) -> tuple[np.ndarray, np.ndarray]:
        """``(x, y)`` in ``[0, 1) × [0, 1]`` (float64) of unit world directions ``(..., 3)`` (module docstring)."""
        import numpy as np

        g = np.asarray(directions, dtype=np.float64)
        cos_r, sin_r = self._rotation()
        gx = cos_r * g[..., 0] + sin_r * g[..., 1]
        gy = -sin_r * g[..., 0] + cos_r * g[..., 1]
        x = np.arctan2(gx, gy) / (2.0 * np.pi)
        x = x - np.floor(x)
        x = np.where(x >= 1.0, 0.0, x)  # −tiny/2π + 1 rounds to 1
        y = np.arccos(np.clip(g[..., 2], -1.0, 1.0)) / np.pi
        return x, y

    def directions(self, x: object, y: object) -> np.ndarray:
        """Unit world directions ``(..., 3)`` (float64) at map coordinates ``(x, y)`` (broadcast)."""
        import numpy as np

        xs, ys = np.broadcast_arrays(np.asarray(x, dtype=np.float64), np.asarray(y, dtype=np.float64))
        theta, phi = np.pi * ys, 2.0 * np.pi * xs
        sin_theta = np.sin(theta)
        local_x, local_y, z = sin_theta * np.sin(phi), sin_theta * np.cos(phi), np.cos(theta)
        cos_r, sin_r = self._rotation()
        return np.stack([cos_r * local_x - sin_r * local_y, sin_r * local_x + cos_r * local_y, z], axis=-1)

    def radiance(self, directions: object) -> np.ndarray:
        """Linear sRGB radiance ``(..., 3)`` (float64, scaled) seen looking along unit world ``directions``
        ``(..., 3)``: the bilinear lookup of the module docstring, as Mitsuba's ``envmap.eval`` computes it."""
        import numpy as np

        x, y = self.map_coordinates(directions)
        height, width = self.shape
        u = x - 0.5 / width
        s = (u - np.floor(u)) * width
        i0 = np.minimum(np.floor(s), width - 1).astype(np.int64)
        fx = (s - i0)[..., None]
        i1 = np.where(i0 + 1 == width, 0, i0 + 1)
        t = y * (height - 1)
        j0 = np.minimum(np.floor(t), height - 2).astype(np.int64)
        fy = (t - j0)[..., None]
        m = self.radiance_map
        top = (1.0 - fx) * m[j0, i0] + fx * m[j0, i1]
        bottom = (1.0 - fx) * m[j0 + 1, i0] + fx * m[j0 + 1, i1]
        return ((1.0 - fy) * top + fy * bottom) * self.scale

    def brightest_azimuth_degrees(self) -> float:
        """The world azimuth (degrees from +x towards +y, in (−180, 180]) of the map's brightest texel (CIE Y of the
        linear sRGB radiance) above the horizon, as the map is turned now: where its sun or key light stands."""
        import numpy as np

        luminance = self.radiance_map.astype(np.float64) @ np.asarray(LUMINANCE_WEIGHTS)
        height, width = self.shape
        x, y = texel_coordinates(height, width)
        luminance = np.where(y < 0.5, luminance, -1.0)  # above the horizon: a light that can reach a surface
        row, column = np.unravel_index(int(np.argmax(luminance)), luminance.shape)
        direction = self.directions(x[row, column], y[row, column])
        return float(np.degrees(np.arctan2(direction[1], direction[0])))

    def distribution(self) -> PiecewiseConstant2D:
        """The importance distribution over ``(x, y)``: ``(H − 1) × W`` cells, weights of the module docstring."""
        return self._distribution

    @functools.cached_property
    def _distribution(self) -> PiecewiseConstant2D:
        import numpy as np

        from gratnet.sampling2d import PiecewiseConstant2D

        luminance = self.radiance_map.astype(np.float64) @ np.asarray(LUMINANCE_WEIGHTS)
        rows = np.maximum(luminance[:-1], luminance[1:])  # rows j and j + 1 of cell row j
        cells = np.maximum(np.maximum(np.roll(rows, 1, axis=1), rows), np.roll(rows, -1, axis=1))
        height = self.shape[0]
        sin_theta = np.sin(np.pi * (np.arange(height - 1) + 0.5) / (height - 1))
        return PiecewiseConstant2D.from_weights(cells * sin_theta[:, None])

    def pdf(self, directions: object) -> np.ndarray:
        """Solid-angle density (sr⁻¹, float64) of :meth:`sample` at unit world ``directions`` ``(..., 3)``."""
        import numpy as np

        g = np.asarray(directions, dtype=np.float64)
        x, y = self.map_coordinates(g)
        sin_theta = np.hypot(g[..., 0], g[..., 1])
        density = self.distribution().pdf(x, y)
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.where(sin_theta > 0.0, density / (2.0 * np.pi**2 * sin_theta), 0.0)

    def sample(self, xi_row: object, xi_column: object) -> tuple[np.ndarray, np.ndarray]:
        """Directions drawn for uniform numbers in [0, 1) (broadcast): ``(directions (..., 3), pdf (...))``, the
        unit world directions and their solid-angle density (sr⁻¹; 0 only on the poles' measure-zero rims)."""
        import numpy as np

        x, y, density = self.distribution().sample(xi_row, xi_column)
        sin_theta = np.sin(np.pi * y)
        with np.errstate(divide="ignore", invalid="ignore"):
            pdf = np.where(sin_theta > 0.0, density / (2.0 * np.pi**2 * sin_theta), 0.0)
        return self.directions(x, y), pdf


def texel_coordinates(height: int, width: int) -> tuple[np.ndarray, np.ndarray]:
    """``(x, y)`` grids ``(H, W)`` where the lookup returns texel ``(r, c)`` exactly: ``x = (c + 0.5)/W``,
    ``y = r/(H − 1)``. A generator that evaluates radiance there makes the map that reproduces it."""
    import numpy as np

    x = (np.arange(width) + 0.5) / width
    y = np.arange(height) / (height - 1)
    return np.broadcast_to(x[None, :], (height, width)), np.broadcast_to(y[:, None], (height, width))


# ----------------------------------------------------------------------------------------------
# Checks


def _check_rotation_and_scale(rotation_degrees: object, scale: object) -> None:
    try:
        rotation, factor = float(rotation_degrees), float(scale)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        raise GratNetError(f"environment rotation and scale must be numbers, got {rotation_degrees!r}, "
                           f"{scale!r}") from None
    if not math.isfinite(rotation):
        raise GratNetError(f"environment rotation must be a finite number of degrees, got {rotation_degrees!r}")
    if not (math.isfinite(factor) and factor >= 0.0):
        raise GratNetError(f"environment scale must be a finite number ≥ 0, got {scale!r}")


def _check_shape(height: int, width: int, what: str) -> None:
    """Aspect and size, from the header alone (before any pixel is read)."""
    if width != 2 * height:
        raise GratNetError(f"{what} must be a lat-long map twice as wide as high, got {width}×{height} (W×H)")
    if height < MIN_HEIGHT:
        raise GratNetError(f"{what} is {width}×{height} (W×H): at least {2 * MIN_HEIGHT}×{MIN_HEIGHT} is needed")
    if height > MAX_HEIGHT:
        raise GratNetError(f"{what} is {width}×{height} (W×H): at most {2 * MAX_HEIGHT}×{MAX_HEIGHT} is supported; "
                           "downsample it")


def check_radiance_map(values: np.ndarray, what: str = "environment map") -> None:
    """Refuse (one-line GratNetError naming ``what``) a map that is not ``(H, W, 3)`` 2:1 within the size limits,
    holds NaN, inf or negative values (the first such texel is named: row, column, channel) or is all 0."""
    import numpy as np

    if values.ndim != 3 or values.shape[2] != 3:
        raise GratNetError(f"{what} must be an (H, W, 3) RGB array, got shape {values.shape}")
    _check_shape(int(values.shape[0]), int(values.shape[1]), what)
    bad = ~np.isfinite(values) | (values < 0.0)
    if bad.any():
        row, column, channel = (int(i) for i in np.argwhere(bad)[0])
        raise GratNetError(f"{what} has {values[row, column, channel]!r} at row {row}, column {column}, channel "
                           f"{'RGB'[channel]}: radiance must be finite and ≥ 0")
    if not values.any():
        raise GratNetError(f"{what} is all 0: it emits nothing and has nothing to sample (use none)")


# ----------------------------------------------------------------------------------------------
# Specs and files


def constant_environment(rgb: tuple[float, float, float], rotation_degrees: float = 0.0,
                         scale: float = 1.0) -> Environment:
    """A constant linear sRGB radiance everywhere, as a :data:`CONSTANT_SHAPE` map (the one code path)."""
    import numpy as np

    values = np.empty((*CONSTANT_SHAPE, 3), dtype=np.float32)
    values[...] = np.asarray(rgb, dtype=np.float32)
    text = ",".join(f"{float(v):g}" for v in rgb)
    return Environment("constant", values, rotation_degrees, scale, f"constant linear sRGB radiance {text}")


def load_environment(spec: str, rotation_degrees: float = 0.0, scale: float = 1.0, *,
                     what: str = "environment") -> Environment | None:
    """The environment a spec names, or None for ``none`` (also for a constant 0: it emits nothing).

    ``spec``: ``none``; ``sky`` or ``studio`` (assets/environments/); one number ≥ 0 (grey constant radiance);
    ``R,G,B`` (constant linear sRGB); or the path of an OpenEXR ``.exr`` (channels R, G, B; half or float) or a
    Radiance ``.hdr`` (RGBE) lat-long map, linear sRGB. Everything is checked (a one-line GratNetError) before
    the pixels are read: rotation and scale, then the file's header (aspect 2:1, size), then the pixels.
    ``what`` starts the messages about the spec itself (a command passes its flag, ``--environment``).
    """
    _check_rotation_and_scale(rotation_degrees, scale)
    text = str(spec).strip()
    if text.lower() in ("", "none"):
        return None
    if text.lower() in SHIPPED_ENVIRONMENTS:
        path = ENVIRONMENTS_FOLDER / f"{text.lower()}.exr"
        values, source = read_radiance_map(path)
        return Environment(text.lower(), values, rotation_degrees, scale, source)
    values_text = _numbers(text)
    if values_text is not None:
        if len(values_text) not in (1, 3) or not all(math.isfinite(v) and v >= 0.0 for v in values_text):
            raise GratNetError(f"{what} expects {_SPEC_FORMS}, got {text!r}")
        if max(values_text) >= 3e38:
            raise GratNetError(f"{what} radiance {text!r} does not fit a float32")
        rgb = (values_text[0],) * 3 if len(values_text) == 1 else (values_text[0], values_text[1], values_text[2])
        if max(rgb) == 0.0:
            return None
        return constant_environment(rgb, rotation_degrees, scale)
    path = Path(text).expanduser()
    if path.suffix.lower() not in (".exr", ".hdr"):
        raise GratNetError(f"{what} expects {_SPEC_FORMS}, got {text!r}")
    values, source = read_radiance_map(path)
    return Environment(str(path), values, rotation_degrees, scale, source)


def _numbers(text: str) -> list[float] | None:
    try:
        return [float(part) for part in text.split(",")]
    except ValueError:
        return None


def read_radiance_map(path: str | Path) -> tuple[np.ndarray, str]:
    """A checked lat-long map ``float32 (H, W, 3)`` from an ``.exr`` or ``.hdr`` file, and its provenance line
    (an EXR's ``gratnet_source`` attribute where the generator wrote one)."""
    source = Path(path)
    suffix = source.suffix.lower()
    what = f"environment map {source}"
    if suffix == ".exr":
        magic = read_magic(source, "environment map", 4)
        if magic != b"\x76\x2f\x31\x01":
            raise GratNetError(f"{what} is not an OpenEXR file (wrong magic number)")
        values, provenance = _read_exr(source, what)
    elif suffix == ".hdr":
        values, provenance = _read_hdr(source, what)
    else:
        raise GratNetError(f"{what}: only .exr and .hdr files are read")
    check_radiance_map(values, what)
    return values, provenance


def _read_exr(source: Path, what: str) -> tuple[np.ndarray, str]:
    import numpy as np
    import OpenEXR

    def opened(header_only: bool) -> Any:
        try:
            return OpenEXR.File(str(source), separate_channels=True, header_only=header_only)
        except Exception as error:  # the binding raises RuntimeError on a bad file; be safe
            raise GratNetError(f"cannot read {what}: not a valid OpenEXR file or truncated ({error})") from error

    parts = list(opened(True).parts)
    if not parts:
        raise GratNetError(f"{what} has no image part")
    header = parts[0].header
    try:
        low, high = (np.asarray(corner, dtype=np.int64) for corner in header["dataWindow"])
        width, height = (int(v) for v in high - low + 1)
    except (KeyError, TypeError, ValueError) as error:
        raise GratNetError(f"{what} has no readable data window") from error
    _check_shape(height, width, what)  # before the pixels
    channels = opened(False).parts[0].channels
    planes = []
    for name in "RGB":
        channel = channels.get(name)
        pixels = None if channel is None else channel.pixels
        if pixels is None:
            raise GratNetError(f"{what} has no {name} channel (R, G and B are needed; it has "
                               f"{', '.join(sorted(channels)) or 'none'})")
        if pixels.dtype.kind != "f" or pixels.shape != (height, width):
            raise GratNetError(f"{what}: channel {name} is not {width}×{height} half or float pixels "
                               f"({pixels.dtype}, {pixels.shape})")
        planes.append(pixels)
    provenance = header.get("gratnet_source")
    text = provenance if isinstance(provenance, str) else f"file {source}"
    return np.stack(planes, axis=-1).astype(np.float32), text


#: Radiance's resolution line for the standard orientation (rows top to bottom, columns left to right).
_HDR_RESOLUTION = re.compile(rb"^-Y (\d+) \+X (\d+)$")


def _read_hdr(source: Path, what: str) -> tuple[np.ndarray, str]:
    """A Radiance RGBE picture: header lines up to a blank one, the resolution line, then scanlines (flat or
    new-style run-length encoded). Decoded as ``mantissa · 2^(exponent − 136)`` (Walter's rgbe.c, stb_image);
    EXPOSURE and COLORCORR lines are ignored, as Mitsuba ignores them. Other orientations and XYZE are refused."""
    import numpy as np

    read_magic(source, "environment map", 2)  # exists, is a file, is readable
    try:
        data = source.read_bytes()
    except OSError as error:
        raise GratNetError(f"cannot read {what}: {error.strerror or error}") from error
    if not (data.startswith(b"#?") and b"\n\n" in data[:65536]):
        raise GratNetError(f"{what} is not a Radiance .hdr file (no '#?' header ending in a blank line)")
    header_end = data.index(b"\n\n") + 2
    lines = data[:header_end].split(b"\n")
    formats = [line.split(b"=", 1)[1].strip() for line in lines if line.startswith(b"FORMAT=")]
    if formats and formats[-1] != b"32-bit_rle_rgbe":
        raise GratNetError(f"{what} has FORMAT={formats[-1].decode('ascii', 'replace')}; only 32-bit_rle_rgbe "
                           "(RGB) is read")
    line_end = data.find(b"\n", header_end)
    match = _HDR_RESOLUTION.match(data[header_end:line_end].strip()) if line_end > 0 else None
    if match is None:
        raise GratNetError(f"{what}: the resolution line must read '-Y HEIGHT +X WIDTH' (other orientations are "
                           "not read)")
    height, width = int(match.group(1)), int(match.group(2))
    _check_shape(height, width, what)  # before the pixels
    rgbe = _decode_scanlines(memoryview(data)[line_end + 1:], height, width, what)
    exponent = rgbe[..., 3].astype(np.int32)
    factor = np.where(exponent > 0, np.ldexp(1.0, exponent - 136), 0.0)
    return (rgbe[..., :3] * factor[..., None]).astype(np.float32), f"file {source}"


def _decode_scanlines(data: memoryview, height: int, width: int, what: str) -> np.ndarray:
    import numpy as np

    truncated = GratNetError(f"{what} is truncated or corrupt (its scanlines end early or overrun)")
    result = np.empty((height, width, 4), dtype=np.uint8)
    position = 0
    for row in range(height):
        start = bytes(data[position:position + 4])
        encoded = (8 <= width < 32768 and len(start) == 4 and start[0] == 2 and start[1] == 2
                   and start[2] < 128)
        if not encoded:  # flat: 4 bytes per pixel (the old run-length form is not read)
            flat = np.frombuffer(data[position:position + 4 * width], dtype=np.uint8)
            if flat.size != 4 * width:
                raise truncated
            pixels = flat.reshape(width, 4)
            if np.any(np.all(pixels[:, :3] == 1, axis=1)):
                raise GratNetError(f"{what} uses the old run-length encoding, which is not read; re-save it")
            result[row] = pixels
            position += 4 * width
            continue
        if (start[2] << 8 | start[3]) != width:
            raise truncated
        position += 4
        for channel in range(4):
            column = 0
            line = result[row, :, channel]
            while column < width:
                if position >= len(data):
                    raise truncated
                count = data[position]
                position += 1
                if count > 128:  # a run of one byte
                    count -= 128
                    if column + count > width or position >= len(data):
                        raise truncated
                    line[column:column + count] = data[position]
                    position += 1
                else:  # count literal bytes
                    if count == 0 or column + count > width or position + count > len(data):
                        raise truncated
                    line[column:column + count] = np.frombuffer(data[position:position + count], dtype=np.uint8)
                    position += count
                column += count
    return result
