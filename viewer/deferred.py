"""The deferred render path (issue 12): a cheap G-buffer pass, then the network in a compute shader.

:class:`~viewer.scene.SceneRenderer` renders a mesh on one of two paths with the same output (exposed CIE
XYZ and coverage, ``float32`` ``(H, W, 4)``, row 0 at the top):

* ``forward`` (:mod:`viewer.forward`): ``shaders/surface.glsl`` runs the network in the fragment shader
  (depth pre-pass first);
* ``deferred`` (this module):

  1. **G-buffer**: ``surface.glsl`` compiled with ``GBUFFER`` rasterizes the mesh with the depth test and
     writes, per pixel, the key vector and the factor ``exposure · irradiance · A`` (RGBA32F; cleared to
     ``(0, 0, 0, −1)``, so a negative factor is background). No network there: overdraw costs little.
  2. **Compaction** (``shaders/deferred.glsl`` ``COMPACT``): the pixels that need the network — covered,
     factor > 0, not excluded by the skip bound (``shaders/skip.glsl``) when a ``skip_threshold`` is given
     — are appended to a list in an SSBO with an atomic counter; the others are finished in place
     (``(0, 0, 0, coverage)``). Background, A = 0 and bound-dark pixels cost nothing afterwards.
  3. **Shading** (``SHADE``): one invocation per list entry evaluates the same
     ``encoding.glsl``/``mlp.glsl``/``range.glsl`` as the forward path and writes ``factor · XYZ`` into
     the G-buffer texel. The list's length is read back (4 bytes) and the list is shaded in pieces of
     entries, each one dispatch finished before the next (:mod:`viewer.pacing`: no GL call runs long, so
     Ctrl-C is answered; each texel is computed as in one dispatch, bit for bit). The G-buffer pass, the
     compaction and the resolve run in bands of rows for the same reason (sized by the rows' costs estimated
     from the mesh's projected triangles).
  4. **Tint** (``TINT``, only under sampled light; below), then **resolve** (``RESOLVE``, only for several
     samples): the mean of a pixel's samples.

Samples: ``offsets_px`` (``(N, 2)`` pixels, :func:`viewer.antialias.sample_offsets`) renders N G-buffers
stacked in one texture (sample k in rows ``k·H … k·H + H − 1``, each drawn with
``view_projection @ jitter_matrix(offset)``), then one compaction and one MLP dispatch over the N-times-longer
list, then the per-pixel mean (coverage averaged too). N = 1 at offset (0, 0) is the un-jittered render.
Where ``N · H`` exceeds the largest texture, the samples are taken in chunks, each accumulated.

Sampled light (issue 43: an environment and/or area lights, :class:`~viewer.environment_light.EnvironmentPass`):
the G-buffer pass is ``surface.glsl`` compiled with ``GBUFFER`` and ``ENVIRONMENT``: it runs the forward path's
estimator (``environment_incidence``), sample k as pass ``first_sample + k`` with ``u_pixel_origin`` lowered by
``k·H`` rows, so its random numbers are keyed by the picture's pixel as the forward path's are, not by the stacked
row. It writes the pass's linear sRGB tint (0 where the pixel is not lit) into a second RGBA32F texture stacked
alike, and the pass's control-variate term (exposed linear sRGB, docs/physics.md "Environment light") into a third
(32 bytes more per stacked texel); after the shading kernel, whichever it is, ``TINT`` turns each texel's
``factor · XYZ`` into ``environment_tint``'s value plus that term. Skipping by the bound stays off (the caller's).
Deferred equals forward per pixel to the float32 differences of the stacked samples
(tests/runtime/test_environment_light.py).
A scene takes this path under sampled light only for a render that asks for it
(:meth:`viewer.scene.SceneRenderer.path_for_render`).

Weights of the compute pass (:data:`DEFERRED_WEIGHTS`, each parsed into a :class:`gratnet.codes.WeightForm`):
``texture`` (the packed RGBA32F texture, as the forward path), ``ssbo`` (the same texels in a std430 buffer),
``shared`` (that buffer copied into each work group's shared memory: only nets whose texels fit the driver's
shared memory, 32 KiB on llvmpipe, i.e. not the shipped 28k-MAC nets) or ``baked`` (viewer/baked.py's
literals, the fastest form on llvmpipe).
``ssbo-fp16`` / ``shared-fp16``: the same with each weight stored as an IEEE half (``unpackHalf2x16``, GL
4.3 core; the sums stay float32): half the memory traffic, at an error measured in docs/benchmarks.md.
``tiled``, ``tiled-fp16``: the same buffer (float32, or halves as ``ssbo-fp16``) read by another kernel,
``SHADE_TILED`` (``shaders/mlp_tiled.glsl``, issue 32): a work group evaluates a tile of list entries as a
matrix product, each layer's weights staged in shared memory once per tile (in chunks of input columns when
they do not fit), the activations kept there between layers, each invocation 4 outputs × 4 pixels in
registers; tile and blocking from the layer widths and the driver's shared memory (:mod:`viewer.tiled`).
Same list, same includes (encoding, feature grid, eq. 7), same texels written. ``tiled-half``: that kernel
with half-precision arithmetic (f16vec4; needs GL_NV_gpu_shader5 or GL_AMD_gpu_shader_half_float, refused
elsewhere, e.g. on llvmpipe; half storage, float32 sums across chunks).
``auto``: ``baked`` when the :class:`~viewer.renderer.NetworkRenderer` bakes; else ``texture`` on a
software rasterizer (llvmpipe: 1.2–1.3× faster than ``ssbo``, docs/benchmarks.md "Render paths") and
``ssbo`` on a GPU (the fastest form of the H100 micro-benchmark, shared/notes/opengl-on-a-gpu.md; the
compute pass's H100 frame times: docs/benchmarks.md "GPU bench").

Which path a render takes: :func:`viewer.scene.choose_render_path`.

Rendering only: no glfw, no imgui, no torch.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable

import moderngl
import numpy as np

from gratnet.codes import (
    BINDINGS,
    DEFERRED_TILE,
    DEFERRED_WEIGHTS,
    TILED_WEIGHTS,
    Kernel,
    Precision,
    WeightForm,
    WeightSource,
)
from gratnet.errors import GratNetError
from viewer.antialias import check_offsets, jitter_matrix
from viewer.camera import Camera, Light
from viewer.environment_light import ENVIRONMENT_DEFINES, EnvironmentLighting, EnvironmentPass
from viewer.forward import SURFACE_PROGRAM
from viewer.glsl import compile_compute, compile_program
from viewer.pacing import BLOCK, Pacer, Progress, projected_row_costs, read_rows
from viewer.renderer import NetworkRenderer, is_software_rasterizer, set_uniform, skip_threshold_value
from viewer.surface import MeshBuffers, set_surface_uniforms
from viewer.tiled import HALF_EXTENSIONS, TilePlan, half_extension, plan_for_context

__all__ = ["CHUNK_TEXELS", "DEFERRED_WEIGHTS", "FP16_MAX", "FP16_RELATIVE_ERROR", "TILED_WEIGHTS", "DeferredRenderer"]

_LOG = logging.getLogger("gratnet.deferred")  # the gratnet command shows its INFO lines (gratnet/cli.py)
#: Largest finite IEEE half: a weight beyond it cannot be stored as fp16.
FP16_MAX = 65504.0
#: The documented error of the fp16 weight sources against fp32: relative, per XYZ channel, on pixels at
#: least 1e-3 of the image's peak. Measured ≤ 0.41 % on the shipped cd and blazed nets
#: (docs/benchmarks.md); tests/runtime/test_deferred.py holds it for a random net.
FP16_RELATIVE_ERROR = 0.01
_HALF_AS_FLOAT = "float"  # tiled-half's code path in float types (half_as_float)
_HALF_DEFINES = {**HALF_EXTENSIONS, _HALF_AS_FLOAT: "TILED_HALF_AS_FLOAT"}  # deferred.glsl enables the extension
_PROGRAM = "deferred"
_SHADE_GROUP = 64  # invocations per SHADE work group
_LIST_BINDING = BINDINGS["DEFERRED_LIST_BINDING"]  # gratnet/codes.py: the bindings, the tile of COMPACT / RESOLVE
_WEIGHTS_BINDING = BINDINGS["WEIGHTS_BINDING"]
_GBUFFER_IMAGE = BINDINGS["GBUFFER_IMAGE_BINDING"]
_RESOLVED_IMAGE = BINDINGS["RESOLVED_IMAGE_BINDING"]
_OFFSET_IMAGE = BINDINGS["OFFSET_IMAGE_BINDING"]
CHUNK_TEXELS = 1 << 26  # G-buffer texels per chunk of samples at most (1 GiB of RGBA32F)
_MAX_GROUPS = 65535  # work groups per dimension of a dispatch (the least GL 4.3 guarantees)
_PIECE_ENTRIES = 256  # SHADE pieces start at multiples of 256 list entries: 1 KiB-aligned SSBO offsets
_FIRST_GBUFFER_PIXELS = 1 << 16  # the first band of the G-buffer pass (no MLP; covered pixels, estimated)
_FIRST_COMPACT_PIXELS = 1 << 16  # ... of the compaction (covered texels, estimated)
_FIRST_RESOLVE_ROWS = 64  # ... of the resolve (rows; every pixel costs alike)
_FIRST_TINT_ROWS = 64  # ... of the tint under sampled light (texel rows of the stacked G-buffer; alike too)
_FIRST_SHADE_ENTRIES = 4096  # the first SHADE piece (entries: ~0.1 s of the texture-weights net on llvmpipe)
_GBUFFER_SHARE = 0.1  # the share of a chunk's progress given to its G-buffer and compaction


def _groups(count: int, size: int) -> int:
    return max(1, -(-count // size))


class DeferredRenderer:
    """The deferred path of a :class:`~viewer.scene.SceneRenderer` (see the module docstring).

    Args:
        network: the owner's :class:`~viewer.renderer.NetworkRenderer`: the defines, model uniforms, weights
            and skip bound (:mod:`viewer.surface` sets the camera and light).
        weights: one of :data:`DEFERRED_WEIGHTS`, or its :class:`~gratnet.codes.WeightForm`.
        half_as_float: with ``tiled-half``, compile its half-precision code path with float types
            (``TILED_HALF_AS_FLOAT``): the kernel's structure checked where no driver has half arithmetic
            (llvmpipe; tests/runtime/test_tiled.py). Not faster than ``tiled``.

    Attributes:
        form: the weight form chosen (never ``auto``); ``weights``: its name, as configs save it.
    """

    def __init__(self, network: NetworkRenderer, weights: str | WeightForm = "auto",
                 half_as_float: bool = False) -> None:
        form = WeightForm.parse(weights)
        baked = WeightSource(network.weights_path) is WeightSource.BAKED
        if form.source is WeightSource.AUTO:
            software = is_software_rasterizer(network.ctx)
            form = WeightForm.reading(WeightSource.BAKED if baked else WeightSource.TEXTURE if software
                                      else WeightSource.BUFFER)
        if form.source is WeightSource.BAKED and not baked:
            raise GratNetError("deferred weights 'baked' need a SceneRenderer with weights_path='baked'")
        #: Weights stored as IEEE halves in the buffer (``*-fp16``, ``tiled-half``).
        self.fp16_storage = form.storage is Precision.FLOAT16
        if self.fp16_storage and not np.all(np.abs(network.packed_weights) <= FP16_MAX):
            raise GratNetError(f"deferred weights {form.name!r}: the net has weights beyond fp16's range "
                               f"(±{FP16_MAX:g})")
        self.ctx = network.ctx
        self.network = network
        self.form = form
        self.weights = form.name
        #: The tiled kernel's plan (:mod:`viewer.tiled`; ``None`` for the per-entry SHADE kernel).
        self.tile_plan: TilePlan | None = None
        self._half_extension: str | None = None
        if form.kernel is Kernel.TILED:
            if form.arithmetic is Precision.FLOAT16 and half_as_float:
                self._half_extension = _HALF_AS_FLOAT
            elif form.arithmetic is Precision.FLOAT16:
                self._half_extension = half_extension(network.ctx)
                if self._half_extension is None:
                    renderer = network.ctx.info.get("GL_RENDERER", "this driver")
                    raise GratNetError(f"deferred weights 'tiled-half' need half-precision arithmetic in GLSL "
                                       f"({' or '.join(HALF_EXTENSIONS)}), which {renderer} lacks: use tiled or "
                                       f"tiled-fp16")
            self.tile_plan = plan_for_context(network.ctx, network.layout,
                                              half=self._half_extension not in (None, _HALF_AS_FLOAT))
            _LOG.debug("deferred weights %s: %s", form.name, self.tile_plan.describe(network.layout))
        self._gbuffer_programs: dict[bool, moderngl.Program] = {}  # by tinted: compiled with ENVIRONMENT
        self._programs: dict[str, moderngl.ComputeShader] = {}
        self._weight_buffer: moderngl.Buffer | None = None
        self._weight_texture: moderngl.Texture | None = None  # texture weights beside a baked network
        self._list: moderngl.Buffer | None = None
        # ((width, rows, tinted), colour textures (the G-buffer, then the tint's), depth, framebuffer)
        self._targets: tuple[tuple[int, int, bool], list[moderngl.Texture], moderngl.Renderbuffer,
                             moderngl.Framebuffer] | None = None
        self._output: moderngl.Texture | None = None
        #: Called with the fraction of the render done (0 … 1) after each band and piece; None: not reported.
        self.progress: Progress | None = None
        #: The sizes of the G-buffer's, COMPACT's and RESOLVE's bands of rows and of the SHADE pieces of the list,
        #: from the time of those before (kept between renders).
        self.gbuffer_pacer = Pacer(self.ctx, first_cost=_FIRST_GBUFFER_PIXELS)
        self.compact_pacer = Pacer(self.ctx, first_cost=_FIRST_COMPACT_PIXELS)
        self.shade_pacer = Pacer(self.ctx, first_cost=_FIRST_SHADE_ENTRIES)
        self.resolve_pacer = Pacer(self.ctx, first_cost=_FIRST_RESOLVE_ROWS)
        self.tint_pacer = Pacer(self.ctx, first_cost=_FIRST_TINT_ROWS)

    # ---------------------------------------------------------------------------------------------
    # Programs

    def _defines(self) -> dict[str, int | float]:
        return {**self.network.defines, "SHADE_GROUP": _SHADE_GROUP}

    def _gbuffer_program(self, tinted: bool = False) -> moderngl.Program:
        """The G-buffer's program; ``tinted``: with ``ENVIRONMENT`` (sampled light: it writes the tint too)."""
        if tinted not in self._gbuffer_programs:
            defines = {**self.network.defines, "GBUFFER": 1, **(ENVIRONMENT_DEFINES if tinted else {})}
            self._gbuffer_programs[tinted] = compile_program(self.ctx, SURFACE_PROGRAM, defines,
                                                             self.network.shader_root)
        return self._gbuffer_programs[tinted]

    def _compute(self, kernel: str, counting: bool = False) -> moderngl.ComputeShader:
        key = kernel + ("#count" if counting else "")
        if key not in self._programs:
            defines = {**self._defines(), kernel: 1}
            overrides = None
            form = self.form
            if kernel == "SHADE":
                overrides = self.network.overrides if form.source is WeightSource.BAKED else None
                if form.buffer:
                    texels = int(np.prod(self.network.packed_weights.shape[:2]))
                    if form.source is WeightSource.SHARED:
                        defines["WEIGHTS_SHARED"] = texels
                    else:
                        defines["WEIGHTS_SSBO"] = 1  # ssbo*, and the tiled kernel's staging reads
                    if self.fp16_storage:
                        defines["WEIGHTS_FP16"] = 1
                if self.tile_plan is not None:  # the tiled kernel in SHADE's place
                    del defines["SHADE"], defines["SHADE_GROUP"]
                    defines.update(SHADE_TILED=1, **self.tile_plan.defines())
                    if self._half_extension is not None:
                        defines.update({"TILED_HALF": 1, _HALF_DEFINES[self._half_extension]: 1})
                if form.source is WeightSource.BAKED:
                    _LOG.info("deferred shading program with baked weights (%d MACs per pixel): the first dispatch "
                              "JIT-compiles it (~25 s at 28k MACs on llvmpipe; Mesa's shader cache keeps it)",
                              self.network.model.macs_per_evaluation)
            if counting:
                defines["COUNT_EVALUATIONS"] = 1
            try:
                program = compile_compute(self.ctx, _PROGRAM, defines, self.network.shader_root, overrides)
            except GratNetError as error:
                if form.source is WeightSource.SHARED and kernel == "SHADE":
                    bytes_needed = form.texel_bytes * int(np.prod(self.network.packed_weights.shape[:2]))
                    raise GratNetError(f"deferred weights 'shared': the net's {bytes_needed} bytes of weights must fit "
                                       f"the GPU's compute shared memory (32 KiB on llvmpipe): {error}") from error
                if self.tile_plan is not None and kernel == "SHADE":  # name the plan (GRATNET_TILE_PLAN may change it)
                    plan = self.tile_plan.describe(self.network.layout)
                    raise GratNetError(f"deferred weights {self.weights!r} ({plan}): {error}") from error
                raise
            if kernel == "SHADE":
                self.network.model_uniforms(program, form.source)
            self._programs[key] = program
        return self._programs[key]

    def _bind_weights(self) -> None:
        if self.form.source is WeightSource.TEXTURE or self.network.model.grids:
            self.network.use_weights(0)  # the weight texture, and a feature-grid model's grids on their units
        if self.form.source is WeightSource.TEXTURE and self.network.weights_path != "texture":
            # A baked network holds a 1-texel placeholder (it read as a black picture): the texels in our own.
            if self._weight_texture is None:
                texels = self.network.packed_weights
                self._weight_texture = self.ctx.texture((texels.shape[1], texels.shape[0]), 4, texels.tobytes(),
                                                        dtype="f4")
                self._weight_texture.filter = moderngl.NEAREST, moderngl.NEAREST
            self._weight_texture.use(location=0)
        if self.form.buffer:
            if self._weight_buffer is None:
                texels = self.network.packed_weights
                if self.fp16_storage:  # four halves per texel, in packHalf2x16 order (little-endian)
                    texels = texels.astype("<f2")
                self._weight_buffer = self.ctx.buffer(np.ascontiguousarray(texels).tobytes())
            self._weight_buffer.bind_to_storage_buffer(_WEIGHTS_BINDING)

    def compile_steps(self, tinted: bool = False) -> list[Callable[[], object]]:
        """One callable per program, each compiling (or linking from the driver's cache) that program: the
        viewer runs one per frame, since linking them all at once from Mesa's cache blocked a frame 0.6 s.
        ``tinted``: the programs of sampled light (the G-buffer with ``ENVIRONMENT`` and the ``TINT`` kernel)."""
        steps: list[Callable[[], object]] = [lambda: self._gbuffer_program(tinted)]
        kernels = ("COMPACT", "SHADE", *(("TINT",) if tinted else ()), "RESOLVE")
        return steps + [lambda kernel=kernel: self._compute(kernel) for kernel in kernels]

    def compile(self) -> None:
        """Compile every program now (the first render would otherwise)."""
        for step in self.compile_steps():
            step()

    # ---------------------------------------------------------------------------------------------
    # Buffers (kept between renders of the same size: a view renders many frames)

    def _gbuffer(self, width: int, rows: int, tinted: bool) -> tuple[list[moderngl.Texture], moderngl.Framebuffer]:
        """The G-buffer's textures (``tinted``: and the tint's, stacked alike) and their framebuffer."""
        if self._targets is None or self._targets[0] != (width, rows, tinted):
            self._release_targets()
            # tinted: the tint's and the control variate's textures, stacked as the G-buffer
            textures = [self.ctx.texture((width, rows), 4, dtype="f4") for _ in range(3 if tinted else 1)]
            depth = self.ctx.depth_renderbuffer((width, rows))
            framebuffer = self.ctx.framebuffer(color_attachments=textures, depth_attachment=depth)
            self._targets = ((width, rows, tinted), textures, depth, framebuffer)
        return self._targets[1], self._targets[3]

    def _list_buffer(self, entries: int) -> moderngl.Buffer:
        size = 16 + 4 * entries
        if self._list is None or self._list.size < size:
            if self._list is not None:
                self._list.release()
            self._list = self.ctx.buffer(reserve=size)
        return self._list

    def _output_texture(self, width: int, height: int) -> moderngl.Texture:
        if self._output is None or self._output.size != (width, height):
            if self._output is not None:
                self._output.release()
            self._output = self.ctx.texture((width, height), 4, dtype="f4")
        return self._output

    # ---------------------------------------------------------------------------------------------
    # Rendering

    def render(self, uploaded: MeshBuffers, camera: Camera, light: Light, size: tuple[int, int], exposure: float,
               ior: float | None, skip_threshold: float | None = None, statistics: dict[str, int] | None = None,
               offsets_px: np.ndarray | None = None, first_sample: int = 0,
               environment: EnvironmentPass | None = None) -> np.ndarray:
        """Exposed CIE XYZ and coverage, ``float32`` ``(H, W, 4)``, row 0 at the top: the mean over the
        samples at ``offsets_px`` (``(N, 2)`` pixels, x right, y up; ``None``: one sample at the centre).

        ``statistics`` receives the counters of ``viewer.renderer.STATISTICS_KEYS`` summed over the samples
        (``evaluations`` = the list's length).

        ``environment``: sampled light (shaders/environment.glsl), as :meth:`viewer.forward.ForwardRenderer.render`
        takes it: sample k is pass ``first_sample + k`` of the estimator, its random numbers keyed by the picture's
        pixel (``environment.pixel_origin`` added), not by its row in the stacked G-buffer; the G-buffer pass writes
        each pass's tint beside it, and the TINT kernel applies it after the network. The caller turns the skip
        bound off (a pass's sample is not the pixel)."""
        width, height = size
        offsets = np.zeros((1, 2)) if offsets_px is None else check_offsets(offsets_px)
        threshold = skip_threshold_value(skip_threshold)
        max_rows = int(self.ctx.info.get("GL_MAX_TEXTURE_SIZE", 16384))
        per_chunk = max(1, min(len(offsets), max_rows // height, CHUNK_TEXELS // (width * height)))
        tinted = environment is not None
        gbuffer_program = self._gbuffer_program(tinted)
        set_surface_uniforms(gbuffer_program, camera, light, width, height, float(exposure), ior,
                             self.network.slope_covariance)
        tint = None
        if environment is not None:
            environment.lighting.set_uniforms(gbuffer_program, environment.delta_light, environment.seed,
                                              environment.sampling, tinted=False)
            tint = self._compute("TINT")
            EnvironmentLighting.set_colour_uniforms(tint)
        compact = self._compute("COMPACT", counting=statistics is not None)
        bound, unit = self.network.skip_uniforms(compact, threshold)
        shade, resolve = self._compute("SHADE"), self._compute("RESOLVE")
        # float64, as the forward path jitters it before its float32 cast: the same matrix per sample, bit for bit.
        view_projection = camera.view_projection(width / height)
        vertex_array = None
        if not uploaded.empty:
            vertex_array = uploaded.vertex_array_for(gbuffer_program)
        if statistics is not None:
            self.network.reset_counters()
        chunks = [offsets[k:k + per_chunk] for k in range(0, len(offsets), per_chunk)]
        textures, framebuffer = self._gbuffer(width, height * len(chunks[0]), tinted)
        texture = textures[0]
        list_buffer = self._list_buffer(width * height * len(chunks[0]))
        several = len(offsets) > 1
        output = self._output_texture(width, height) if several else None
        # The rows' costs, estimated from the mesh's projected triangles: they size the G-buffer's and the
        # compaction's bands (viewer.pacing).
        row_costs = np.full(height, float(width))
        if not (uploaded.empty or self.gbuffer_pacer.fits(width * height) and self.compact_pacer.fits(
                width * height * len(chunks[0]))):
            row_costs = projected_row_costs(uploaded.mesh.positions, uploaded.mesh.indices, view_projection, size)
        scope = self.ctx.scope(framebuffer, enable_only=moderngl.DEPTH_TEST)
        readable = None
        try:
            with scope:
                for number, chunk in enumerate(chunks):
                    def report(fraction: float, number: int = number) -> None:
                        if self.progress is not None:
                            self.progress(min(1.0, (number + fraction) / len(chunks)))

                    passes = None
                    if environment is not None:  # this chunk's first pass: the samples before it numbered on
                        environment.lighting.bind()
                        passes = environment, first_sample + number * per_chunk
                    self._draw_gbuffer(framebuffer, gbuffer_program, vertex_array, view_projection, chunk, row_costs,
                                       lambda done: report(_GBUFFER_SHARE * done), passes)
                    list_buffer.write(np.array([0, 1, 1, 0], dtype=np.uint32).tobytes())
                    list_buffer.bind_to_storage_buffer(_LIST_BINDING)
                    texture.bind_to_image(_GBUFFER_IMAGE, read=True, write=True)
                    bound.use(location=unit)
                    for first, end in self.compact_pacer.pieces(height * len(chunk), np.tile(row_costs, len(chunk)),
                                                                multiple=DEFERRED_TILE):
                        set_uniform(compact, "u_first_row", first)
                        compact.run(_groups(width, DEFERRED_TILE), _groups(end - first, DEFERRED_TILE))
                    self.ctx.memory_barrier()
                    entries = int(np.frombuffer(list_buffer.read(4, offset=12), dtype=np.uint32)[0])
                    self._bind_weights()
                    texture.bind_to_image(_GBUFFER_IMAGE, read=True, write=True)
                    share = (1.0 - _GBUFFER_SHARE) / max(entries, 1)

                    def shaded(end: int, share: float = share) -> None:
                        report(_GBUFFER_SHARE + share * end)

                    for first, end in self.shade_pacer.pieces(entries, multiple=_PIECE_ENTRIES, done=shaded):
                        self._shade(shade, list_buffer, first, end)
                    self.ctx.memory_barrier()
                    if tint is not None:
                        self._tint(tint, texture, textures[1], textures[2], width, height * len(chunk))
                    if output is not None:
                        set_uniform(resolve, "u_samples", len(chunk))
                        set_uniform(resolve, "u_height", height)
                        set_uniform(resolve, "u_scale", 1.0 / len(offsets))
                        set_uniform(resolve, "u_accumulate", number > 0)
                        texture.bind_to_image(_GBUFFER_IMAGE, read=True, write=False)
                        output.bind_to_image(_RESOLVED_IMAGE, read=True, write=True)
                        for first, end in self.resolve_pacer.pieces(height, multiple=DEFERRED_TILE):
                            set_uniform(resolve, "u_first_row", first)
                            resolve.run(_groups(width, DEFERRED_TILE), _groups(end - first, DEFERRED_TILE))
                        self.ctx.memory_barrier()
                    report(1.0)
                if statistics is not None:
                    self.network.read_counters(statistics)
                readable = framebuffer if output is None else self.ctx.framebuffer(color_attachments=[output])
                pixels = read_rows(readable, (width, height))  # sample 0's rows, or the resolved mean
        finally:
            scope.release()
            if readable is not None and readable is not framebuffer:
                readable.release()
            if vertex_array is not None:
                vertex_array.release()
        return pixels[::-1].copy()  # GL rows start at the bottom; ours at the top

    def _shade(self, shade: moderngl.ComputeShader, list_buffer: moderngl.Buffer, first: int, end: int) -> None:
        """The SHADE kernel over list entries ``first … end − 1``: the list is bound from byte ``4 · first``, so
        that the kernel's header (dispatch size, entry count) lies on entries ``first − 4 … first − 1``, which
        earlier pieces have shaded already (``first`` is 0 or a multiple of :data:`_PIECE_ENTRIES`, so the
        binding offset is 1 KiB-aligned); the header says ``end − first`` entries."""
        count = end - first
        offset = 4 * first
        list_buffer.write(np.array([0, 0, 1, count], dtype=np.uint32).tobytes(), offset=offset)
        list_buffer.bind_to_storage_buffer(_LIST_BINDING, offset=offset, size=16 + 4 * count)
        groups = _groups(count, _SHADE_GROUP if self.tile_plan is None else self.tile_plan.pixels)
        shade.run(min(groups, _MAX_GROUPS), _groups(groups, _MAX_GROUPS))

    def shade_keys(self, keys: np.ndarray, factor: float = 1.0, piece_entries: int | None = None,
                   timings: list[tuple[float, float]] | None = None, repeats: int = 1) -> np.ndarray:
        """The SHADE kernel of this renderer's weights on key vectors ``keys`` (``(N, 3)``): ``factor · XYZ``,
        ``float32`` ``(N, 3)``. The list holds exactly these N entries in order (no G-buffer pass, no
        compaction), so tests choose its length: tile edges, 1, 0. ``piece_entries`` (a multiple of 256):
        shade in pieces of that many entries, as :meth:`render` does (default: one dispatch).

        ``timings``: receives ``(GL timer seconds, wall seconds)`` of the shading dispatches alone, once per
        repeat (``repeats`` runs, the keys uploaded again before each, outside the timing; the wall time ends
        with ``ctx.finish()``): the kernel's own time, without the G-buffer, compaction and read-back of a frame
        (benchmarks/shade_kernels.py). llvmpipe's timer reads about 0 for compute work: take the wall time there."""
        keys = np.asarray(keys, dtype=np.float32).reshape(-1, 3)
        count = len(keys)
        width = max(1, min(count, 1024))
        rows = max(1, -(-count // width))
        texels = np.zeros((rows * width, 4), dtype=np.float32)
        texels[:count, :3] = keys
        texels[:count, 3] = factor
        index = np.arange(count, dtype=np.uint32)
        packed = (index % width) | ((index // width) << 16)
        header = np.array([0, 1, 1, count], dtype=np.uint32)
        piece = count if piece_entries is None else piece_entries
        if piece_entries is not None and (piece_entries <= 0 or piece_entries % _PIECE_ENTRIES):
            raise GratNetError(f"piece_entries must be a positive multiple of {_PIECE_ENTRIES}, got {piece_entries}")
        texture = self.ctx.texture((width, rows), 4, texels.tobytes(), dtype="f4")
        listed = np.concatenate([header, packed]).tobytes()
        list_buffer = self.ctx.buffer(listed)
        try:
            shade = self._compute("SHADE")
            self._bind_weights()
            texture.bind_to_image(_GBUFFER_IMAGE, read=True, write=True)
            query = self.ctx.query(time=True) if timings is not None else None
            for repeat in range(max(1, repeats)):
                if repeat:
                    texture.write(texels.tobytes())  # the kernel replaced the keys by its outputs
                    list_buffer.write(listed)  # and pieces' headers overwrote entries
                    self.ctx.memory_barrier()
                    self.ctx.finish()
                if query is not None and timings is not None:  # both or neither
                    start = time.perf_counter()
                    with query:
                        for first in range(0, max(count, 1), max(piece, 1)):
                            self._shade(shade, list_buffer, first, min(count, first + piece))
                        self.ctx.finish()
                    wall = time.perf_counter() - start
                    timings.append((query.elapsed * 1e-9, wall))  # reading elapsed waits for the result
                else:
                    for first in range(0, max(count, 1), max(piece, 1)):
                        self._shade(shade, list_buffer, first, min(count, first + piece))
            self.ctx.memory_barrier()
            result = np.frombuffer(texture.read(), dtype=np.float32).reshape(-1, 4)
        finally:
            list_buffer.release()
            texture.release()
        return result[:count, :3].copy()

    def _tint(self, tint: moderngl.ComputeShader, texture: moderngl.Texture, tints: moderngl.Texture,
              offsets: moderngl.Texture, width: int, rows: int) -> None:
        """The TINT kernel over the chunk's ``rows`` texel rows, in bands (sampled light, after the shading)."""
        texture.bind_to_image(_GBUFFER_IMAGE, read=True, write=True)
        tints.bind_to_image(_RESOLVED_IMAGE, read=True, write=False)
        offsets.bind_to_image(_OFFSET_IMAGE, read=True, write=False)
        for first, end in self.tint_pacer.pieces(rows, multiple=DEFERRED_TILE):
            set_uniform(tint, "u_first_row", first)
            tint.run(_groups(width, DEFERRED_TILE), _groups(end - first, DEFERRED_TILE))
        self.ctx.memory_barrier()

    def _draw_gbuffer(self, framebuffer: moderngl.Framebuffer, program: moderngl.Program,
                      vertex_array: moderngl.VertexArray | None, view_projection: np.ndarray, chunk: np.ndarray,
                      row_costs: np.ndarray, done: Callable[[float], None],
                      passes: tuple[EnvironmentPass, int] | None = None) -> None:
        """Sample k of ``chunk`` into rows ``k·height …`` of the G-buffer, with its jittered projection
        (``view_projection``: float64, cast after jittering as the forward path does), in bands of rows (a scissor
        box inside the sample's viewport; :mod:`viewer.pacing`) sized by ``row_costs`` (per GL row of one sample).
        ``done``: the fraction of the chunk's G-buffer drawn, after each band. ``passes``: sampled light and the
        pass index of the chunk's first sample."""
        framebuffer.use()
        framebuffer.clear(0.0, 0.0, 0.0, -1.0, depth=1.0)  # factor −1: background (and tint and offset 0)
        if vertex_array is None:
            return
        width, height = framebuffer.width, len(row_costs)
        try:
            for k, offset in enumerate(chunk):
                matrix = view_projection
                if offset[0] != 0.0 or offset[1] != 0.0:  # (0, 0): the forward path's matrix, bit for bit
                    matrix = view_projection @ jitter_matrix(offset, width, height)
                set_uniform(program, "u_view_projection", np.ascontiguousarray(matrix, dtype=np.float32))
                if passes is not None:  # sample k lies k·height rows up: key its pixels as the picture's
                    environment, first = passes
                    origin_x, origin_y = environment.pixel_origin
                    environment.lighting.set_pass(program, first + k, (origin_x, origin_y - k * height))
                self.ctx.viewport = (0, k * height, width, height)
                def drawn(end: int, k: int = k) -> None:
                    done((k + end / height) / len(chunk))

                for first, end in self.gbuffer_pacer.pieces(height, row_costs, multiple=BLOCK[1], done=drawn):
                    # The scissor box also clips what the viewport does not on every implementation (guard bands).
                    self.ctx.scissor = (0, k * height + first, width, end - first)
                    vertex_array.render(moderngl.TRIANGLES)
        finally:
            self.ctx.scissor = None

    def release(self) -> None:
        """Free the GL objects (the programs, buffers and targets of this path)."""
        for gbuffer_program in self._gbuffer_programs.values():
            gbuffer_program.release()
        self._gbuffer_programs.clear()
        for program in self._programs.values():
            program.release()
        self._programs.clear()
        self._release_targets()
        for resource in (self._weight_buffer, self._list, self._output, self._weight_texture):
            if resource is not None:
                resource.release()
        self._weight_buffer = self._list = self._output = self._weight_texture = None

    def _release_targets(self) -> None:
        if self._targets is not None:
            _, textures, depth, framebuffer = self._targets
            framebuffer.release()
            depth.release()
            for texture in textures:
                texture.release()
            self._targets = None
