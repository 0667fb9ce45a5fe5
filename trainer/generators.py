"""Seeded generators of built-in height fields (heights in µm, sample spacing in µm).

Each generator has a frozen dataclass of parameters (physical units in the names: ``*_um`` in
micrometres, ``lines_per_mm`` per millimetre, ``*_jitter`` as dimensionless fractions) and a function
``params -> HeightField``. ``GENERATORS`` maps a name to ``(ParamsClass, function)``; ``generate(name,
**overrides)`` builds one with its defaults overridden.

Shared conventions:
- Square patch ``size_um`` wide, sampled every ``dx_um`` at x = ix · dx, y = iy · dx
  (``heights_um[iy, ix]``). The default spacing 0.08 µm resolves the slopes of every default.
- Heights are shifted so that the lowest sample is at 0 µm.
- Every generator except ``corner_cube`` is exactly periodic in its patch, so periodic tiling has no
  seam. For the periodic structures (sinusoidal, blazed, cd, pits) the patch is snapped to a whole
  number of periods and ``dx_um`` is then adjusted slightly (by at most half a sample over the patch)
  so that the patch also holds a whole number of samples; the field's ``dx_um`` is the one used.
- The ``seed`` picks all random choices; for the deterministic structures it picks a random lateral
  offset (phase) of the pattern, so every seed gives the same structure, shifted.
- ``HeightField.source`` records the generator name and all its parameters.
"""

from __future__ import annotations

import dataclasses
import math
import typing
from collections.abc import Callable
from typing import Any

import numpy as np
from scipy import special

from gratnet.config import config_field
from gratnet.errors import GratNetError
from trainer.heightfield import HeightField

# Samples per side above which a patch would need gigabytes: refuse rather than thrash.
MAX_SAMPLES_PER_SIDE = 8192
DEFAULT_DX_UM = 0.08


# ---------------------------------------------------------------------------------------------------
# Parameter fields and their checks


def _length(default: float, help: str, *, zero_ok: bool = False) -> Any:  # noqa: A002
    """A length in µm (must be > 0, or ≥ 0 with ``zero_ok``)."""
    return config_field(default, help, check="nonnegative" if zero_ok else "positive")


def _fraction(default: float, help: str) -> Any:  # noqa: A002
    """A dimensionless fraction in [0, 1)."""
    return config_field(default, help, check="fraction")


def _size(default: float, note: str = "") -> Any:
    return config_field(default, f"patch width = height (µm; square patch){note}", check="positive")


def _dx() -> Any:
    return config_field(DEFAULT_DX_UM, "sample spacing (µm)", check="positive")


def _seed(effect: str) -> Any:
    return config_field(0, f"random seed, ≥ 0 ({effect})", check="seed")


_CHECKS: dict[str, tuple[Callable[[float], bool], str]] = {
    "positive": (lambda value: value > 0, "must be > 0"),
    "nonnegative": (lambda value: value >= 0, "must be ≥ 0"),
    "fraction": (lambda value: 0 <= value < 1, "must be a fraction in [0, 1)"),
    # Bounded so that a typo (1e9 scratches) is refused instead of running for days.
    "count": (lambda value: 0 <= value <= 10_000, "must be a whole number from 0 to 10000"),
    "seed": (lambda value: value >= 0, "must be a whole number ≥ 0"),
}


class _Parameters:
    """Type and range checks shared by every parameter set (a mixin: it adds no fields)."""

    if typing.TYPE_CHECKING:  # every parameter set is a dataclass
        __dataclass_fields__: typing.ClassVar[dict[str, dataclasses.Field[Any]]]

    def __post_init__(self) -> None:
        hints = typing.get_type_hints(type(self))
        name = getattr(type(self), "generator_name", type(self).__name__)
        for field in dataclasses.fields(self):
            value = getattr(self, field.name)
            kind = hints[field.name]
            where = f"{name} parameter {field.name}"
            # bool is an int subclass: refuse it explicitly for numeric fields.
            if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
                raise GratNetError(f"{where} must be a number, got {value!r}")
            if kind is int:
                if float(value) != math.floor(float(value)):
                    raise GratNetError(f"{where} must be a whole number, got {value!r}")
                value = int(value)
            else:
                value = float(value)
                if not math.isfinite(value):
                    raise GratNetError(f"{where} must be finite, got {value!r}")
            check = field.metadata.get("check")
            if check is not None:
                accept, rule = _CHECKS[check]
                if not accept(value):
                    raise GratNetError(f"{where} {rule}, got {value!r}")
            object.__setattr__(self, field.name, value)
        self.check()

    def check(self) -> None:
        """Cross-field checks (overridden where needed)."""


# ---------------------------------------------------------------------------------------------------
# Parameter sets


@dataclasses.dataclass(frozen=True)
class SinusoidalParams(_Parameters):
    """Holographic (sinusoidal) grating: grooves along y, height varies along x."""

    generator_name: typing.ClassVar[str] = "sinusoidal"
    lines_per_mm: float = config_field(600.0, "groove density (lines per mm); period = 1000/lines_per_mm µm",
                                       check="positive")
    peak_to_peak_um: float = _length(0.15, "peak-to-peak height of the sinusoid (µm)")
    size_um: float = _size(20.0, ", snapped to whole periods")
    dx_um: float = _dx()
    seed: int = _seed("random phase of the sinusoid")


@dataclasses.dataclass(frozen=True)
class BlazedParams(_Parameters):
    """Blazed (sawtooth) grating: height rises along +x over each period, then drops."""

    generator_name: typing.ClassVar[str] = "blazed"
    period_um: float = _length(2.5, "grating period along x (µm)")
    max_height_um: float = _length(0.25, "height of each sawtooth tooth (µm)")
    size_um: float = _size(20.0, ", snapped to whole periods")
    dx_um: float = _dx()
    seed: int = _seed("random lateral offset of the teeth")


@dataclasses.dataclass(frozen=True)
class CDParams(_Parameters):
    """Synthetic compact disc: straight pit tracks along x, stacked along y."""

    generator_name: typing.ClassVar[str] = "cd"
    track_pitch_um: float = _length(1.6, "distance between tracks along y (µm)")
    channel_bit_um: float = _length(0.2777, "channel bit length T (µm); pits and lands are whole multiples")
    min_run: int = config_field(3, "shortest pit/land, in channel bits (3T on a CD)", check="count")
    max_run: int = config_field(11, "longest pit/land, in channel bits (11T on a CD)", check="count")
    pit_width_um: float = _length(0.5, "pit width across the track (µm)")
    depth_um: float = _length(0.11, "pit depth below the land (µm)")
    edge_blur_um: float = _length(0.05, "standard deviation of the Gaussian softening the pit walls (µm)",
                                  zero_ok=True)
    size_um: float = _size(20.0, ", snapped to whole track pitches")
    dx_um: float = _dx()
    seed: int = _seed("pit sequences")

    def check(self) -> None:
        if not 1 <= self.min_run <= self.max_run:
            raise GratNetError(f"cd needs 1 ≤ min_run ≤ max_run, got {self.min_run} and {self.max_run}")
        if self.pit_width_um >= self.track_pitch_um:
            raise GratNetError(f"cd pit_width_um ({self.pit_width_um}) must be below track_pitch_um "
                               f"({self.track_pitch_um})")


@dataclasses.dataclass(frozen=True)
class GaussianParams(_Parameters):
    """Gaussian-correlated random surface: autocorrelation ∝ exp(-r²/ℓ²), ℓ the correlation length."""

    generator_name: typing.ClassVar[str] = "gaussian"
    correlation_length_um: float = _length(1.5, "correlation length ℓ (µm): autocorrelation ∝ exp(-r²/ℓ²)")
    max_height_um: float = _length(1.0, "heights are rescaled to [0, max_height_um] (µm)")
    size_um: float = _size(20.0)
    dx_um: float = _dx()
    seed: int = _seed("the white noise")


@dataclasses.dataclass(frozen=True)
class SnakeParams(_Parameters):
    """Snake-skin-like quasi-periodic V-grooves running mostly along y."""

    generator_name: typing.ClassVar[str] = "snake"
    period_um: float = _length(1.2, "mean groove spacing along x (µm); adjusted so whole grooves fill the patch")
    period_jitter: float = _fraction(0.1, "per-groove spacing variation, uniform ± this fraction (dimensionless)")
    depth_um: float = _length(0.3, "mean groove depth below the ridges (µm)")
    depth_jitter: float = _fraction(0.2, "per-groove depth variation, uniform ± this fraction (dimensionless)")
    waviness_um: float = _length(0.1, "largest sideways wander of a groove along its length (µm)", zero_ok=True)
    waviness_wavelength_um: float = _length(10.0, "wavelength of the wander along y (µm; snapped to the patch)")
    size_um: float = _size(20.0)
    dx_um: float = _dx()
    seed: int = _seed("spacings, depths and wander")

    def check(self) -> None:
        # Keep neighbouring grooves in order: wander below a quarter of the narrowest spacing.
        narrowest = self.period_um * (1 - self.period_jitter)
        if self.waviness_um >= narrowest / 4:
            raise GratNetError(f"snake waviness_um ({self.waviness_um}) must be below a quarter of the narrowest "
                               f"groove spacing ({narrowest / 4:.4g} µm)")


@dataclasses.dataclass(frozen=True)
class ScratchesParams(_Parameters):
    """Random straight scratches with a rounded (ball-tip) cross-section."""

    generator_name: typing.ClassVar[str] = "scratches"
    count: int = config_field(12, "number of scratches (dimensionless)", check="count")
    tip_radius_um: float = _length(0.5, "radius of the spherical tip cutting the groove (µm)")
    depth_um: float = _length(0.15, "mean scratch depth (µm)")
    depth_jitter: float = _fraction(0.3, "per-scratch depth variation, uniform ± this fraction (dimensionless)")
    min_length_um: float = _length(3.0, "shortest scratch (µm)")
    max_length_um: float = _length(15.0, "longest scratch (µm)")
    damping_sigma_um: float = _length(0.0, "std of a Gaussian damping window centred on the patch that fades the "
                                           "cuts towards the edges (µm); 0 = off", zero_ok=True)
    max_depth_um: float = _length(0.0, "if > 0, the cuts are rescaled so that the deepest is this deep (µm); "
                                       "0 = as cut", zero_ok=True)
    size_um: float = _size(20.0)
    dx_um: float = _dx()
    seed: int = _seed("positions, orientations, lengths and depths")

    def check(self) -> None:
        if self.min_length_um > self.max_length_um:
            raise GratNetError(f"scratches min_length_um ({self.min_length_um}) exceeds max_length_um "
                               f"({self.max_length_um})")
        deepest = self.depth_um * (1 + self.depth_jitter)
        if deepest > self.tip_radius_um:
            raise GratNetError(f"scratches deepest cut ({deepest:.4g} µm = depth_um × (1 + depth_jitter)) must not "
                               f"exceed tip_radius_um ({self.tip_radius_um})")


@dataclasses.dataclass(frozen=True)
class PitsParams(_Parameters):
    """Semi-spherical pits (depressions) on a square lattice, mildly randomised."""

    generator_name: typing.ClassVar[str] = "pits"
    spacing_um: float = _length(2.5, "lattice spacing (µm)")
    radius_um: float = _length(0.8, "mean pit radius at the surface (µm)")
    radius_jitter: float = _fraction(0.1, "per-pit radius variation, uniform ± this fraction (dimensionless)")
    position_jitter: float = _fraction(0.05, "per-pit offset from its lattice site, uniform ± this fraction of "
                                             "spacing_um along x and y (dimensionless)")
    depth_fraction: float = _length(1.0, "pit depth / pit radius (dimensionless): 1 = hemisphere, "
                                         "< 1 = flattened spheroidal pit")
    size_um: float = _size(20.0, ", snapped to whole lattice spacings")
    dx_um: float = _dx()
    seed: int = _seed("radii and placements")


@dataclasses.dataclass(frozen=True)
class CornerCubeParams(_Parameters):
    """Array of concave full-cube corner cubes (a retroreflector array); faces are cube faces."""

    generator_name: typing.ClassVar[str] = "corner_cube"
    max_height_um: float = _length(1.5, "peak-to-valley height (µm); sets the cube edge = max_height_um·√3/2")
    mirror_tile_um: float = _length(0.0, "if > 0, a design this wide (µm) is repeated mirrored (tile, mirror "
                                         "image, tile, …) to fill the patch; 0 = one design", zero_ok=True)
    size_um: float = _size(20.0)
    dx_um: float = _dx()
    seed: int = _seed("random lateral offset of the array")


# ---------------------------------------------------------------------------------------------------
# Helpers


def _grid(name: str, size_um: float, dx_um: float, period_um: float | None = None) -> tuple[int, float, float]:
    """(samples per side, used spacing in µm, patch width in µm).

    With ``period_um`` the patch is snapped to whole periods and the spacing adjusted so that the
    patch is exactly a whole number of samples wide (seamless periodic tiling).
    """
    width = size_um if period_um is None else max(1, round(size_um / period_um)) * period_um
    samples = max(2, round(width / dx_um))
    if samples > MAX_SAMPLES_PER_SIDE:
        raise GratNetError(f"{name}: a {width:.4g} µm patch at dx = {dx_um:.4g} µm needs {samples} samples per side "
                           f"(limit {MAX_SAMPLES_PER_SIDE}); reduce size_um or increase dx_um")
    if period_um is None:
        return samples, dx_um, samples * dx_um
    return samples, width / samples, width


def _source(params: Any) -> str:
    values = ", ".join(f"{field.name}={getattr(params, field.name)!r}" for field in dataclasses.fields(params))
    return f"generator:{params.generator_name}({values})"


def _field(heights: np.ndarray, dx_um: float, params: Any) -> HeightField:
    return HeightField(heights - heights.min(), dx_um, _source(params))


def _soft_box(coordinate: np.ndarray, start: float, end: float, blur: float) -> np.ndarray:
    """The indicator of [start, end) blurred by a Gaussian of standard deviation ``blur`` (same units)."""
    if blur == 0:
        return ((coordinate >= start) & (coordinate < end)).astype(np.float64)
    scale = 1 / (math.sqrt(2) * blur)
    return 0.5 * (special.erf((coordinate - start) * scale) - special.erf((coordinate - end) * scale))


def _periodic_soft_box(coordinate: np.ndarray, start: float, end: float, blur: float, period: float) -> np.ndarray:
    """``_soft_box`` repeated with ``period`` (the interval may straddle the patch edge)."""
    length = min(end - start, period)
    start %= period
    before, here, after = (_soft_box(coordinate, start + shift, start + length + shift, blur)
                           for shift in (-period, 0.0, period))
    return before + here + after


# ---------------------------------------------------------------------------------------------------
# Generators


def sinusoidal(params: SinusoidalParams) -> HeightField:
    """Holographic grating h = A/2·(1 + sin(2π(x − x0)/Λ)), Λ = 1000/lines_per_mm µm (600/mm: 1.667 µm)."""
    period = 1000.0 / params.lines_per_mm
    samples, dx, _ = _grid("sinusoidal", params.size_um, params.dx_um, period)
    phase = np.random.default_rng(params.seed).uniform(0, 2 * math.pi)
    x = np.arange(samples) * dx
    profile = 0.5 * params.peak_to_peak_um * (1 + np.sin(2 * math.pi * x / period + phase))
    return _field(np.tile(profile, (samples, 1)), dx, params)


def blazed(params: BlazedParams) -> HeightField:
    """Sawtooth: within each period the height rises linearly along +x to max_height_um, then drops.

    This sign matters: with the project's Fourier convention it sends the blazed order to u > 0.
    """
    samples, dx, _ = _grid("blazed", params.size_um, params.dx_um, params.period_um)
    offset = np.random.default_rng(params.seed).uniform(0, params.period_um)
    x = np.arange(samples) * dx
    profile = params.max_height_um * np.mod((x - offset) / params.period_um, 1.0)
    return _field(np.tile(profile, (samples, 1)), dx, params)


def _track_runs(rng: np.random.Generator, length: float, low: int, high: int) -> list[float]:
    """Alternating pit, land lengths (in channel bits) from [low, high], summing exactly to ``length``.

    All runs are whole channel bits except the last land, which absorbs the remaining fraction so the
    track wraps seamlessly around the periodic patch.
    """
    runs: list[float] = []
    failures = 0
    while length > 2 * high and failures < 1000:
        pit, land = (int(value) for value in rng.integers(low, high + 1, size=2))
        if length - pit - land >= 2 * low:  # leave room for a final legal pit and land
            runs += [pit, land]
            length -= pit + land
        else:
            failures += 1
    lowest, highest = max(low, math.ceil(length - high)), min(high, math.floor(length - low))
    last_pit = float(rng.integers(lowest, highest + 1)) if lowest <= highest else length / 2
    return runs + [last_pit, length - last_pit]


def cd(params: CDParams) -> HeightField:
    """Synthetic compact disc: tracks along x every track_pitch_um in y; pits are depressions.

    Pits and lands take run lengths min_run…max_run channel bits (3T…11T, T = 0.2777 µm), drawn
    uniformly, one random sequence per track; pits are rectangles pit_width_um wide whose walls are
    softened by a Gaussian blur of edge_blur_um (so the profile is not stair-cased by the pixels).
    """
    samples, dx, width = _grid("cd", params.size_um, params.dx_um, params.track_pitch_um)
    rng = np.random.default_rng(params.seed)
    coordinates = np.arange(samples) * dx
    depression = np.zeros((samples, samples))
    for track in range(round(width / params.track_pitch_um)):
        centre_y = (track + 0.5) * params.track_pitch_um
        across = _periodic_soft_box(coordinates, centre_y - params.pit_width_um / 2,
                                    centre_y + params.pit_width_um / 2, params.edge_blur_um, width)
        runs = _track_runs(rng, width / params.channel_bit_um, params.min_run, params.max_run)
        start = rng.uniform(0, width)
        along = np.zeros(samples)
        for index, run in enumerate(runs):
            end = start + run * params.channel_bit_um
            if index % 2 == 0:  # even runs are pits, odd ones lands
                along += _periodic_soft_box(coordinates, start, end, params.edge_blur_um, width)
            start = end
        depression += np.outer(across, along)
    return _field(-params.depth_um * depression, dx, params)


def gaussian(params: GaussianParams) -> HeightField:
    """White noise smoothed by a Gaussian (σ = ℓ/2, so the autocorrelation is ∝ exp(−r²/ℓ²)).

    Filtered in the Fourier domain, hence periodic; rescaled to heights in [0, max_height_um].
    """
    samples, dx, _ = _grid("gaussian", params.size_um, params.dx_um)
    noise = np.random.default_rng(params.seed).standard_normal((samples, samples))
    sigma = params.correlation_length_um / 2
    frequency_y = np.fft.fftfreq(samples, dx)[:, None]
    frequency_x = np.fft.rfftfreq(samples, dx)[None, :]
    kernel = np.exp(-2 * (math.pi * sigma) ** 2 * (frequency_x**2 + frequency_y**2))
    smooth = np.fft.irfft2(np.fft.rfft2(noise) * kernel, s=noise.shape)
    span = smooth.max() - smooth.min()
    if span <= 0:
        raise GratNetError("gaussian: the smoothed field is flat; decrease correlation_length_um")
    return _field((smooth - smooth.min()) * (params.max_height_um / span), dx, params)


def snake(params: SnakeParams) -> HeightField:
    """Quasi-periodic V-grooves along y (snake-skin-like), with natural jitter.

    round(size_um / period_um) grooves, spacings jittered by ±period_jitter and rescaled to fill the
    patch exactly; depths jittered by ±depth_jitter; each groove wanders sideways along y by up to
    waviness_um with a whole number of cycles per patch. Cross-section: straight walls from each groove
    bottom up to the ridge half-way to its neighbour (a V).
    """
    samples, dx, width = _grid("snake", params.size_um, params.dx_um)
    rng = np.random.default_rng(params.seed)
    grooves = max(2, round(width / params.period_um))
    spacings = params.period_um * (1 + params.period_jitter * rng.uniform(-1, 1, grooves))
    bottoms = (np.cumsum(spacings) - spacings[0]) * (width / spacings.sum()) + rng.uniform(0, width)
    depths = params.depth_um * (1 + params.depth_jitter * rng.uniform(-1, 1, grooves))
    cycles = max(1, round(width / params.waviness_wavelength_um))
    amplitudes = params.waviness_um * rng.uniform(0.5, 1.0, grooves)
    phases = rng.uniform(0, 2 * math.pi, grooves)
    coordinates = np.arange(samples) * dx
    wander = amplitudes * np.sin(2 * math.pi * cycles * coordinates[:, None] / width + phases)
    values = np.concatenate([-depths, np.zeros(grooves)])
    heights = np.empty((samples, samples))
    for row in range(samples):
        centres = bottoms + wander[row]
        following = np.roll(centres, -1)
        following[-1] += width
        knots = np.concatenate([centres, (centres + following) / 2])
        heights[row] = np.interp(coordinates, knots, values, period=width)
    return _field(heights, dx, params)


def scratches(params: ScratchesParams) -> HeightField:
    """Random straight scratches cut by a spherical tip (e.g. a ball-pen tip) into a flat surface.

    Each scratch: uniform random centre and orientation, length uniform in [min_length_um,
    max_length_um], depth δ = depth_um·(1 ± depth_jitter); cross-section of a sphere of radius R pressed
    δ deep (half-width √(2Rδ − δ²)), rounded ends. Overlaps keep the deepest cut; wrapped periodically.
    With damping_sigma_um > 0 the cuts are multiplied by exp(−r²/(2σ²)), r the distance (µm) from the
    patch centre (the paper's "Gaussian damping window" on its scratch scan, §4); with max_depth_um > 0
    they are then rescaled so that the deepest is max_depth_um deep (the height span).
    """
    samples, dx, width = _grid("scratches", params.size_um, params.dx_um)
    rng = np.random.default_rng(params.seed)
    radius = params.tip_radius_um
    heights = np.zeros((samples, samples))
    for _ in range(params.count):
        centre = rng.uniform(0, width, 2)
        angle = rng.uniform(0, math.pi)
        half_length = rng.uniform(params.min_length_um, params.max_length_um) / 2
        depth = params.depth_um * (1 + params.depth_jitter * rng.uniform(-1, 1))
        half_width = math.sqrt(2 * radius * depth - depth**2)
        direction = np.array([math.cos(angle), math.sin(angle)])
        reach = np.abs(direction) * half_length + half_width  # bounding half-extent along x, y
        for shift_y in (-width, 0.0, width):
            for shift_x in (-width, 0.0, width):
                centre_x, centre_y = centre[0] + shift_x, centre[1] + shift_y
                columns = _index_range(centre_x, reach[0], dx, samples)
                rows = _index_range(centre_y, reach[1], dx, samples)
                if columns.size == 0 or rows.size == 0:
                    continue
                offset_x = columns[None, :] * dx - centre_x
                offset_y = rows[:, None] * dx - centre_y
                along = np.clip(offset_x * direction[0] + offset_y * direction[1], -half_length, half_length)
                distance_sq = (offset_x - along * direction[0]) ** 2 + (offset_y - along * direction[1]) ** 2
                cut = -(depth - radius + np.sqrt(np.maximum(radius**2 - distance_sq, 0.0)))
                cut = np.where(distance_sq < half_width**2, cut, 0.0)
                window = np.ix_(rows, columns)
                heights[window] = np.minimum(heights[window], cut)
    if params.damping_sigma_um > 0:
        offsets = np.arange(samples) * dx - width / 2
        damping = np.exp(-(offsets**2) / (2 * params.damping_sigma_um**2))
        heights *= np.outer(damping, damping)
    if params.max_depth_um > 0 and heights.min() < 0:
        heights *= params.max_depth_um / -heights.min()
    return _field(heights, dx, params)


def _index_range(centre: float, reach: float, dx: float, samples: int) -> np.ndarray:
    """Sample indices within [centre − reach, centre + reach] (µm), clipped to the patch."""
    first = max(0, math.floor((centre - reach) / dx))
    last = min(samples - 1, math.ceil((centre + reach) / dx))
    return np.arange(first, last + 1)


def pits(params: PitsParams) -> HeightField:
    """Semi-spherical pits on a square lattice: h = −f·√(r² − ρ²) inside each pit (f = depth_fraction).

    Radii r = radius_um·(1 ± radius_jitter); centres at the lattice-cell centres moved by
    ±position_jitter·spacing_um; overlapping pits (only with large jitter) keep the deeper one.
    """
    samples, dx, width = _grid("pits", params.size_um, params.dx_um, params.spacing_um)
    spacing = params.spacing_um
    cells = round(width / spacing)
    rng = np.random.default_rng(params.seed)
    radii = params.radius_um * (1 + params.radius_jitter * rng.uniform(-1, 1, (cells, cells)))
    jitter = params.position_jitter * spacing * rng.uniform(-1, 1, (2, cells, cells))
    coordinates = np.arange(samples) * dx
    cell_of = np.floor(coordinates / spacing).astype(int)
    heights = np.zeros((samples, samples))
    for step_y in (-1, 0, 1):
        cell_y = (cell_of + step_y)[:, None]
        for step_x in (-1, 0, 1):
            cell_x = (cell_of + step_x)[None, :]
            wrapped = (cell_y % cells, cell_x % cells)
            centre_x = (cell_x + 0.5) * spacing + jitter[0][wrapped]
            centre_y = (cell_y + 0.5) * spacing + jitter[1][wrapped]
            distance_sq = (coordinates[None, :] - centre_x) ** 2 + (coordinates[:, None] - centre_y) ** 2
            depth = params.depth_fraction * np.sqrt(np.maximum(radii[wrapped] ** 2 - distance_sq, 0.0))
            heights = np.minimum(heights, -depth)
    return _field(heights, dx, params)


def corner_cube(params: CornerCubeParams) -> HeightField:
    """Concave full-cube corner-cube array: stacked unit cubes seen along their (1,1,1) diagonal.

    The solid is {p : ⌊px⌋ + ⌊py⌋ + ⌊pz⌋ ≤ −1} (cube units); the surface height above lateral point q
    (in the plane ⊥ d = (1,1,1)/√3) is the largest s with q + s·d inside. Writing p = q + t·(1,1,1),
    f(t) = Σ⌊q_i + t⌋ starts at −m, m = Σ frac(q_i) ∈ {0, 1, 2} (as Σ q_i = 0), and steps up by one at
    t_i = 1 − frac(q_i); so t* is the m-th smallest t_i and s = √3·t*. The height spans 0 (concave
    corners) to 2/√3 cube edges (convex corners), so the cube edge is max_height_um·√3/2. Faces are cube
    faces, tilted 54.74° (slope √2). Hexagonal cells √2 edges apart: not periodic in a square patch.
    With mirror_tile_um > 0 the design is made on a square tile that wide and the patch is filled with
    it and its mirror images alternately along x and y (the paper's corner cubes: a 24 µm design
    mirrored to 72 µm, §4); the patch is then a whole number of tiles (size_um rounded).
    """
    if params.mirror_tile_um > 0:
        tiles = max(1, round(params.size_um / params.mirror_tile_um))
        _grid("corner_cube", tiles * params.mirror_tile_um, params.dx_um)  # refuses an oversized patch up front
        tile = corner_cube(dataclasses.replace(params, mirror_tile_um=0.0, size_um=params.mirror_tile_um))
        rows = [tile.heights_um if index % 2 == 0 else tile.heights_um[::-1] for index in range(tiles)]
        column = np.concatenate(rows, axis=0)
        blocks = [column if index % 2 == 0 else column[:, ::-1] for index in range(tiles)]
        return _field(np.concatenate(blocks, axis=1), tile.dx_um, params)
    samples, dx, width = _grid("corner_cube", params.size_um, params.dx_um)
    edge = params.max_height_um * math.sqrt(3) / 2
    offset = np.random.default_rng(params.seed).uniform(0, 2 * width, 2)
    basis_1 = np.array([1.0, -1.0, 0.0]) / math.sqrt(2)
    basis_2 = np.array([1.0, 1.0, -2.0]) / math.sqrt(6)
    coordinates = np.arange(samples) * dx
    u = (coordinates[None, :] - offset[0])[..., None]
    v = (coordinates[:, None] - offset[1])[..., None]
    q = (u * basis_1 + v * basis_2) / edge  # (rows, columns, 3), cube units, Σ q_i = 0
    fractions = q - np.floor(q)
    jumps = np.rint(fractions.sum(axis=-1)).astype(int)
    steps = np.sort(1.0 - fractions, axis=-1)
    t = np.take_along_axis(steps, np.clip(jumps - 1, 0, 2)[..., None], axis=-1)[..., 0]
    t = np.where(jumps == 0, 0.0, t)
    return _field(edge * math.sqrt(3) * t, dx, params)


# ---------------------------------------------------------------------------------------------------
# Registry

GENERATORS: dict[str, tuple[type, Callable[[Any], HeightField]]] = {
    "sinusoidal": (SinusoidalParams, sinusoidal),
    "blazed": (BlazedParams, blazed),
    "cd": (CDParams, cd),
    "gaussian": (GaussianParams, gaussian),
    "snake": (SnakeParams, snake),
    "scratches": (ScratchesParams, scratches),
    "pits": (PitsParams, pits),
    "corner_cube": (CornerCubeParams, corner_cube),
}


def parameters_for(name: str, **overrides: Any) -> Any:
    """The checked parameter set of generator ``name``: its defaults with ``overrides`` applied."""
    if name not in GENERATORS:
        raise GratNetError(f"unknown generator {name!r}; built-in generators: {', '.join(GENERATORS)}")
    params_class = GENERATORS[name][0]
    known = [field.name for field in dataclasses.fields(params_class)]
    unknown = [key for key in overrides if key not in known]
    if unknown:
        raise GratNetError(f"generator {name!r} has no parameter {', '.join(map(repr, unknown))}; "
                           f"its parameters: {', '.join(known)}")
    return params_class(**overrides)


def generate(name: str, **overrides: Any) -> HeightField:
    """Generate the built-in height field ``name`` with its defaults overridden by ``overrides``."""
    params = parameters_for(name, **overrides)
    return GENERATORS[name][1](params)
