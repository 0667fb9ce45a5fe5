"""GPU evaluation of a trained model: BRDF slices and network values at arbitrary key vectors.

:class:`NetworkRenderer` uploads a :class:`~gratnet.modelfile.ModelFile`'s packed weight texture
(RGBA32F, NEAREST, no mipmaps; docs/formats.md "Weight texture layout"), compiles the GLSL programs
with the model's array capacities as defines (``MAX_BLOCKS``, ``MAX_LAYERS``, ``MAX_FREQUENCIES``) and
sets everything else — layer layout, activations, encoding frequencies, range transform, scheme — as
uniforms. The shaders implement docs/physics.md eq. 5–7 and mirror ``gratnet.encoding``,
``gratnet.modelfile.evaluate_keys`` and ``gratnet.brdf.a_term``; tests/test_shader_parity.py ties them.

Rendering only: no glfw, no imgui, no torch. Programs are compiled on first use.
"""

from __future__ import annotations

import math
from pathlib import Path

import moderngl
import numpy as np

from gratnet.brdf import direction
from gratnet.errors import GratNetError
from gratnet.modelfile import LEAKY_RELU_SLOPE, ModelFile, pack_texture, texture_layout
from viewer.glsl import compile_program

__all__ = ["NetworkRenderer", "model_defines", "xyz_to_linear_srgb_matrix"]

# Codes of the GLSL `const int`s (shaders/encoding.glsl, mlp.glsl, range.glsl, evaluate_keys.glsl).
_SCHEMES = {"regular": 0, "simple": 1, "simple-max": 2}
_HIDDEN = {"relu": 0, "leaky_relu": 1, "silu": 2}
_OUTPUT = {"clamp": 0, "sigmoid": 1, "none": 2}
_RANGES = {"power-log": 0, "log": 1, "log1p": 2}
_MODE_XYZ, _MODE_NETWORK, _MODE_ENCODING, _MODE_A_TERM = 0, 1, 2, 3
_PASS_WIDTH = 1024  # pixels per row of a key-evaluation pass
_PASS_PIXELS = 1 << 20  # keys per pass: bounds memory and the time of one draw
_FREQUENCY_BITS = 10  # significant bits of the exact part of s^j (see shaders/encoding.glsl)


def model_defines(model: ModelFile) -> dict[str, int | float]:
    """The ``#define``s the programs need for ``model``: array capacities and the leaky-ReLU slope."""
    layout = texture_layout(list(model.layer_sizes))
    return {
        "MAX_BLOCKS": max(max(entry["in_blocks"], entry["out_blocks"]) for entry in layout),
        "MAX_LAYERS": len(layout),
        "MAX_FREQUENCIES": max(model.encoding.frequencies, model.encoding.t_frequencies, 1),
        "LEAKY_RELU_SLOPE": float(LEAKY_RELU_SLOPE),
    }


def _split_frequency(value: float) -> tuple[float, float]:
    """value = a + b with ``a`` rounded to 10 significant bits and b = float32(value - a)."""
    if value == 0.0:
        return 0.0, 0.0
    mantissa, exponent = math.frexp(value)
    exact = math.ldexp(round(mantissa * (1 << _FREQUENCY_BITS)), exponent - _FREQUENCY_BITS)
    return exact, float(np.float32(value - exact))


def _frequency_table(model: ModelFile, rows: int) -> np.ndarray:
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


def _ior_uniform(ior: float | None) -> float:
    """The shader's IOR uniform: 0 turns Fresnel off (``None`` or 0, as in physics.md eq. 5)."""
    if ior is None or ior == 0:
        return 0.0
    if not (math.isfinite(ior) and ior > 0) or ior == 1.0:
        raise GratNetError(f"ior must be a finite number > 0 other than 1 (or 0/None for no Fresnel), got {ior!r}")
    return float(ior)


def _set(program: moderngl.Program, name: str, value: object) -> None:
    """Set a uniform that the program must have (a missing one means shader and renderer disagree)."""
    if name not in program:
        raise GratNetError(f"GLSL program lacks uniform {name!r}; the shaders and viewer/renderer.py disagree")
    member = program[name]
    if isinstance(value, np.ndarray):
        member.write(value.tobytes())  # type: ignore[union-attr]
    else:
        member.value = value  # type: ignore[union-attr]


class NetworkRenderer:
    """Renders a model's BRDF slices and evaluates it at key vectors on the GPU (one fragment per value).

    Args:
        ctx: an OpenGL ≥ 4.3 context (see :mod:`viewer.context`).
        model: the trained network; validated and packed here.
        shader_root: folder of the GLSL files (default: the repository's ``shaders/``).
    """

    def __init__(self, ctx: moderngl.Context, model: ModelFile, shader_root: str | Path | None = None) -> None:
        texture, layout = pack_texture(model)  # validates the model
        self.ctx = ctx
        self.model = model
        self.layout = layout
        self.defines = model_defines(model)
        self.shader_root = shader_root
        height, width = texture.shape[:2]
        self._weights = ctx.texture((width, height), 4, np.ascontiguousarray(texture).tobytes(), dtype="f4")
        self._weights.filter = (moderngl.NEAREST, moderngl.NEAREST)  # texelFetch ignores it; be explicit
        self._weights.repeat_x = self._weights.repeat_y = False
        self._programs: dict[str, moderngl.Program] = {}
        self._vertex_arrays: dict[str, moderngl.VertexArray] = {}

    # ---------------------------------------------------------------------------------------------
    # Programs

    def _model_uniforms(self, program: moderngl.Program) -> None:
        """Everything the encoding, MLP and range-transform includes read, from the model."""
        layers = np.zeros((int(self.defines["MAX_LAYERS"]), 4), dtype=np.int32)
        for k, entry in enumerate(self.layout):
            layers[k, :3] = entry["row_offset"], entry["in_blocks"], entry["out_blocks"]
        model = self.model
        _set(program, "u_weights", 0)
        _set(program, "u_layer_count", len(self.layout))
        _set(program, "u_layers", layers)
        _set(program, "u_hidden_activation", _HIDDEN[model.activation])
        _set(program, "u_output_activation", _OUTPUT[model.output_activation])
        _set(program, "u_scheme", _SCHEMES[model.scheme])
        _set(program, "u_frequencies", model.encoding.frequencies)
        _set(program, "u_t_frequencies", model.encoding.t_frequencies)
        _set(program, "u_frequency", _frequency_table(model, int(self.defines["MAX_FREQUENCIES"])))
        _set(program, "u_range_kind", _RANGES[model.range.kind])
        _set(program, "u_range_bits", float(model.range.bits))
        _set(program, "u_range_power", float(model.range.power))
        _set(program, "u_range_white", tuple(float(c) for c in model.range.white))

    def program(self, name: str) -> moderngl.Program:
        """Program ``name`` (``brdf_slice``, ``evaluate_keys``, ``display``, or another program of the network
        includes such as ``surface``, whose model uniforms are set likewise), compiled on first use."""
        if name not in self._programs:
            if name == "display":
                program = compile_program(self.ctx, name, {}, self.shader_root)
                matrix = xyz_to_linear_srgb_matrix()
                _set(program, "u_xyz_to_linear_srgb", np.ascontiguousarray(matrix.T, dtype=np.float32))
                _set(program, "u_xyz", 1)
            else:
                program = compile_program(self.ctx, name, self.defines, self.shader_root)
                self._model_uniforms(program)
                if name == "evaluate_keys":
                    _set(program, "u_inputs", 1)
                    _set(program, "u_inputs2", 2)
            self._programs[name] = program
            self._vertex_arrays[name] = self.ctx.vertex_array(program, [])  # full-screen triangle: no buffers
        return self._programs[name]

    def use_weights(self, location: int = 0) -> None:
        """Bind the weight texture to texture unit ``location`` (the programs' ``u_weights`` reads unit 0),
        for callers that draw a :meth:`program` with their own geometry (viewer.scene)."""
        self._weights.use(location=location)

    def _draw(self, name: str, framebuffer: moderngl.Framebuffer,
              textures: tuple[tuple[moderngl.Texture, int], ...] = ()) -> None:
        """One full-screen triangle into ``framebuffer``, with blending/depth test off and the caller's
        framebuffer and enable flags restored afterwards (a window may share this context)."""
        # Textures are bound by hand: moderngl 5.13's scope(textures=...) left the samplers reading 0.
        scope = self.ctx.scope(framebuffer, enable_only=moderngl.NOTHING)
        try:
            with scope:
                framebuffer.use()  # the scope binds the framebuffer but leaves the viewport as it was
                for texture, unit in ((self._weights, 0), *textures):
                    texture.use(location=unit)
                self._vertex_arrays[name].render(moderngl.TRIANGLES, vertices=3)
        finally:
            scope.release()

    # ---------------------------------------------------------------------------------------------
    # BRDF slices

    def render_brdf_slice_layers(
        self, theta_deg: float, phi_deg: float, size: int, exposure: float = 1.0, ior: float | None = 1.5
    ) -> tuple[np.ndarray, np.ndarray]:
        """A BRDF slice (docs/physics.md "BRDF slice") and the network's XYZ behind it.

        Returns:
            ``(exposed, network)``, both ``float32`` ``(size, size, 3)`` with row 0 at the top (as
            ``gratnet.brdf.slice_view_directions``): ``exposed = exposure · A · XYZ`` (CIE XYZ, linear)
            and ``network`` = XYZ at each pixel's key vector; both 0 outside the unit disc.
        """
        if isinstance(size, bool) or not isinstance(size, (int, np.integer)) or not 1 <= size <= 16384:
            raise GratNetError(f"slice size must be an integer in 1 … 16384, got {size!r}")
        if not all(math.isfinite(value) for value in (theta_deg, phi_deg, exposure)):
            raise GratNetError(
                f"light angles and exposure must be finite, got {theta_deg!r}, {phi_deg!r}, {exposure!r}"
            )
        program = self.program("brdf_slice")
        _set(program, "u_size", int(size))
        _set(program, "u_light", tuple(float(c) for c in direction(theta_deg, phi_deg)))
        _set(program, "u_exposure", float(exposure))
        _set(program, "u_ior", _ior_uniform(ior))
        targets = [self.ctx.texture((size, size), 4, dtype="f4") for _ in range(2)]
        framebuffer = self.ctx.framebuffer(color_attachments=targets)
        try:
            self._draw("brdf_slice", framebuffer)
            images = [
                np.frombuffer(framebuffer.read(components=4, dtype="f4", attachment=k), dtype=np.float32)
                .reshape(size, size, 4)[::-1, :, :3]  # GL rows start at the bottom; ours at the top
                .copy()
                for k in range(2)
            ]
        finally:
            framebuffer.release()
            for target in targets:
                target.release()
        return images[0], images[1]

    def render_brdf_slice(
        self, theta_deg: float, phi_deg: float, size: int, exposure: float = 1.0, ior: float | None = 1.5
    ) -> np.ndarray:
        """Exposed CIE XYZ of a BRDF slice, ``float32`` ``(size, size, 3)``, row 0 at the top.

        The light is at polar angle ``theta_deg`` and azimuth ``phi_deg``; pixel ``(i, j)`` holds
        ``exposure · A(ωi, ωo) · XYZ(−(ωi + ωo))`` (eq. 5) for its view direction, 0 outside the disc.
        ``ior`` is the Fresnel refractive index (``None`` or 0: no Fresnel).
        """
        return self.render_brdf_slice_layers(theta_deg, phi_deg, size, exposure, ior)[0]

    # ---------------------------------------------------------------------------------------------
    # Values at arbitrary inputs (program evaluate_keys)

    def _evaluate(self, mode: int, first: np.ndarray, second: np.ndarray | None = None, block: int = 0,
                  ior: float = 0.0) -> np.ndarray:
        """Run evaluate_keys in ``mode`` on ``(N, 3)`` inputs; returns ``(N, 4)`` float32."""
        program = self.program("evaluate_keys")
        _set(program, "u_mode", mode)
        _set(program, "u_block", block)
        _set(program, "u_ior", ior)
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
            self._draw("evaluate_keys", framebuffer, ((inputs[0], 1), (inputs[1], 2)))
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
        return self._evaluate(_MODE_XYZ, keys)[:, :3].reshape(*shape, 3)

    def network_outputs(self, u: object, v: object, w: object) -> np.ndarray:
        """The network's raw outputs (range-transformed XYZ, before eq. 7's inverse), ``float32`` ``(…, 3)``."""
        keys, shape = self._keys(u, v, w)
        if keys.shape[0] == 0:
            return np.zeros((*shape, 3), dtype=np.float32)
        return self._evaluate(_MODE_NETWORK, keys)[:, :3].reshape(*shape, 3)

    def encode_keys(self, u: object, v: object, w: object) -> np.ndarray:
        """The shader's encoded input features (eq. 6) at key vectors, ``float32`` ``(…, features)``.

        The GPU counterpart of ``gratnet.encoding.encode(network_coordinates(u, v, w, scheme), spec)``.
        """
        keys, shape = self._keys(u, v, w)
        features = self.model.encoding.features
        if keys.shape[0] == 0:
            return np.zeros((*shape, features), dtype=np.float32)
        blocks = [self._evaluate(_MODE_ENCODING, keys, block=b) for b in range(-(-features // 4))]
        return np.concatenate(blocks, axis=-1)[:, :features].reshape(*shape, features)

    def a_term(self, light: np.ndarray, view: np.ndarray, ior: float | None = 1.5) -> np.ndarray:
        """The shader's A-term (eq. 5) for direction pairs ``(…, 3)`` (broadcast), ``float32`` ``(…)``."""
        light, view = np.broadcast_arrays(np.asarray(light, dtype=np.float64), np.asarray(view, dtype=np.float64))
        if light.shape[-1:] != (3,):
            raise GratNetError(f"directions must have shape (…, 3), got {light.shape}")
        shape = light.shape[:-1]
        first = light.reshape(-1, 3).astype(np.float32)
        if first.shape[0] == 0:
            return np.zeros(shape, dtype=np.float32)
        values = self._evaluate(_MODE_A_TERM, first, view.reshape(-1, 3).astype(np.float32), ior=_ior_uniform(ior))
        return values[:, 0].reshape(shape)

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
        _set(program, "u_exposure", float(exposure))
        padded = np.zeros((height, width, 4), dtype=np.float32)
        padded[..., :3] = image[::-1]  # our row 0 is the top; GL's is the bottom
        source = self.ctx.texture((width, height), 4, padded.tobytes(), dtype="f4")
        target = self.ctx.texture((width, height), 4, dtype="f4")
        framebuffer = self.ctx.framebuffer(color_attachments=[target])
        try:
            self._draw("display", framebuffer, ((source, 1),))
            data = framebuffer.read(components=4, dtype="f4")
        finally:
            framebuffer.release()
            target.release()
            source.release()
        return np.frombuffer(data, dtype=np.float32).reshape(height, width, 4)[::-1, :, :3].copy()

    def __enter__(self) -> NetworkRenderer:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.release()

    def release(self) -> None:
        """Free the GL objects (the context itself belongs to the caller)."""
        for vertex_array in self._vertex_arrays.values():
            vertex_array.release()
        for program in self._programs.values():
            program.release()
        self._weights.release()
        self._vertex_arrays.clear()
        self._programs.clear()
