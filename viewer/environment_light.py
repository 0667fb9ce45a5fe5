"""Sampled light on the GPU (issue 43): an environment map, its luminance distribution and the material's
importance table as textures, area lights as uniforms: shaders/environment.glsl and shaders/area_lights.glsl.

:class:`EnvironmentLighting` holds an optional :class:`gratnet.environment.Environment`, any area lights
(:class:`gratnet.area_lights.AreaLight`) and one :class:`gratnet.importance.MaterialTable` on a context. The forward
path (viewer.forward) compiles its surface program with ``ENVIRONMENT`` when a render has sampled light, calls
:meth:`EnvironmentLighting.set_uniforms` once and :meth:`EnvironmentLighting.set_pass` before each pass (sample) k,
and binds :meth:`EnvironmentLighting.textures` with the material's; the deferred path (viewer.deferred) does the
same for its G-buffer pass and applies the tint after its compute pass. The estimator (one sample per pixel and pass,
MIS between each emitter's own sampling and the material's, the delta light in turn) is shaders/environment.glsl's;
docs/physics.md "Environment light" and "Area lights" are its contract.

Rendering only: no glfw, no imgui, no torch.
"""

from __future__ import annotations

import dataclasses
import math

import moderngl
import numpy as np

from gratnet.area_lights import MAX_AREA_LIGHTS, AreaLight
from gratnet.codes import DEFAULT_ENVIRONMENT_SAMPLING, ENVIRONMENT_SAMPLING
from gratnet.environment import Environment
from gratnet.errors import GratNetError
from gratnet.importance import (
    COLOUR_SLICES,
    DEFENSIVE_SHARE,
    RESAMPLING_CANDIDATES,
    RESAMPLING_MATERIAL_CANDIDATES,
    MaterialTable,
)
from gratnet.sampling2d import PiecewiseConstant2D
from viewer.shading import MaterialTexture, set_uniform
from viewer.srgb import XYZ_TO_LINEAR_SRGB, linear_srgb

__all__ = ["ENVIRONMENT_DEFINES", "ENVIRONMENT_UNITS", "EnvironmentLighting", "EnvironmentPass", "MAX_SEED",
           "check_seed"]

#: The define that compiles shaders/environment.glsl into the surface program.
ENVIRONMENT_DEFINES = {"ENVIRONMENT": 1}
#: Texture units of the map, its distribution, the material's table and its colour table (the control variate's), in
#: the order the textures are made: units no other program of a mesh render takes (0 weights, 1–2 passes' inputs,
#: 3 skip bound, 6 reference volume, 8… grid levels; the colour table's 47 lies above any model's grid units, within
#: GL 4.3's 96 combined units).
ENVIRONMENT_UNITS = {"u_environment": 4, "u_environment_table": 5, "u_material_table": 7, "u_material_colour": 47}
#: Seeds are 32-bit unsigned integers in the shader.
MAX_SEED = 2**32 - 1


def check_seed(seed: object) -> int:
    """``seed`` as an int in 0 … :data:`MAX_SEED`, else GratNetError."""
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or not 0 <= seed <= MAX_SEED:
        raise GratNetError(f"the seed must be an integer in 0…{MAX_SEED}, got {seed!r}")
    return int(seed)


def _colour_texture(ctx: moderngl.Context, colour: np.ndarray | None) -> moderngl.Texture:
    """The control variate's colour table (gratnet.importance.MaterialTable.colour) in linear sRGB, its w slices
    stacked in rows (slice j: rows j·R … (j + 1)·R − 1); a 1 × 1 placeholder for a table without one."""
    if colour is None:
        rgb = np.zeros((1, 1, 3), np.float32)
    else:
        slices, rows, columns, _ = colour.shape
        rgb = linear_srgb(colour).astype(np.float32).reshape(slices * rows, columns, 3)
    texture = ctx.texture((rgb.shape[1], rgb.shape[0]), 3, np.ascontiguousarray(rgb).tobytes(), dtype="f4")
    texture.filter = moderngl.NEAREST, moderngl.NEAREST
    return texture


def _table_texture(ctx: moderngl.Context, distribution: PiecewiseConstant2D) -> moderngl.Texture:
    packed = np.ascontiguousarray(distribution.packed())
    texture = ctx.texture((packed.shape[1], packed.shape[0]), 1, packed.tobytes(), dtype="f4")
    texture.filter = moderngl.NEAREST, moderngl.NEAREST
    return texture


class EnvironmentLighting:
    """An environment and a material's importance table on ``ctx`` (see the module docstring); release when done.

    Args:
        ctx: the render's context.
        environment: the map (its rotation and scale applied here as in gratnet.environment), or None: area lights
            only (1 × 1 placeholder textures on the map's units, never read).
        table: the material's importance table (gratnet.importance), built for this material.
        area_lights: up to :data:`gratnet.area_lights.MAX_AREA_LIGHTS` area lights.
    """

    def __init__(self, ctx: moderngl.Context, environment: Environment | None, table: MaterialTable,
                 area_lights: tuple[AreaLight, ...] = ()) -> None:
        if environment is None and not area_lights:
            raise GratNetError("sampled light needs an environment or an area light")
        if len(area_lights) > MAX_AREA_LIGHTS:
            raise GratNetError(f"a render takes at most {MAX_AREA_LIGHTS} area lights, got {len(area_lights)}")
        self.environment = environment
        self.area_lights = tuple(area_lights)
        self.table = table
        self.cells = (1, 1)
        self._textures: list[moderngl.Texture] = []
        try:
            if environment is not None:
                radiance = np.ascontiguousarray(environment.radiance_map * np.float32(environment.scale),
                                                dtype=np.float32)
                distribution = environment.distribution()
                rows, columns = distribution.shape
                self.cells = columns, rows  # (W, H − 1): cells between the map's rows (gratnet.environment)
                height, width = radiance.shape[:2]
                map_texture = ctx.texture((width, height), 3, radiance.tobytes(), dtype="f4")
                map_texture.filter = moderngl.NEAREST, moderngl.NEAREST  # texelFetch: bilinear by hand, as Mitsuba
                self._textures.append(map_texture)
                self._textures.append(_table_texture(ctx, distribution))
            else:
                for components in (3, 1):
                    placeholder = ctx.texture((1, 1), components, np.zeros(components, np.float32).tobytes(),
                                              dtype="f4")
                    placeholder.filter = moderngl.NEAREST, moderngl.NEAREST
                    self._textures.append(placeholder)
            self._textures.append(_table_texture(ctx, table.distribution))
            self._textures.append(_colour_texture(ctx, table.colour))
        except BaseException:
            self.release()
            raise

    def matches(self, environment: Environment | None, area_lights: tuple[AreaLight, ...]) -> bool:
        """Whether this holds ``environment`` (the same object) and ``area_lights`` (equal)."""
        return self.environment is environment and self.area_lights == tuple(area_lights)

    def textures(self) -> tuple[tuple[MaterialTexture, int], ...]:
        """``(texture, unit)`` pairs to bind before a draw."""
        return tuple(zip(self._textures, ENVIRONMENT_UNITS.values(), strict=True))

    def set_uniforms(self, program: moderngl.Program, delta_light: bool, seed: int,
                     sampling: str = DEFAULT_ENVIRONMENT_SAMPLING, tinted: bool = True) -> None:
        """The uniforms of shaders/environment.glsl but the pass index: ``delta_light``: the light of lights.glsl
        takes its turn too; ``sampling``: :data:`gratnet.codes.ENVIRONMENT_SAMPLING`; ``tinted``: the program
        applies the tint (False: the deferred path's G-buffer, whose compiler drops the colour matrices; its TINT
        kernel takes them, :meth:`set_colour_uniforms`)."""
        set_uniform(program, ENVIRONMENT_SAMPLING.uniform_name, ENVIRONMENT_SAMPLING.code(sampling))
        set_uniform(program, "u_delta_light", bool(delta_light))
        for name, unit in ENVIRONMENT_UNITS.items():
            set_uniform(program, name, unit)
        rows, columns = self.table.distribution.shape
        angle = math.radians(self.environment.rotation_degrees if self.environment is not None else 0.0)
        set_uniform(program, "u_has_environment", self.environment is not None)
        _set_area_uniforms(program, self.area_lights)
        set_uniform(program, "u_environment_cells", self.cells)
        set_uniform(program, "u_material_cells", (columns, rows))
        set_uniform(program, "u_environment_rotation", (math.cos(angle), math.sin(angle)))
        set_uniform(program, "u_material_key_range", (float(self.table.key_min), float(self.table.key_max)))
        set_uniform(program, "u_defensive_share", float(DEFENSIVE_SHARE))
        set_uniform(program, "u_candidates", RESAMPLING_CANDIDATES)
        set_uniform(program, "u_material_candidates", RESAMPLING_MATERIAL_CANDIDATES)
        set_uniform(program, "u_control_variate", self.table.colour is not None)
        set_uniform(program, "u_colour_slices", COLOUR_SLICES)
        set_uniform(program, "u_seed", check_seed(seed))
        if tinted:
            self.set_colour_uniforms(program)

    @staticmethod
    def set_colour_uniforms(program: moderngl.Program | moderngl.ComputeShader) -> None:
        """The tint's matrices ``u_xyz_to_rgb`` and ``u_rgb_to_xyz`` (shaders/tint.glsl, which environment.glsl and
        deferred.glsl's TINT include)."""
        to_rgb = XYZ_TO_LINEAR_SRGB  # colour-science's matrix, without importing it (viewer.srgb)
        # GLSL mat3 uniforms are column-major: the transpose of the row-major numpy matrix.
        set_uniform(program, "u_xyz_to_rgb", np.ascontiguousarray(to_rgb.T, dtype=np.float32))
        set_uniform(program, "u_rgb_to_xyz", np.ascontiguousarray(np.linalg.inv(to_rgb).T, dtype=np.float32))

    @staticmethod
    def set_pass(program: moderngl.Program, index: int, pixel_origin: tuple[int, int] = (0, 0)) -> None:
        """The pass (sample) index k of the next draw, and the render target's lower-left pixel in the whole
        picture (GL pixels, y up: a band of rows drawn alone keys its random numbers as the whole picture would)."""
        set_uniform(program, "u_sample_index", int(index))
        set_uniform(program, "u_pixel_origin", (int(pixel_origin[0]), int(pixel_origin[1])))

    def bind(self) -> None:
        """Bind the textures to their units."""
        for texture, unit in self.textures():
            texture.use(location=unit)

    def release(self) -> None:
        for texture in self._textures:
            texture.release()
        self._textures.clear()


def _set_area_uniforms(program: moderngl.Program, lights: tuple[AreaLight, ...]) -> None:
    """shaders/area_lights.glsl's uniforms: the count and the arrays (unused entries zero)."""
    set_uniform(program, "u_area_count", len(lights))
    if not lights:
        return  # the arrays are never read: a compiler may have dropped them
    kinds = np.zeros(MAX_AREA_LIGHTS, np.int32)
    vectors = {name: np.zeros((MAX_AREA_LIGHTS, 3), np.float32) for name in
               ("u_area_centre", "u_area_axis_u", "u_area_axis_v", "u_area_radiance")}
    for index, light in enumerate(lights):
        kinds[index] = light.code
        for name, value in zip(vectors, (light.centre, light.axis_u, light.axis_v, light.radiance), strict=True):
            vectors[name][index] = value
    set_uniform(program, "u_area_kind", kinds)
    for name, values in vectors.items():
        set_uniform(program, name, values)


@dataclasses.dataclass(frozen=True)
class EnvironmentPass:
    """What a render (either path) needs of an environment: the textures, whether the delta light takes its turn,
    the seed of the random numbers, the sampling (:data:`gratnet.codes.ENVIRONMENT_SAMPLING`) and where the render
    target lies in the whole picture (``pixel_origin``: GL pixels of its lower-left corner; a band of a larger
    picture)."""

    lighting: EnvironmentLighting
    delta_light: bool
    seed: int = 0
    sampling: str = DEFAULT_ENVIRONMENT_SAMPLING
    pixel_origin: tuple[int, int] = (0, 0)

    def __post_init__(self) -> None:
        check_seed(self.seed)
        ENVIRONMENT_SAMPLING.code(self.sampling)  # a one-line error for another name
