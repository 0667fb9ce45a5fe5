"""The network's input and output contract (docs/physics.md, "Network input and output").

One implementation for numpy arrays and torch tensors alike (array-api-compat picks the namespace), used
by the trainer (torch, with autograd) and the runtime's numpy evaluator; the GLSL shader implements the
same formulas and a parity test ties them together.

Input: a key vector (u, v, w) → grid coordinates (u*, v*) (inverse of the volume's domain transform) and
t ∈ [0, 1] (w remapped) → network coordinates c_u = u*/2, c_v = v*/2, c_t = 2t − 1, each in [−1, 1] →
encoding (physics.md eq. 6):

    [c_u, c_v, c_t,
     sin(s^j π c), j = 0…L−1, then cos(s^j π c), j = 0…L−1,   for c in (c_u, c_v, c_u + c_v, c_u − c_v),
     sin(s_t^j π c_t), j = 0…L_t−1, then cos(s_t^j π c_t), j = 0…L_t−1]

3 + 2·(4·L + L_t) features (163 for L = 19, L_t = 4). Without the diagonal groups (``diagonals = False``, eq. 6a)
the spatial terms are those of c_u and c_v alone: 3 + 2·(2·L + L_t) features, half the first layer's inputs at
the same frequency ladder. The scales put the top frequency at the Nyquist rate
of the training grid: s = ((R − 1)/2)^(1/(L−1)) (≈ 1.41 for R = 1001), s_t = ((S − 1)/2)^(1/(L_t−1)).

Output: the range transform y = T(x) of each CIE XYZ channel (eq. 7), applied to x = XYZ / XYZ_white
(channel by channel, XYZ_white = the D65 white of eq. 3, (0.9504, 1, 1.0888)) so that a perfect mirror
maps to 1 in every channel instead of clipping Z:

    power-log (default):  y = clamp(1 + log2(x)/B, 0, 1)^n            (B = 48, n = 8)
    log:                  y = clamp(1 + log2(x)/B, 0, 1)
    log1p:                y = log2(1 + x)
"""

from __future__ import annotations

import dataclasses
import functools
import math
from typing import Any

import array_api_compat
import numpy as np

from gratnet.codes import RANGE, SCHEME, choices_text
from gratnet.errors import GratNetError

RangeKind = str  #: one of gratnet.codes.RANGE.names
Scheme = str  #: one of gratnet.codes.SCHEME.names
TINY = 1e-30  # floor before log2: x ≤ 1e-30 maps to y = 0 for any B ≤ 99


def _namespace(*arrays: Any) -> Any:
    return array_api_compat.array_namespace(*arrays)


@dataclasses.dataclass(frozen=True)
class EncodingSpec:
    """Sinusoidal input encoding: frequency counts and scales (see module docstring)."""

    frequencies: int = 19  # L, for c_u, c_v, c_u + c_v, c_u − c_v
    t_frequencies: int = 4  # L_t, for c_t
    scale: float = 1.4125  # s
    t_scale: float = 1.7100  # s_t
    diagonals: bool = True  # the c_u ± c_v groups (eq. 6); False: c_u and c_v alone (eq. 6a)

    @classmethod
    def for_grid(cls, resolution: int, slices: int, frequencies: int = 19, t_frequencies: int = 4,
                 diagonals: bool = True) -> EncodingSpec:
        """Scales with the top frequency at the Nyquist rate of an R × R × S training grid."""
        if frequencies < 1 or t_frequencies < 0:
            raise GratNetError(f"frequency counts must be ≥ 1 and ≥ 0, got {frequencies}, {t_frequencies}")
        scale = ((resolution - 1) / 2.0) ** (1.0 / (frequencies - 1)) if frequencies > 1 else 1.0
        t_scale = ((max(slices, 2) - 1) / 2.0) ** (1.0 / (t_frequencies - 1)) if t_frequencies > 1 else 1.0
        return cls(frequencies, t_frequencies, float(scale), float(t_scale), diagonals)

    @property
    def groups(self) -> int:
        """Spatial groups: 4 (c_u, c_v, c_u + c_v, c_u − c_v), or 2 (c_u, c_v) without the diagonals."""
        return 4 if self.diagonals else 2

    @property
    def features(self) -> int:
        """Encoded input width: 3 + 2·(G·L + L_t), G = :attr:`groups`."""
        return 3 + 2 * (self.groups * self.frequencies + self.t_frequencies)

    def as_dict(self) -> dict[str, Any]:
        """The JSON form of a model file's ``encoding``: ``diagonals`` only when False, so that every file written
        before the option (and its cache keys) stays byte for byte what it was."""
        fields = dataclasses.asdict(self)
        if self.diagonals:
            del fields["diagonals"]
        return fields

    def angular_frequencies(self) -> tuple[np.ndarray, np.ndarray]:
        """π·s^j (j < L) and π·s_t^j (j < L_t), float64."""
        return (math.pi * self.scale ** np.arange(self.frequencies, dtype=np.float64),
                math.pi * self.t_scale ** np.arange(self.t_frequencies, dtype=np.float64))


@dataclasses.dataclass(frozen=True)
class RangeSpec:
    """Range transform of the XYZ targets (module docstring, eq. 7)."""

    kind: RangeKind = "power-log"
    bits: float = 48.0  # B
    power: float = 8.0  # n (power-log only)
    white: tuple[float, float, float] = (0.9504297, 1.0, 1.0888006)  # XYZ of a perfect mirror (eq. 3)

    def __post_init__(self) -> None:
        if self.kind not in RANGE:
            raise GratNetError(f"unknown range transform {self.kind!r}; choose {choices_text(RANGE.names)}")
        # Finite too: B = inf maps every x > 0 to y = 1, and the model file refuses it only after training.
        if not (0 < self.bits < math.inf and 0 < self.power < math.inf):
            raise GratNetError(f"range transform needs finite B > 0 and n > 0, got B={self.bits}, n={self.power}")


def key_to_grid(key: Any, scheme: Scheme) -> Any:
    """u → u* (inverse of the volume's domain transform; physics.md "Sampling")."""
    xp = _namespace(key)
    if scheme == "regular":
        return key
    if scheme in SCHEME:  # simple, simple-max: the square-root domain
        return xp.sign(key) * 2.0 * xp.sqrt(xp.clip(xp.abs(key) * 0.5, 0.0, None))
    raise GratNetError(f"unknown sampling scheme {scheme!r}")


def key_to_t(u: Any, v: Any, w: Any, scheme: Scheme) -> Any:
    """w → t ∈ [0, 1]: t = w/−2, or for simple-max t = w/−sqrt(4 − u² − v²) (0 where that is 0)."""
    xp = _namespace(u, v, w)
    if scheme == "simple-max":
        depth = xp.sqrt(xp.clip(4.0 - u * u - v * v, 0.0, None))
        t = xp.where(depth > 1e-12, -w / xp.clip(depth, 1e-12, None), xp.zeros_like(w))
    else:
        t = -w * 0.5
    return xp.clip(t, 0.0, 1.0)


def network_coordinates(u: Any, v: Any, w: Any, scheme: Scheme) -> Any:
    """(c_u, c_v, c_t) ∈ [−1, 1]³ stacked on a new last axis."""
    xp = _namespace(u, v, w)
    return xp.stack([key_to_grid(u, scheme) * 0.5, key_to_grid(v, scheme) * 0.5,
                     2.0 * key_to_t(u, v, w, scheme) - 1.0], axis=-1)


@functools.lru_cache(maxsize=64)
def _angular_frequencies(spec: EncodingSpec, xp: Any, dtype: Any, device: Any) -> tuple[Any, Any]:
    """:meth:`EncodingSpec.angular_frequencies` as arrays of ``xp`` on ``device``, made once: on a GPU each
    fresh copy is a blocking host-to-device transfer, which at small training batches stalled every step (and
    a CUDA graph cannot capture one). Callers never write to them."""
    omega, omega_t = spec.angular_frequencies()
    return (xp.asarray(omega, dtype=dtype, device=device), xp.asarray(omega_t, dtype=dtype, device=device))


def encode(coordinates: Any, spec: EncodingSpec) -> Any:
    """Sinusoidal encoding (eq. 6) of network coordinates (…, 3) → (…, spec.features)."""
    xp = _namespace(coordinates)
    omega, omega_t = _angular_frequencies(spec, xp, coordinates.dtype, array_api_compat.device(coordinates))
    c_u, c_v, c_t = coordinates[..., 0:1], coordinates[..., 1:2], coordinates[..., 2:3]
    # All four groups in one (…, 4, L) phase array, sines and cosines stacked as (…, 4, 2, L): the same
    # elementwise products as one group at a time (bit-identical), in far fewer ops and copies (the trainer
    # encodes every batch).
    groups = xp.stack([c_u, c_v, c_u + c_v, c_u - c_v] if spec.diagonals else [c_u, c_v], axis=-2)  # (…, G, 1)
    phase = groups * omega
    spatial = xp.stack([xp.sin(phase), xp.cos(phase)], axis=-2)  # (…, G, 2, L)
    parts = [coordinates, xp.reshape(spatial, (*coordinates.shape[:-1], 2 * spec.groups * spec.frequencies))]
    if spec.t_frequencies:
        phase_t = c_t * omega_t
        parts += [xp.sin(phase_t), xp.cos(phase_t)]
    return xp.concat(parts, axis=-1)


def _white(reference: Any, spec: RangeSpec) -> Any:
    xp = _namespace(reference)
    return xp.asarray(spec.white, dtype=reference.dtype, device=array_api_compat.device(reference))


def range_forward(xyz: Any, spec: RangeSpec) -> Any:
    """CIE XYZ (…, 3) → network targets y (…, 3) (eq. 7); x ≤ 1e-30 (and 0) maps to 0 for the log kinds."""
    xp = _namespace(xyz)
    x = xyz / _white(xyz, spec)
    if spec.kind == "log1p":
        return xp.log1p(xp.clip(x, 0.0, None)) / math.log(2.0)  # log2(1 + x) without losing small x
    y = xp.clip(1.0 + xp.log2(xp.clip(x, TINY, None)) / spec.bits, 0.0, 1.0)
    return y**spec.power if spec.kind == "power-log" else y


def range_inverse(y: Any, spec: RangeSpec) -> Any:
    """Network outputs y (…, 3) → CIE XYZ, the exact inverse of :func:`range_forward` on its image; y ≤ 0
    (and NaN) → 0."""
    xp = _namespace(y)
    if spec.kind == "log1p":
        positive = xp.where(y > 0.0, y, xp.zeros_like(y))  # not clip: it keeps NaN (the other kinds give 0)
        return xp.expm1(positive * math.log(2.0)) * _white(y, spec)
    clipped = xp.clip(y, 0.0, 1.0)
    root = clipped ** (1.0 / spec.power) if spec.kind == "power-log" else clipped
    x = xp.where(clipped > 0.0, 2.0 ** (spec.bits * (root - 1.0)), xp.zeros_like(clipped))
    return x * _white(y, spec)
