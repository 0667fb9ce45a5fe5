"""What every material on the GPU shares: its programs, work counters and BRDF slices.

A *material* is what the shading code evaluates at a key vector: the network (:class:`viewer.renderer.NetworkRenderer`,
shaders/mlp.glsl) or the ground-truth volume's look-up (:class:`viewer.reference.ReferenceRenderer`,
shaders/reference.glsl). Both subclass :class:`ShadingPrograms`, which compiles the programs with the material's
defines (cached per name, with counting and depth-only variants), binds its textures, keeps the work counters and
draws BRDF slices; the forward path (:mod:`viewer.forward`) draws meshes with either.

Rendering only: no glfw, no imgui, no torch.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from pathlib import Path
from typing import TypeAlias, TypeVar, cast

import moderngl
import numpy as np

from gratnet.brdf import direction
from gratnet.codes import BINDINGS, COUNTER, COUNTER_SLOTS
from gratnet.display import xyz_to_display_srgb8
from gratnet.errors import GratNetError
from gratnet.shadowing import NO_SHADOWING, check_slope_covariance
from viewer.glsl import GeneratedSource, compile_program
from viewer.pacing import Blocks, Pacer, Progress, disc_block_costs, read_rows

__all__ = ["SKIP_COUNTER_BINDING", "STATISTICS_KEYS", "MaterialTexture", "ShadingPrograms", "ior_uniform",
           "set_uniform", "skip_threshold_value"]

#: A texture a material binds (with its unit): the network's weights (2D); a feature-grid model's grids, the skip
#: bound and the reference volume (3D).
MaterialTexture: TypeAlias = "moderngl.Texture | moderngl.Texture3D"
#: The work counters' names (gratnet.codes.COUNTER, in slot order), the keys of a render's ``statistics``.
STATISTICS_KEYS = COUNTER.names
#: SSBO binding of the work counters (shaders/counters.glsl; gratnet.codes.BINDINGS).
SKIP_COUNTER_BINDING = BINDINGS["SKIP_COUNTER_BINDING"]
_COUNTING_SUFFIX = "#count"  # program-cache key of a program compiled with COUNT_EVALUATIONS
_DEPTH_ONLY_SUFFIX = "#depth"  # ... and of one compiled with DEPTH_ONLY (the depth pre-pass)
_FIRST_SLICE_PIXELS = 2048  # a BRDF slice's first band: ~2k pixels in the disc


def set_uniform(program: moderngl.Program | moderngl.ComputeShader, name: str, value: object) -> None:
    """Set a uniform that the program must have (a missing one means shader and renderer disagree)."""
    if name not in program:
        raise GratNetError(f"GLSL program lacks uniform {name!r}; the shaders and the renderer disagree")
    # A plain uniform: the stubs' union also has blocks, attributes and varyings, which no caller names.
    member = cast(moderngl.Uniform, program[name])
    if isinstance(value, np.ndarray):
        member.write(value.tobytes())
    else:
        member.value = value


def ior_uniform(ior: float | None) -> float:
    """The shader's IOR uniform: 0 turns Fresnel off (``None`` or 0, as in physics.md eq. 5)."""
    from gratnet.brdf import check_ior

    checked = check_ior(ior, "ior")  # 1 is allowed: R/R0 has a limit there (physics.md, "The A-term")
    return 0.0 if checked is None else checked


def skip_threshold_value(threshold: float | None) -> float:
    """The shaders' ``u_skip_threshold``: ``None`` or 0 turns skipping off (exact linear output)."""
    if threshold is None:
        return 0.0
    value = float(threshold)
    if not (math.isfinite(value) and value >= 0.0):
        raise GratNetError(f"skip threshold must be a finite number ≥ 0 (0 or None: off), got {threshold!r}")
    return value


ShadingT = TypeVar("ShadingT", bound="ShadingPrograms")


class ShadingPrograms:
    """Programs of one material on one context (see the module docstring).

    Args:
        ctx: an OpenGL ≥ 4.3 context.
        defines: the material's GLSL defines (array capacities, ``REFERENCE``, …; values never substituted).
        shader_root: folder of the GLSL files (default: the repository's ``shaders/``).
        overrides: include → generated source (e.g. the baked mlp.glsl).
        slope_covariance: the material's relief slopes (Σxx, Σxy, Σyy) for Smith's shadowing (gratnet.shadowing).

    Subclasses set their uniforms in :meth:`configure_program`, name their textures in
    :meth:`material_textures` and say how they skip work in :meth:`skip_uniforms`.
    """

    def __init__(self, ctx: moderngl.Context, defines: Mapping[str, int | float], shader_root: str | Path | None,
                 overrides: Mapping[str, GeneratedSource] | None = None,
                 slope_covariance: tuple[float, float, float] = NO_SHADOWING) -> None:
        self.ctx = ctx
        #: The relief's slope covariance (Σxx, Σxy, Σyy) of Smith's shadowing (gratnet.shadowing): the surface
        #: programs' ``u_slope_covariance``; NO_SHADOWING renders unshadowed.
        self.slope_covariance = check_slope_covariance(slope_covariance)
        self.defines = dict(defines)
        self.shader_root = shader_root
        self.overrides: dict[str, GeneratedSource] = dict(overrides or {})
        #: Compiled programs by cache key (name, or name + a variant suffix) and their full-screen vertex arrays.
        self.compiled: dict[str, moderngl.Program] = {}
        self.vertex_arrays: dict[str, moderngl.VertexArray] = {}
        self._counters: moderngl.Buffer | None = None
        #: The sizes of a BRDF slice's bands of rows, from the time of the bands before (viewer.pacing).
        self.slice_pacer = Pacer(ctx, first_cost=_FIRST_SLICE_PIXELS)

    # ---------------------------------------------------------------------------------------------
    # What a material says about itself

    def configure_program(self, program: moderngl.Program, name: str) -> None:
        """Set the material's uniforms on a freshly compiled ``program`` (``name`` without variant suffix)."""

    def material_textures(self) -> tuple[tuple[MaterialTexture, int], ...]:
        """``(texture, unit)`` pairs the material's programs read."""
        return ()

    def skip_uniforms(self, program: moderngl.Program | moderngl.ComputeShader, skip_threshold: float | None
                      ) -> tuple[MaterialTexture, int]:
        """Set the skipping uniforms on ``program``; returns ``(texture, unit)`` to bind."""
        raise NotImplementedError

    # ---------------------------------------------------------------------------------------------
    # Programs

    def _compile(self, key: str, name: str, defines: Mapping[str, int | float]) -> moderngl.Program:
        program = compile_program(self.ctx, name, defines, self.shader_root, self.overrides)
        self.configure_program(program, name)
        self.compiled[key] = program
        self.vertex_arrays[key] = self.ctx.vertex_array(program, [])  # full-screen triangle: no buffers
        return program

    def program(self, name: str) -> moderngl.Program:
        """Program ``name`` (``brdf_slice``, ``surface``, …) with the material's defines and uniforms, compiled
        on first use."""
        if name not in self.compiled:
            return self._compile(name, name, self.defines)
        return self.compiled[name]

    def counting_program(self, name: str) -> tuple[str, moderngl.Program]:
        """``(key, program)``: program ``name`` compiled with ``COUNT_EVALUATIONS`` (atomic counters in an
        SSBO; shaders/counters.glsl), cached under ``key`` beside :meth:`program`'s. For measurements only: the
        atomics cost time, so time renders without it."""
        key = name + _COUNTING_SUFFIX
        if key not in self.compiled:
            self.program(name)  # compile errors surface from the plain program first
            self._compile(key, name, {**self.defines, "COUNT_EVALUATIONS": 1})
        return key, self.compiled[key]

    def variant_program(self, name: str, extra: Mapping[str, int | float]) -> moderngl.Program:
        """Program ``name`` compiled with the material's defines and ``extra`` (e.g. ``ENVIRONMENT``; with
        ``COUNT_EVALUATIONS`` too for a counting variant), cached under a key that names them."""
        if not extra:
            return self.program(name)
        key = name + "#" + ",".join(f"{define}={value}" for define, value in sorted(extra.items()))
        if key not in self.compiled:  # not the plain program first: a baked network's compile takes ~25 s
            self._compile(key, name, {**self.defines, **extra})
        return self.compiled[key]

    def depth_only_program(self, name: str) -> moderngl.Program:
        """Program ``name`` compiled with ``DEPTH_ONLY`` (shaders/surface.glsl: the same vertex stage, an
        empty fragment stage) for a depth pre-pass; it reads only the vertex stage's uniforms."""
        key = name + _DEPTH_ONLY_SUFFIX
        if key not in self.compiled:
            self.compiled[key] = compile_program(self.ctx, name, {**self.defines, "DEPTH_ONLY": 1},
                                                 self.shader_root, self.overrides)
        return self.compiled[key]

    def bind_material(self) -> None:
        """Bind the material's textures to their units, for callers that draw a :meth:`program` with their own
        geometry (viewer.forward)."""
        for texture, unit in self.material_textures():
            texture.use(location=unit)

    def draw(self, key: str, framebuffer: moderngl.Framebuffer,
             textures: tuple[tuple[MaterialTexture, int], ...] = (),
             scissor: tuple[int, int, int, int] | None = None) -> None:
        """One full-screen triangle of program ``key`` into ``framebuffer`` (only inside ``scissor`` = x, y,
        width, height in GL pixels when given), with blending/depth test off and the caller's framebuffer and
        enable flags restored afterwards (a window may share this context)."""
        # Textures are bound by hand: moderngl 5.13's scope(textures=...) left the samplers reading 0.
        scope = self.ctx.scope(framebuffer, enable_only=moderngl.NOTHING)
        try:
            with scope:
                framebuffer.use()  # the scope binds the framebuffer but leaves the viewport as it was
                for texture, unit in (*self.material_textures(), *textures):
                    texture.use(location=unit)
                if scissor is not None:
                    self.ctx.scissor = scissor
                try:
                    self.vertex_arrays[key].render(moderngl.TRIANGLES, vertices=3)
                finally:
                    if scissor is not None:
                        self.ctx.scissor = None
        finally:
            scope.release()

    # ---------------------------------------------------------------------------------------------
    # Work counters (shaders/counters.glsl)

    def reset_counters(self) -> None:
        """Zero the work counters and bind them for the next counting draw."""
        if self._counters is None:
            self._counters = self.ctx.buffer(reserve=4 * COUNTER_SLOTS)
        self._counters.write(np.zeros(COUNTER_SLOTS, dtype=np.uint32).tobytes())
        self._counters.bind_to_storage_buffer(SKIP_COUNTER_BINDING)

    def read_counters(self, statistics: dict[str, int]) -> None:
        """Fill ``statistics`` with the counters (:data:`STATISTICS_KEYS`) since :meth:`reset_counters`."""
        if self._counters is None:
            raise GratNetError("work counters read before reset_counters")
        self.ctx.finish()
        counts = np.frombuffer(self._counters.read(), dtype=np.uint32)
        statistics.clear()
        statistics.update({key: int(counts[k]) for k, key in enumerate(STATISTICS_KEYS)})

    # ---------------------------------------------------------------------------------------------
    # BRDF slices

    def render_brdf_slice_layers(
        self, theta_deg: float, phi_deg: float, size: int, exposure: float = 1.0, ior: float | None = 1.5,
        skip_threshold: float | None = None, statistics: dict[str, int] | None = None,
        rows: tuple[int, int] | None = None, progress: Progress | None = None,
    ) -> tuple[np.ndarray, np.ndarray]:
        """A BRDF slice (docs/physics.md "BRDF slice") and the material's XYZ behind it.

        Args:
            skip_threshold: exposed linear sRGB below which the display shows 0 (``DISPLAY_SKIP_THRESHOLD``
                for 8-bit display output): the material is skipped (and the pixel is 0) where it cannot reach
                it (:meth:`skip_uniforms`). ``None`` or 0: off, the exact linear image (EXR, comparisons).
            statistics: a dict to fill with the work counters (:data:`STATISTICS_KEYS`); renders with a
                counting variant of the program (slower: time renders without it).
            rows: ``(first, end)``: compute only these rows (from the top; a scissor box, so the time is the
                band's); the other rows are not written. The viewer refines a slice in such bands between frames.
            progress: called with the fraction done (0 … 1) after each piece: the rows are drawn in pieces of
                about :data:`viewer.pacing.PIECE_SECONDS` each (Ctrl-C is answered between them).

        Returns:
            ``(exposed, material)``, both ``float32`` ``(size, size, 3)`` with row 0 at the top (as
            ``gratnet.brdf.slice_view_directions``): ``exposed = exposure · A · XYZ`` (CIE XYZ, linear)
            and ``material`` = XYZ at each pixel's key vector; both 0 outside the unit disc, and ``material``
            is 0 where it was skipped (A = 0, or by the bound).
        """
        if isinstance(size, bool) or not isinstance(size, (int, np.integer)) or not 1 <= size <= 16384:
            raise GratNetError(f"slice size must be an integer in 1 … 16384, got {size!r}")
        if rows is not None and not (0 <= rows[0] < rows[1] <= size):
            raise GratNetError(f"slice rows must satisfy 0 ≤ first < end ≤ {size}, got {rows!r}")
        if not all(math.isfinite(value) for value in (theta_deg, phi_deg, exposure)):
            raise GratNetError(
                f"light angles and exposure must be finite, got {theta_deg!r}, {phi_deg!r}, {exposure!r}"
            )
        key = "brdf_slice"
        program = self.program(key)
        if statistics is not None:
            key, program = self.counting_program(key)
            self.reset_counters()
        bound, unit = self.skip_uniforms(program, skip_threshold)
        set_uniform(program, "u_size", int(size))
        set_uniform(program, "u_light", tuple(float(c) for c in direction(theta_deg, phi_deg)))
        set_uniform(program, "u_exposure", float(exposure))
        set_uniform(program, "u_ior", ior_uniform(ior))
        targets = [self.ctx.texture((size, size), 4, dtype="f4") for _ in range(2)]
        framebuffer = self.ctx.framebuffer(color_attachments=targets)
        try:
            # Pieces of blocks (scissor boxes), each finished before the next: no GL call runs long (viewer.pacing).
            first, end = (0, size) if rows is None else rows
            blocks = Blocks(size, (size - end, size - first))  # GL rows: bottom up
            costs = disc_block_costs(size, blocks)
            cumulative = np.cumsum(costs) / costs.sum()
            done = None if progress is None else lambda block: progress(float(cumulative[block - 1]))
            for start, stop in self.slice_pacer.pieces(blocks.count, costs, done=done):
                for box in blocks.rectangles(start, stop):
                    self.draw(key, framebuffer, ((bound, unit),), box)
            if statistics is not None:
                self.read_counters(statistics)
            # GL rows start at the bottom; ours at the top.
            images = [read_rows(framebuffer, (size, size), attachment=k)[::-1, :, :3].copy() for k in range(2)]
        finally:
            framebuffer.release()
            for target in targets:
                target.release()
        return images[0], images[1]

    def render_brdf_slice(
        self, theta_deg: float, phi_deg: float, size: int, exposure: float = 1.0, ior: float | None = 1.5,
        skip_threshold: float | None = None, statistics: dict[str, int] | None = None,
        rows: tuple[int, int] | None = None, progress: Progress | None = None,
    ) -> np.ndarray:
        """Exposed CIE XYZ of a BRDF slice, ``float32`` ``(size, size, 3)``, row 0 at the top.

        The light is at polar angle ``theta_deg`` and azimuth ``phi_deg``; pixel ``(i, j)`` holds
        ``exposure · A(ωi, ωo) · XYZ(−(ωi + ωo))`` (eq. 5) for its view direction, 0 outside the disc.
        ``ior`` is the Fresnel refractive index (``None`` or 0: no Fresnel). ``skip_threshold``,
        ``statistics``, ``rows`` and ``progress``: see :meth:`render_brdf_slice_layers` (default: no skipping,
        exact linear values, every row).
        """
        return self.render_brdf_slice_layers(theta_deg, phi_deg, size, exposure, ior, skip_threshold,
                                             statistics, rows, progress)[0]

    def render_brdf_slice_srgb8(
        self, theta_deg: float, phi_deg: float, size: int, exposure: float = 1.0, ior: float | None = 1.5,
        skip_threshold: float | None = None, statistics: dict[str, int] | None = None,
    ) -> np.ndarray:
        """8-bit display sRGB ``(size, size, 3)`` of a BRDF slice (``gratnet.display``)."""
        xyz = self.render_brdf_slice(theta_deg, phi_deg, size, exposure, ior, skip_threshold, statistics)
        return xyz_to_display_srgb8(np.asarray(xyz, dtype=np.float64), 1.0)

    # ---------------------------------------------------------------------------------------------

    def __enter__(self: ShadingT) -> ShadingT:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.release()

    def release(self) -> None:
        """Free the GL objects (subclasses add their textures)."""
        self.release_programs()

    def release_programs(self) -> None:
        """Free the programs, their vertex arrays and the counters (subclasses free their own textures)."""
        for vertex_array in self.vertex_arrays.values():
            vertex_array.release()
        for program in self.compiled.values():
            program.release()
        if self._counters is not None:
            self._counters.release()
            self._counters = None
        self.vertex_arrays.clear()
        self.compiled.clear()
