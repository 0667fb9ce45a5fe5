"""Per-cell upper bounds of a trained network's output, for skipping pixels that cannot light up.

The renderers (``shaders/skip.glsl``) skip the MLP at a pixel when
``exposure · irradiance · A · max_r(M⁺_r · XYZ_bound)`` is below the display's smallest step, where
``XYZ_bound`` is the bound of the cell of network coordinates ``(c_u, c_v, c_t)`` (docs/physics.md eq. 6)
that the pixel's key vector falls into and ``M⁺`` is the positive part of the CIE XYZ → linear sRGB matrix.

**What kind of bound this is.** An interval-arithmetic bound through the sin/cos encoding (top frequency
at the training grid's Nyquist rate) would be far too loose to skip anything, so this is an *empirical*
bound, not a proof:

1. the network is evaluated (numpy, float32 after the first layer) on a regular grid of network
   coordinates twice as fine as its training grid: ``resolution`` samples per ``u*``/``v*`` axis
   (default: 2(R − 1) + 1 for the source volume's R, from the model's metadata) and ``t_oversample``
   samples per interval between training slices in ``t``;
2. the raw outputs (range-transformed XYZ, eq. 7) are max-reduced per coarse cell;
3. the cell maxima are dilated by ``dilation`` neighbouring cells in every axis (a peak between samples
   sits next to a sampled high value; this also absorbs the shader choosing the neighbouring cell at a
   boundary in float32);
4. ``margin_output`` (1e-4) is added in the network's output domain, then the exact inverse range
   transform maps them to CIE XYZ, where a floor (2^−B of the white, the transform's own floor) and a
   safety margin of ``margin_bits`` (a factor 2^margin_bits) are applied.

Its validity is *measured*: :func:`validate_output_bounds` evaluates the network (float64) at many
random off-grid points and counts how often it exceeds the bound (tests/runtime/test_skip_work.py asserts zero
on a shipped model; ``benchmarks/skip_work.py`` reports the counts). A network with features sharper
than its sampling grid can exceed it between samples. Sampled at the training grid itself (where the
encoding's top frequency sits at the Nyquist rate), the shipped blazed and sinusoidal models beat a
128-cell bound at 3 and 5 of 300 000 random keys (by up to 5000×, in tails near XYZ 1e-10) and the
network exceeded the sampled maxima by up to 0.04 in its output domain; sampled twice as finely, by at
most 3e-5, and no key beat the bound (docs/benchmarks.md, "Skip work").

Computing a bound at the default resolution takes one to two minutes on 2 CPU cores, so :func:`output_bounds` caches it
as ``$XDG_CACHE_HOME/gratnet/bounds/<hash>.npz`` (else ``~/.cache/gratnet/bounds/``), keyed by a hash
of the network's weights, its contract and the bound parameters; ``python -m gratnet.bounds MODEL.npz…``
precomputes it. Runtime-side: numpy only, no torch.
"""

from __future__ import annotations

import argparse
import dataclasses
import hashlib
import json
import math
import sys
from collections.abc import Iterable
from pathlib import Path

import numpy as np

from gratnet.atomic import atomic_path, cache_folder
from gratnet.encoding import range_inverse
from gratnet.errors import GratNetError
from gratnet.modelfile import ModelFile, content_digest, load_model, mlp_forward, network_inputs
from gratnet.network import activate_hidden, activate_output

__all__ = [
    "DISPLAY_SKIP_THRESHOLD",
    "BoundParameters",
    "OutputBounds",
    "bounds_cache_path",
    "compute_output_bounds",
    "display_skip_matrix",
    "output_bounds",
    "validate_output_bounds",
]

#: The display's smallest step in exposed linear sRGB: below 0.5/255/12.92 ≈ 1.52e-4 the sRGB transfer
#: function (linear part 12.92·L) and rounding to 8 bits give display sRGB level 0.
DISPLAY_SKIP_THRESHOLD = 0.5 / 255.0 / 12.92
_FORMAT = "gratnet-output-bounds"
_FORMAT_VERSION = 1


@dataclasses.dataclass(frozen=True)
class BoundParameters:
    """How a bound table is made (see the module docstring).

    Attributes:
        cells_uv: coarse cells per ``u*`` and per ``v*`` axis (at most (resolution − 1)/2 are used).
        t_cells: coarse cells in ``t``; ``None``: one per interval between training slices (S − 1).
        resolution: grid samples per ``u*``/``v*`` axis; ``None``: ``uv_oversample`` · (R − 1) + 1 with R the
            source volume's resolution (metadata).
        uv_oversample: grid refinement over the training grid when ``resolution`` is ``None``. The
            encoding's top frequency sits at the training grid's Nyquist rate, where samples can miss a
            peak entirely; at 2× the measured excess of the network over the sampled maxima fell from
            0.04 to 3e-5 in the network's output domain (sinusoidal and CD models, 400 000 random keys).
        t_oversample: grid samples per interval between training slices in ``t``.
        dilation: neighbouring cells (each axis) merged into each cell's maximum.
        margin_bits: safety factor 2^margin_bits on the CIE XYZ bound. 1 (a factor 2): with it the largest
            network/bound over 300 000 random keys was 0.51–0.57 for the shipped cd, blazed and sinusoidal
            models; 2 bits skipped 40 % fewer pixels on the gratings' 30° slices (docs/benchmarks.md).
        margin_output: added to the cell maxima in the network's output domain (eq. 7) before the inverse
            range transform: covers the dark cells, where a multiplicative margin on a bound of ~0 is ~0.
    """

    cells_uv: int = 512
    t_cells: int | None = None
    resolution: int | None = None
    uv_oversample: int = 2
    t_oversample: int = 2
    dilation: int = 1
    margin_bits: float = 1.0
    margin_output: float = 1e-4

    def resolved(self, model: ModelFile) -> BoundParameters:
        """These parameters with ``None`` filled in from ``model``'s metadata (volume R and S)."""
        volume = model.metadata.get("volume", {}) if isinstance(model.metadata, dict) else {}
        training_resolution = int(volume.get("resolution", 1001))
        resolution = (self.resolution if self.resolution is not None
                      else self.uv_oversample * (training_resolution - 1) + 1)
        slices = int(volume.get("slices", 11))
        t_cells = self.t_cells if self.t_cells is not None else max(slices - 1, 1)
        cells = min(self.cells_uv, max(1, (resolution - 1) // 2))  # at least two samples per cell
        result = dataclasses.replace(self, cells_uv=cells, resolution=resolution, t_cells=t_cells)
        result.check()
        return result

    def check(self) -> None:
        if not 1 <= self.cells_uv <= 4096 or (self.t_cells is not None and not 1 <= self.t_cells <= 4096):
            raise GratNetError(f"bound cells must be in 1 … 4096, got {self.cells_uv}, {self.t_cells}")
        if self.resolution is not None and self.resolution < 2:
            raise GratNetError(f"bound grid resolution must be ≥ 2, got {self.resolution}")
        if (self.t_oversample < 1 or self.uv_oversample < 1 or self.dilation < 0 or not math.isfinite(self.margin_bits)
                or self.margin_bits < 0 or not 0 <= self.margin_output < 1):
            raise GratNetError(f"invalid bound parameters {self}")


@dataclasses.dataclass(eq=False)
class OutputBounds:
    """Upper bounds of the network's CIE XYZ over coarse cells of network coordinates.

    Cell ``(k, j, i)`` covers ``c_t ∈ [−1 + 2k/Ct, −1 + 2(k+1)/Ct]``, ``c_v`` likewise with ``j``/Cv and
    ``c_u`` with ``i``/Cu (c = u*/2, v*/2, 2t − 1; docs/physics.md eq. 6). A point's cell index is
    ``clamp(floor((c + 1)/2 · C), 0, C − 1)`` per axis, as in ``shaders/skip.glsl``.

    Attributes:
        xyz: ``float32`` ``(Ct, Cv, Cu, 3)``: the CIE XYZ bound (D65-normalised, a mirror's peak Y = 1).
        parameters: the resolved :class:`BoundParameters`.
    """

    xyz: np.ndarray
    parameters: BoundParameters

    @property
    def cells(self) -> tuple[int, int, int]:
        """``(Cu, Cv, Ct)``."""
        t, v, u = self.xyz.shape[:3]
        return int(u), int(v), int(t)

    def cell_indices(self, coordinates: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(k, j, i)`` cell indices of network coordinates ``(…, 3)`` (c_u, c_v, c_t)."""
        coordinates = np.asarray(coordinates, dtype=np.float64)
        indices = []
        for axis, count in enumerate(self.cells):
            scaled = np.floor((coordinates[..., axis] + 1.0) * 0.5 * count)
            indices.append(np.clip(scaled, 0, count - 1).astype(np.intp))
        return indices[2], indices[1], indices[0]

    def lookup(self, coordinates: np.ndarray) -> np.ndarray:
        """The CIE XYZ bound ``(…, 3)`` at network coordinates ``(…, 3)``."""
        return self.xyz[self.cell_indices(coordinates)]


def display_skip_matrix() -> np.ndarray:
    """The positive part of colour-science's CIE XYZ → linear sRGB matrix (3×3, float64).

    For XYZ ≥ 0, every linear sRGB channel ``M_r · XYZ ≤ M⁺_r · XYZ``, so ``max_r M⁺_r · bound`` bounds
    every displayed channel of any XYZ below ``bound``.
    """
    import colour  # deferred: ~1 s to import

    matrix = np.asarray(colour.RGB_COLOURSPACES["sRGB"].matrix_XYZ_to_RGB, dtype=np.float64)
    return np.maximum(matrix, 0.0)


# ------------------------------------------------------------------------------------------------
# Computing


def _first_layer_tables(model: ModelFile, grid: np.ndarray, t_grid: np.ndarray) -> dict[str, np.ndarray]:
    """The first layer, split by coordinate: eq. 6's features of c_u, c_v, c_u + c_v, c_u − c_v and c_t each
    depend on one grid index (i, j, i + j, i − j, k), so W0 · features = U[i] + V[j] + S[i+j] + D[i−j] + T[k]
    (eq. 6a, without the diagonals: no S and D tables)."""
    spec = model.encoding
    weight = model.weights[0].astype(np.float64)
    omega, omega_t = spec.angular_frequencies()
    count = grid.size
    step = (grid[-1] - grid[0]) / (count - 1)
    width = 2 * spec.frequencies

    def group(values: np.ndarray, columns: slice, linear_column: int | None) -> np.ndarray:
        phase = values[:, None] * omega[None, :]
        features = np.concatenate([np.sin(phase), np.cos(phase)], axis=1)
        table = features @ weight[:, columns].T
        if linear_column is not None:
            table += values[:, None] * weight[None, :, linear_column]
        return table

    sums = 2.0 * grid[0] + step * np.arange(2 * count - 1)  # c_u + c_v at index i + j
    differences = step * np.arange(-(count - 1), count)  # c_u − c_v at index i − j + (count − 1)
    tables = {"u": group(grid, slice(3, 3 + width), 0), "v": group(grid, slice(3 + width, 3 + 2 * width), 1)}
    if spec.diagonals:
        tables["sum"] = group(sums, slice(3 + 2 * width, 3 + 3 * width), None)
        tables["difference"] = group(differences, slice(3 + 3 * width, 3 + 4 * width), None)
    t_first = 3 + spec.groups * width
    t_table = t_grid[:, None] * weight[None, :, 2] + model.biases[0].astype(np.float64)[None, :]
    if spec.t_frequencies:
        phase = t_grid[:, None] * omega_t[None, :]
        features = np.concatenate([np.sin(phase), np.cos(phase)], axis=1)
        t_table += features @ weight[:, t_first:t_first + 2 * spec.t_frequencies].T
    tables["t"] = t_table
    return {name: table.astype(np.float32) for name, table in tables.items()}


def _cell_starts(samples: int, cells: int) -> np.ndarray:
    """First sample index of each cell for ``samples`` grid points on [−1, 1] (``np.maximum.reduceat``)."""
    index = np.clip(np.floor(np.arange(samples) / (samples - 1) * cells), 0, cells - 1).astype(np.intp)
    starts = np.searchsorted(index, np.arange(cells), side="left")
    if np.any(np.diff(starts) <= 0) or starts[-1] >= samples:
        raise GratNetError(f"{cells} bound cells need more than {samples} grid samples per axis")
    return starts


def compute_output_bounds(model: ModelFile, parameters: BoundParameters | None = None,
                          progress: bool = True) -> OutputBounds:
    """Compute the bound table of ``model`` (no cache; see :func:`output_bounds`). Tens of seconds at R = 1001."""
    params = (parameters or BoundParameters()).resolved(model)
    assert params.resolution is not None and params.t_cells is not None
    if model.grids:  # the first-layer tables below assume the encoding alone feeds the network
        raise GratNetError("skip-work bounds are not built for feature-grid models; render them with skipping off")
    if model.layer_sizes[0] != model.encoding.features:
        raise GratNetError("model input width does not match its encoding")
    resolution, cells, t_cells = params.resolution, params.cells_uv, params.t_cells
    grid = np.linspace(-1.0, 1.0, resolution)
    t_samples = t_cells * params.t_oversample + 1
    t_grid = np.linspace(-1.0, 1.0, t_samples)
    tables = _first_layer_tables(model, grid, t_grid)
    weights = [w.astype(np.float32).T.copy() for w in model.weights[1:]]
    biases = [b.astype(np.float32) for b in model.biases[1:]]
    v_starts = _cell_starts(resolution, cells)
    u_starts = _cell_starts(resolution, cells)

    # Per t sample and grid row i: the maximum over each v cell, (t_samples, resolution, Cv, 3).
    row_max = np.empty((t_samples, resolution, cells, 3), dtype=np.float32)
    rows_per_batch = max(1, 65536 // resolution)
    batches = [(k, start) for k in range(t_samples) for start in range(0, resolution, rows_per_batch)]
    iterator: Iterable[tuple[int, int]] = batches
    if progress:
        from tqdm import tqdm

        iterator = tqdm(batches, desc="output bound", unit="batch", leave=False)
    j = np.arange(resolution)
    for k, start in iterator:
        i = np.arange(start, min(start + rows_per_batch, resolution))
        x = tables["u"][i][:, None, :] + tables["v"][None, :, :]
        if "sum" in tables:  # eq. 6's diagonal groups (the sum in its earlier order: the same float32 bound)
            x = (x + tables["sum"][i[:, None] + j[None, :]]
                 + tables["difference"][i[:, None] - j[None, :] + resolution - 1])
        x = x + tables["t"][k][None, None, :]
        x = activate_hidden(x.reshape(-1, x.shape[-1]), model.activation)
        last = len(weights) - 1
        for layer, (weight, bias) in enumerate(zip(weights, biases, strict=True)):
            x = x @ weight + bias
            x = (activate_output(x, model.output_activation) if layer == last
                 else activate_hidden(x, model.activation))
        y = x.reshape(i.size, resolution, 3)
        row_max[k, i] = np.maximum.reduceat(y, v_starts, axis=1)
    cell_max = np.maximum.reduceat(row_max, u_starts, axis=1)  # (t_samples, Cu, Cv, 3)
    # t cells: samples k·os … (k+1)·os inclusive (a sample on a cell boundary belongs to both cells)
    t_max = np.stack([cell_max[k * params.t_oversample:(k + 1) * params.t_oversample + 1].max(axis=0)
                      for k in range(t_cells)])  # (Ct, Cu, Cv, 3)
    y_bound = np.transpose(t_max, (0, 2, 1, 3))  # (Ct, Cv, Cu, 3)
    y_bound = _dilate(y_bound, params.dilation) + params.margin_output
    xyz = np.asarray(range_inverse(y_bound.astype(np.float64), model.range), dtype=np.float64)
    floor = 2.0 ** -float(model.range.bits) * np.asarray(model.range.white, dtype=np.float64)
    xyz = np.maximum(xyz, floor) * 2.0**params.margin_bits
    return OutputBounds(xyz.astype(np.float32), params)


def _dilate(values: np.ndarray, radius: int) -> np.ndarray:
    """Maximum over the (2·radius + 1)³ neighbourhood of each cell (edges: the cells that exist)."""
    result = values
    for axis in range(3):
        for _ in range(radius):
            padded = result
            shifted_up = np.concatenate([padded.take([0], axis=axis), padded], axis=axis)
            shifted_down = np.concatenate([padded, padded.take([-1], axis=axis)], axis=axis)
            size = padded.shape[axis]
            result = np.maximum(np.maximum(padded, shifted_up.take(range(size), axis=axis)),
                                shifted_down.take(range(1, size + 1), axis=axis))
    return result


# ------------------------------------------------------------------------------------------------
# Cache


def _model_digest(model: ModelFile, params: BoundParameters) -> str:
    digest = hashlib.sha256(content_digest(model).encode("ascii"))
    contract = {"parameters": dataclasses.asdict(params), "format": _FORMAT, "version": _FORMAT_VERSION}
    digest.update(json.dumps(contract, sort_keys=True).encode("utf-8"))
    return digest.hexdigest()[:32]


def bounds_cache_path(model: ModelFile, parameters: BoundParameters | None = None) -> Path:
    """Where :func:`output_bounds` keeps ``model``'s bound for ``parameters`` (may not exist yet)."""
    params = (parameters or BoundParameters()).resolved(model)
    return cache_folder("bounds") / f"{_model_digest(model, params)}.npz"


def _read_cached(path: Path, params: BoundParameters) -> OutputBounds | None:
    try:
        with np.load(path, allow_pickle=False) as archive:
            header = json.loads(str(archive["header"]))
            xyz = np.asarray(archive["xyz"], dtype=np.float32)
    except (OSError, ValueError, KeyError):
        return None  # missing or unreadable: recompute
    if header.get("format") != _FORMAT or header.get("parameters") != dataclasses.asdict(params):
        return None
    expected = (params.t_cells, params.cells_uv, params.cells_uv, 3)
    if xyz.shape != expected or not np.all(np.isfinite(xyz)) or np.any(xyz < 0):
        return None
    return OutputBounds(xyz, params)


def output_bounds(model: ModelFile, parameters: BoundParameters | None = None, cache: bool = True,
                  progress: bool = True) -> OutputBounds:
    """``model``'s bound table, from the cache if present, else computed (and cached, atomically)."""
    params = (parameters or BoundParameters()).resolved(model)
    path = bounds_cache_path(model, params)
    if cache:
        cached = _read_cached(path, params)
        if cached is not None:
            return cached
    bounds = compute_output_bounds(model, params, progress)
    if cache:
        header = json.dumps({"format": _FORMAT, "version": _FORMAT_VERSION,
                             "parameters": dataclasses.asdict(params)})
        try:
            with atomic_path(path, output=False) as temporary, open(temporary, "wb") as handle:
                np.savez(handle, header=np.array(header), xyz=bounds.xyz)
        except (OSError, GratNetError) as error:  # a read-only cache only costs time
            print(f"note: could not cache the output bound at {path}: {error}", file=sys.stderr)
    return bounds


# ------------------------------------------------------------------------------------------------
# Validation


def validate_output_bounds(model: ModelFile, bounds: OutputBounds, samples: int = 200_000, seed: int = 0,
                           batch: int = 65_536) -> dict[str, float | int]:
    """Measure the bound: the network (float64, ``mlp_forward``) at ``samples`` uniformly random network
    coordinates in [−1, 1]³ (off every grid), against the bound of each point's cell.

    Returns:
        ``samples``, ``violations`` (points where any XYZ channel exceeds its bound), ``worst_ratio``
        (max network / bound over channels with a positive network value; < 1 means no violation) and
        ``median_log2_slack`` (median of log2(bound / network) over channels where the network > 0).
    """
    rng = np.random.default_rng(seed)
    violations = 0
    worst = 0.0
    slack: list[np.ndarray] = []
    for start in range(0, samples, batch):
        count = min(batch, samples - start)
        coordinates = rng.uniform(-1.0, 1.0, size=(count, 3))
        xyz = np.asarray(range_inverse(mlp_forward(model, network_inputs(model, coordinates)), model.range))
        bound = bounds.lookup(coordinates).astype(np.float64)
        violations += int(np.count_nonzero(np.any(xyz > bound, axis=-1)))
        positive = xyz > 0.0
        if np.any(positive):
            ratio = xyz[positive] / bound[positive]
            worst = max(worst, float(ratio.max()))
            slack.append(-np.log2(ratio))
    median = float(np.median(np.concatenate(slack))) if slack else float("inf")
    return {"samples": int(samples), "violations": violations, "worst_ratio": worst, "median_log2_slack": median}


def main(argv: list[str] | None = None) -> int:
    """``python -m gratnet.bounds MODEL.npz…``: precompute (and cache) bound tables, optionally validate."""
    parser = argparse.ArgumentParser(prog="python -m gratnet.bounds", description=__doc__.split("\n\n")[0])
    parser.add_argument("models", nargs="+", help="model files (.npz)")
    parser.add_argument("--cells", type=int, default=BoundParameters.cells_uv, help="cells per u*/v* axis")
    parser.add_argument("--dilation", type=int, default=BoundParameters.dilation,
                        help="neighbouring cells merged into each cell's maximum")
    parser.add_argument("--margin-bits", type=float, default=BoundParameters.margin_bits,
                        help="safety factor 2^bits on the CIE XYZ bound")
    parser.add_argument("--validate", type=int, default=0, metavar="N", help="check N random keys per model")
    arguments = parser.parse_args(argv)
    for name in arguments.models:
        model = load_model(name)
        params = BoundParameters(cells_uv=arguments.cells, dilation=arguments.dilation,
                                 margin_bits=arguments.margin_bits)
        bounds = output_bounds(model, params)
        line: dict[str, object] = {"model": name, "cache": str(bounds_cache_path(model, params)),
                                   "cells": bounds.cells, "dilation": params.dilation,
                                   "margin_bits": params.margin_bits}
        if arguments.validate:
            line.update(validate_output_bounds(model, bounds, arguments.validate))
        print(json.dumps(line))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
