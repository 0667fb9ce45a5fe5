"""The reference material: the ground-truth volume itself, looked up where the network would be evaluated.

docs/physics.md "The reference look-up". A renderer that shades with the volume instead of the network takes
the same key vector → network coordinates ``(c_u, c_v, c_t)`` (eq. 6, the volume's own scheme) and interpolates
the volume's samples trilinearly there (eq. 6g, ``linear``: sample ``(s, i, j)`` is the node at
``c = −1 + 2·index/(N − 1)`` on each axis), giving CIE XYZ exactly at the samples — the look-up-table approach of
the earlier real-time diffraction shaders (Dhillon et al.). The A-term, Fresnel and exposure are the network's.

Storage (:data:`PRECISIONS`): ``float16`` (the default) keeps ``XYZ · 2¹⁵`` in half floats, so the values a
display can show at any exposure this project uses keep 11 significant bits: relative rounding ≤ 2⁻¹¹ for
``Y ≥ 1.9·10⁻⁹`` of a mirror's peak (half floats' normal range, 6.1·10⁻⁵ … 65504, divided by 2¹⁵; the white's
largest channel, Z = 1.0888, becomes 35 678), and subnormal steps of 1.8·10⁻¹² below. ``float32`` keeps the
volume's own values at twice the memory. :func:`stored_values` is the rounding a renderer applies; the numpy
look-up here of the stored values is what the GLSL look-up (``shaders/reference.glsl``) must reproduce.

The contract side: numpy only (no torch, no GL).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np

from gratnet.encoding import network_coordinates
from gratnet.errors import GratNetError
from gratnet.featuregrid import grid_features

__all__ = [
    "FLOAT16_SCALE",
    "PRECISIONS",
    "check_precision",
    "check_uniform_slices",
    "check_volume_matches",
    "reference_xyz",
    "stored_values",
    "texture_bytes",
]

#: How the reference texture stores XYZ: ``float16`` (scaled by :data:`FLOAT16_SCALE`) or ``float32``.
PRECISIONS = ("float16", "float32")
#: The power of two that lifts XYZ into half floats' normal range before rounding (exact to undo).
FLOAT16_SCALE = 2.0**15
_CHANNELS = 3
# Metadata that must agree between a volume and a material's training volume for the look-up to be its truth:
# the height field (generator with its parameters, dataset, or file, plus what was done to it) and σs (µm).
_SURFACE_KEYS = ("source", "sigma_s_um")


def check_precision(precision: object) -> str:
    """``precision`` if it is one of :data:`PRECISIONS`, else one clear error."""
    if precision not in PRECISIONS:
        raise GratNetError(f"reference precision must be one of {', '.join(PRECISIONS)}, got {precision!r}")
    return str(precision)


def check_uniform_slices(metadata: Mapping[str, Any], slices: int, name: str = "volume") -> None:
    """One clear error unless the volume's slices sit at ``t_s = s/(S − 1)`` (docs/formats.md): the look-up places
    slice ``s`` there. A volume without ``slice_t`` is taken to follow the format."""
    recorded = metadata.get("slice_t")
    if recorded is None:
        return
    expected = np.linspace(0.0, 1.0, slices) if slices > 1 else np.zeros(1)
    values = np.asarray(recorded, dtype=np.float64) if isinstance(recorded, (list, tuple)) else None
    if values is None or values.shape != expected.shape or not np.allclose(values, expected, rtol=0.0, atol=1e-9):
        raise GratNetError(f"{name}: its slices are not at t = s/(S − 1) (slice_t {recorded!r}); the reference "
                           "look-up needs uniform slices")


def texture_bytes(slices: int, resolution: int, precision: str = "float16") -> int:
    """Bytes of the reference texture of an ``S × R × R`` volume: three channels of 2 or 4 bytes per sample
    (a 41-slice 1001² volume: 246 MB as float16; drivers may pad RGB to RGBA, a third more)."""
    check_precision(precision)
    return int(slices) * int(resolution) ** 2 * _CHANNELS * (2 if precision == "float16" else 4)


def stored_values(xyz: np.ndarray, precision: str = "float16") -> np.ndarray:
    """The volume's XYZ ``(S, R, R, 3)`` as the reference texture holds them, back in XYZ units (``float32``):
    rounded through ``float16`` at :data:`FLOAT16_SCALE`, or unchanged for ``float32``."""
    check_precision(precision)
    values = np.asarray(xyz, dtype=np.float32)
    if precision == "float32":
        return values
    with np.errstate(over="ignore"):
        half = (values * np.float32(FLOAT16_SCALE)).astype(np.float16)
    if not np.all(np.isfinite(half)):
        peak = float(np.max(np.abs(values)))
        raise GratNetError(f"volume values up to {peak:.6g} do not fit the float16 reference texture (at most "
                           f"{65504 / FLOAT16_SCALE:.4g}): use the float32 precision")
    return half.astype(np.float32) / np.float32(FLOAT16_SCALE)


def reference_xyz(values: np.ndarray, scheme: str, u: Any, v: Any, w: Any) -> np.ndarray:
    """CIE XYZ of the reference look-up at key vectors ``(u, v, w)`` (broadcast together), ``float64 (…, 3)``.

    ``values``: the volume's samples ``(S, R, R, 3)`` (axes t, v*, u*, XYZ) — pass :func:`stored_values` to get
    what a renderer shows; ``scheme``: the volume's sampling scheme. Network coordinates as eq. 6, trilinear
    interpolation as eq. 6g (``linear``), clamped to the volume's extent; exact at the samples.
    """
    u, v, w = np.broadcast_arrays(*(np.asarray(c, dtype=np.float64) for c in (u, v, w)))
    coordinates = network_coordinates(u, v, w, scheme)
    samples = np.asarray(values, dtype=np.float64)
    if samples.shape[0] == 1:  # one slice: constant along t (eq. 6g needs two nodes per axis)
        samples = np.concatenate([samples, samples])
    return grid_features([samples], coordinates, "linear")


def check_volume_matches(volume_metadata: Mapping[str, Any], model_volume: Mapping[str, Any], volume_name: str,
                         material_name: str) -> None:
    """One clear error unless the volume comes from the material's own surface: the same ``source`` (height field
    with its parameters) and ``sigma_s_um`` (σs, µm) as the volume the material was trained on (its model file's
    ``metadata.volume``). Sampling (R, S, scheme) may differ: the look-up is the truth at its own samples."""
    differences = []
    for key in _SURFACE_KEYS:
        mine, theirs = volume_metadata.get(key), model_volume.get(key)
        if mine is None or theirs is None:
            missing = volume_name if mine is None else material_name
            raise GratNetError(f"cannot check that {volume_name} is {material_name}'s ground truth: {missing} "
                               f"records no {key}")
        same = (math.isclose(float(mine), float(theirs), rel_tol=1e-9)
                if isinstance(mine, (int, float)) and isinstance(theirs, (int, float)) else mine == theirs)
        if not same:
            differences.append(f"{key} {mine!r} against {theirs!r}")
    if differences:
        raise GratNetError(f"{volume_name} is not the ground truth of {material_name}: " + "; ".join(differences))
