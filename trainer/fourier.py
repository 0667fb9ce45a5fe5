"""The F-term: windowed Kirchhoff integral of a height field (Stam; Dhillon et al. 2014), spectrally.

Contract (docs/physics.md, "The F-term"): with k = 2π/λ, a Gaussian window g of std σs centred on the
patch, x, y (µm) measured from the patch centre and h(x, y) the height (µm),

    P(u,v,w,λ) = ∫∫ g(x,y) · exp(i k (u x + v y + w h(x,y))) dx dy                        (physics.md eq. 1)
    F(u,v,w,λ) = |P|² / |∫∫ g dx dy|²                                                    (eq. 2)

Method (physics.md, "How F is computed"): on the sample grid the integral is a sum that separates in
x and y once the height term is fixed: P = Ey · exp(i k w H) · Exᵀ, with Ex[j, n] = g_x(x_n) e^{i k u_j x_n}
(a "zoom" DFT evaluated at exactly the requested u, uniform or not). For a slice of constant w this is
exact and costs two complex matrix products. Where w varies from sample to sample (``simple-max``,
BRDF slices), P is, for fixed (u, v), an entire function of w whose "frequencies" k·h lie in
[−k·hmax, k·hmax]; it is interpolated in w from exact transforms at Chebyshev nodes, with the node
count chosen from the Bessel-function bound of the Chebyshev coefficients of e^{i k h w}. Unlike the
paper's Taylor series in (i k w h)ⁿ/n!, whose terms grow like e^{k|w|hmax} before they cancel, every
quantity here is bounded by 1 (interpolation weights by the Lebesgue constant), so tall fields are
as accurate as flat ones.
"""

from __future__ import annotations

import contextlib
import dataclasses
import math
from collections.abc import Callable, Iterator, Sequence
from typing import Any

import numpy as np
from tqdm.auto import tqdm

from gratnet.config import config_field
from gratnet.errors import GratNetError
from trainer.heightfield import HeightField, RepeatMode, cover_window, resample
from trainer.spectral import SpectralWeights, spectral_weights

Report = Callable[[str], None]


@dataclasses.dataclass(frozen=True)
class OpticsConfig:
    """Optics of the ground truth: coherence window, spectral sampling and numerical limits."""

    sigma_s_um: float = config_field(
        65.0 / 4.0, "std σs of the Gaussian coherence window (µm); 4σs = 65 µm is the paper's",
        flag="--sigma-s",
    )
    window_extent_sigmas: float = config_field(
        6.0, "width of the integration patch in units of σs (the window is truncated at ±extent/2)"
    )
    repeat: RepeatMode = config_field(
        "periodic", "how a patch narrower than the integration width is repeated to cover it"
    )
    wavelength_start_nm: float = config_field(380.0, "shortest wavelength (nm)")
    wavelength_end_nm: float = config_field(780.0, "longest wavelength (nm), included")
    wavelength_step_nm: float = config_field(5.0, "wavelength step (nm)")
    max_grid_samples: int = config_field(
        4096, "largest integration grid side (samples) before refusing: the cost grows with its square"
    )
    tolerance: float = config_field(
        1e-9, "bound on the w-interpolation error of P relative to ∫g (Chebyshev node count)"
    )

    def __post_init__(self) -> None:
        if not (self.sigma_s_um > 0 and math.isfinite(self.sigma_s_um)):
            raise GratNetError(f"--sigma-s must be a positive number of µm, got {self.sigma_s_um}")
        if not self.window_extent_sigmas > 0:
            raise GratNetError(f"window extent must be positive, got {self.window_extent_sigmas} σs")
        if not 0 < self.tolerance < 1:
            raise GratNetError(f"tolerance must lie in (0, 1), got {self.tolerance}")

    @property
    def extent_um(self) -> float:
        """Width of the integration patch (µm)."""
        return self.sigma_s_um * self.window_extent_sigmas

    @classmethod
    def from_volume_metadata(cls, metadata: dict) -> OpticsConfig:
        """The optics a volume (or a model's ``metadata["volume"]``) was computed with, so that ground truth
        computed later (BRDF slices for evaluation) matches it; missing entries take the defaults."""
        defaults = cls()
        wavelengths = metadata.get("wavelengths_nm") or [defaults.wavelength_start_nm, defaults.wavelength_end_nm]
        sigma = float(metadata.get("sigma_s_um") or defaults.sigma_s_um)
        return cls(
            sigma_s_um=sigma,
            window_extent_sigmas=float(metadata.get("window_extent_um") or 6 * sigma) / sigma,
            repeat=metadata.get("repeat") or "periodic",
            wavelength_start_nm=float(wavelengths[0]),
            wavelength_end_nm=float(wavelengths[-1]),
            wavelength_step_nm=float(wavelengths[1] - wavelengths[0]) if len(wavelengths) > 1 else 5.0,
        )


@dataclasses.dataclass(frozen=True, eq=False)
class PreparedSurface:
    """A height field ready for the integral: resampled, repeated to the window, centred.

    ``heights_um`` is centred on its mid-range (a constant height is a global phase and leaves F
    unchanged), so |h| ≤ ``half_span_um``. ``window_x``/``window_y`` are the separable Gaussian
    window sampled at ``x_um``/``y_um`` (µm from the patch centre), each normalised to sum 1, so
    that F = |P|² directly (eq. 2).
    """

    heights_um: np.ndarray  # (Ny, Nx) float32, centred
    dx_um: float
    x_um: np.ndarray  # (Nx,) float64
    y_um: np.ndarray  # (Ny,) float64
    window_x: np.ndarray  # (Nx,) float64, Σ = 1
    window_y: np.ndarray  # (Ny,) float64, Σ = 1
    half_span_um: float
    source: str
    source_patch_um: tuple[float, float]
    notes: tuple[str, ...]


def required_spacing_um(field: HeightField, wavelength_min_um: float, safety: float = 0.95) -> float:
    """The coarsest sample spacing (µm) for which the sum stays free of aliasing at every |u| ≤ 2.

    exp(i k w h) has local spatial frequencies |w|·|∇h|/λ ≤ 2·slope/λ; the sum reproduces the integral
    at |u|/λ ≤ 2/λ when 1/dx exceeds 2/λ + 2·slope/λ, i.e. dx < λmin / (2 + 2·slope) (physics.md).
    """
    slope = field.slope_percentile(99.0)
    return safety * wavelength_min_um / (2.0 + 2.0 * slope)


def prepare_surface(
    field: HeightField, optics: OpticsConfig, report: Report | None = None
) -> PreparedSurface:
    """Resample (if too coarse), repeat (if too small) and window ``field`` for the F-term integral."""
    notes: list[str] = []

    def say(message: str) -> None:
        notes.append(message)
        if report:
            report(message)

    wavelength_min_um = optics.wavelength_start_nm / 1000.0
    needed = required_spacing_um(field, wavelength_min_um)
    if field.dx_um > needed * (1 + 1e-9):
        side = math.ceil(optics.extent_um / needed)
        if side > optics.max_grid_samples:
            raise GratNetError(
                f"height field spacing {field.dx_um:.4g} µm is too coarse for λ = {optics.wavelength_start_nm:g} nm "
                f"(needs ≤ {needed:.4g} µm), and resampling it would need a {side}² grid, over the limit of "
                f"{optics.max_grid_samples}; lower --sigma-s, the window extent, or raise max_grid_samples"
            )
        say(
            f"resampled: spacing {field.dx_um:.4g} µm is coarser than the {needed:.4g} µm that λ = "
            f"{optics.wavelength_start_nm:g} nm at |u| ≤ 2 needs (99th-percentile slope "
            f"{field.slope_percentile():.3g}); cubic-spline resampling to {needed:.4g} µm"
        )
        field = resample(field, needed, mode=optics.repeat)
    side = math.ceil(optics.extent_um / field.dx_um - 1e-9)
    if side > optics.max_grid_samples:
        raise GratNetError(
            f"the integration grid would be {side}² samples ({optics.extent_um:.4g} µm at dx = {field.dx_um:.4g} µm), "
            f"over the limit of {optics.max_grid_samples}; lower --sigma-s or resample the height field coarser"
        )
    rows, columns = field.shape
    if rows < side or columns < side:
        say(
            f"repeated ({optics.repeat}): the {field.size_um[0]:.4g}×{field.size_um[1]:.4g} µm patch is narrower "
            f"than the {optics.extent_um:.4g} µm integration width ({optics.window_extent_sigmas:g} σs)"
        )
    covered = cover_window(field, side, optics.repeat)
    heights = covered.heights_um
    low, high = float(heights.min()), float(heights.max())
    centred = (heights - 0.5 * (low + high)).astype(np.float32)
    positions = (np.arange(side) - (side - 1) / 2.0) * field.dx_um
    window = np.exp(-0.5 * np.square(positions / optics.sigma_s_um))
    window /= window.sum()
    for array in (centred, positions, window):
        array.setflags(write=False)
    return PreparedSurface(
        heights_um=centred,
        dx_um=field.dx_um,
        x_um=positions,
        y_um=positions,
        window_x=window,
        window_y=window,
        half_span_um=0.5 * (high - low),
        source=covered.source,
        source_patch_um=field.size_um,
        notes=tuple(notes),
    )


def chebyshev_node_count(phase_range: float, tolerance: float) -> int:
    """Nodes M so that interpolating e^{i a s}, s ∈ [−1, 1], a = ``phase_range``, errs < tolerance.

    The Chebyshev coefficients of e^{i a s} are 2·iⁿ·Jₙ(a), |Jₙ(a)| ≤ (a/2)ⁿ/n!; interpolation
    at M Chebyshev–Lobatto nodes errs at most about twice the sum of the dropped coefficients.
    """
    half = 0.5 * abs(phase_range)
    term = 1.0
    for order in range(1, 10_000):
        term *= half / order  # (a/2)^n / n!
        if order > half and 8.0 * term < tolerance:
            return order + 1
    raise GratNetError(f"w range too large for interpolation (phase range {phase_range:.3g} rad)")


class FTerm:
    """Evaluates XYZ(u, v, w) (eq. 1–3) of a prepared surface on (u, v) grids, slice by slice."""

    def __init__(
        self, surface: PreparedSurface, spectral: SpectralWeights | None = None, tolerance: float = 1e-9,
        device: str | None = None,
    ) -> None:
        """``device`` None runs :meth:`xyz_grid` in numpy (the reference); a torch device name ("cuda",
        "cpu") runs its matrix products in torch there: the same complex64 products and float64 sums,
        agreeing with numpy to float32 rounding (tests/trainer/test_fourier.py ties them)."""
        self.surface = surface
        self.spectral = spectral or spectral_weights()
        self.heights = surface.heights_um
        self.tolerance = tolerance
        self.device = device
        self.last_node_count = 0  # Chebyshev nodes used by the last xyz_grid call (0: none needed)

    def _kernel(self, keys: np.ndarray, positions_um: np.ndarray, window: np.ndarray, wavenumber: float) -> np.ndarray:
        """K[j, n] = window_n · exp(i k key_j position_n), complex64 (phase reduced in float64)."""
        phase = np.remainder(wavenumber * np.outer(keys, positions_um), 2.0 * np.pi).astype(np.float32)
        kernel = np.empty(phase.shape, dtype=np.complex64)
        kernel.real = np.cos(phase)
        kernel.imag = np.sin(phase)
        kernel *= window.astype(np.float32)[None, :]
        return kernel

    def _height_phasor(self, wavenumber: float, w: float) -> np.ndarray:
        """exp(i k w h) on the integration grid, complex64 (numpy)."""
        return _NumpyOps().height_phasor(self.heights, wavenumber, w)

    def xyz_grid(
        self,
        u: np.ndarray,
        v: np.ndarray,
        w_slices: Sequence[float | np.ndarray],
        progress: bool | str = False,
        wavelengths: Sequence[int] | None = None,
        initial: np.ndarray | None = None,
        after_wavelength: Callable[[int, Callable[[], np.ndarray]], None] | None = None,
    ) -> np.ndarray:
        """CIE XYZ on the grid u (columns) × v (rows) for each entry of ``w_slices``.

        Each entry is a scalar w (the whole slice at one w: exact direct transform) or an array of
        shape (len(v), len(u)) giving w per sample (Chebyshev interpolation in w, shared by all such
        entries). Returns float64 of shape (len(w_slices), len(v), len(u), 3). ``progress`` shows a
        bar over wavelengths (a string sets its label). ``wavelengths`` (indices into the spectral
        samples) sums only those wavelengths' terms: XYZ is a sum over λ, so parts computed apart add
        up to the whole (the Chebyshev plan still follows the full spectrum, so every part uses the
        same nodes). ``initial`` (float64, the result's shape) is a sum to continue from, and
        ``after_wavelength(done, fetch)`` is called after each wavelength with the number done and a function
        returning the sum so far as numpy: together they make a resumable computation whose sum is the
        uninterrupted one's, bit for bit (trainer.groundtruth's checkpoints).
        """
        u = np.asarray(u, dtype=np.float64)
        v = np.asarray(v, dtype=np.float64)
        if u.ndim != 1 or v.ndim != 1 or u.size == 0 or v.size == 0:
            raise GratNetError("u and v must be non-empty 1-D arrays")
        constant = [index for index, w in enumerate(w_slices) if np.ndim(w) == 0]
        varying = [index for index, w in enumerate(w_slices) if np.ndim(w) != 0]
        for index in varying:
            if np.shape(w_slices[index]) != (v.size, u.size):
                raise GratNetError(f"w array of slice {index} has shape {np.shape(w_slices[index])}, "
                                   f"expected {(v.size, u.size)}")
        ops = _NumpyOps() if self.device is None else _TorchOps(self.device)
        heights = ops.put(self.heights)  # the integration grid's heights where the products run
        shape = (len(w_slices), v.size, u.size, 3)
        if initial is not None and initial.shape != shape:
            raise GratNetError(f"the sum to continue from has shape {initial.shape}, expected {shape}")
        result = ops.zeros(shape, complex_=False) if initial is None else ops.put(np.array(initial, dtype=np.float64))
        interpolation = _ChebyshevPlan(
            np.stack([np.asarray(w_slices[i], dtype=np.float64) for i in varying]) if varying else None,
            self.surface.half_span_um,
            2.0 * np.pi / self.spectral.wavelengths_um.min(),
            self.tolerance,
        )
        self.last_node_count = interpolation.count if varying else 0
        chosen = range(len(self.spectral.wavelengths_um)) if wavelengths is None else list(wavelengths)
        bar = tqdm(
            total=len(chosen), desc=progress if isinstance(progress, str) else "F-term",
            unit="λ", disable=not progress, leave=False,
        )
        with bar, ops.exact_products():
            for done, (wavelength, weights) in enumerate(
                    zip(self.spectral.wavelengths_um[chosen], self.spectral.xyz_weights[chosen], strict=True), 1):
                wavenumber = 2.0 * np.pi / wavelength
                kernel_x = ops.put(self._kernel(u, self.surface.x_um, self.surface.window_x, wavenumber))
                kernel_y = ops.put(self._kernel(v, self.surface.y_um, self.surface.window_y, wavenumber))
                xyz_weights = ops.put(np.asarray(weights, dtype=np.float64))

                def transform(w: float, kx: Any = kernel_x, ky: Any = kernel_y, k: float = wavenumber) -> Any:
                    # P = Ey · exp(i k w H) · Exᵀ  (eq. 1 as a separable sum)
                    return (ky @ ops.height_phasor(heights, k, w)) @ kx.T

                for index in constant:
                    power = ops.power(transform(float(w_slices[index])))
                    result[index] += power[..., None] * xyz_weights
                if varying:
                    power = interpolation.power(transform, ops)
                    result[varying] += power[..., None] * xyz_weights
                bar.update(1)
                if after_wavelength is not None:
                    after_wavelength(done, lambda: ops.fetch(result))
        return ops.fetch(result)

    def xyz_points(self, u: np.ndarray, v: np.ndarray, w: np.ndarray, chunk: int = 4096,
                   progress: bool | str = False) -> np.ndarray:
        """CIE XYZ at arbitrary key vectors (u, v, w) (broadcast together); shape (…, 3).

        Scattered points have no grid to share, so each costs one Ny×Nx product per Chebyshev node
        and wavelength: P = Σ_m Ey[p, m] · (exp(i k w H) · Exᵀ)[m, p]. Prefer :meth:`xyz_grid` when
        (u, v) form a grid (volumes, BRDF slices).
        """
        u, v, w = np.broadcast_arrays(*(np.asarray(a, dtype=np.float64) for a in (u, v, w)))
        shape = u.shape
        u, v, w = u.ravel(), v.ravel(), w.ravel()
        result = np.zeros((u.size, 3))
        wavelengths = self.spectral.wavelengths_um
        chunks = range(0, u.size, chunk)
        bar = tqdm(total=len(chunks) * len(wavelengths), desc=progress if isinstance(progress, str) else "F-term",
                   unit="λ", disable=not progress, leave=False)
        with bar:
            for start in chunks:
                part = slice(start, start + chunk)
                plan = _ChebyshevPlan(w[part], self.surface.half_span_um,
                                      2.0 * np.pi / wavelengths.min(), self.tolerance)
                for wavelength, weights in zip(wavelengths, self.spectral.xyz_weights, strict=True):
                    wavenumber = 2.0 * np.pi / wavelength
                    kernel_x = self._kernel(u[part], self.surface.x_um, self.surface.window_x, wavenumber)
                    kernel_y = self._kernel(v[part], self.surface.y_um, self.surface.window_y, wavenumber)

                    def transform(w_node: float, kx: np.ndarray = kernel_x, ky: np.ndarray = kernel_y,
                                  k: float = wavenumber) -> np.ndarray:
                        return np.einsum("mp,pm->p", self._height_phasor(k, w_node) @ kx.T, ky)

                    result[part] += plan.power(transform)[:, None] * weights
                    bar.update(1)
        return result.reshape(shape + (3,))


class _ChebyshevPlan:
    """Interpolation in w between exact transforms at Chebyshev–Lobatto nodes (see module docstring)."""

    def __init__(
        self, w: np.ndarray | None, half_span_um: float, wavenumber_max: float, tolerance: float,
        cache_bytes: int = 2 << 30,
    ) -> None:
        self.w = w
        self.count = 0
        if w is None:
            return
        low, high = float(w.min()), float(w.max())
        self.centre, self.half_width = 0.5 * (low + high), 0.5 * (high - low)
        phase_range = wavenumber_max * half_span_um * self.half_width
        # A (nearly) single w needs one exact transform; otherwise chebyshev_node_count gives ≥ 2 nodes.
        self.count = 1 if phase_range < 1e-12 else chebyshev_node_count(phase_range, tolerance)
        if self.count == 1:
            return
        order = np.arange(self.count)
        self.nodes = np.cos(np.pi * order / (self.count - 1))  # s_j on [−1, 1]
        self.node_w = self.centre + self.half_width * self.nodes
        self.barycentric = np.where(order % 2 == 0, 1.0, -1.0)
        self.barycentric[[0, -1]] *= 0.5
        s = (w - self.centre) / self.half_width
        # One node at a time: a (nodes × samples) array would not fit for full volumes.
        self.exact_node = np.full(s.shape, -1, dtype=np.int32)
        self.denominator = np.zeros(s.shape)
        with np.errstate(divide="ignore", invalid="ignore"):
            for j in range(self.count):
                difference = s - self.nodes[j]
                self.exact_node[difference == 0] = j
                self.denominator += self.barycentric[j] / difference
        self.s = s
        # The bases do not depend on λ: keep them when they fit in a modest budget.
        self.cache: dict[int, np.ndarray] | None = {} if self.count * s.size * 4 <= cache_bytes else None

    def basis(self, j: int) -> np.ndarray:
        """Lagrange basis ℓ_j(s) at every sample (barycentric form; 1/0 exactly at nodes)."""
        if self.cache is not None and j in self.cache:
            return self.cache[j]
        with np.errstate(divide="ignore", invalid="ignore"):
            value = (self.barycentric[j] / (self.s - self.nodes[j])) / self.denominator
        value = np.where(self.exact_node >= 0, (self.exact_node == j).astype(np.float64), value)
        if self.cache is not None:
            # The float32 copy from the first wavelength on, so that every wavelength (and a run resumed at any
            # of them) sums the same numbers.
            self.cache[j] = value = value.astype(np.float32)
        return value

    def power(self, transform: Callable[[float], Any], ops: _NumpyOps | _TorchOps | None = None) -> Any:
        """|P|² (float64) at every sample of every varying slice, as ``ops`` arrays (numpy by default)."""
        assert self.w is not None
        ops = ops or _NumpyOps()
        if self.count == 1:
            if isinstance(ops, _TorchOps):
                return ops.power(transform(self.centre)).expand(self.w.shape).clone()
            return np.broadcast_to(ops.power(transform(self.centre)), self.w.shape).copy()
        total = ops.zeros(self.w.shape, complex_=True)
        for j in range(self.count):
            total += ops.put_basis(self, j) * transform(float(self.node_w[j]))
        return ops.power(total)


class _NumpyOps:
    """The array operations of :meth:`FTerm.xyz_grid` in numpy (the reference implementation)."""

    def put(self, array: np.ndarray) -> np.ndarray:
        return array

    def put_basis(self, plan: _ChebyshevPlan, j: int) -> np.ndarray:
        return plan.basis(j)

    def zeros(self, shape: tuple[int, ...], complex_: bool) -> np.ndarray:
        return np.zeros(shape, dtype=np.complex128 if complex_ else np.float64)

    def height_phasor(self, heights: np.ndarray, wavenumber: float, w: float) -> np.ndarray:
        """exp(i k w h) on the integration grid, complex64."""
        phase = np.float32(wavenumber * w) * heights
        phasor = np.empty(phase.shape, dtype=np.complex64)
        phasor.real = np.cos(phase)
        phasor.imag = np.sin(phase)
        return phasor

    def power(self, amplitude: np.ndarray) -> np.ndarray:
        return np.square(np.abs(amplitude), dtype=np.float64)

    def fetch(self, array: np.ndarray) -> np.ndarray:
        return array

    def exact_products(self) -> contextlib.AbstractContextManager[None]:
        return contextlib.nullcontext()


class _TorchOps:
    """The same operations in torch on ``device``: complex64 products, float64 sums (as numpy's)."""

    def __init__(self, device: str) -> None:
        try:
            import torch
        except ImportError as error:  # torch comes with the trainer extra
            raise GratNetError("--device other than numpy's cpu needs torch: pip install 'gratnet[trainer]'") from error
        self.torch = torch
        self.device = torch.device(device)
        self._bases: dict[int, Any] = {}

    def put(self, array: np.ndarray) -> Any:
        writable = array if array.flags.writeable and array.flags.c_contiguous else np.array(array, copy=True)
        return self.torch.from_numpy(writable).to(self.device)

    def put_basis(self, plan: _ChebyshevPlan, j: int) -> Any:
        # The bases do not depend on λ: upload each once (float32, as numpy's cache keeps them); one plan per
        # xyz_grid call, as one ops.
        if j not in self._bases:
            self._bases[j] = self.put(np.asarray(plan.basis(j), dtype=np.float32))
        return self._bases[j]

    def zeros(self, shape: tuple[int, ...], complex_: bool) -> Any:
        dtype = self.torch.complex128 if complex_ else self.torch.float64
        return self.torch.zeros(shape, dtype=dtype, device=self.device)

    def height_phasor(self, heights: Any, wavenumber: float, w: float) -> Any:
        """exp(i k w h) of ``heights`` (a float32 tensor from :meth:`put`), complex64."""
        phase = float(np.float32(wavenumber * w)) * heights  # float32, as numpy's
        return self.torch.polar(self.torch.ones_like(phase), phase)

    def power(self, amplitude: Any) -> Any:
        return amplitude.abs().to(self.torch.float64).square()

    def fetch(self, array: Any) -> np.ndarray:
        return array.cpu().numpy()

    @contextlib.contextmanager
    def exact_products(self) -> Iterator[None]:
        """Full float32 matrix products (no TF32, whose 10-bit mantissa would cost 1e-3 relative)."""
        matmul = self.torch.backends.cuda.matmul
        saved = matmul.allow_tf32
        matmul.allow_tf32 = False
        try:
            yield
        finally:
            matmul.allow_tf32 = saved
