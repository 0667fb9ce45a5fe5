"""The forward render path: the material (network or reference look-up) in the fragment shader of
``shaders/surface.glsl``.

Per sample (a sub-pixel offset, :func:`viewer.antialias.sample_offsets`): a depth pre-pass (on by default)
draws the mesh's depth, then the shading pass runs the network once per visible pixel (no overdraw; the
invariant vertex stage gives bit-identical depths, so ``LEQUAL`` passes exactly the visible surface). With
several samples, each is added into RGBA32F sums on the GPU (``shaders/accumulate.glsl``, additive
blending) and the mean is read back once; one sample is read directly (bit-identical to a render without
anti-aliasing when its offset is the pixel centre).

:class:`~viewer.scene.SceneRenderer` chooses between this path and :mod:`viewer.deferred`; both give the
same image (exposed CIE XYZ and coverage, ``float32`` ``(H, W, 4)``, row 0 at the top) and share the mesh
buffers and surface uniforms of :mod:`viewer.surface`. Only this path renders the key-vector layer
(``layers=2``: ``SceneRenderer.render_layers``).

Rendering only: no glfw, no imgui, no torch.
"""

from __future__ import annotations

import moderngl
import numpy as np

from viewer.antialias import jitter_matrix
from viewer.camera import Camera, Light
from viewer.glsl import compile_program
from viewer.shading import ShadingPrograms, set_uniform
from viewer.surface import MeshBuffers, set_surface_uniforms

__all__ = ["SURFACE_PROGRAM", "ForwardRenderer"]

#: The program both paths rasterize (the deferred path compiles it with ``GBUFFER``).
SURFACE_PROGRAM = "surface"
_ACCUMULATE = "accumulate"  # shaders/accumulate.glsl: adds a sample image into a float32 sum
_SAMPLE_UNIT = 1  # texture unit of accumulate.glsl's u_sample (the weights use 0, the skip bound 3)


def _bound_to(vertex_array: moderngl.VertexArray, program: moderngl.Program) -> bool:
    """Whether ``vertex_array`` binds its buffers to ``program`` (attribute locations differ between programs)."""
    return vertex_array.program.glo == program.glo


def _color_masks(enabled: bool, attachments: int) -> object:
    """moderngl 5's ``Framebuffer.color_mask`` value: one RGBA tuple, or a list of them for several attachments."""
    mask = (enabled,) * 4
    return mask if attachments == 1 else [mask] * attachments


class ForwardRenderer:
    """The forward path over a material's ``surface`` program: the network's
    (:class:`~viewer.renderer.NetworkRenderer`) or the ground-truth volume's
    (:class:`~viewer.reference.ReferenceRenderer`)."""

    def __init__(self, shading: ShadingPrograms) -> None:
        self.shading = shading
        self.ctx = shading.ctx
        self._accumulate_program: moderngl.Program | None = None
        self._accumulate_array: moderngl.VertexArray | None = None

    @property
    def program(self) -> moderngl.Program:
        """The ``surface`` program, compiled on first use with the material's defines and uniforms."""
        return self.shading.program(SURFACE_PROGRAM)

    def render(self, uploaded: MeshBuffers, camera: Camera, light: Light, size: tuple[int, int], exposure: float,
               ior: float | None, layers: int, skip_threshold: float | None, depth_prepass: bool,
               statistics: dict[str, int] | None, offsets: np.ndarray) -> list[np.ndarray]:
        """``layers`` images (1: exposed XYZ and coverage; 2: also the key vector and A), each ``float32``
        ``(H, W, 4)`` with row 0 at the top, the mean over the samples at ``offsets`` (pixels, ``(N, 2)``)."""
        width, height = size
        program = self.program
        if statistics is not None:
            _, program = self.shading.counting_program(SURFACE_PROGRAM)
        set_surface_uniforms(program, camera, light, width, height, float(exposure), ior)
        bound, unit = self.shading.skip_uniforms(program, skip_threshold)
        vertex_array = uploaded.vertex_array
        if vertex_array is not None and not _bound_to(vertex_array, program):
            # The counting variant, or buffers uploaded for another material's program (the viewer draws the
            # network's mesh buffers with the reference look-up too): a binding of its own for this render.
            vertex_array = uploaded.vertex_array_for(program)
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
                    self.shading.reset_counters()
                for offset in offsets:
                    self._draw_sample(framebuffer, uploaded, vertex_array, program, bound, unit, camera,
                                      (width, height), offset, layers, depth_prepass)
                    if count > 1:
                        self._accumulate(targets, sum_framebuffers)
                if statistics is not None:
                    self.shading.read_counters(statistics)
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
        # GL rows start at the bottom; ours at the top. N samples: the float32 sum over N (their mean).
        images = [np.frombuffer(layer, dtype=np.float32).reshape(height, width, 4)[::-1].copy() for layer in data]
        if count > 1:
            images = [image / np.float32(count) for image in images]
        return images

    def _draw_sample(self, framebuffer: moderngl.Framebuffer, uploaded: MeshBuffers,
                     vertex_array: moderngl.VertexArray | None, program: moderngl.Program, bound: moderngl.Texture,
                     unit: int, camera: Camera, size: tuple[int, int], offset: np.ndarray, layers: int,
                     depth_prepass: bool) -> None:
        """One sample into ``framebuffer`` (cleared first): the camera's view-projection moved by ``offset``
        (pixels, x right, y up; :func:`viewer.antialias.jitter_matrix`), then the depth pre-pass and the
        shading pass. The other uniforms are set by the caller."""
        width, height = size
        view_projection = camera.view_projection(width / height)
        if np.any(offset != 0.0):  # the pixel centre: the un-jittered matrix itself (bit-identical renders)
            view_projection = view_projection @ jitter_matrix(offset, width, height)
        view_projection = np.ascontiguousarray(view_projection, dtype=np.float32)
        set_uniform(program, "u_view_projection", view_projection)
        framebuffer.use()  # the scope binds the framebuffer but leaves the viewport as it was
        framebuffer.clear(0.0, 0.0, 0.0, 0.0, depth=1.0)
        if vertex_array is None:
            return
        self.shading.bind_material()
        bound.use(location=unit)
        if depth_prepass:
            # Pass 1: depth only (the DEPTH_ONLY program: same vertex stage, no MLP; colour writes masked).
            # Pass 2: the invariant vertex stage gives bit-identical depths, so LEQUAL passes exactly the
            # visible surface and early fragment tests stop every other fragment before the MLP.
            depth_program = self.shading.depth_only_program(SURFACE_PROGRAM)
            set_uniform(depth_program, "u_view_projection", view_projection)
            if uploaded.depth_vertex_array is None:
                uploaded.depth_vertex_array = uploaded.vertex_array_for(depth_program)
            depth_array = uploaded.depth_vertex_array
            if not _bound_to(depth_array, depth_program):  # another material's depth program made it
                depth_array = uploaded.vertex_array_for(depth_program)
            framebuffer.color_mask = _color_masks(False, layers)
            try:
                depth_array.render(moderngl.TRIANGLES)
            finally:
                framebuffer.color_mask = _color_masks(True, layers)
                if depth_array is not uploaded.depth_vertex_array:
                    depth_array.release()
            self.ctx.depth_func = "<="
        try:
            vertex_array.render(moderngl.TRIANGLES)
        finally:
            self.ctx.depth_func = "<"  # moderngl's default

    def _accumulate(self, samples: list[moderngl.Texture], sums: list[moderngl.Framebuffer]) -> None:
        """Add each sample image into its RGBA32F sum: a full-screen draw with additive blending."""
        if self._accumulate_program is None:
            self._accumulate_program = compile_program(self.ctx, _ACCUMULATE, {}, self.shading.shader_root)
            self._accumulate_array = self.ctx.vertex_array(self._accumulate_program, [])
        program, array = self._accumulate_program, self._accumulate_array
        set_uniform(program, "u_sample", _SAMPLE_UNIT)
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

    def release(self) -> None:
        """Free this path's own GL objects (the material belongs to the caller)."""
        for owned in (self._accumulate_array, self._accumulate_program):
            if owned is not None:
                owned.release()
        self._accumulate_array = self._accumulate_program = None
