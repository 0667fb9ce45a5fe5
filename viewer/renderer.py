"""GPU evaluation of a trained model: BRDF slices and network values at arbitrary key vectors.

:class:`NetworkRenderer` uploads a :class:`~gratnet.modelfile.ModelFile`'s packed weight texture
(RGBA32F, NEAREST, no mipmaps; docs/formats.md "Weight texture layout"), compiles the GLSL programs
with the model's array capacities as defines (``MAX_BLOCKS``, ``MAX_LAYERS``, ``MAX_FREQUENCIES``) and
sets everything else — layer layout, activations, encoding frequencies, range transform, scheme — as
uniforms. The shaders implement docs/physics.md eq. 5–7 and mirror ``gratnet.encoding``,
``gratnet.modelfile.evaluate_keys`` and ``gratnet.brdf.a_term``; tests/runtime/test_shader_parity.py ties them.

Rendering only: no glfw, no imgui, no torch. Programs are compiled on first use.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Mapping
from pathlib import Path

import moderngl
import numpy as np

from gratnet.bounds import DISPLAY_SKIP_THRESHOLD, OutputBounds, display_skip_matrix, output_bounds
from gratnet.codes import HIDDEN, MODE, OUTPUT, RANGE, SCHEME, WEIGHTS_PATHS, WeightSource
from gratnet.errors import GratNetError
from gratnet.featuregrid import CHUNK_FEATURES, grid_chunks
from gratnet.modelfile import LEAKY_RELU_SLOPE, ModelFile, pack_texture, texture_layout
from gratnet.shadowing import model_slope_covariance
from viewer.baked import baked_mlp_source
from viewer.glsl import GeneratedSource, compile_program
from viewer.shading import (
    STATISTICS_KEYS,
    MaterialTexture,
    ShadingPrograms,
    ior_uniform,
    set_uniform,
    skip_threshold_value,
)

__all__ = [
    "BAKED_MAX_MACS",
    "DISPLAY_SKIP_THRESHOLD",
    "STATISTICS_KEYS",
    "WEIGHTS_PATHS",
    "NetworkRenderer",
    "check_grid_texture_units",
    "choose_weights_path",
    "frequency_table",
    "ior_uniform",
    "is_software_rasterizer",
    "model_defines",
    "set_uniform",
    "skip_threshold_value",
    "xyz_to_linear_srgb_matrix",
]

# WEIGHTS_PATHS (gratnet.codes): where the MLP's weights come from: ``texture`` (shaders/mlp.glsl reads the packed
# RGBA32F texture), ``baked`` (viewer/baked.py writes them into the shader as literals) or ``auto``
# (:func:`choose_weights_path`).
#: The largest net (multiply-adds per evaluation) that ``auto`` bakes on a software rasterizer: the first
#: compile grows faster than the net. Measured on Mesa llvmpipe (2 cores, shader cache off), brdf_slice
#: compile + first draw: 2.8 s at 3.9k MACs, 23–29 s at 28.4k (the shipped 163-108-66-40-24-3), 131 s at
#: 59k (funnel-176); the 28.4k net then ran 4–7x faster than on the texture path (docs/benchmarks.md).
BAKED_MAX_MACS = 32_000
SOFTWARE_RASTERIZERS = ("llvmpipe", "softpipe", "swrast")  # substrings of GL_RENDERER
_LOG = logging.getLogger("gratnet.renderer")  # the gratnet command shows its INFO lines (gratnet/cli.py)

# The codes of the GLSL (schemes, activations, range kinds, evaluate_keys' modes) are gratnet/codes.py's.
_PASS_WIDTH = 1024  # pixels per row of a key-evaluation pass
_PASS_PIXELS = 1 << 20  # keys per pass: bounds memory and the time of one draw
_FREQUENCY_BITS = 10  # significant bits of the exact part of s^j (see shaders/encoding.glsl)
#: The counters of shaders/skip.glsl (COUNTER_*), in order, as the keys of a render's ``statistics`` dict.
_SKIP_BOUND_UNIT = 3  # texture unit of u_skip_bound (weights: 0; evaluate_keys/display inputs: 1, 2)
#: Texture unit of a feature-grid model's first grid texture: chunk k of level l (featuregrid.glsl) is on unit
#: _GRID_UNIT + l * chunks + k, chunks = ceil(C/4) (level l: _GRID_UNIT + l when C ≤ 4).
_GRID_UNIT = 8
#: Samplers a program may have besides the grids, on units 0–3 (u_weights; evaluate_keys' u_inputs, u_inputs2;
#: u_skip_bound): a stage's sampler limit must leave room for them beside the grid textures.
_OTHER_SAMPLERS = 4
#: How a feature-grid model's grids are interpolated (shaders/featuregrid.glsl): ``manual`` (eight texelFetches,
#: float32 weights: eq. 6g exactly) or ``hardware`` (one GL_LINEAR texture() call; GPUs may quantise the weights).
GRID_FILTERS = ("manual", "hardware")


def model_defines(model: ModelFile) -> dict[str, int | float]:
    """The ``#define``s the programs need for ``model``: array capacities and the leaky-ReLU slope."""
    layout = texture_layout(list(model.layer_sizes))
    defines: dict[str, int | float] = {
        "MAX_BLOCKS": max(max(entry["in_blocks"], entry["out_blocks"]) for entry in layout),
        "MAX_LAYERS": len(layout),
        "MAX_FREQUENCIES": max(model.encoding.frequencies, model.encoding.t_frequencies, 1),
        "LEAKY_RELU_SLOPE": float(LEAKY_RELU_SLOPE),
    }
    if model.grids:  # shaders/featuregrid.glsl is compiled in only for feature-grid models
        features = int(model.grids[0].shape[-1])
        defines.update({"GRID_LEVELS": len(model.grids), "GRID_FEATURES": features,
                        "GRID_CHUNKS": grid_chunks(features)})
    return defines


def check_grid_texture_units(info: Mapping[str, object], textures: int) -> None:
    """Refuse (:class:`GratNetError`) a feature-grid model whose ``textures`` grid textures (levels × chunks) do
    not fit the context (``ctx.info``): their units _GRID_UNIT … must exist, and the fragment and compute
    stages must take them beside the programs' other samplers. Missing limits count as GL 4.3's minima."""
    def limit(name: str, minimum: int) -> int:
        value = info.get(name, minimum)
        return int(value) if isinstance(value, (int, np.integer)) else minimum

    if textures == 0:
        return
    combined = limit("GL_MAX_COMBINED_TEXTURE_IMAGE_UNITS", 96)
    per_stage = min(limit("GL_MAX_TEXTURE_IMAGE_UNITS", 16), limit("GL_MAX_COMPUTE_TEXTURE_IMAGE_UNITS", 16))
    if _GRID_UNIT + textures > combined or _OTHER_SAMPLERS + textures > per_stage:
        raise GratNetError(
            f"the feature-grid model needs {textures} grid textures (levels × ceil(features/4)) on texture units "
            f"{_GRID_UNIT}…{_GRID_UNIT + textures - 1}, plus up to {_OTHER_SAMPLERS} other samplers per shader, but "
            f"this OpenGL context has {combined} texture units and {per_stage} samplers per fragment/compute shader: "
            f"use fewer levels or features per level")


def _split_frequency(value: float) -> tuple[float, float]:
    """value = a + b with ``a`` rounded to 10 significant bits and b = float32(value - a)."""
    if value == 0.0:
        return 0.0, 0.0
    mantissa, exponent = math.frexp(value)
    exact = math.ldexp(round(mantissa * (1 << _FREQUENCY_BITS)), exponent - _FREQUENCY_BITS)
    return exact, float(np.float32(value - exact))


def frequency_table(model: ModelFile, rows: int) -> np.ndarray:
    """Rows (a_j, b_j, a_t_j, b_t_j): s^j and s_t^j in half-turns (float64 powers, then split), zero-padded."""
    table = np.zeros((rows, 4), dtype=np.float32)
    spec = model.encoding
    for j in range(spec.frequencies):
        table[j, 0:2] = _split_frequency(spec.scale**j)
    for j in range(spec.t_frequencies):
        table[j, 2:4] = _split_frequency(spec.t_scale**j)
    return table


def xyz_to_linear_srgb_matrix() -> np.ndarray:
    """colour-science's CIE XYZ → linear sRGB matrix (3×3, float64), as used by ``gratnet.display``."""
    import colour  # deferred: colour-science takes ~1 s to import and only display needs it

    return np.asarray(colour.RGB_COLOURSPACES["sRGB"].matrix_XYZ_to_RGB, dtype=np.float64)


def is_software_rasterizer(ctx: moderngl.Context) -> bool:
    """Whether ``ctx`` renders on the CPU (Mesa llvmpipe, softpipe, swrast), from its GL_RENDERER string."""
    renderer = str(ctx.info.get("GL_RENDERER", "")).lower()
    return any(name in renderer for name in SOFTWARE_RASTERIZERS)


def choose_weights_path(ctx: moderngl.Context, model: ModelFile, weights_path: str = "auto") -> str:
    """``texture`` or ``baked``: ``weights_path`` itself unless it is ``auto``, which picks

    * ``baked`` on a software rasterizer (``GL_RENDERER`` names llvmpipe, softpipe or swrast) for nets of
      at most :data:`BAKED_MAX_MACS` multiply-adds per evaluation: there every texel fetch is a gather on
      the CPU, and straight-line literal weights ran the shipped 28k-MAC nets at 12–20 GMAC/s against
      ~3 on the texture path, at the cost of a first compile that grows faster than the net (~25 s at
      28k MACs; Mesa's disk shader cache makes later ones take ~1 s);
    * ``texture`` otherwise: on a GPU texel fetches are cheap and a program per model is not worth its
      compile time, and big nets would take llvmpipe minutes to compile; and for feature-grid models, whose
      texture-path programs compile in seconds: on llvmpipe the paper-cd grid model's first
      `gratnet render --mesh cd` took 9.8 s on the texture path and 65 s baked (its frames: 97.5 against
      25.7 ms on the 128² probe), so ``baked`` is theirs only when asked for (their grids are textures on
      either path).

    Raises:
        GratNetError: ``weights_path`` is not one of :data:`WEIGHTS_PATHS`.
    """
    if weights_path not in WEIGHTS_PATHS:
        raise GratNetError(f"weights path must be one of {', '.join(WEIGHTS_PATHS)}, got {weights_path!r}")
    if weights_path != "auto":
        return weights_path
    if model.grids:
        return "texture"
    software = is_software_rasterizer(ctx)
    return "baked" if software and model.macs_per_evaluation <= BAKED_MAX_MACS else "texture"


class NetworkRenderer(ShadingPrograms):
    """Renders a model's BRDF slices and evaluates it at key vectors on the GPU (one fragment per value).

    Args:
        ctx: an OpenGL ≥ 4.3 context (see :mod:`viewer.context`).
        model: the trained network; validated and packed here.
        shader_root: folder of the GLSL files (default: the repository's ``shaders/``).
        weights_path: ``texture`` (shaders/mlp.glsl reads the packed weight texture), ``baked`` (the
            weights are literals in a generated mlp.glsl, :mod:`viewer.baked`: no weight texture and no
            ``u_weights``/``u_layers``/activation uniforms) or ``auto`` (:func:`choose_weights_path`: baked
            for nets up to :data:`BAKED_MAX_MACS` multiply-adds on a software rasterizer, else texture).
            Both paths compute the same sums in float32; tests/runtime/test_baked.py ties them.
        baked_source: the baked ``mlp.glsl`` text of ``model`` made earlier (:attr:`baked_source` of another
            renderer of the same model, e.g. in another process): spares generating it again (~0.3 s for a
            shipped model) and keeps the program text, hence Mesa's shader-cache key, identical.

    Attributes:
        weights_path: the path chosen, ``texture`` or ``baked``.
        baked_source: the generated ``mlp.glsl`` on the baked path, else ``None``.
    """

    def __init__(self, ctx: moderngl.Context, model: ModelFile, shader_root: str | Path | None = None,
                 weights_path: str = "auto", baked_source: str | None = None, grid_filter: str = "manual") -> None:
        texture, layout = pack_texture(model)  # validates the model
        if grid_filter not in GRID_FILTERS:
            raise GratNetError(f"grid filter must be one of {', '.join(GRID_FILTERS)}, got {grid_filter!r}")
        self.grid_filter = grid_filter
        #: The packed weight texture (docs/formats.md), ``float32`` ``(rows, texels per row, 4)``, on either path
        #: (the deferred path's weight buffers hold the same texels).
        self.packed_weights = np.ascontiguousarray(texture, dtype=np.float32)
        super().__init__(ctx, model_defines(model), shader_root, slope_covariance=model_slope_covariance(model))
        self.model = model
        self.layout = layout
        self.weights_path = choose_weights_path(ctx, model, weights_path)
        self.baked_source: str | None = None
        if self.weights_path == "baked":
            label = f"{'-'.join(map(str, model.layer_sizes))} {model.activation}"
            self.baked_source = baked_source if baked_source is not None else baked_mlp_source(model, label)
            self.overrides["mlp.glsl"] = GeneratedSource(f"<baked mlp.glsl: {label}>", self.baked_source)
            texture = np.zeros((1, 1, 4), dtype=np.float32)  # a placeholder: the baked programs read no texture
        height, width = texture.shape[:2]
        self._weights = ctx.texture((width, height), 4, np.ascontiguousarray(texture).tobytes(), dtype="f4")
        self._weights.filter = (moderngl.NEAREST, moderngl.NEAREST)  # texelFetch ignores it; be explicit
        self._weights.repeat_x = self._weights.repeat_y = False
        # A feature-grid model's grids: per level (T, R_v, R_u, C) → ceil(C/4) (R_u, R_v, T) textures, chunk k
        # holding features 4k … 4k + 3 in float channels; a last partial chunk has only the C − 4k channels it
        # needs (no padding bytes; the shader reads no lane beyond C, the baked MLP weighs them 0). With C ≤ 4:
        # one texture per level, exactly as before chunks. Units: _GRID_UNIT + level * chunks + k.
        self._grids: list[moderngl.Texture3D] = []
        if model.grids:
            check_grid_texture_units(ctx.info, len(model.grids) * grid_chunks(model.grids[0].shape[-1]))
        for grid in model.grids:
            dtype = "f2" if grid.dtype == np.float16 else "f4"
            for first in range(0, grid.shape[3], CHUNK_FEATURES):
                chunk = grid[..., first:first + CHUNK_FEATURES]
                texture3d = ctx.texture3d((grid.shape[2], grid.shape[1], grid.shape[0]), chunk.shape[3],
                                          np.ascontiguousarray(chunk).tobytes(), dtype=dtype)
                texture3d.filter = (moderngl.LINEAR, moderngl.LINEAR)  # texelFetch ignores it; texture() filters
                texture3d.repeat_x = texture3d.repeat_y = texture3d.repeat_z = False  # clamp to edge: eq. 6g clamps c
                self._grids.append(texture3d)
        # Skipping work (gratnet/bounds.py, shaders/skip.glsl): the bound table and the counters are made on
        # first use; the 1-texel placeholder is bound when skipping is off (the sampler must read something).
        self._output_bounds: OutputBounds | None = None
        self._skip_texture: moderngl.Texture3D | None = None
        self._skip_placeholder = ctx.texture3d((1, 1, 1), 4, np.zeros(4, dtype=np.float32).tobytes(), dtype="f4")
        self._skip_placeholder.filter = (moderngl.NEAREST, moderngl.NEAREST)

    # ---------------------------------------------------------------------------------------------
    # Programs

    def model_uniforms(self, program: moderngl.Program | moderngl.ComputeShader,
                       source: WeightSource | None = None) -> None:
        """Everything the encoding, MLP and range-transform includes read, from the model. ``source``: where
        the program's mlp.glsl reads the weights (the texture, baked literals, or the deferred path's buffer or
        shared memory; default: :attr:`weights_path`)."""
        source = WeightSource(self.weights_path) if source is None else source
        layers = np.zeros((int(self.defines["MAX_LAYERS"]), 4), dtype=np.int32)
        for k, entry in enumerate(self.layout):
            layers[k, :3] = entry["row_offset"], entry["in_blocks"], entry["out_blocks"]
        model = self.model
        if source is not WeightSource.BAKED:  # the baked mlp.glsl has the layout and activations in its code
            if source is WeightSource.TEXTURE:
                set_uniform(program, "u_weights", 0)
            else:
                set_uniform(program, "u_weights_width", int(self.packed_weights.shape[1]))
            set_uniform(program, "u_layer_count", len(self.layout))
            set_uniform(program, "u_layers", layers)
            set_uniform(program, HIDDEN.uniform_name, HIDDEN.code(model.activation))
            set_uniform(program, OUTPUT.uniform_name, OUTPUT.code(model.output_activation))
        if self._grids:
            set_uniform(program, "u_grid", np.arange(_GRID_UNIT, _GRID_UNIT + len(self._grids), dtype=np.int32))
            set_uniform(program, "u_grid_hardware_filter", int(self.grid_filter == "hardware"))
            set_uniform(program, "u_grid_smoothstep", int(model.grid_interpolation == "smoothstep"))
        set_uniform(program, SCHEME.uniform_name, SCHEME.code(model.scheme))
        # encoded_feature (encoding.glsl) reads the counts; the baked MLP has them in its code, so baked
        # programs that do not call encoded_feature (all but encode_keys) lack these uniforms.
        if source is not WeightSource.BAKED or "u_frequencies" in program:
            set_uniform(program, "u_frequencies", model.encoding.frequencies)
            set_uniform(program, "u_t_frequencies", model.encoding.t_frequencies)
            set_uniform(program, "u_spatial_groups", model.encoding.groups)
        set_uniform(program, "u_frequency", frequency_table(model, int(self.defines["MAX_FREQUENCIES"])))
        set_uniform(program, RANGE.uniform_name, RANGE.code(model.range.kind))
        set_uniform(program, "u_range_bits", float(model.range.bits))
        set_uniform(program, "u_range_power", float(model.range.power))
        set_uniform(program, "u_range_white", tuple(float(c) for c in model.range.white))

    def configure_program(self, program: moderngl.Program, name: str) -> None:
        """The model's uniforms (:meth:`model_uniforms`), and evaluate_keys' input units."""
        self.model_uniforms(program)
        if name == "evaluate_keys":
            set_uniform(program, "u_inputs", 1)
            set_uniform(program, "u_inputs2", 2)

    def material_textures(self) -> tuple[tuple[MaterialTexture, int], ...]:
        """The weight texture on unit 0 (none on the baked path) and a feature-grid model's grids on theirs."""
        weights = ((self._weights, 0),) if self.weights_path == "texture" else ()
        return weights + tuple((grid, _GRID_UNIT + index) for index, grid in enumerate(self._grids))

    def program(self, name: str) -> moderngl.Program:
        """Program ``name`` (``brdf_slice``, ``evaluate_keys``, ``display``, or another program of the network
        includes such as ``surface``, whose model uniforms are set likewise), compiled on first use."""
        if name in self.compiled:
            return self.compiled[name]
        if name == "display":  # no network in it: no defines, no model uniforms
            program = compile_program(self.ctx, name, {}, self.shader_root)
            matrix = xyz_to_linear_srgb_matrix()
            set_uniform(program, "u_xyz_to_linear_srgb", np.ascontiguousarray(matrix.T, dtype=np.float32))
            set_uniform(program, "u_xyz", 1)
            self.compiled[name] = program
            self.vertex_arrays[name] = self.ctx.vertex_array(program, [])
            return program
        if self.weights_path == "baked":
            _LOG.info("program %r with baked weights (%d MACs per pixel): the first draw JIT-compiles "
                      "it, which can take ~25 s at 28k MACs on llvmpipe; Mesa's shader cache keeps it",
                      name, self.model.macs_per_evaluation)
        return super().program(name)

    def use_weights(self, location: int = 0) -> None:
        """Bind the weight texture to texture unit ``location`` (the programs' ``u_weights`` reads unit 0),
        for callers that draw a :meth:`program` with their own geometry; nothing to bind on the baked path."""
        if self.weights_path == "texture":
            self._weights.use(location=location)
        for index, grid in enumerate(self._grids):  # a feature-grid model's grid textures, on their fixed units
            grid.use(location=_GRID_UNIT + index)

    # ---------------------------------------------------------------------------------------------
    # Skipping work (issue 5: gratnet/bounds.py, shaders/skip.glsl)

    def set_output_bounds(self, bounds: OutputBounds | None) -> None:
        """Use ``bounds`` for skipping (``None``: the cached default of ``gratnet.bounds.output_bounds``,
        computed on first use; tens of seconds for a shipped model unless precomputed)."""
        if bounds is not None and not isinstance(bounds, OutputBounds):
            raise GratNetError(f"expected gratnet.bounds.OutputBounds, got {type(bounds).__name__}")
        self._output_bounds = bounds
        if self._skip_texture is not None:
            self._skip_texture.release()
            self._skip_texture = None

    @property
    def output_bounds(self) -> OutputBounds:
        """The bound table used for skipping (computed or read from the cache on first use)."""
        if self._output_bounds is None:
            self._output_bounds = output_bounds(self.model)
        return self._output_bounds

    def _skip_bound_texture(self, threshold: float) -> moderngl.Texture3D:
        """The bound as an RGBA32F 3D texture (Cu, Cv, Ct); a 1-texel placeholder when skipping is off."""
        if threshold <= 0.0:
            return self._skip_placeholder
        if self._skip_texture is None:
            bounds = self.output_bounds
            cells = bounds.cells
            data = np.zeros((*bounds.xyz.shape[:3], 4), dtype=np.float32)
            data[..., :3] = bounds.xyz  # (Ct, Cv, Cu): texel (i, j, k) = cell (c_u i, c_v j, c_t k)
            self._skip_texture = self.ctx.texture3d(cells, 4, data.tobytes(), dtype="f4")
            self._skip_texture.filter = (moderngl.NEAREST, moderngl.NEAREST)
        return self._skip_texture

    def skip_uniforms(self, program: moderngl.Program | moderngl.ComputeShader, skip_threshold: float | None
                       ) -> tuple[MaterialTexture, int]:
        """Set skip.glsl's uniforms on ``program``; returns ``(texture, unit)`` of the bound to bind."""
        threshold = skip_threshold_value(skip_threshold)
        if threshold > 0.0 and self.model.grids:  # gratnet/bounds.py builds no bound for grid models
            _LOG.info("skipping work is not built for feature-grid models: evaluating every pixel")
            threshold = 0.0
        texture = self._skip_bound_texture(threshold)
        set_uniform(program, "u_skip_threshold", threshold)
        set_uniform(program, "u_skip_bound", _SKIP_BOUND_UNIT)
        # Read only when skipping (skip.glsl returns first otherwise): no colour-science import (~1 s) then.
        matrix = display_skip_matrix() if threshold > 0.0 else np.zeros((3, 3))
        set_uniform(program, "u_skip_matrix", np.ascontiguousarray(matrix.T, dtype=np.float32))  # GLSL: column-major
        return texture, _SKIP_BOUND_UNIT

    # ---------------------------------------------------------------------------------------------
    # Values at arbitrary inputs (program evaluate_keys)

    def _evaluate(self, mode: int, first: np.ndarray, second: np.ndarray | None = None, block: int = 0,
                  ior: float = 0.0) -> np.ndarray:
        """Run evaluate_keys in ``mode`` on ``(N, 3)`` inputs; returns ``(N, 4)`` float32."""
        program = self.program("evaluate_keys")
        set_uniform(program, MODE.uniform_name, mode)
        set_uniform(program, "u_block", block)
        set_uniform(program, "u_ior", ior)
        set_uniform(program, "u_slope_covariance", self.slope_covariance)
        count = first.shape[0]
        result = np.empty((count, 4), dtype=np.float32)
        for start in range(0, count, _PASS_PIXELS):
            stop = min(start + _PASS_PIXELS, count)
            result[start:stop] = self._evaluate_pass(mode, first[start:stop],
                                                     None if second is None else second[start:stop])
        return result

    def _evaluate_pass(self, mode: int, first: np.ndarray, second: np.ndarray | None) -> np.ndarray:
        count = first.shape[0]
        width = min(count, _PASS_WIDTH)
        height = -(-count // width)

        def upload(values: np.ndarray) -> moderngl.Texture:
            padded = np.zeros((height * width, 4), dtype=np.float32)
            padded[:count, :3] = values
            texture = self.ctx.texture((width, height), 4, padded.tobytes(), dtype="f4")
            texture.filter = (moderngl.NEAREST, moderngl.NEAREST)
            return texture

        inputs = [upload(first), upload(first if second is None else second)]
        target = self.ctx.texture((width, height), 4, dtype="f4")
        framebuffer = self.ctx.framebuffer(color_attachments=[target])
        try:
            self.draw("evaluate_keys", framebuffer, ((inputs[0], 1), (inputs[1], 2)))
            data = framebuffer.read(components=4, dtype="f4")
        finally:
            framebuffer.release()
            for texture in (target, *inputs):
                texture.release()
        # Row-major texel order in and out (no flip: both are GL rows), so pixel n is value n.
        return np.frombuffer(data, dtype=np.float32).reshape(height * width, 4)[:count]

    @staticmethod
    def _keys(u: object, v: object, w: object) -> tuple[np.ndarray, tuple[int, ...]]:
        arrays = np.broadcast_arrays(*(np.asarray(c, dtype=np.float64) for c in (u, v, w)))
        shape = arrays[0].shape
        keys = np.stack([a.reshape(-1) for a in arrays], axis=-1).astype(np.float32)
        if not np.all(np.isfinite(keys)):
            raise GratNetError("key vectors must be finite")
        return keys, shape

    def evaluate_keys(self, u: object, v: object, w: object) -> np.ndarray:
        """CIE XYZ at key vectors ``(u, v, w)`` (broadcast together), evaluated by the shader.

        The GPU counterpart of ``gratnet.modelfile.evaluate_keys``: keys are rounded to float32 and
        evaluated one per pixel. Returns ``float32`` ``(…, 3)``, ``…`` the broadcast shape.
        """
        keys, shape = self._keys(u, v, w)
        if keys.shape[0] == 0:
            return np.zeros((*shape, 3), dtype=np.float32)
        return self._evaluate(MODE.code("xyz"), keys)[:, :3].reshape(*shape, 3)

    def network_outputs(self, u: object, v: object, w: object) -> np.ndarray:
        """The network's raw outputs (range-transformed XYZ, before eq. 7's inverse), ``float32`` ``(…, 3)``."""
        keys, shape = self._keys(u, v, w)
        if keys.shape[0] == 0:
            return np.zeros((*shape, 3), dtype=np.float32)
        return self._evaluate(MODE.code("network"), keys)[:, :3].reshape(*shape, 3)

    def encode_keys(self, u: object, v: object, w: object) -> np.ndarray:
        """The shader's encoded input features (eq. 6) at key vectors, ``float32`` ``(…, features)``.

        The GPU counterpart of ``gratnet.encoding.encode(network_coordinates(u, v, w, scheme), spec)``.
        """
        keys, shape = self._keys(u, v, w)
        features = self.model.encoding.features
        if keys.shape[0] == 0:
            return np.zeros((*shape, features), dtype=np.float32)
        blocks = [self._evaluate(MODE.code("encoding"), keys, block=b) for b in range(-(-features // 4))]
        return np.concatenate(blocks, axis=-1)[:, :features].reshape(*shape, features)

    def a_term(self, light: np.ndarray, view: np.ndarray, ior: float | None = 1.5) -> np.ndarray:
        """The shader's A-term (eq. 5) for direction pairs ``(…, 3)`` (broadcast), ``float32`` ``(…)``."""
        return self._direction_pairs(light, view, ior)[..., 0]

    def shadowing(self, light: np.ndarray, view: np.ndarray) -> np.ndarray:
        """The shader's Smith shadowing (gratnet.shadowing.smith_shadowing) with the model's slope covariance, for
        direction pairs ``(…, 3)`` (broadcast), ``float32`` ``(…)``."""
        return self._direction_pairs(light, view, None)[..., 1]

    def _direction_pairs(self, light: np.ndarray, view: np.ndarray, ior: float | None) -> np.ndarray:
        """evaluate_keys' MODE_A_TERM at direction pairs: ``float32`` ``(…, 2)``, A and S."""
        light, view = np.broadcast_arrays(np.asarray(light, dtype=np.float64), np.asarray(view, dtype=np.float64))
        if light.shape[-1:] != (3,):
            raise GratNetError(f"directions must have shape (…, 3), got {light.shape}")
        shape = light.shape[:-1]
        first = light.reshape(-1, 3).astype(np.float32)
        if first.shape[0] == 0:
            return np.zeros((*shape, 2), dtype=np.float32)
        values = self._evaluate(MODE.code("a_term"), first, view.reshape(-1, 3).astype(np.float32),
                                ior=ior_uniform(ior))
        return values[:, :2].reshape(*shape, 2)

    # ---------------------------------------------------------------------------------------------
    # Display

    def display_srgb(self, xyz: np.ndarray, exposure: float = 1.0) -> np.ndarray:
        """Display sRGB in [0, 1] (before 8-bit rounding) of an XYZ image ``(H, W, 3)``, as the viewer shows it.

        The GPU counterpart of ``gratnet.display.xyz_to_display_srgb8`` without the final ``round(255·)``.
        """
        image = np.asarray(xyz, dtype=np.float32)
        if image.ndim != 3 or image.shape[2] != 3 or min(image.shape[:2]) < 1:
            raise GratNetError(f"XYZ image must have shape (H, W, 3), got {image.shape}")
        height, width = image.shape[:2]
        program = self.program("display")
        set_uniform(program, "u_exposure", float(exposure))
        padded = np.zeros((height, width, 4), dtype=np.float32)
        padded[..., :3] = image[::-1]  # our row 0 is the top; GL's is the bottom
        source = self.ctx.texture((width, height), 4, padded.tobytes(), dtype="f4")
        target = self.ctx.texture((width, height), 4, dtype="f4")
        framebuffer = self.ctx.framebuffer(color_attachments=[target])
        try:
            self.draw("display", framebuffer, ((source, 1),))
            data = framebuffer.read(components=4, dtype="f4")
        finally:
            framebuffer.release()
            target.release()
            source.release()
        return np.frombuffer(data, dtype=np.float32).reshape(height, width, 4)[::-1, :, :3].copy()

    def release(self) -> None:
        """Free the GL objects (the context itself belongs to the caller)."""
        self.release_programs()
        self._weights.release()
        for grid in self._grids:
            grid.release()
        self._grids.clear()
        self._skip_placeholder.release()
        if self._skip_texture is not None:
            self._skip_texture.release()
        self._skip_texture = None
