"""The kinds of light, in one registry (issue 45): what each kind's numbers mean, how its light reaches a surface
point, its Mitsuba emitter and the flag that chooses it.

A light (:class:`viewer.camera.Light`) is a kind, a vector and an intensity. The shaders receive them as uniforms
(:meth:`LightKind.uniforms`: ``u_light_kind``, ``u_light``, ``u_light_intensity``) and ``light_incidence`` in
shaders/lights.glsl turns them into the world direction towards the light and the irradiance at a surface point,
one branch per kind, on the codes ``LIGHT_<NAME>`` that :mod:`gratnet.codes` generates from this registry (a
kind's code is its place in :data:`LIGHT_KINDS`). The readers:

- ``viewer.camera.Light``: its checks (:attr:`LightKind.prepare`) and the CPU twin of lights.glsl
  (:attr:`LightKind.incidence`);
- ``viewer.surface``: the uniforms;
- ``viewer.scene_config``: the flags that choose a kind other than the default (:class:`LightFlag`: ``--point-light``),
  their checks and the default exposure they scale; :func:`chosen_kind` reads a scene config;
- ``mitsuba_plugin.scene``: the emitter (:attr:`LightKind.mitsuba`).

The default kind, :data:`DIRECTIONAL`, is the one ``--light θ,φ`` sets (viewer.scene_config, viewer.defaults and
the viewer's sliders hold its angles).

Adding a kind: a :class:`LightKind` at the end of :data:`LIGHT_KINDS` (its functions beside it) and its branch
``u_light_kind == LIGHT_<NAME>`` in shaders/lights.glsl (with any uniform of its own, set by its
:attr:`LightKind.uniforms`). A kind chosen by a flag also names the ``SceneConfig`` field that saves the flag's
values (:attr:`LightFlag.field`; tests/contract/test_shared_codes.py checks that the field exists).

Standard library at import (numpy when a function runs): the flag declarations import this module.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Sequence
from typing import Any, Protocol, TypeVar

from gratnet.errors import GratNetError

__all__ = ["DIRECTIONAL", "DISTANCE_RANGE_METRES", "LIGHT_KINDS", "POINT", "LightFlag", "LightKind", "chosen_kind",
           "kind_named", "light_kind"]

#: The distances (metres) the float32 shaders handle: camera distances and light positions (beyond them 1/d²
#: and the view matrices overflow or lose every digit).
DISTANCE_RANGE_METRES = (1e-6, 1e6)

Vector = tuple[float, float, float]


@dataclasses.dataclass(frozen=True)
class LightFlag:
    """The command-line flag that chooses a kind in place of the default (``gratnet render``, ``mitsuba-render``).

    Attributes:
        flag: its name (``--point-light``); ``dest``: its argparse destination (the text as given).
        field: the ``SceneConfig`` field that holds its values (``None`` there: the flag was not given).
        metavar, count, form: the values' form (``X,Y,Z``), how many numbers, and how a message describes them.
        check: refuses (one-line GratNetError, naming ``flag``) values the shaders cannot use.
        exposure_scale: the factor on the default exposure (found for a unit directional light) that the
            flag's values call for, or ``None`` for 1.
    """

    flag: str
    dest: str
    field: str
    metavar: str
    count: int
    form: str
    check: Callable[[Sequence[float], str], None]
    exposure_scale: Callable[[Sequence[float]], float | None]


@dataclasses.dataclass(frozen=True)
class LightKind:
    """One kind of light (see the module docstring).

    Attributes:
        name: ``Light.kind``, as configs and messages spell it; its GLSL code is ``LIGHT_<NAME>``.
        vector, intensity: what ``Light.vector`` (``u_light``) and ``Light.intensity`` (``u_light_intensity``) mean.
        prepare: the checked vector (one-line GratNetError), e.g. made unit length.
        incidence: ``(vector, intensity, point)`` → (unit world direction from ``point`` towards the light,
            irradiance there): what shaders/lights.glsl computes, in float64.
        mitsuba: ``(vector, rgb)`` → the Mitsuba emitter's ``load_dict`` entry, ``rgb`` its white scaled by the
            intensity.
        flag: the flag that chooses the kind, ``None`` for the default kind.
    """

    name: str
    vector: str
    intensity: str
    prepare: Callable[[Vector], Vector]
    incidence: Callable[[Vector, float, Any], tuple[Any, float]]
    mitsuba: Callable[[Vector, dict[str, Any]], dict[str, Any]]
    flag: LightFlag | None = None

    @property
    def code(self) -> int:
        """``u_light_kind``'s value: the kind's place in :data:`LIGHT_KINDS` (GLSL ``LIGHT_<NAME>``)."""
        return LIGHT_KINDS.index(self)

    def uniforms(self, vector: Vector, intensity: float) -> dict[str, Any]:
        """The uniforms of shaders/lights.glsl for a light of this kind."""
        return {"u_light_kind": self.code, "u_light": tuple(float(c) for c in vector),
                "u_light_intensity": float(intensity)}


# ----------------------------------------------------------------------------------------------
# Directional: a direction towards the light, irradiance independent of the point


def _unit(vector: Vector) -> Vector:
    import numpy as np

    values = np.asarray(vector, dtype=np.float64)
    largest = float(np.max(np.abs(values)))
    if largest == 0.0:
        raise GratNetError("a directional light needs a non-zero direction")
    values = values / largest  # first: |v| of (1e308, 1e308, 0) overflows, of denormals loses digits
    values = values / float(np.linalg.norm(values))
    x, y, z = (float(c) for c in values)
    return x, y, z


def _directional_incidence(vector: Vector, intensity: float, point: Any) -> tuple[Any, float]:
    import numpy as np

    return np.asarray(vector), intensity


DIRECTIONAL = LightKind(
    "directional", vector="the unit direction towards the light (world)",
    intensity="the irradiance on a plane facing the light", prepare=_unit, incidence=_directional_incidence,
    mitsuba=lambda vector, rgb: {"type": "directional", "direction": [-float(c) for c in vector], "irradiance": rgb})


# ----------------------------------------------------------------------------------------------
# Point: a position, irradiance falling off as 1/d²


def _point_incidence(vector: Vector, intensity: float, point: Any) -> tuple[Any, float]:
    import numpy as np

    offset = np.asarray(vector) - np.asarray(point, dtype=np.float64)
    distance_squared = float(np.dot(offset, offset))
    if distance_squared == 0.0:
        return np.zeros(3), 0.0
    return offset / math.sqrt(distance_squared), intensity / distance_squared


def _check_position(position: Sequence[float], flag: str) -> None:
    low, high = DISTANCE_RANGE_METRES
    if max(abs(value) for value in position) > high:
        raise GratNetError(f"{flag} coordinates must lie within ±{high:g} metres, got {position}")
    if math.hypot(*position) < low:
        raise GratNetError(f"{flag} must be at least {low:g} m from the origin, got {position}")


def _distance_squared(position: Sequence[float]) -> float | None:
    """|position|² (m²): the irradiance at the origin is 1/|position|² of a unit directional light's."""
    squared = sum(x * x for x in position)
    if not (math.isfinite(squared) and squared > 0):
        return None
    return float(f"{squared:.3g}")  # as the defaults are rounded (viewer.defaults)


POINT = LightKind(
    "point", vector="the light's position (metres, world)",
    intensity="the irradiance at 1 m (W/sr: it falls off as 1/d²)", prepare=lambda vector: vector,
    incidence=_point_incidence,
    mitsuba=lambda vector, rgb: {"type": "point", "position": [float(c) for c in vector], "intensity": rgb},
    flag=LightFlag("--point-light", "point_light_text", "point_light", "X,Y,Z", 3, "X,Y,Z in metres such as 0,0.1,0.2",
                   _check_position, _distance_squared))

#: Every kind, in code order; the first is the default (``--light θ,φ``).
LIGHT_KINDS: tuple[LightKind, ...] = (DIRECTIONAL, POINT)


KindT = TypeVar("KindT", bound="_Named")


class _Named(Protocol):
    @property
    def name(self) -> str: ...


def kind_named(kinds: Sequence[KindT], name: object, what: str) -> KindT:
    """The entry of a registry of kinds (this module's, gratnet.area_lights') called ``name``, or a one-line
    GratNetError that says ``what`` must be one of them."""
    for kind in kinds:
        if kind.name == name:
            return kind
    names = [kind.name for kind in kinds]
    raise GratNetError(f"{what} must be {', '.join(names[:-1])} or {names[-1]}, got {name!r}")


def light_kind(name: object) -> LightKind:
    """The kind called ``name``, or a one-line GratNetError."""
    return kind_named(LIGHT_KINDS, name, "light kind")


def chosen_kind(config: Any) -> LightKind:
    """The kind a scene config (``viewer.scene_config.SceneConfig`` or a config with its fields) chooses: the first
    whose flag's field is set, else the default."""
    for kind in LIGHT_KINDS:
        if kind.flag is not None and getattr(config, kind.flag.field, None) is not None:
            return kind
    return LIGHT_KINDS[0]
