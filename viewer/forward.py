"""The forward render path: the material (network or reference look-up) in the fragment shader of
``shaders/surface.glsl``.

Per sample (a sub-pixel offset, :func:`viewer.antialias.sample_offsets`): a depth pre-pass (on by default)
draws the mesh's depth, then the shading pass runs the network once per visible pixel (no overdraw; the
invariant vertex stage gives bit-identical depths, so ``LEQUAL`` passes exactly the visible surface). With
several samples, each is added into RGBA32F sums on the GPU (``shaders/accumulate.glsl``, additive
blending) and the mean is read back once; one sample is read directly (bit-identical to a render without
anti-aliasing when its offset is the pixel centre).

No GL call runs long (issue 36: a CPU rasterizer runs a whole draw inside one call, and Ctrl-C waits for it):
each pass is drawn in pieces, scissor boxes sized by :mod:`viewer.pacing` to about 0.2 s each and finished one
by one: the depth pass in bands of rows, the shading pass in runs of 64×4-pixel blocks weighed by the pixels the
depth pass covered. A scissor box changes which pixels a draw computes, not how: the pieces give the one-draw
image bit for bit.

:class:`~viewer.scene.SceneRenderer` chooses between this path and :mod:`viewer.deferred`; both give the
same image (exposed CIE XYZ and coverage, ``float32`` ``(H, W, 4)``, row 0 at the top) and share the mesh
buffers and surface uniforms of :mod:`viewer.surface`. Only this path renders the key-vector layer
(``layers=2``: ``SceneRenderer.render_layers``).

Rendering only: no glfw, no imgui, no torch.
"""

from __future__ import annotations

from collections.abc import Callable

import moderngl
import numpy as np

from viewer.antialias import jitter_matrix
from viewer.camera import Camera, Light
from viewer.environment_light import ENVIRONMENT_DEFINES, EnvironmentPass
from viewer.glsl import compile_program
from viewer.pacing import BLOCK, Blocks, Pacer, Progress, covered_block_costs, projected_row_costs, read_rows
from viewer.shading import MaterialTexture, ShadingPrograms, set_uniform
from viewer.surface import MeshBuffers, set_surface_uniforms

__all__ = ["SURFACE_PROGRAM", "ForwardRenderer"]

#: The program both paths rasterize (the deferred path compiles it with ``GBUFFER``).
SURFACE_PROGRAM = "surface"
_ACCUMULATE = "accumulate"  # shaders/accumulate.glsl: adds a sample image into a float32 sum
_SAMPLE_UNIT = 1  # texture unit of accumulate.glsl's u_sample (the weights use 0, the skip bound 3)
_FIRST_DEPTH_PIXELS = 1 << 16  # the depth pass's first band (covered pixels, estimated): no MLP, cheap
_FIRST_SHADE_PIXELS = 1024  # the shading pass's first band: ~1k covered pixels (0.1 s at 10k pixels/s on llvmpipe)


def _bound_to(vertex_array: moderngl.VertexArray, program: moderngl.Program) -> bool:
    """Whether ``vertex_array`` binds its buffers to ``program`` (attribute locations differ between programs)."""
    return vertex_array.program.glo == program.glo


# moderngl-stubs 5.x type Framebuffer.scissor and .color_mask narrower than moderngl 5 takes them: these two
# helpers hold the ignores.


def _set_color_masks(framebuffer: moderngl.Framebuffer, enabled: bool, attachments: int) -> None:
    """Set moderngl 5's ``Framebuffer.color_mask``: one RGBA tuple, or a list of them for several attachments."""
    mask = (enabled,) * 4
    masks = mask if attachments == 1 else [mask] * attachments
    framebuffer.color_mask = masks  # type: ignore[assignment]  # the stubs omit the list form


def _scissor_off(framebuffer: moderngl.Framebuffer) -> None:
    """No scissor test on ``framebuffer``: moderngl documents ``scissor = None`` for it."""
    framebuffer.scissor = None  # type: ignore[assignment]  # the stubs omit None


class ForwardRenderer:
    """The forward path over a material's ``surface`` program: the network's
    (:class:`~viewer.renderer.NetworkRenderer`) or the ground-truth volume's
    (:class:`~viewer.reference.ReferenceRenderer`)."""

    def __init__(self, shading: ShadingPrograms) -> None:
        self.shading = shading
        self.ctx = shading.ctx
        self._accumulate_program: moderngl.Program | None = None
        self._accumulate_array: moderngl.VertexArray | None = None
        #: Called with the fraction of the render done (0 … 1) after each band; None: not reported.
        self.progress: Progress | None = None
        #: The bands' sizes, from the time of the bands before (kept between renders: the first band of the next
        #: render starts at the rate measured): the depth pass's rows, and the shading pass's (weighed by coverage).
        self.depth_pacer = Pacer(self.ctx, first_cost=_FIRST_DEPTH_PIXELS)
        self.shade_pacer = Pacer(self.ctx, first_cost=_FIRST_SHADE_PIXELS)

    @property
    def program(self) -> moderngl.Program:
        """The ``surface`` program, compiled on first use with the material's defines and uniforms."""
        return self.shading.program(SURFACE_PROGRAM)

    def render(self, uploaded: MeshBuffers, camera: Camera, light: Light, size: tuple[int, int], exposure: float,
               ior: float | None, layers: int, skip_threshold: float | None, depth_prepass: bool,
               statistics: dict[str, int] | None, offsets: np.ndarray, first_sample: int = 0,
               environment: EnvironmentPass | None = None) -> list[np.ndarray]:
        """``layers`` images (1: exposed XYZ and coverage; 2: also the key vector and A), each ``float32``
        ``(H, W, 4)`` with row 0 at the top, the mean over the samples at ``offsets`` (pixels, ``(N, 2)``).

        ``environment``: light the mesh with an environment too (shaders/environment.glsl): sample k of the
        render is pass ``first_sample + k`` of its estimator (the surface program compiled with ``ENVIRONMENT``).

        Each sample is drawn in bands of rows (a scissor box; :mod:`viewer.pacing`), each band finished before
        the next: the same pixels, bit for bit, as one draw, but no GL call runs long (Ctrl-C is answered)."""
        width, height = size
        program = self.program
        if environment is not None:
            extra: dict[str, int | float] = dict(ENVIRONMENT_DEFINES)
            if statistics is not None:
                extra["COUNT_EVALUATIONS"] = 1
            program = self.shading.variant_program(SURFACE_PROGRAM, extra)
        elif statistics is not None:
            _, program = self.shading.counting_program(SURFACE_PROGRAM)
        set_surface_uniforms(program, camera, light, width, height, float(exposure), ior,
                             self.shading.slope_covariance)
        if environment is not None:
            environment.lighting.set_uniforms(program, environment.delta_light, environment.seed, environment.sampling)
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
        depth_array: moderngl.VertexArray | None = None
        # The scope restores the caller's framebuffer and enable flags (a window may share this context).
        scope = self.ctx.scope(framebuffer, enable_only=moderngl.DEPTH_TEST)
        try:
            with scope:
                for target in sum_framebuffers:
                    target.clear(0.0, 0.0, 0.0, 0.0)
                if statistics is not None:
                    self.shading.reset_counters()
                row_costs = np.full(height, float(width))
                if vertex_array is not None:
                    depth_array = self._depth_array(uploaded)
                    if not self.depth_pacer.fits(width * height):
                        row_costs = projected_row_costs(uploaded.mesh.positions, uploaded.mesh.indices,
                                                        camera.view_projection(width / height), size)
                for number, offset in enumerate(offsets):
                    def sampled(fraction: float, number: int = number) -> None:
                        self._report((number + fraction) / count)

                    if environment is not None:
                        environment.lighting.set_pass(program, first_sample + number, environment.pixel_origin)
                        environment.lighting.bind()

                    self._draw_sample(framebuffer, targets, vertex_array, depth_array, program, bound, unit,
                                      camera, offset, depth_prepass, row_costs, sum_framebuffers, sampled)
                if statistics is not None:
                    self.shading.read_counters(statistics)
                readable = sum_framebuffers if count > 1 else [framebuffer] * layers
                images = [read_rows(source, size, attachment=0 if count > 1 else k)
                          for k, source in enumerate(readable)]
        finally:
            scope.release()
            for target in (framebuffer, *sum_framebuffers):
                _scissor_off(target)
            resources: list[moderngl.Framebuffer | moderngl.Renderbuffer | moderngl.Texture] = [
                framebuffer, depth, *targets, *sum_framebuffers, *sums]
            for owned in resources:
                owned.release()
            if vertex_array is not None and vertex_array is not uploaded.vertex_array:
                vertex_array.release()
            if depth_array is not None and depth_array is not uploaded.depth_vertex_array:
                depth_array.release()
        # GL rows start at the bottom; ours at the top. N samples: the float32 sum over N (their mean).
        images = [image[::-1].copy() for image in images]
        if count > 1:
            images = [image / np.float32(count) for image in images]
        return images

    def _report(self, fraction: float) -> None:
        if self.progress is not None:
            self.progress(min(1.0, fraction))

    def _depth_array(self, uploaded: MeshBuffers) -> moderngl.VertexArray:
        """The mesh buffers bound to the depth-only program (the depth pre-pass, and the coverage that sizes the
        bands); the caller releases it unless it is ``uploaded.depth_vertex_array``."""
        depth_program = self.shading.depth_only_program(SURFACE_PROGRAM)
        if uploaded.depth_vertex_array is None:
            uploaded.depth_vertex_array = uploaded.vertex_array_for(depth_program)
        depth_array = uploaded.depth_vertex_array
        if not _bound_to(depth_array, depth_program):  # another material's depth program made it
            depth_array = uploaded.vertex_array_for(depth_program)
        return depth_array

    def _draw_sample(self, framebuffer: moderngl.Framebuffer, targets: list[moderngl.Texture],
                     vertex_array: moderngl.VertexArray | None, depth_array: moderngl.VertexArray | None,
                     program: moderngl.Program, bound: MaterialTexture, unit: int, camera: Camera, offset: np.ndarray,
                     depth_prepass: bool, row_costs: np.ndarray, sums: list[moderngl.Framebuffer],
                     done: Callable[[float], None]) -> None:
        """One sample into ``framebuffer`` (colour ``targets``, cleared first), added into ``sums`` when given:
        the camera's view-projection moved by ``offset`` (pixels, x right, y up;
        :func:`viewer.antialias.jitter_matrix`), then the depth pass in bands of rows and the shading pass in
        pieces of blocks. The other uniforms are set by the caller.

        The depth pass (the depth-only program: same vertex stage, no MLP, colour writes masked) is drawn first
        over the whole image, in bands of its own (sized by ``row_costs``, estimated from the projected mesh:
        :func:`viewer.pacing.projected_row_costs`): its coverage weighs the blocks of the shading pieces (unless the
        whole image fits one piece). With ``depth_prepass`` it stays, and the shading pass tests ``LEQUAL``
        against it: the invariant vertex stage gives bit-identical depths, so exactly the visible surface passes
        and early fragment tests stop every other fragment before the MLP. Without it the depth is cleared again
        before the shading pass (or not drawn at all when the coverage is not needed)."""
        width, height = framebuffer.size
        layers = len(targets)
        view_projection = camera.view_projection(width / height)
        if np.any(offset != 0.0):  # the pixel centre: the un-jittered matrix itself (bit-identical renders)
            view_projection = view_projection @ jitter_matrix(offset, width, height)
        view_projection = np.ascontiguousarray(view_projection, dtype=np.float32)
        set_uniform(program, "u_view_projection", view_projection)
        _scissor_off(framebuffer)
        framebuffer.use()  # the scope binds the framebuffer but leaves the viewport as it was
        framebuffer.clear(0.0, 0.0, 0.0, 0.0, depth=1.0)
        if vertex_array is None or depth_array is None:
            self._accumulate(framebuffer, targets, sums, (0, 0, width, height))
            done(1.0)
            return
        blocks = Blocks(width, (0, height))
        one_piece = self.shade_pacer.fits(width * height)  # even if every pixel is covered: no coverage needed
        if depth_prepass or not one_piece:
            set_uniform(self.shading.depth_only_program(SURFACE_PROGRAM), "u_view_projection", view_projection)
            _set_color_masks(framebuffer, False, layers)
            try:
                for first, end in self.depth_pacer.pieces(height, row_costs, multiple=BLOCK[1]):
                    framebuffer.scissor = (0, first, width, end - first)
                    framebuffer.use()
                    depth_array.render(moderngl.TRIANGLES)
            finally:
                _set_color_masks(framebuffer, True, layers)
                _scissor_off(framebuffer)
        costs = np.full(blocks.count, float(BLOCK[0] * BLOCK[1])) if one_piece else covered_block_costs(
            framebuffer, blocks)
        if depth_prepass:
            self.ctx.depth_func = "<="
        elif not one_piece:
            framebuffer.use()
            framebuffer.clear(0.0, 0.0, 0.0, 0.0, depth=1.0)
        cumulative = np.cumsum(costs) / costs.sum()
        try:
            for start, end in self.shade_pacer.pieces(blocks.count, costs,
                                                       done=lambda end: done(float(cumulative[end - 1]))):
                for box in blocks.rectangles(start, end):
                    framebuffer.scissor = box
                    framebuffer.use()
                    self.shading.bind_material()
                    bound.use(location=unit)
                    vertex_array.render(moderngl.TRIANGLES)
                    self._accumulate(framebuffer, targets, sums, box)
        finally:
            self.ctx.depth_func = "<"  # moderngl's default
            _scissor_off(framebuffer)

    def _accumulate(self, framebuffer: moderngl.Framebuffer, samples: list[moderngl.Texture],
                    sums: list[moderngl.Framebuffer], box: tuple[int, int, int, int]) -> None:
        """Add ``box`` of each sample image (``framebuffer``'s colour attachments) into its RGBA32F sum (a
        full-screen draw with additive blending, scissored to ``box``); nothing when ``sums`` is empty.
        ``framebuffer`` is bound again afterwards."""
        if not sums:
            return
        program, array = self._accumulate_program, self._accumulate_array
        if program is None or array is None:
            program = compile_program(self.ctx, _ACCUMULATE, {}, self.shading.shader_root)
            array = self.ctx.vertex_array(program, [])
            self._accumulate_program, self._accumulate_array = program, array
        set_uniform(program, "u_sample", _SAMPLE_UNIT)
        self.ctx.enable_only(moderngl.BLEND)
        self.ctx.blend_func = moderngl.ONE, moderngl.ONE
        try:
            for sample, target in zip(samples, sums, strict=True):
                sample.use(location=_SAMPLE_UNIT)
                target.scissor = box
                target.use()
                array.render(moderngl.TRIANGLES, vertices=3)
        finally:
            for target in sums:
                _scissor_off(target)
            self.ctx.blend_func = moderngl.SRC_ALPHA, moderngl.ONE_MINUS_SRC_ALPHA  # DEFAULT_BLENDING (stubs: int)
            self.ctx.enable_only(moderngl.DEPTH_TEST)
            framebuffer.use()

    def release(self) -> None:
        """Free this path's own GL objects (the material belongs to the caller)."""
        for owned in (self._accumulate_array, self._accumulate_program):
            if owned is not None:
                owned.release()
        self._accumulate_array = self._accumulate_program = None
