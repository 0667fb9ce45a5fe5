"""An orbit camera and the lights of a scene (world space, metres, +z up).

World space: right-handed, +z up; the built-in meshes (viewer.meshes) lie in or around the xy-plane
and face +z, so a world direction at polar angle θ and azimuth φ,
``(sinθ cosφ, sinθ sinφ, cosθ)``, means on a plane what it means in docs/physics.md's surface frame.

Matrices come from pyrr and follow its convention: row vectors, ``clip = [x, y, z, 1] @ M``; the bytes of
a pyrr matrix uploaded as a GLSL ``mat4`` uniform give ``M_gl * vec4(p, 1)`` with the same result
(pyrr's row-major storage is OpenGL's column-major ``M_glᵀ``). Runtime-side: numpy + pyrr, no GL.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Protocol

import numpy as np
import pyrr

from gratnet.brdf import direction
from gratnet.errors import GratNetError
from gratnet.lights import DIRECTIONAL, POINT, chosen_kind, light_kind

__all__ = ["Camera", "Light", "LightConfig", "world_direction"]


def world_direction(theta_deg: float, phi_deg: float) -> np.ndarray:
    """Unit world vector at polar angle θ from +z and azimuth φ from +x towards +y (degrees); exact at
    multiples of 90°, so that a light at θ = 90° lies on a +z-facing surface's horizon (not 6e-17 above)."""
    return direction(theta_deg, phi_deg)


def _finite(name: str, value: float) -> float:
    try:
        number = float(value)
    except (TypeError, ValueError):
        raise GratNetError(f"{name} must be a number, got {value!r}") from None
    if not math.isfinite(number):
        raise GratNetError(f"{name} must be finite, got {value!r}")
    return number


def _vector(name: str, value: object) -> tuple[float, float, float]:
    array = np.asarray(value, dtype=np.float64).reshape(-1)
    if array.shape != (3,) or not np.all(np.isfinite(array)):
        raise GratNetError(f"{name} must be three finite numbers, got {value!r}")
    return float(array[0]), float(array[1]), float(array[2])


@dataclasses.dataclass(frozen=True)
class Camera:
    """A perspective camera orbiting ``target``.

    Attributes:
        distance: from the target to the eye, metres (> 0).
        azimuth_deg: the eye's azimuth around +z, from +x towards +y, degrees.
        elevation_deg: the eye's angle above the xy-plane, degrees in [−90, 90] (90: looking straight
            down −z; 0: level).
        target: the point looked at (metres).
        fov_deg: vertical field of view, degrees in (0, 180).
        near, far: clipping distances (metres); ``None``: ``distance / 100`` and ``distance · 100``.

    The screen's up vector is the direction in which increasing the elevation moves the eye, so it is
    well defined at every elevation, ±90° included (there it points away from the azimuth).
    """

    distance: float = 0.2
    azimuth_deg: float = -90.0
    elevation_deg: float = 45.0
    target: tuple[float, float, float] = (0.0, 0.0, 0.0)
    fov_deg: float = 40.0
    near: float | None = None
    far: float | None = None

    def __post_init__(self) -> None:
        distance = _finite("camera distance", self.distance)
        if distance <= 0.0:
            raise GratNetError(f"camera distance must be > 0 metres, got {self.distance!r}")
        elevation = _finite("camera elevation", self.elevation_deg)
        if not -90.0 <= elevation <= 90.0:
            raise GratNetError(f"camera elevation must be in −90 … 90 degrees, got {self.elevation_deg!r}")
        fov = _finite("field of view", self.fov_deg)
        if not 0.0 < fov < 180.0:
            raise GratNetError(f"field of view must be in (0, 180) degrees, got {self.fov_deg!r}")
        object.__setattr__(self, "distance", distance)
        object.__setattr__(self, "elevation_deg", elevation)
        object.__setattr__(self, "azimuth_deg", _finite("camera azimuth", self.azimuth_deg))
        object.__setattr__(self, "fov_deg", fov)
        object.__setattr__(self, "target", _vector("camera target", self.target))
        near, far = self.clip_range()
        if not 0.0 < near < far:
            raise GratNetError(f"camera clip range must satisfy 0 < near < far, got {near!r}, {far!r}")

    def clip_range(self) -> tuple[float, float]:
        """``(near, far)`` in metres, the defaults filled in."""
        near = self.distance / 100.0 if self.near is None else _finite("near", self.near)
        far = self.distance * 100.0 if self.far is None else _finite("far", self.far)
        return near, far

    def _angles(self) -> tuple[float, float, float, float]:
        azimuth, elevation = math.radians(self.azimuth_deg), math.radians(self.elevation_deg)
        return math.cos(azimuth), math.sin(azimuth), math.cos(elevation), math.sin(elevation)

    def eye(self) -> np.ndarray:
        """The eye position (metres), ``float64`` ``(3,)``."""
        ca, sa, ce, se = self._angles()
        return np.asarray(self.target) + self.distance * np.array([ce * ca, ce * sa, se])

    def up(self) -> np.ndarray:
        """The screen's up direction in world space (unit, ⟂ to the viewing direction)."""
        ca, sa, ce, se = self._angles()
        return np.array([-se * ca, -se * sa, ce])

    def view_matrix(self) -> np.ndarray:
        """World → eye space, ``float32`` 4×4 in pyrr's convention."""
        return pyrr.matrix44.create_look_at(self.eye(), np.asarray(self.target), self.up(), dtype=np.float32)

    def projection_matrix(self, aspect: float) -> np.ndarray:
        """Eye → clip space for width / height ``aspect``, ``float32`` 4×4 in pyrr's convention."""
        aspect = _finite("aspect ratio", aspect)
        if aspect <= 0.0:
            raise GratNetError(f"aspect ratio must be > 0, got {aspect!r}")
        near, far = self.clip_range()
        return pyrr.matrix44.create_perspective_projection(self.fov_deg, aspect, near, far, dtype=np.float32)

    def view_projection(self, aspect: float) -> np.ndarray:
        """World → clip space (``view @ projection``: pyrr multiplies row vectors on the left)."""
        return np.asarray(self.view_matrix() @ self.projection_matrix(aspect), dtype=np.float32)

    def pixel_ray(self, row: float, column: float, width: int, height: int) -> tuple[np.ndarray, np.ndarray]:
        """``(eye, unit direction)`` of the ray through the centre of pixel ``(row, column)`` of a
        ``width`` × ``height`` image (row 0 at the top), in world space."""
        ca, sa, ce, se = self._angles()
        backward = np.array([ce * ca, ce * sa, se])  # from the target towards the eye
        up = self.up()
        right = np.cross(up, backward)
        half_height = math.tan(math.radians(self.fov_deg) / 2.0)
        x = (2.0 * (column + 0.5) / width - 1.0) * half_height * width / height
        y = (1.0 - 2.0 * (row + 0.5) / height) * half_height
        ray = x * right + y * up - backward
        return self.eye(), ray / np.linalg.norm(ray)


class LightConfig(Protocol):
    """What :meth:`Light.from_config` reads of a scene config (``viewer.scene_config.SceneConfig``): the
    directional light's angles, and the field of another kind's flag (``point_light``) by name."""

    @property
    def light_theta_degrees(self) -> float: ...

    @property
    def light_phi_degrees(self) -> float: ...


@dataclasses.dataclass(frozen=True)
class Light:
    """A light of one of the kinds of :data:`gratnet.lights.LIGHT_KINDS` (world space): a directional or point light.

    Attributes:
        kind: the kind's name, ``"directional"`` or ``"point"``.
        vector: for a directional light the unit direction **towards** the light; for a point light its
            position (metres).
        intensity: a directional light's irradiance scale; a point light's at 1 m (falls off as 1/d²).

    The rendered value is ``exposure · intensity' · A(ωi, ωo) · XYZ(−(ωi + ωo))`` with ``intensity'`` the
    intensity (directional) or ``intensity / d²`` (point), as a BRDF slice with a unit light (physics.md).
    """

    kind: str
    vector: tuple[float, float, float]
    intensity: float = 1.0

    def __post_init__(self) -> None:
        kind = light_kind(self.kind)
        object.__setattr__(self, "vector", kind.prepare(_vector("light vector", self.vector)))
        intensity = _finite("light intensity", self.intensity)
        if intensity < 0.0:
            raise GratNetError(f"light intensity must be ≥ 0, got {self.intensity!r}")
        object.__setattr__(self, "intensity", intensity)

    @classmethod
    def directional(cls, theta_deg: float, phi_deg: float, intensity: float = 1.0) -> Light:
        """A light in the world direction at polar angle θ from +z and azimuth φ (degrees)."""
        return cls(DIRECTIONAL.name, tuple(world_direction(_finite("light θ", theta_deg),
                                                           _finite("light φ", phi_deg))), intensity)

    @classmethod
    def point(cls, position: object, intensity: float = 1.0) -> Light:
        """A point light at ``position`` (metres)."""
        return cls(POINT.name, _vector("light position", position), intensity)

    @classmethod
    def from_config(cls, config: LightConfig, intensity: float = 1.0) -> Light:
        """The light a scene config (``viewer.scene_config.SceneConfig``) describes: the kind whose flag's field is
        set (``point_light``), else the directional light at its ``light_theta_degrees``, ``light_phi_degrees``."""
        kind = chosen_kind(config)
        if kind.flag is None:
            return cls.directional(config.light_theta_degrees, config.light_phi_degrees, intensity)
        return cls(kind.name, getattr(config, kind.flag.field), intensity)

    def towards(self, point: object) -> tuple[np.ndarray, float]:
        """``(unit direction from point to the light, irradiance scale)`` at a world ``point``: what
        shaders/lights.glsl computes."""
        return light_kind(self.kind).incidence(self.vector, self.intensity, point)
