"""Rendering a trained material on a mesh: one light, one camera, the network per pixel.

:class:`SceneRenderer` rasterizes a :class:`~viewer.meshes.Mesh` with ``shaders/surface.glsl``: each
covered pixel takes the light direction ωi and the view direction ωo into the surface's tangent frame
(x = tangent, y = bitangent, z = normal), evaluates the network at the key vector ``−(ωi + ωo)``
(docs/physics.md eq. 6–7) and multiplies by the A-term (eq. 5), the light's irradiance and the exposure.
The output is **exposed CIE XYZ**, linear, ``float32`` ``(H, W, 3)`` with row 0 at the top; pixels the
mesh does not cover are 0 (``render_rgba``'s alpha is the coverage, 1 or 0). The depth test is on, face
culling off (back faces are covered but black).

Two render paths (issue 12, ``render_path``): this module's forward path, and the deferred one of
:mod:`viewer.deferred` (a G-buffer pass, then the network in a compute shader over the pixels that need
it), which also takes sub-pixel sample offsets; ``_render`` dispatches between them in one place.

Work skipped (issue 5): a depth pre-pass (on by default) draws the mesh's depth first, so that the shading
pass runs the network once per visible pixel (no overdraw); back faces and A = 0 never run it; with a
``skip_threshold`` (:data:`~gratnet.bounds.DISPLAY_SKIP_THRESHOLD` for 8-bit display output, as
``gratnet render --skip-dark`` passes) pixels whose output bound (``gratnet.bounds``) cannot reach the
display's smallest step are 0 without running it. Nothing skips by default: exact linear values for EXR
files and comparisons, and the bound costs minutes to build on first use per model (then it is cached).
A ``statistics`` dict receives the work counters.

The network's weight texture, the model uniforms and the shader defines are those of
:class:`~viewer.renderer.NetworkRenderer`, which this class owns; its BRDF slices are available too.

Display: :meth:`SceneRenderer.display_srgb8` and :meth:`SceneRenderer.linear_srgb` use ``gratnet.display``
(colour-science, float64), the path that the trainer's PNGs (``gratnet brdfslice``, evaluation reports)
take, so a render and a ground-truth image of the same XYZ are byte-identical. The GLSL ``display``
program that an interactive window would use agrees with it to 2e-6 before the 8-bit rounding
(tests/test_shader_parity.py), i.e. at most one level where a value sits on a rounding boundary.

Rendering only: no glfw, no imgui, no torch.
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import moderngl
import numpy as np

from gratnet.display import xyz_to_display_srgb8, xyz_to_linear_srgb
from gratnet.errors import GratNetError
from gratnet.modelfile import ModelFile
from viewer.antialias import check_offsets, jitter_matrix, sample_range_offsets
from viewer.camera import Camera, Light
from viewer.glsl import compile_program
from viewer.meshes import Mesh
from viewer.renderer import NetworkRenderer, _ior_uniform, _set, skip_threshold_value

__all__ = ["MAX_IMAGE_SIZE", "MeshBuffers", "SceneRenderer", "check_size"]

#: Largest image side (pixels); GL implementations guarantee at least this much for render targets.
MAX_IMAGE_SIZE = 16384
_PROGRAM = "surface"
_ACCUMULATE = "accumulate"  # shaders/accumulate.glsl: adds a sample image into a float32 sum
_SAMPLE_UNIT = 1  # texture unit of accumulate.glsl's u_sample (the weights use 0, the skip bound 3)
_LIGHT_KINDS = {"directional": 0, "point": 1}  # LIGHT_* of shaders/surface.glsl
_ATTRIBUTES = (("in_position", "positions"), ("in_normal", "normals"), ("in_tangent", "tangents"))


def check_size(size: object) -> tuple[int, int]:
    """``(width, height)`` from a pair of positive integers ≤ :data:`MAX_IMAGE_SIZE`, else GratNetError."""
    try:
        width, height = size  # type: ignore[misc]
    except (TypeError, ValueError):
        raise GratNetError(f"image size must be (width, height), got {size!r}") from None
    for value in (width, height):
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or not 1 <= value <= MAX_IMAGE_SIZE:
            raise GratNetError(f"image width and height must be integers in 1 … {MAX_IMAGE_SIZE}, got {size!r}")
    return int(width), int(height)


def _color_masks(enabled: bool, attachments: int) -> object:
    """moderngl 5's ``Framebuffer.color_mask`` value: one RGBA tuple, or a list of them for several attachments."""
    mask = (enabled,) * 4
    return mask if attachments == 1 else [mask] * attachments


@dataclasses.dataclass(eq=False)
class MeshBuffers:
    """A mesh uploaded to the GPU: one vertex buffer per attribute and the index buffer.

    Keep one for a mesh that is drawn many times (an interactive view); :meth:`release` frees it.
    """

    mesh: Mesh
    buffers: dict[str, moderngl.Buffer]
    index_buffer: moderngl.Buffer | None
    vertex_array: moderngl.VertexArray | None
    #: The same buffers bound to the depth pre-pass's program (made on the first pre-pass).
    depth_vertex_array: moderngl.VertexArray | None = None

    def release(self) -> None:
        for vertex_array in (self.vertex_array, self.depth_vertex_array):
            if vertex_array is not None:
                vertex_array.release()
        for buffer in self.buffers.values():
            buffer.release()
        if self.index_buffer is not None:
            self.index_buffer.release()
        self.buffers.clear()
        self.vertex_array = self.depth_vertex_array = self.index_buffer = None


class SceneRenderer:
    """Renders meshes shaded by a trained network (see the module docstring).

    Args:
        ctx: an OpenGL ≥ 4.3 context (:func:`viewer.context.create_headless_context`).
        model: the trained network.
        shader_root: folder of the GLSL files (default: the repository's ``shaders/``).
        weights_path: ``auto``, ``texture`` or ``baked``: where the shader reads the weights
            (:class:`~viewer.renderer.NetworkRenderer`; the choice is ``self.network.weights_path``).
        baked_source: as :class:`~viewer.renderer.NetworkRenderer` (a baked ``mlp.glsl`` made earlier).
        render_path: ``forward`` (the network in the fragment shader), ``deferred`` (a G-buffer pass, then the
            network in a compute shader over the pixels that need it: :mod:`viewer.deferred`) or ``auto``
            (:func:`viewer.deferred.choose_render_path`: measured once per GPU and network shape, cached).
            Both give the same images; :meth:`render_layers` (key vectors and A) and BRDF slices always run
            forward, and ``depth_prepass`` only concerns the forward path.
        deferred_weights: where the deferred path's compute shader reads the weights
            (:data:`viewer.deferred.DEFERRED_WEIGHTS`).
        measure_render_path: ``auto`` may time both paths when nothing is cached (False: ``forward`` then;
            the viewer, whose compile process measures off the window's thread).
    """

    def __init__(self, ctx: moderngl.Context, model: ModelFile, shader_root: str | Path | None = None,
                 weights_path: str = "auto", baked_source: str | None = None, render_path: str = "auto",
                 deferred_weights: str = "auto", measure_render_path: bool = True) -> None:
        from viewer.deferred import DeferredRenderer, check_render_path

        self._requested_path = check_render_path(render_path)
        self.ctx = ctx
        self.network = NetworkRenderer(ctx, model, shader_root, weights_path, baked_source)
        self.model = model
        self._accumulate_program: moderngl.Program | None = None
        self._accumulate_array: moderngl.VertexArray | None = None
        self.deferred = DeferredRenderer(self, deferred_weights)  # compiles nothing until used
        self._render_path: tuple[str, str] | None = None
        self._measure_render_path = measure_render_path

    @property
    def render_path(self) -> str:
        """The path mesh renders take, ``forward`` or ``deferred`` (``auto`` measures on first use)."""
        return self._resolved_path()[0]

    @property
    def render_path_reason(self) -> str:
        """Why :attr:`render_path` was taken, e.g. ``requested`` or ``deferred: 12.1 ms vs forward 31.0 ms …``."""
        return self._resolved_path()[1]

    def _resolved_path(self) -> tuple[str, str]:
        if self._render_path is None:
            from viewer.deferred import choose_render_path

            self._render_path = choose_render_path(self, self._requested_path, self._measure_render_path)
        return self._render_path

    def _render_path_probe(self, uploaded: MeshBuffers, camera: Camera, light: Light, size: tuple[int, int],
                           path: str) -> None:
        """One render on ``path`` (the ``auto`` probe of :func:`viewer.deferred.choose_render_path`)."""
        saved, self._render_path = self._render_path, (path, "probe")
        try:
            self._render(uploaded, camera, light, size, 1.0, 1.5, 1)
        finally:
            self._render_path = saved

    @property
    def program(self) -> moderngl.Program:
        """The ``surface`` program, compiled on first use with the network's defines and model uniforms."""
        return self.network.program(_PROGRAM)

    def upload(self, mesh: Mesh) -> MeshBuffers:
        """Upload ``mesh`` for drawing (the caller releases the result)."""
        if not isinstance(mesh, Mesh):
            raise GratNetError(f"expected a viewer.meshes.Mesh, got {type(mesh).__name__}")
        program = self.program
        buffers: dict[str, moderngl.Buffer] = {}
        if mesh.triangle_count == 0:
            return MeshBuffers(mesh, buffers, None, None)
        for attribute, field in _ATTRIBUTES:
            buffers[attribute] = self.ctx.buffer(np.ascontiguousarray(getattr(mesh, field)).tobytes())
        index_buffer = self.ctx.buffer(np.ascontiguousarray(mesh.indices).tobytes())
        return MeshBuffers(mesh, buffers, index_buffer, self._vertex_array(program, buffers, index_buffer))

    def _vertex_array(self, program: moderngl.Program, buffers: dict[str, moderngl.Buffer],
                      index_buffer: moderngl.Buffer | None) -> moderngl.VertexArray:
        """``buffers`` bound to ``program``'s attributes (one the compiler dropped cannot be bound)."""
        content = [(buffers[attribute], "3f", attribute) for attribute, _ in _ATTRIBUTES if attribute in program]
        return self.ctx.vertex_array(program, content, index_buffer=index_buffer, index_element_size=4)

    def _set_uniforms(self, camera: Camera, light: Light, width: int, height: int, exposure: float,
                      ior: float | None, program: moderngl.Program | None = None) -> None:
        if not isinstance(camera, Camera):
            raise GratNetError(f"expected a viewer.camera.Camera, got {type(camera).__name__}")
        if not isinstance(light, Light):
            raise GratNetError(f"expected a viewer.camera.Light, got {type(light).__name__}")
        if not math.isfinite(exposure) or exposure < 0.0:
            raise GratNetError(f"exposure must be a finite number ≥ 0, got {exposure!r}")
        program = self.program if program is None else program
        _set(program, "u_view_projection", np.ascontiguousarray(camera.view_projection(width / height)))
        _set(program, "u_eye", tuple(float(c) for c in camera.eye()))
        _set(program, "u_light_kind", _LIGHT_KINDS[light.kind])
        _set(program, "u_light", tuple(float(c) for c in light.vector))
        _set(program, "u_light_intensity", float(light.intensity))
        _set(program, "u_exposure", float(exposure))
        _set(program, "u_ior", _ior_uniform(ior))

    def render_layers(self, mesh: Mesh | MeshBuffers, camera: Camera, light: Light,
                      size: tuple[int, int] = (256, 256), exposure: float = 1.0,
                      ior: float | None = 1.5, *, skip_threshold: float | None = None, depth_prepass: bool = True,
                      statistics: dict[str, int] | None = None, samples: int = 1,
                      first_sample: int = 0) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`render_rgba` and, per pixel, the key vector and the A-term behind it.

        Returns:
            ``(rgba, key_a)``, both ``float32`` ``(H, W, 4)`` with row 0 at the top: ``rgba`` as
            :meth:`render_rgba`; ``key_a[..., :3]`` = ``−(ωi + ωo)`` in the tangent frame (float32, as the
            network saw it) and ``key_a[..., 3]`` = A(ωi, ωo); 0 for back faces and uncovered pixels.
            With ``samples`` > 1 both are means over the samples (as :meth:`render_rgba`).
        """
        rgba, key_a = self._render(mesh, camera, light, size, exposure, ior, 2, skip_threshold, depth_prepass,
                                   statistics, samples, first_sample)
        return rgba, key_a

    def render_rgba(self, mesh: Mesh | MeshBuffers, camera: Camera, light: Light, size: tuple[int, int] = (256, 256),
                    exposure: float = 1.0, ior: float | None = 1.5, *, skip_threshold: float | None = None,
                    depth_prepass: bool = True, statistics: dict[str, int] | None = None, samples: int = 1,
                    first_sample: int = 0) -> np.ndarray:
        """Exposed CIE XYZ and coverage, ``float32`` ``(H, W, 4)``, row 0 at the top.

        Channels 0–2: ``exposure · irradiance · A(ωi, ωo) · XYZ(−(ωi + ωo))`` (physics.md eq. 5–7) with
        ωi, ωo in the tangent frame at the pixel's surface point; 0 for back faces, directions below the
        surface's horizon, and uncovered pixels. Channel 3: 1 where the mesh covers the pixel centre.
        ``ior`` is the Fresnel refractive index (``None`` or 0: no Fresnel).

        ``skip_threshold``: exposed linear sRGB below which the display shows 0 (``DISPLAY_SKIP_THRESHOLD``
        for 8-bit display output): the network is skipped (pixel 0) where its bound cannot reach it;
        ``None``/0: off (exact). ``depth_prepass``: draw the depth first so each visible pixel runs the
        network once (False: one shading pass, occluded fragments drawn earlier still run it).
        ``statistics``: a dict to fill with the work counters (``viewer.renderer.STATISTICS_KEYS``), from a
        counting variant of the program (slower: time renders without it).

        Anti-aliasing (issue 12): ``samples`` per pixel (1 … :data:`viewer.antialias.MAX_SAMPLES`), each a full
        render with the view-projection moved by a sub-pixel offset (:func:`viewer.antialias.sample_offsets`:
        Halton (2, 3), the first at the pixel centre), so each sample has its own surface point, ωi, ωo and
        key vector; the result is their mean in float32, coverage included (the fraction of the samples that
        hit the mesh). ``first_sample``: start at that index of the sequence (progressive accumulation adds
        samples k, k + 1, … one render at a time; the mean of samples 0 … N−1 so rendered is the N-sample
        render). ``samples=1`` (the default) is the render without anti-aliasing, bit for bit.
        """
        return self._render(mesh, camera, light, size, exposure, ior, 1, skip_threshold, depth_prepass,
                            statistics, samples, first_sample)[0]

    def _render(self, mesh: Mesh | MeshBuffers, camera: Camera, light: Light, size: tuple[int, int],
                exposure: float, ior: float | None, layers: int, skip_threshold: float | None = None,
                depth_prepass: bool = True, statistics: dict[str, int] | None = None, samples: int = 1,
                first_sample: int = 0, offsets_px: np.ndarray | None = None) -> list[np.ndarray]:
        """Every render method's checks, then the render path with the sub-pixel offsets of samples
        ``first_sample`` … ``first_sample + samples − 1`` (:func:`viewer.antialias.sample_offsets`), or
        explicit ``offsets_px`` (pixels, ``(N, 2)``: tests and benchmarks)."""
        width, height = check_size(size)
        skip_threshold_value(skip_threshold)  # check before any GL work
        offsets = sample_range_offsets(samples, first_sample) if offsets_px is None else check_offsets(offsets_px)
        if layers == 1 and self.render_path == "deferred":
            # The deferred path (viewer/deferred.py) takes all samples in one list; render_layers stays forward.
            uploaded = mesh if isinstance(mesh, MeshBuffers) else self.upload(mesh)
            try:
                return [self.deferred.render(uploaded, camera, light, (width, height), exposure, ior, skip_threshold,
                                             statistics, offsets)]
            finally:
                if uploaded is not mesh:
                    uploaded.release()
        return self._render_forward(mesh, camera, light, (width, height), exposure, ior, layers, skip_threshold,
                                    depth_prepass, statistics, offsets)

    def _render_forward(self, mesh: Mesh | MeshBuffers, camera: Camera, light: Light, size: tuple[int, int],
                        exposure: float, ior: float | None, layers: int, skip_threshold: float | None,
                        depth_prepass: bool, statistics: dict[str, int] | None,
                        offsets: np.ndarray) -> list[np.ndarray]:
        """The forward path: per sample (``offsets``, pixels, ``(N, 2)``) a depth pre-pass and the shading
        pass (:meth:`_draw_sample`) into float targets; with N > 1 each sample is added into RGBA32F sums on
        the GPU (``accumulate.glsl``, additive blending) and the mean is read back once. One sample is read
        directly (bit-identical to a render without anti-aliasing when its offset is the pixel centre)."""
        width, height = size
        program = self.program
        if statistics is not None:
            _, program = self.network.counting_program(_PROGRAM)
        self._set_uniforms(camera, light, width, height, float(exposure), ior, program)
        bound, unit = self.network._skip_uniforms(program, skip_threshold)
        uploaded = mesh if isinstance(mesh, MeshBuffers) else self.upload(mesh)
        vertex_array = uploaded.vertex_array
        if vertex_array is not None and program is not self.program:  # the counting variant: its own binding
            vertex_array = self._vertex_array(program, uploaded.buffers, uploaded.index_buffer)
        count = len(offsets)
        targets = [self.ctx.texture((width, height), 4, dtype="f4") for _ in range(layers)]
        depth = self.ctx.depth_renderbuffer((width, height))
        framebuffer = self.ctx.framebuffer(color_attachments=targets, depth_attachment=depth)
        sums = [self.ctx.texture((width, height), 4, dtype="f4") for _ in range(layers)] if count > 1 else []
        sum_framebuffers = [self.ctx.framebuffer(color_attachments=[target]) for target in sums]
        # The scope restores the caller's framebuffer and enable flags (a window may share this context).
        scope = self.ctx.scope(framebuffer, enable_only=moderngl.DEPTH_TEST)
        try:
            with scope:
                for target in sum_framebuffers:
                    target.clear(0.0, 0.0, 0.0, 0.0)
                if statistics is not None:
                    self.network._reset_counters()
                for offset in offsets:
                    self._draw_sample(framebuffer, uploaded, vertex_array, program, bound, unit, camera,
                                      (width, height), offset, layers, depth_prepass)
                    if count > 1:
                        self._accumulate(targets, sum_framebuffers)
                if statistics is not None:
                    self.network._read_counters(statistics)
                if count > 1:
                    data = [target.read() for target in sums]
                else:
                    data = [framebuffer.read(components=4, dtype="f4", attachment=k) for k in range(layers)]
        finally:
            scope.release()
            for owned in (framebuffer, depth, *targets, *sum_framebuffers, *sums):
                owned.release()
            if vertex_array is not None and vertex_array is not uploaded.vertex_array:
                vertex_array.release()
            if uploaded is not mesh:
                uploaded.release()
        # GL rows start at the bottom; ours at the top. N samples: the float32 sum over N (their mean).
        images = [np.frombuffer(layer, dtype=np.float32).reshape(height, width, 4)[::-1].copy() for layer in data]
        if count > 1:
            images = [image / np.float32(count) for image in images]
        return images

    def _draw_sample(self, framebuffer: moderngl.Framebuffer, uploaded: MeshBuffers,
                     vertex_array: moderngl.VertexArray | None, program: moderngl.Program, bound: moderngl.Texture,
                     unit: int, camera: Camera, size: tuple[int, int], offset: np.ndarray, layers: int,
                     depth_prepass: bool) -> None:
        """One sample of the forward path into ``framebuffer`` (cleared first): the camera's view-projection
        moved by ``offset`` (pixels, x right, y up; :func:`viewer.antialias.jitter_matrix`), then the depth
        pre-pass and the shading pass. The other uniforms are set by the caller."""
        width, height = size
        view_projection = camera.view_projection(width / height)
        if np.any(offset != 0.0):  # the pixel centre: the un-jittered matrix itself (bit-identical renders)
            view_projection = view_projection @ jitter_matrix(offset, width, height)
        view_projection = np.ascontiguousarray(view_projection, dtype=np.float32)
        _set(program, "u_view_projection", view_projection)
        framebuffer.use()  # the scope binds the framebuffer but leaves the viewport as it was
        framebuffer.clear(0.0, 0.0, 0.0, 0.0, depth=1.0)
        if vertex_array is None:
            return
        self.network.use_weights(0)
        bound.use(location=unit)
        if depth_prepass:
            # Pass 1: depth only (the DEPTH_ONLY program: same vertex stage, no MLP; colour writes masked).
            # Pass 2: the invariant vertex stage gives bit-identical depths, so LEQUAL passes exactly the
            # visible surface and early fragment tests stop every other fragment before the MLP.
            depth_program = self.network.depth_only_program(_PROGRAM)
            _set(depth_program, "u_view_projection", view_projection)
            if uploaded.depth_vertex_array is None:
                uploaded.depth_vertex_array = self._vertex_array(depth_program, uploaded.buffers,
                                                                 uploaded.index_buffer)
            framebuffer.color_mask = _color_masks(False, layers)
            try:
                uploaded.depth_vertex_array.render(moderngl.TRIANGLES)
            finally:
                framebuffer.color_mask = _color_masks(True, layers)
            self.ctx.depth_func = "<="
        try:
            vertex_array.render(moderngl.TRIANGLES)
        finally:
            self.ctx.depth_func = "<"  # moderngl's default

    def _accumulate(self, samples: list[moderngl.Texture], sums: list[moderngl.Framebuffer]) -> None:
        """Add each sample image into its RGBA32F sum: a full-screen draw with additive blending."""
        if self._accumulate_program is None:
            self._accumulate_program = compile_program(self.ctx, _ACCUMULATE, {}, self.network.shader_root)
            self._accumulate_array = self.ctx.vertex_array(self._accumulate_program, [])
        program, array = self._accumulate_program, self._accumulate_array
        _set(program, "u_sample", _SAMPLE_UNIT)
        self.ctx.enable_only(moderngl.BLEND)
        self.ctx.blend_func = moderngl.ONE, moderngl.ONE
        try:
            for sample, target in zip(samples, sums, strict=True):
                sample.use(location=_SAMPLE_UNIT)
                target.use()
                array.render(moderngl.TRIANGLES, vertices=3)
        finally:
            self.ctx.blend_func = moderngl.DEFAULT_BLENDING
            self.ctx.enable_only(moderngl.DEPTH_TEST)

    def render(self, mesh: Mesh | MeshBuffers, camera: Camera, light: Light, size: tuple[int, int] = (256, 256),
               exposure: float = 1.0, ior: float | None = 1.5, *, skip_threshold: float | None = None,
               depth_prepass: bool = True, statistics: dict[str, int] | None = None, samples: int = 1,
               first_sample: int = 0) -> np.ndarray:
        """Exposed CIE XYZ, ``float32`` ``(H, W, 3)``, row 0 at the top (see :meth:`render_rgba`)."""
        rgba = self.render_rgba(mesh, camera, light, size, exposure, ior, skip_threshold=skip_threshold,
                                depth_prepass=depth_prepass, statistics=statistics, samples=samples,
                                first_sample=first_sample)
        return np.ascontiguousarray(rgba[..., :3])

    def render_srgb8(self, mesh: Mesh | MeshBuffers, camera: Camera, light: Light,
                     size: tuple[int, int] = (256, 256), exposure: float = 1.0, ior: float | None = 1.5, *,
                     skip_threshold: float | None = None, depth_prepass: bool = True,
                     statistics: dict[str, int] | None = None, samples: int = 1, first_sample: int = 0) -> np.ndarray:
        """8-bit display sRGB ``(H, W, 3)`` (``gratnet.display``) of :meth:`render`; with
        ``skip_threshold=gratnet.bounds.DISPLAY_SKIP_THRESHOLD`` the network is skipped where the display
        would show 0 (off by default: the first use per model builds its output bound, minutes on a CPU)."""
        xyz = self.render(mesh, camera, light, size, exposure, ior, skip_threshold=skip_threshold,
                          depth_prepass=depth_prepass, statistics=statistics, samples=samples,
                          first_sample=first_sample)
        return self.display_srgb8(xyz)

    def render_brdf_slice(self, theta_deg: float, phi_deg: float, size: int, exposure: float = 1.0,
                          ior: float | None = 1.5, skip_threshold: float | None = None,
                          statistics: dict[str, int] | None = None, rows: tuple[int, int] | None = None) -> np.ndarray:
        """The network's BRDF slice (``NetworkRenderer.render_brdf_slice``): exposed XYZ ``(size, size, 3)``."""
        return self.network.render_brdf_slice(theta_deg, phi_deg, size, exposure, ior, skip_threshold, statistics,
                                              rows)

    # ---------------------------------------------------------------------------------------------
    # Display (gratnet.display: the same numbers as every other PNG GratNet writes)

    @staticmethod
    def display_srgb8(xyz: np.ndarray) -> np.ndarray:
        """8-bit display sRGB ``(H, W, 3)`` of an exposed XYZ image (exposure already applied):
        linear sRGB, clipped to [0, 1], sRGB transfer function, rounded (``gratnet.display``)."""
        return xyz_to_display_srgb8(np.asarray(xyz, dtype=np.float64), 1.0)

    @staticmethod
    def linear_srgb(xyz: np.ndarray) -> np.ndarray:
        """Linear sRGB ``float32`` ``(H, W, 3)`` of an exposed XYZ image, unclipped (for EXR files)."""
        return xyz_to_linear_srgb(np.asarray(xyz, dtype=np.float64)).astype(np.float32)

    def __enter__(self) -> SceneRenderer:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.release()

    def release(self) -> None:
        """Free the GL objects (the context belongs to the caller)."""
        for owned in (self._accumulate_array, self._accumulate_program):
            if owned is not None:
                owned.release()
        self._accumulate_array = self._accumulate_program = None
        self.deferred.release()
        self.network.release()
