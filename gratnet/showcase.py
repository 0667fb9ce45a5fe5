"""How to show a material: where its diffraction lands, what exposure shows it, and whether a picture shows anything.

Two questions, answered from numbers alone (runtime-side: numpy, no GL, no torch):

1. **Where is the material's diffraction, and how bright is it?** :func:`analyse_model` evaluates the
   network (``gratnet.modelfile.evaluate_keys``, the runtime's own pipeline) on a regular grid of key
   vectors ``(u, v)`` at one ``w`` (``ANALYSIS_W``), leaves out the specular neighbourhood ``|(u, v)| <
   specular_radius``, and finds the brightest off-specular peaks (local maxima, refined on a finer grid).
   Their key vectors tell a renderer where to aim the light and camera (``viewer.defaults``); the
   brightest peak gives the material's suggested exposure, the one that puts that peak at display white.
   Brightness is the largest **linear sRGB** channel of the network's CIE XYZ (physics.md "Colour"): a
   display pixel clips per channel, so that channel decides when it saturates. The result is stored in
   the model file (``metadata["display"]``, docs/formats.md) when the trainer saves a model;
   :func:`material_display` reads it back, or computes it for older files.

2. **Is a rendered picture black on the display?** :func:`black_fraction` counts the pixels that 8-bit
   display sRGB (``gratnet.display``) shows as (0, 0, 0); :func:`suggest_exposure` proposes an exposure
   from the rendered float image; :func:`black_image_hint` turns both into the one-line message that
   ``gratnet render`` prints on stderr and the viewer can show.

Units: key vectors are dimensionless direction-cosine sums (physics.md "Units and frames"); exposures
are linear factors applied to CIE XYZ before display; brightness is exposed linear sRGB, where 1 is
display white.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np

from gratnet.bounds import DISPLAY_SKIP_THRESHOLD
from gratnet.display import xyz_to_display_srgb8, xyz_to_linear_srgb
from gratnet.modelfile import ModelFile, evaluate_keys

__all__ = [
    "ANALYSIS_W",
    "BLACK_FRACTION_WARNING",
    "DISPLAY_KEY",
    "MaterialDisplay",
    "analyse_model",
    "black_fraction",
    "exposure_for_brightness",
    "black_image_hint",
    "brightness",
    "material_display",
    "suggest_exposure",
    "with_display",
]

#: Where the analysis lives in a model file's free-form metadata (``metadata["display"]``).
DISPLAY_KEY = "display"
#: Version of the ``metadata["display"]`` object; another version is recomputed, not read.
DISPLAY_VERSION = 1
#: The key vector's ``w`` of the analysis: ``−(cos θi + cos θo)`` for light and view about 35° off the
#: normal, the middle of the geometries the default views use (orders move little with ``w``; their
#: power does, through the phase ``k·w·h``).
ANALYSIS_W = -1.6
#: Half-width of the analysed square of ``(u, v)``: reachable with light and view each ≤ 37° from the
#: normal on the same side (``|u| ≤ sin θi + sin θo``); farther orders need grazing angles.
ANALYSIS_EXTENT = 1.2
#: Grid step of the coarse search in ``u`` and ``v``. The shipped networks' narrowest lobes (a grating
#: order across its grooves) are about 0.005–0.01 wide, so a step of 0.01 lands on or next to each.
ANALYSIS_STEP = 0.01
#: Half-width and step of the fine grid around each coarse peak (the peak's value sets the exposure).
REFINE_EXTENT = 0.012
REFINE_STEP = 0.001
#: Key vectors closer than this to the specular direction (0, 0) count as the specular peak, not as
#: diffraction: about 10 standard deviations of a flat patch's specular lobe at 780 nm for the default
#: σs = 16.25 µm (physics.md: std = λ / (2π σs) = 0.0076), with room for the network's blur.
MIN_SPECULAR_RADIUS = 0.08
#: Peaks dimmer than this fraction of the brightest one are not kept as candidates.
CANDIDATE_FRACTION = 0.3
#: At most this many candidate peaks are kept (brightest first).
MAX_CANDIDATES = 8
#: A local maximum must be the largest value within this many grid steps on each side.
PEAK_NEIGHBOURHOOD = 4
#: Below this brightness (relative to the specular peak) a material has no diffraction worth showing:
#: it is shown by its specular reflection instead.
NO_DIFFRACTION = 1e-6
#: ``gratnet render`` warns when at least this fraction of the display pixels is black.
BLACK_FRACTION_WARNING = 0.99
#: A suggested exposure puts this percentile of the lit pixels' brightness at display white …
HINT_PERCENTILE = 99.0
#: … but is at least the one that lifts this fraction of the whole image to ``HINT_MARGIN`` times the
#: display's smallest step (``gratnet.bounds.DISPLAY_SKIP_THRESHOLD``), so that a re-render is not black.
HINT_VISIBLE_FRACTION = 0.03
HINT_MARGIN = 8.0


@dataclasses.dataclass(frozen=True)
class MaterialDisplay:
    """Where a material's diffraction lands and the exposure that shows it (see the module docstring).

    Attributes:
        exposure: the suggested exposure: display white / ``peak_brightness`` (linear factor on XYZ).
        peak_keys_uv: ``(u, v)`` of the off-specular peaks, brightest first (tangent frame, dimensionless;
            at least one entry; ``(0, 0)`` when the material has no diffraction to speak of).
        peak_brightness: brightness of each peak (largest linear sRGB channel of the network's XYZ at
            ``w = analysis_w``, unexposed; a flat mirror's specular peak has about 1).
        specular_brightness: the same at ``(0, 0, analysis_w)``.
        specular_radius: ``|(u, v)|`` below which the analysis counted a key as specular.
        analysis_w: the ``w`` of the analysis (``ANALYSIS_W``).
        stored: whether it was read from the model file (False: computed now).
    """

    exposure: float
    peak_keys_uv: tuple[tuple[float, float], ...]
    peak_brightness: tuple[float, ...]
    specular_brightness: float
    specular_radius: float
    analysis_w: float = ANALYSIS_W
    stored: bool = False

    def to_json(self) -> dict[str, Any]:
        """The ``metadata["display"]`` object written into a model file (docs/formats.md)."""
        return {
            "version": DISPLAY_VERSION,
            "exposure": _rounded(self.exposure),
            "peak_keys_uv": [[_rounded(u), _rounded(v)] for u, v in self.peak_keys_uv],
            "peak_brightness": [_rounded(b) for b in self.peak_brightness],
            "specular_brightness": _rounded(self.specular_brightness),
            "specular_radius": _rounded(self.specular_radius),
            "analysis_w": self.analysis_w,
        }

    @classmethod
    def from_json(cls, document: object) -> MaterialDisplay | None:
        """The analysis stored in a model file, or ``None`` when it is absent, of another version or malformed."""
        if not isinstance(document, dict) or document.get("version") != DISPLAY_VERSION:
            return None
        try:
            keys = tuple((float(u), float(v)) for u, v in document["peak_keys_uv"])
            peaks = tuple(float(b) for b in document["peak_brightness"])
            result = cls(exposure=float(document["exposure"]), peak_keys_uv=keys, peak_brightness=peaks,
                         specular_brightness=float(document["specular_brightness"]),
                         specular_radius=float(document["specular_radius"]),
                         analysis_w=float(document["analysis_w"]), stored=True)
        except (KeyError, TypeError, ValueError):
            return None
        numbers = [result.exposure, result.specular_brightness, result.specular_radius, result.analysis_w,
                   *peaks, *(c for key in keys for c in key)]
        if not keys or len(keys) != len(peaks) or not all(math.isfinite(x) for x in numbers) or result.exposure <= 0:
            return None
        return result


def _rounded(value: float) -> float:
    """Six significant digits: enough for an exposure or a key vector, short in the JSON."""
    return float(f"{float(value):.6g}")


def brightness(xyz: np.ndarray) -> np.ndarray:
    """Largest linear sRGB channel of CIE XYZ ``(…, 3)``, at least 0: what clips first on the display."""
    return np.maximum(np.max(xyz_to_linear_srgb(xyz), axis=-1), 0.0)


def _specular_radius(model: ModelFile) -> float:
    """``MIN_SPECULAR_RADIUS``, or 10 specular-lobe widths at the longest wavelength when that is wider
    (a model trained with a smaller coherence window σs has a wider specular lobe: std λ / (2π σs))."""
    volume = model.metadata.get("volume") if isinstance(model.metadata, dict) else None
    if not isinstance(volume, dict):
        return MIN_SPECULAR_RADIUS
    try:
        sigma_um = float(volume["sigma_s_um"])
        longest_um = max(float(x) for x in volume["wavelengths_nm"]) / 1000.0
    except (KeyError, TypeError, ValueError):
        return MIN_SPECULAR_RADIUS
    if not (math.isfinite(sigma_um) and sigma_um > 0 and math.isfinite(longest_um) and longest_um > 0):
        return MIN_SPECULAR_RADIUS
    return max(MIN_SPECULAR_RADIUS, 10.0 * longest_um / (2.0 * math.pi * sigma_um))


def _local_maxima(values: np.ndarray, radius: int) -> np.ndarray:
    """Mask of the entries of a 2-D array that equal the maximum of their (2·radius + 1)² neighbourhood."""
    padded = np.pad(values, radius, constant_values=-np.inf)
    windows = np.lib.stride_tricks.sliding_window_view(padded, (2 * radius + 1, 2 * radius + 1))
    return values >= windows.max(axis=(-2, -1))


def analyse_model(model: ModelFile) -> MaterialDisplay:
    """Find the material's off-specular peaks and its suggested exposure (module docstring, item 1).

    Cost: one network evaluation per grid point: (2·1.2/0.01 + 1)² ≈ 58 000 key vectors plus ≤ 8 × 625
    for refinement, about 0.5–1.5 s for the shipped 28k-parameter networks on one CPU core.

    Returns:
        a :class:`MaterialDisplay` with ``stored=False``.
    """
    radius = _specular_radius(model)
    axis = np.linspace(-ANALYSIS_EXTENT, ANALYSIS_EXTENT, int(round(2 * ANALYSIS_EXTENT / ANALYSIS_STEP)) + 1)
    u, v = np.meshgrid(axis, axis, indexing="xy")
    values = brightness(evaluate_keys(model, u, v, ANALYSIS_W))
    specular = float(brightness(evaluate_keys(model, 0.0, 0.0, ANALYSIS_W)))
    distance = np.hypot(u, v)
    values = np.where((distance >= radius) & (distance <= ANALYSIS_EXTENT), values, 0.0)
    best = float(values.max())
    if not best > NO_DIFFRACTION * max(specular, 1e-30):
        # No diffraction worth showing: show the specular reflection, at white.
        exposure = 1.0 / specular if specular > 0 else 1.0
        return _as_stored(MaterialDisplay(exposure, ((0.0, 0.0),), (specular,), specular, radius))
    peaks = _local_maxima(values, PEAK_NEIGHBOURHOOD) & (values >= CANDIDATE_FRACTION * best)
    order = np.argsort(-values[peaks], kind="stable")[: 2 * MAX_CANDIDATES]
    coarse = np.stack([u[peaks], v[peaks]], axis=-1)[order]
    fine_axis = np.linspace(-REFINE_EXTENT, REFINE_EXTENT, int(round(2 * REFINE_EXTENT / REFINE_STEP)) + 1)
    du, dv = np.meshgrid(fine_axis, fine_axis, indexing="xy")
    fine_u = coarse[:, 0, None, None] + du
    fine_v = coarse[:, 1, None, None] + dv
    fine = brightness(evaluate_keys(model, fine_u, fine_v, ANALYSIS_W))
    fine = np.where(np.hypot(fine_u, fine_v) >= radius, fine, 0.0).reshape(len(coarse), -1)
    index = np.argmax(fine, axis=1)
    found = sorted(
        ((float(fine[k, i]), float(fine_u.reshape(len(coarse), -1)[k, i]), float(fine_v.reshape(len(coarse), -1)[k, i]))
         for k, i in enumerate(index)),
        key=lambda entry: -entry[0],
    )
    top = found[0][0]
    kept = [entry for entry in found if entry[0] >= CANDIDATE_FRACTION * top][:MAX_CANDIDATES]
    return _as_stored(MaterialDisplay(
        exposure=1.0 / top,
        peak_keys_uv=tuple((round(u_, 4), round(v_, 4)) for _, u_, v_ in kept),
        peak_brightness=tuple(b for b, _, _ in kept),
        specular_brightness=specular,
        specular_radius=radius,
    ))


def _as_stored(result: MaterialDisplay) -> MaterialDisplay:
    """``result`` rounded exactly as the model file stores it, so that a computed analysis and a stored one
    give the same defaults (``stored`` stays False)."""
    rounded = MaterialDisplay.from_json(result.to_json())
    if rounded is None:  # not reachable for finite results; keep the unrounded one rather than fail
        return result
    return dataclasses.replace(rounded, stored=False)


def material_display(model: ModelFile) -> MaterialDisplay:
    """The material's display analysis: the one stored in the model file (``metadata["display"]``,
    written by the trainer), else :func:`analyse_model` (older files; about a second)."""
    stored = MaterialDisplay.from_json(model.metadata.get(DISPLAY_KEY)) if isinstance(model.metadata, dict) else None
    return stored if stored is not None else analyse_model(model)


def with_display(model: ModelFile) -> ModelFile:
    """``model`` with its analysis stored in ``metadata["display"]`` (what the trainer saves; weights untouched)."""
    metadata = dict(model.metadata) if isinstance(model.metadata, dict) else {}
    metadata[DISPLAY_KEY] = analyse_model(model).to_json()
    return dataclasses.replace(model, metadata=metadata)


# --------------------------------------------------------------------------------------------------
# Black pictures


def black_fraction(xyz_exposed: np.ndarray) -> float:
    """Fraction of the pixels of an exposed XYZ image ``(H, W, 3)`` that 8-bit display sRGB shows as
    (0, 0, 0) (``gratnet.display.xyz_to_display_srgb8``; 1.0 for an empty image)."""
    display = xyz_to_display_srgb8(np.asarray(xyz_exposed, dtype=np.float64), 1.0)
    pixels = display.reshape(-1, 3)
    if pixels.shape[0] == 0:
        return 1.0
    return float(np.mean(~np.any(pixels > 0, axis=1)))


def suggest_exposure(xyz_exposed: np.ndarray, exposure: float) -> float | None:
    """An exposure that shows a picture rendered at ``exposure`` (``xyz_exposed`` already includes it).

    It maps the ``HINT_PERCENTILE``-th percentile of the lit pixels' brightness (the largest linear sRGB
    channel; lit: brightness > 0) to display white, and is raised, if needed, until the brightest
    ``HINT_VISIBLE_FRACTION`` of all pixels reach ``HINT_MARGIN`` × the display's smallest step, so that
    rendering again at the suggestion is not black on the display. Since the image is linear in the
    exposure, no re-render is needed to find it.

    Returns:
        the suggested exposure (a linear factor, rounded to 3 significant digits), or ``None`` when no pixel
        is lit (no exposure would show anything: the light or camera must change) or ``exposure`` is 0.
    """
    if not (math.isfinite(exposure) and exposure > 0):
        return None
    return exposure_for_brightness(brightness(np.asarray(xyz_exposed, dtype=np.float64)) / exposure)


def exposure_for_brightness(values: np.ndarray) -> float | None:
    """:func:`suggest_exposure`'s rule on the pixels' brightness at exposure 1 (the largest linear sRGB channel, any
    shape): for callers that have the brightness without colour-science (the viewer: viewer.srgb)."""
    values = np.asarray(values, dtype=np.float64).reshape(-1)
    lit = values[values > 0]
    if lit.size == 0:
        return None
    by_percentile = 1.0 / float(np.percentile(lit, HINT_PERCENTILE))
    rank = min(lit.size, max(1, math.ceil(HINT_VISIBLE_FRACTION * values.size)))
    needed = float(np.sort(lit)[::-1][rank - 1])
    by_visibility = HINT_MARGIN * DISPLAY_SKIP_THRESHOLD / needed
    return float(f"{max(by_percentile, by_visibility):.3g}")


def black_image_hint(xyz_exposed: np.ndarray, exposure: float) -> str | None:
    """The one-line hint for a picture that is at least ``BLACK_FRACTION_WARNING`` black on the display,
    else ``None``. ``xyz_exposed``: the rendered image with ``exposure`` applied (``(H, W, 3)`` XYZ)."""
    fraction = black_fraction(xyz_exposed)
    if fraction < BLACK_FRACTION_WARNING:
        return None
    suggestion = suggest_exposure(xyz_exposed, exposure)
    where = f"{100.0 * fraction:.1f} % of the image is black on the display at exposure {exposure:g}"
    if suggestion is None:
        return f"{where}, and no pixel is lit: move the light or the camera (see --light, --camera)"
    return f"{where}; try --exposure {suggestion:g}"
