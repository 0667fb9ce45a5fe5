"""Area lights (issue 43): the kinds of light with an extent, in one registry, and what they mean.

An area light emits a constant radiance (W m⁻² sr⁻¹, linear sRGB, as an environment's texels) from a surface in
the world (metres). It is given on the command line as ``--area-light KIND:NUMBERS`` (repeatable: several at
once), parsed by :func:`parse_area_light`:

- ``rect:X,Y,Z,NX,NY,NZ,W,H,L`` (or ``…,R,G,B``): a rectangle centred at (X, Y, Z), facing (NX, NY, NZ) (it emits
  on that side only, as Mitsuba's ``rectangle`` with an ``area`` emitter), W × H metres, radiance L (white) or
  R, G, B. Its width runs along ẑ × n normalised (x̂ when n is ±ẑ), its height along n × width;
- ``sphere:X,Y,Z,R,L`` (or ``…,R,G,B``): a sphere of radius R metres centred at (X, Y, Z), emitting outwards from
  every point (Mitsuba's ``sphere`` with an ``area`` emitter).

Every light is held as one :class:`AreaLight`: its kind, centre, two half-extent axes and radiance, the numbers
the shaders receive (shaders/area_lights.glsl, uniforms ``u_area_*``; the kind's code ``AREA_<NAME>`` comes from
:data:`AREA_KINDS` through :mod:`gratnet.codes`). The renderers sample a light by solid angle (a rectangle by
area, converted; a sphere by the cone it subtends) and weigh those samples against the material's own by
multiple importance sampling (shaders/environment.glsl; docs/physics.md "Area lights"). The numpy functions here
(:func:`radiance_towards`, :func:`solid_angle_pdf`) are the CPU twins of the GLSL, used by the tests' quadrature.
Lights neither shadow the surface nor each other (no visibility in the GL runtime), and a camera ray does not see
them (the background stays black, as under an environment).

Adding a kind: an :class:`AreaKind` at the end of :data:`AREA_KINDS` (its parser, its numpy radiance and pdf, its
Mitsuba shape) and its branches ``u_area_kind[i] == AREA_<NAME>`` in shaders/area_lights.glsl.

Standard library at import (numpy when a function runs): the flag declarations import this module.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Sequence
from typing import Any

from gratnet.config import parse_numbers
from gratnet.errors import GratNetError
from gratnet.lights import DISTANCE_RANGE_METRES, kind_named

__all__ = ["AREA_FLAG", "AREA_HELP", "AREA_KINDS", "MAX_AREA_LIGHTS", "RECTANGLE", "SPHERE", "AreaKind", "AreaLight",
           "area_kind", "parse_area_light", "parse_area_lights", "radiance_towards", "solid_angle_pdf"]

#: The flag, the same in every command that takes area lights.
AREA_FLAG = "--area-light"
#: How many area lights one render takes (the shaders' uniform arrays).
MAX_AREA_LIGHTS = 8
#: The largest radiance the float32 estimator handles (W m⁻² sr⁻¹): a sample divides it by densities down to ~1e-8.
MAX_RADIANCE = 1e30

Vector = tuple[float, float, float]


@dataclasses.dataclass(frozen=True)
class AreaLight:
    """One area light (world space, metres).

    Attributes:
        kind: its :class:`AreaKind`'s name.
        centre: the centre, metres.
        axis_u, axis_v: a rectangle's half extents (the vectors from its centre to the middles of its edges,
            metres; ``axis_u × axis_v`` is its emitting normal); a sphere's ``axis_u`` is (radius, 0, 0), its
            ``axis_v`` (0, 0, 0).
        radiance: emitted radiance, W m⁻² sr⁻¹, linear sRGB.
    """

    kind: str
    centre: Vector
    axis_u: Vector
    axis_v: Vector
    radiance: Vector

    @property
    def code(self) -> int:
        """``u_area_kind[i]``: the kind's place in :data:`AREA_KINDS` (GLSL ``AREA_<NAME>``)."""
        return AREA_KINDS.index(area_kind(self.kind))

    def mitsuba(self, mi: Any) -> dict[str, Any]:
        """The Mitsuba 3 shape with an ``area`` emitter that is this light (``mi``: the mitsuba module, a variant
        set)."""
        return area_kind(self.kind).mitsuba(self, mi)

    def text(self) -> str:
        """The flag value that gives this light back (a saved config's form)."""
        return area_kind(self.kind).text(self)


@dataclasses.dataclass(frozen=True)
class AreaKind:
    """One kind of area light (see the module docstring).

    Attributes:
        name: the flag's ``KIND:`` and :attr:`AreaLight.kind`; its GLSL code is ``AREA_<NAME>``.
        form: the numbers after ``KIND:``, for messages and help.
        parse: the numbers (checked: finite, counted) → the light, or a one-line GratNetError.
        counts: how many numbers the flag takes.
        radiance: ``(light, points (N, 3), directions (N, 3))`` → the radiance each ray meets (N, 3), 0 where it
            misses the light or meets its back.
        pdf: ``(light, points, directions)`` → the solid-angle density (sr⁻¹) of the light's sampling strategy.
        mitsuba: ``(light, mi)`` → the Mitsuba shape dict.
        text: the light → its flag value.
    """

    name: str
    form: str
    counts: tuple[int, ...]
    parse: Callable[[Sequence[float]], AreaLight]
    radiance: Callable[[AreaLight, Any, Any], Any]
    pdf: Callable[[AreaLight, Any, Any], Any]
    mitsuba: Callable[[AreaLight, Any], dict[str, Any]]
    text: Callable[[AreaLight], str]

    @property
    def code(self) -> int:
        return AREA_KINDS.index(self)


def _radiance_of(values: Sequence[float], what: str) -> Vector:
    if len(values) == 1:
        values = (values[0],) * 3
    if any(value < 0 for value in values) or max(values) > MAX_RADIANCE:
        raise GratNetError(f"{AREA_FLAG} {what}: radiance must lie in 0 … {MAX_RADIANCE:g} W/m²/sr, got "
                           f"{', '.join(f'{value:g}' for value in values)}")
    if max(values) == 0:
        raise GratNetError(f"{AREA_FLAG} {what}: the radiance is zero (it would light nothing)")
    r, g, b = (float(value) for value in values)
    return r, g, b


def _centre_of(values: Sequence[float], what: str) -> Vector:
    high = DISTANCE_RANGE_METRES[1]
    if max(abs(value) for value in values) > high:
        raise GratNetError(f"{AREA_FLAG} {what}: the centre must lie within ±{high:g} metres, got "
                           f"{', '.join(f'{value:g}' for value in values)}")
    x, y, z = (float(value) for value in values)
    return x, y, z


def _check_size(size: float, name: str, what: str) -> None:
    low, high = DISTANCE_RANGE_METRES
    if not low <= size <= high:
        raise GratNetError(f"{AREA_FLAG} {what}: the {name} must be from {low:g} to {high:g} metres, got {size:g}")


# ----------------------------------------------------------------------------------------------
# Rectangle: sampled uniformly by area, its density converted to solid angle (d² / (A cos θ_light))


def _rectangle_frame(normal: Any) -> tuple[Any, Any, Any]:
    """(width axis, height axis, unit normal) of a rectangle facing ``normal``: width along ẑ × n (x̂ for n = ±ẑ),
    height along n × width, so that width × height = n (Mitsuba's rectangle faces +z of its frame)."""
    import numpy as np

    n = np.asarray(normal, dtype=np.float64)
    n = n / np.linalg.norm(n)
    width = np.cross((0.0, 0.0, 1.0), n)
    if np.linalg.norm(width) < 1e-6:
        width = np.array([1.0, 0.0, 0.0])
    width = width / np.linalg.norm(width)
    return width, np.cross(n, width), n


def _parse_rectangle(values: Sequence[float]) -> AreaLight:
    import numpy as np

    what = "rect"
    centre = _centre_of(values[:3], what)
    normal = values[3:6]
    if max(abs(value) for value in normal) == 0 or not math.isfinite(math.hypot(*normal)):
        raise GratNetError(f"{AREA_FLAG} {what}: the normal NX,NY,NZ must be a non-zero vector, got "
                           f"{', '.join(f'{value:g}' for value in normal)}")
    width, height = values[6], values[7]
    _check_size(width, "width", what)
    _check_size(height, "height", what)
    radiance = _radiance_of(values[8:], what)
    largest = max(abs(value) for value in normal)
    axis_w, axis_h, _ = _rectangle_frame(np.asarray(normal) / largest)
    u = tuple(float(c) for c in axis_w * (width / 2))
    v = tuple(float(c) for c in axis_h * (height / 2))
    return AreaLight("rect", centre, (u[0], u[1], u[2]), (v[0], v[1], v[2]), radiance)


def _rectangle_geometry(light: AreaLight) -> tuple[Any, Any, Any, Any, float]:
    import numpy as np

    centre = np.asarray(light.centre, dtype=np.float64)
    u = np.asarray(light.axis_u, dtype=np.float64)
    v = np.asarray(light.axis_v, dtype=np.float64)
    normal = np.cross(u, v)
    area = 4.0 * float(np.linalg.norm(normal))
    return centre, u, v, normal / np.linalg.norm(normal), area


def _rectangle_hit(light: AreaLight, points: Any, directions: Any) -> tuple[Any, Any, Any]:
    """(hit mask, distance, cos θ at the light) of rays from ``points`` along unit ``directions``: the front only."""
    import numpy as np

    centre, u, v, normal, _ = _rectangle_geometry(light)
    facing = -(directions @ normal)  # cos θ at the light: > 0 when the ray meets its emitting side
    with np.errstate(divide="ignore", invalid="ignore"):
        distance = ((points - centre) @ normal) / facing
    hit_point = points + directions * distance[:, None]
    offset = hit_point - centre
    inside = (np.abs(offset @ u) <= u @ u) & (np.abs(offset @ v) <= v @ v)
    hit = (facing > 0) & (distance > 0) & inside
    return hit, distance, facing


def _rectangle_radiance(light: AreaLight, points: Any, directions: Any) -> Any:
    import numpy as np

    hit, _, _ = _rectangle_hit(light, np.asarray(points, np.float64), np.asarray(directions, np.float64))
    return hit[:, None] * np.asarray(light.radiance)[None, :]


def _rectangle_pdf(light: AreaLight, points: Any, directions: Any) -> Any:
    import numpy as np

    hit, distance, facing = _rectangle_hit(light, np.asarray(points, np.float64), np.asarray(directions, np.float64))
    area = _rectangle_geometry(light)[4]
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(hit, distance * distance / (area * facing), 0.0)


def _rectangle_mitsuba(light: AreaLight, mi: Any) -> dict[str, Any]:
    import numpy as np

    centre, u, v, normal, _ = _rectangle_geometry(light)
    matrix = np.eye(4)
    matrix[:3, 0], matrix[:3, 1], matrix[:3, 2], matrix[:3, 3] = u, v, normal, centre  # [-1, 1]² at z = 0, +z out
    return {"type": "rectangle", "to_world": mi.ScalarTransform4f(matrix.tolist()),
            "emitter": {"type": "area", "radiance": {"type": "rgb", "value": list(light.radiance)}}}


def _rectangle_text(light: AreaLight) -> str:
    import numpy as np

    _, u, v, normal, _ = _rectangle_geometry(light)
    numbers = [*light.centre, *normal, 2 * float(np.linalg.norm(u)), 2 * float(np.linalg.norm(v)), *light.radiance]
    return "rect:" + ",".join(f"{float(n):.9g}" for n in numbers)


RECTANGLE = AreaKind("rect", "rect:X,Y,Z,NX,NY,NZ,W,H,L (or …,R,G,B): centre and facing normal (m), width and "
                     "height (m), radiance (W/m²/sr, linear sRGB)", (9, 11), _parse_rectangle, _rectangle_radiance,
                     _rectangle_pdf, _rectangle_mitsuba, _rectangle_text)


# ----------------------------------------------------------------------------------------------
# Sphere: sampled uniformly in the cone it subtends (density 1 / (2π (1 − cos θ_max)))


def _parse_sphere(values: Sequence[float]) -> AreaLight:
    what = "sphere"
    centre = _centre_of(values[:3], what)
    _check_size(values[3], "radius", what)
    radiance = _radiance_of(values[4:], what)
    return AreaLight("sphere", centre, (float(values[3]), 0.0, 0.0), (0.0, 0.0, 0.0), radiance)


def _sphere_cone(light: AreaLight, points: Any, directions: Any) -> tuple[Any, Any]:
    """(hit mask, 1 − cos θ_max) of rays from points outside the sphere (a point inside sees no light: mask False)."""
    import numpy as np

    radius = light.axis_u[0]
    offset = np.asarray(light.centre, np.float64)[None, :] - points
    distance_squared = np.einsum("ij,ij->i", offset, offset)
    outside = distance_squared > radius * radius
    with np.errstate(divide="ignore", invalid="ignore"):
        sine_squared = radius * radius / distance_squared
        cap = sine_squared / (1.0 + np.sqrt(np.maximum(1.0 - sine_squared, 0.0)))  # 1 − cos θ_max, no cancellation
    across = np.cross(offset, directions)
    ahead = np.einsum("ij,ij->i", offset, directions) > 0
    return outside & ahead & (np.einsum("ij,ij->i", across, across) <= radius * radius), cap


def _sphere_radiance(light: AreaLight, points: Any, directions: Any) -> Any:
    import numpy as np

    hit, _ = _sphere_cone(light, np.asarray(points, np.float64), np.asarray(directions, np.float64))
    return hit[:, None] * np.asarray(light.radiance)[None, :]


def _sphere_pdf(light: AreaLight, points: Any, directions: Any) -> Any:
    import numpy as np

    hit, cap = _sphere_cone(light, np.asarray(points, np.float64), np.asarray(directions, np.float64))
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(hit, 1.0 / (2.0 * math.pi * cap), 0.0)


def _sphere_mitsuba(light: AreaLight, mi: Any) -> dict[str, Any]:
    return {"type": "sphere", "center": list(light.centre), "radius": float(light.axis_u[0]),
            "emitter": {"type": "area", "radiance": {"type": "rgb", "value": list(light.radiance)}}}


def _sphere_text(light: AreaLight) -> str:
    numbers = [*light.centre, light.axis_u[0], *light.radiance]
    return "sphere:" + ",".join(f"{float(n):.9g}" for n in numbers)


SPHERE = AreaKind("sphere", "sphere:X,Y,Z,R,L (or …,R,G,B): centre and radius (m), radiance (W/m²/sr, linear sRGB)",
                  (5, 7), _parse_sphere, _sphere_radiance, _sphere_pdf, _sphere_mitsuba, _sphere_text)

#: Every kind, in code order.
AREA_KINDS: tuple[AreaKind, ...] = (RECTANGLE, SPHERE)

#: ``--area-light``'s help, the same in every command that takes it.
AREA_HELP = (f"an area light, repeatable (up to {MAX_AREA_LIGHTS}): "
             + "; ".join(kind.form for kind in AREA_KINDS)
             + ". Sampled by solid angle and weighed against the material's own sampling (MIS); rendered with "
             "--spp passes like --environment; lights cast no shadows and are not seen by the camera "
             "(docs/physics.md \"Area lights\")")


def area_kind(name: object) -> AreaKind:
    """The kind called ``name``, or a one-line GratNetError."""
    return kind_named(AREA_KINDS, name, f"{AREA_FLAG} kind")


def parse_area_light(text: str) -> AreaLight:
    """``KIND:NUMBERS`` (see the module docstring) → the light, or a one-line GratNetError naming the flag."""
    name, separator, numbers = str(text).partition(":")
    if not separator:
        forms = "; ".join(kind.form for kind in AREA_KINDS)
        raise GratNetError(f"{AREA_FLAG} expects KIND:NUMBERS ({forms}), got {text!r}")
    kind = area_kind(name.strip())
    values = parse_numbers(numbers, kind.counts, f"{AREA_FLAG} {kind.name}", kind.form)
    return kind.parse(values)


def parse_area_lights(texts: Sequence[str] | None) -> tuple[AreaLight, ...]:
    """Every ``--area-light`` value parsed, at most :data:`MAX_AREA_LIGHTS`."""
    texts = tuple(texts or ())
    if len(texts) > MAX_AREA_LIGHTS:
        raise GratNetError(f"{AREA_FLAG} is given {len(texts)} times; a render takes at most {MAX_AREA_LIGHTS}")
    return tuple(parse_area_light(text) for text in texts)


def radiance_towards(lights: Sequence[AreaLight], points: Any, directions: Any) -> Any:
    """The radiance (N, 3; W m⁻² sr⁻¹, linear sRGB) that rays from ``points`` along unit ``directions`` (world, N × 3)
    meet, summed over ``lights`` (no light hides another: as the shaders)."""
    import numpy as np

    points = np.atleast_2d(np.asarray(points, np.float64))
    directions = np.atleast_2d(np.asarray(directions, np.float64))
    points = np.broadcast_to(points, directions.shape)
    total = np.zeros(directions.shape, dtype=np.float64)
    for light in lights:
        total += area_kind(light.kind).radiance(light, points, directions)
    return total


def solid_angle_pdf(light: AreaLight, points: Any, directions: Any) -> Any:
    """The solid-angle density (sr⁻¹) with which the shaders' light sampling of ``light`` draws ``directions`` from
    ``points`` (0 where the ray misses it)."""
    import numpy as np

    points = np.atleast_2d(np.asarray(points, np.float64))
    directions = np.atleast_2d(np.asarray(directions, np.float64))
    return area_kind(light.kind).pdf(light, np.broadcast_to(points, directions.shape), directions)
