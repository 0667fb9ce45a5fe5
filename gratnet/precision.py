"""How far two correct float32 drivers may differ: a per-key bound on |XYZ_A − XYZ_B| (docs/physics.md,
"Float32 error budget: what two drivers may differ by").

The GLSL runtime and any other float32 evaluation of a model (another GPU's driver, llvmpipe) see the same
model file but round differently: the key vector comes out of rasterized, normalised directions, the driver's
sin/cos is an approximation, the MLP's sums are reordered and fused, and exp2/pow are approximations. The bound
has two parts, both in CIE XYZ (the range transform's inverse applied):

- **evaluated part**: the numpy forward pass (float64) with the key moved within ``key_error`` per component,
  c_t within ``t_coordinate_error``, each sin/cos feature within ``sinusoid_error``, each grid level's lookup
  position within ``grid_texel_error`` texels and each layer's pre-activations within their float32 rounding
  bound (Higham's γₙ: any summation order, fused or not); the 8 sign corners of the key box and ``samples``
  seeded random points of all the boxes at once, the largest deviation from the unperturbed XYZ taken. The
  errors propagate through the network's own Jacobian, so this part carries the model's sensitivity: a
  network that ignores its high frequencies gets a tight bound, one that leans on them (or sits on eq. 6's
  sqrt near u = 0, v = 0) a loose one. (Propagating the rounding with |W| instead, all signs aligned, gave
  0.02 in y on the shipped blazed model: four orders of magnitude above any observed difference.)
- **range part**, analytic: GLSL's stated accuracy of pow/exp2 in the range inverse (exp2: 3 + 2|x| ulp; pow
  inherited from exp2(y·log2 x)), amplified by eq. 7's slope.

The sum of both, times ``safety``, is the bound. No torch: this is the contract layer; tests and
scripts/gpu_check_compare.py use it.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np

from gratnet.encoding import encode, network_coordinates, range_inverse
from gratnet.featuregrid import grid_features
from gratnet.modelfile import ModelFile, validated
from gratnet.network import activate_hidden, activate_output

#: float32 unit roundoff u = 2⁻²⁴: a correctly rounded operation errs by at most u relative.
UNIT_ROUNDOFF = 2.0**-24


@dataclasses.dataclass(frozen=True)
class DriverErrors:
    """What a correct float32 driver may get wrong, per quantity (docs/physics.md, "Float32 error budget").

    Attributes:
        key_error: absolute error of each key-vector component. ``key = −(ωi + ωo)`` in the tangent frame: two
            normalised directions (inversesqrt: 2 ulp in GLSL), a 3×3 frame product, the rasterizer's
            interpolated position and normal; 16 u ≈ 9.5·10⁻⁷ (|key| ≤ 2). A scene whose key comes from
            independent float64 geometry (the plane tests' numpy reference) passes its own, larger value.
        sinusoid_error: absolute error of each sin/cos feature. NVIDIA's sin/cos approximation errs by
            2^−21.4 on [−π, π] (the shader reduces the argument to that range exactly, shaders/encoding.glsl);
            GLSL sets no bound, so 2^−20 with a margin.
        grid_texel_error: error of a feature-grid lookup position in texels; ``None``: the manual eight-fetch
            path's, p = (clamp(c) + 1)·(N − 1)/2 in float32 from a c rounded once: 4·u·N per level of N nodes.
            A texture unit's filter quantises the fraction to 8 bits (2⁻⁸ whether it rounds or truncates):
            ``HARDWARE_FILTER`` for ``grid_filter="hardware"``.
        t_coordinate_error: absolute error of c_t = 2t − 1 at a given key: for simple-max t = −w/sqrt(4 − u² − v²),
            a square root and a division of float32 values (≤ 5 u; 2.6 u measured on llvmpipe). c_u and c_v
            are carried as float pairs (shaders/encoding.glsl): their error is negligible.
        arithmetic_ulps: relative error of a hidden SiLU's own evaluation (exp, 1 + e, division, product), in u.
        samples: seeded random perturbations evaluated (besides the 8 sign corners of the key box).
        seed: their seed (deterministic bounds).
        safety: factor on the sum of both parts (the perturbation maximum is a sample, not a supremum).
    """

    key_error: float = 16.0 * UNIT_ROUNDOFF
    sinusoid_error: float = 2.0**-20
    t_coordinate_error: float = 8.0 * UNIT_ROUNDOFF
    grid_texel_error: float | None = None
    arithmetic_ulps: float = 4.0
    samples: int = 8
    seed: int = 0
    safety: float = 2.0


#: The errors of a texture unit's filtered lookup: an 8-bit fraction, rounded or truncated (2⁻⁸ covers both).
HARDWARE_FILTER = DriverErrors(grid_texel_error=2.0**-8)
#: Comparing a render with numpy at the key the shader itself wrote out (the forward path's key layer): the
#: encoding saw exactly that float32 key, so the key contributes no error; the rest is as :class:`DriverErrors`.
OWN_KEYS = DriverErrors(key_error=0.0)


@dataclasses.dataclass(frozen=True)
class DriverBound:
    """A bound on |XYZ_A − XYZ_B| per key, ``(…, 3)`` each (CIE XYZ, the units of ``evaluate_keys``).

    Attributes:
        xyz: the model's XYZ at the keys (numpy, float64).
        bound: ``safety · (inputs + arithmetic)``: the tolerance for a comparison.
        evaluated: the largest XYZ deviation over the perturbed evaluations (key, c_t, sin/cos, grid position,
            the MLP's rounding).
        range_rounding: the range inverse's own rounding (pow, exp2), analytic.
        outputs_spread: the evaluated part in the network's output domain (eq. 7's y), before the inverse.
        outputs_bound: ``safety · outputs_spread``: the tolerance for comparing network outputs themselves.
    """

    xyz: np.ndarray
    bound: np.ndarray
    evaluated: np.ndarray
    range_rounding: np.ndarray
    outputs_spread: np.ndarray
    outputs_bound: np.ndarray


def _gamma(terms: int) -> float:
    """Higham's γₙ = n·u/(1 − n·u): the relative error bound of an n-term float32 sum or dot product, in any
    order, with or without fused multiply-adds."""
    nu = terms * UNIT_ROUNDOFF
    return nu / (1.0 - nu)


def _forward(model: ModelFile, inputs: np.ndarray, rng: np.random.Generator | None, ulps: float = 4.0) -> np.ndarray:
    """The network's outputs (eq. 7's y) on ``inputs`` (N, width), in float64; with ``rng``, every layer's
    pre-activations moved by a random share of their float32 rounding bound γ_{n+1}·(|W|·|x| + |b|) (the
    bias is the (n+1)-th term; any summation order, fused or not), and SiLU's output by ``ulps`` u (exp, 1 + e,
    division, product): one float32 driver's rounding, propagated through the network's own Jacobian."""
    x = inputs
    last = len(model.weights) - 1
    for k, (weight, bias) in enumerate(zip(model.weights, model.biases, strict=True)):
        w64, b64 = weight.astype(np.float64), bias.astype(np.float64)
        pre = x @ w64.T + b64
        if rng is not None:
            rounding = _gamma(w64.shape[1] + 1) * (np.abs(x) @ np.abs(w64).T + np.abs(b64))
            pre = pre + rounding * rng.uniform(-1.0, 1.0, pre.shape)
        if k == last:
            x = activate_output(pre, model.output_activation)
        else:
            x = activate_hidden(pre, model.activation)
            if rng is not None and model.activation == "silu":
                x = x * (1.0 + ulps * UNIT_ROUNDOFF * rng.uniform(-1.0, 1.0, x.shape))
    return x


def _range_arithmetic(model: ModelFile, y: np.ndarray) -> np.ndarray:
    """Relative error of the shader's range inverse (shaders/range.glsl) at exact outputs ``y``: GLSL's
    stated accuracy (exp2: 3 + 2|x| ulp; log2: 2⁻²¹ absolute on [0.5, 2], 3 ulp outside; pow = exp2(y log2 x))."""
    spec = model.range
    u = UNIT_ROUNDOFF
    if spec.kind == "log1p":  # x = e^{y ln 2} − 1 (Taylor or exp2 − 1): exp2's ulps, cancellation ≤ 4.5×
        return np.full_like(y, 4.5 * (3.0 + 2.0 * np.abs(y).max(initial=0.0)) * u)
    clipped = np.clip(y, 1e-300, 1.0)
    if spec.kind == "power-log":
        log2_y = np.log2(clipped)
        log_error = np.where(clipped >= 0.5, 2.0**-21, 3.0 * u * np.abs(log2_y))
        exponent = log2_y / spec.power
        root = np.exp2(exponent)
        root_relative = math.log(2.0) * log_error / spec.power + (3.0 + 2.0 * np.abs(exponent)) * u
    else:
        root, root_relative = clipped, np.zeros_like(clipped)
    argument = spec.bits * (root - 1.0)
    # x = 2^(B(root − 1)): an error ρ·root in root moves x by ln 2 · B · root · ρ relative.
    return math.log(2.0) * spec.bits * root * root_relative + (3.0 + 2.0 * np.abs(argument)) * u


def _grid_inputs(model: ModelFile, coordinates: np.ndarray, texel_shift: np.ndarray | None,
                 texel_error: float | None) -> list[np.ndarray]:
    """Each grid level's features at ``coordinates`` (N, 3), its lookup moved by ``texel_shift`` (levels, N, 3;
    in [−1, 1]) times the texel error (``None``: 4·u·nodes per axis), converted to the level's spacing."""
    parts = []
    for level, grid in enumerate(model.grids):
        t_nodes, v_nodes, u_nodes = (int(n) for n in np.shape(grid)[:3])
        at = coordinates
        if texel_shift is not None:
            nodes = np.array([u_nodes, v_nodes, t_nodes], dtype=np.float64)
            texels = texel_shift[level] * (4.0 * UNIT_ROUNDOFF * nodes if texel_error is None else texel_error)
            at = coordinates + texels * 2.0 / (nodes - 1.0)
        parts.append(grid_features([grid], at, model.grid_interpolation))
    return parts


def _inputs(model: ModelFile, keys: np.ndarray, sinusoid_shift: np.ndarray | None,
            texel_shift: np.ndarray | None, texel_error: float | None = None,
            t_shift: np.ndarray | None = None) -> np.ndarray:
    coordinates = network_coordinates(keys[:, 0], keys[:, 1], keys[:, 2], model.scheme)
    if t_shift is not None:
        coordinates[:, 2] += t_shift
    encoded = encode(coordinates, model.encoding)
    if sinusoid_shift is not None:
        encoded = encoded.copy()
        encoded[:, 3:] += sinusoid_shift
    return np.concatenate([*_grid_inputs(model, coordinates, texel_shift, texel_error), encoded], axis=-1)


def driver_bound(model: ModelFile, u: Any, v: Any, w: Any, errors: DriverErrors = DriverErrors(),
                 key_error: Any = None) -> DriverBound:
    """A bound on how far two correct float32 drivers' XYZ may differ at key vectors ``(u, v, w)``.

    Args:
        model: the network (a :class:`~gratnet.modelfile.ModelFile`).
        u, v, w: key vector components, broadcast together (the values one of the drivers used, or the
            float64 geometry a reference computed them from, with ``errors.key_error`` covering the gap).
        errors: the float32 error model (:class:`DriverErrors`; :data:`HARDWARE_FILTER` for a texture unit's
            filtered grid lookups).
        key_error: per-key absolute key error (broadcast with ``u``), replacing ``errors.key_error`` where a
            scene's geometry sets it (e.g. :func:`raster_key_error`).

    Returns:
        :class:`DriverBound`, every field ``(…, 3)`` float64, ``…`` the broadcast shape of ``u, v, w``.
    """
    valid = validated(model)
    u, v, w = np.broadcast_arrays(*(np.asarray(c, dtype=np.float64) for c in (u, v, w)))
    shape = u.shape
    keys = np.stack([u.ravel(), v.ravel(), w.ravel()], axis=-1)
    count: int = keys.shape[0]
    eta = (np.full((count, 1), errors.key_error) if key_error is None
           else np.broadcast_to(np.asarray(key_error, dtype=np.float64), shape).reshape(count, 1))
    outputs = _forward(valid, _inputs(valid, keys, None, None), None)
    xyz = range_inverse(outputs, valid.range)

    # Evaluated part: the 8 sign corners of the key box (no other perturbation: the key alone, at its extremes),
    # then seeded random perturbations of every input and of every layer's rounding at once.
    rng = np.random.default_rng(errors.seed)
    levels = len(valid.grids)
    deviation = np.zeros_like(xyz)
    spread = np.zeros_like(outputs)
    corners = np.array([[a, b, c] for a in (-1.0, 1.0) for b in (-1.0, 1.0) for c in (-1.0, 1.0)])
    for trial in range(len(corners) + errors.samples):
        random = trial >= len(corners)
        key_shift = rng.uniform(-1.0, 1.0, (count, 3)) if random else np.broadcast_to(corners[trial], (count, 3))
        sinusoid = errors.sinusoid_error * rng.uniform(-1.0, 1.0, (count, valid.encoding.features - 3)) \
            if random else None
        texel = rng.uniform(-1.0, 1.0, (levels, count, 3)) if random and levels else None
        t_shift = errors.t_coordinate_error * rng.uniform(-1.0, 1.0, count) if random else None
        perturbed = _forward(valid, _inputs(valid, keys + eta * key_shift, sinusoid, texel, errors.grid_texel_error,
                                            t_shift), rng if random else None, errors.arithmetic_ulps)
        spread = np.maximum(spread, np.abs(perturbed - outputs))
        deviation = np.maximum(deviation, np.abs(range_inverse(perturbed, valid.range) - xyz))
    range_part = np.abs(xyz) * _range_arithmetic(valid, outputs)
    bound = errors.safety * (deviation + range_part)
    parts = (xyz, bound, deviation, range_part, spread, errors.safety * spread)
    return DriverBound(*(np.reshape(part, (*shape, 3)) for part in parts))


#: Sub-pixel precision assumed of a rasterizer: vertices snapped to 2⁻⁸ pixel (NVIDIA and llvmpipe use 8 bits;
#: GL_SUBPIXEL_BITS may be as low as 4, where this would be too tight).
SUBPIXEL = 2.0**-8


def raster_key_error(keys: np.ndarray, covered: np.ndarray, subpixel: float = SUBPIXEL) -> np.ndarray:
    """How far two rasterizers' key vectors (or one and exact float64 geometry) may differ per pixel.

    Each rasterizer snaps vertices to its sub-pixel grid and interpolates from its own triangle setup (and
    clipping), so the surface point shaded at a pixel centre may move by ``subpixel`` pixels along either
    axis: the key moves by that much of its own change to the next pixel. ``keys`` ``(H, W, 3)`` (the key
    layer, or float64 geometry); ``covered`` ``(H, W)``: pixels with a key. Returns ``(H, W)``: subpixel ·
    (largest |Δkey| to a covered 4-neighbour along x + along y) + 16 u; uncovered pixels 0.
    """
    keys = np.asarray(keys, dtype=np.float64)
    covered = np.asarray(covered, dtype=bool)
    slope = []
    for axis in (0, 1):
        step = np.zeros(covered.shape)
        for shift in (-1, 1):
            neighbour = np.roll(keys, shift, axis=axis)
            valid = covered & np.roll(covered, shift, axis=axis)
            edge = np.zeros_like(valid)  # np.roll wraps around: the first/last row or column has no neighbour there
            if axis == 0:
                edge[0 if shift == 1 else -1, :] = True
            else:
                edge[:, 0 if shift == 1 else -1] = True
            difference = np.abs(keys - neighbour).max(axis=-1)
            step = np.maximum(step, np.where(valid & ~edge, difference, 0.0))
        slope.append(step)
    return np.where(covered, subpixel * (slope[0] + slope[1]) + 16.0 * UNIT_ROUNDOFF, 0.0)


def exceeding(actual: np.ndarray, expected: np.ndarray, bound: np.ndarray, floor: float = 0.0) -> np.ndarray:
    """Mask of values where |actual − expected| > bound + floor (``floor``: an absolute allowance, e.g. for
    pixels a reference cannot place exactly); every argument broadcast together."""
    return np.abs(np.asarray(actual, dtype=np.float64) - expected) > np.asarray(bound) + floor


def assert_within(actual: np.ndarray, expected: np.ndarray, bound: np.ndarray, what: str = "values",
                  floor: float = 0.0) -> None:
    """Raise ``AssertionError`` naming the worst offenders when any |actual − expected| exceeds bound + floor."""
    actual = np.asarray(actual, dtype=np.float64)
    over = exceeding(actual, expected, bound, floor)
    if not over.any():
        return
    excess = np.where(over, np.abs(actual - expected) / (np.asarray(bound) + floor + 1e-300), 0.0)
    worst = np.unravel_index(np.argsort(excess, axis=None)[::-1][:min(5, int(over.sum()))], excess.shape)
    lines = [f"at {tuple(int(i) for i in index)}: {actual[index]:.6g} against {expected[index]:.6g} "
             f"(bound {np.broadcast_to(bound, actual.shape)[index] + floor:.3g})" for index in zip(*worst, strict=True)]
    raise AssertionError(f"{int(over.sum())} of {over.size} {what} beyond the float32 driver bound; worst: "
                         + "; ".join(lines))
