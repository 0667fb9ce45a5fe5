"""What decides the viewer's picture: :class:`ViewerState` and the panel's :data:`SLIDERS`.

World +z up, degrees, metres, as ``gratnet render``. :meth:`ViewerState.render_config` is the ``gratnet
render`` config that reproduces a view (the screenshot's ``.config.json``). No GL, no glfw, no imgui.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

from gratnet.errors import GratNetError
from viewer.camera import Camera, Light
from viewer.defaults import FALLBACK, FOV_DEGREES
from viewer.scene_config import RenderConfig

__all__ = ["SLIDERS", "Slider", "ViewerState"]


@dataclasses.dataclass
class ViewerState:
    """Everything that decides the picture (world +z up, degrees, metres; as ``gratnet render``)."""

    material: str = "blazed"
    mesh: str = "cd"
    # The material-independent defaults shared with `gratnet render` (viewer.defaults.FALLBACK); `gratnet view`
    # starts from viewer.defaults.resolve_defaults for its material and mesh instead.
    light_theta: float = FALLBACK.light_theta_degrees
    light_phi: float = FALLBACK.light_phi_degrees
    camera_azimuth: float = FALLBACK.camera_azimuth_degrees
    camera_elevation: float = FALLBACK.camera_elevation_degrees
    camera_distance: float = FALLBACK.camera_distance
    fov: float = FOV_DEGREES
    exposure: float = FALLBACK.exposure
    fresnel: bool = True
    ior: float = 1.5
    slice_mode: bool = False
    shading: str = "network"  # viewer.reference_view.SHADINGS: network, reference (a loaded volume) or flip
    # The lighting flags of `gratnet render` (viewer.scene_config.LightingConfig), resolved: the light's intensity
    # (0 by default under an environment), the environment's spec (none, sky, studio, a radiance, R,G,B or a map's
    # path), its turn about +z and factor, and the seed of its light samples.
    light_intensity: float = 1.0
    environment: str = "none"
    environment_rotation: float = 0.0
    environment_scale: float = 1.0
    seed: int = 0
    # `--area-light` values as given (gratnet.area_lights): fixed for the session, lit by the same estimator.
    area_light: tuple[str, ...] = ()

    def key(self) -> tuple[Any, ...]:
        """The values that decide the pixels (two states with equal keys render the same picture)."""
        return dataclasses.astuple(self)

    @property
    def effective_ior(self) -> float | None:
        return self.ior if self.fresnel and self.ior != 0 else None

    def camera(self) -> Camera:
        return Camera(self.camera_distance, self.camera_azimuth, self.camera_elevation, fov_deg=self.fov)

    def light(self) -> Light:
        return Light.directional(self.light_theta, self.light_phi, self.light_intensity)

    @property
    def has_environment(self) -> bool:
        """Whether :attr:`environment` names an environment light (``none``, 0 and 0,0,0 do not)."""
        return _names_environment(self.environment)

    @property
    def has_sampled_light(self) -> bool:
        """Whether an environment or an area light lights the view (the passes of shaders/environment.glsl)."""
        return self.has_environment or bool(self.area_light)

    def area_lights(self) -> tuple[Any, ...]:
        """:attr:`area_light` parsed (:class:`gratnet.area_lights.AreaLight`), or a one-line GratNetError."""
        from gratnet.area_lights import parse_area_lights

        return parse_area_lights(self.area_light)

    def render_config(self, width: int, height: int, spp: int = 1) -> RenderConfig:
        """The ``gratnet render`` config that reproduces this view at ``width`` × ``height`` with ``spp``
        samples per pixel."""
        return RenderConfig(
            material=self.material, mesh=self.mesh, light_theta_degrees=self.light_theta,
            light_phi_degrees=self.light_phi, camera_distance=self.camera_distance,
            camera_azimuth_degrees=self.camera_azimuth, camera_elevation_degrees=self.camera_elevation,
            fov_degrees=self.fov, exposure=self.exposure, width=width, height=height, ior=self.ior,
            fresnel=self.fresnel, slice=self.slice_mode, spp=spp, light_intensity=self.light_intensity,
            environment=self.environment, environment_rotation=self.environment_rotation,
            environment_scale=self.environment_scale, seed=self.seed, area_light=self.area_light,
        )


def _names_environment(spec: str) -> bool:
    """``gratnet.environment.load_environment``'s rule for "no environment", without reading a map."""
    text = str(spec).strip().lower()
    if text in ("", "none"):
        return False
    try:
        return any(float(part) != 0.0 for part in text.split(","))
    except ValueError:
        return True  # a name or a path


@dataclasses.dataclass(frozen=True)
class Slider:
    """A numeric control of the panel: state field, label, range, logarithmic or not."""

    field: str
    label: str
    minimum: float
    maximum: float
    log: bool = False
    format: str = "%.1f"

    def clamp(self, value: float) -> float:
        value = float(value)
        if not math.isfinite(value):
            raise GratNetError(f"{self.field} must be a finite number, got {value!r}")
        return min(max(value, self.minimum), self.maximum)


#: The panel's sliders, by name (the names ``drive_slider`` and ``ViewerApp.set`` accept).
SLIDERS: dict[str, Slider] = {
    slider.field: slider
    for slider in (
        Slider("light_theta", "light theta (°)", 0.0, 89.0),  # imgui's default font has no Greek
        Slider("light_phi", "light phi (°)", -180.0, 180.0),
        Slider("camera_azimuth", "azimuth (°)", -180.0, 180.0),
        Slider("camera_elevation", "elevation (°)", -89.0, 89.0),
        Slider("camera_distance", "distance (m)", 0.02, 5.0, log=True, format="%.3f"),
        Slider("exposure", "exposure", 1e-3, 1e7, log=True, format="%.4g"),
        Slider("ior", "IOR", 1.05, 3.0, format="%.2f"),  # n = 1 has no Fresnel reflection: R0 = 0
        # Under an environment (gratnet view --environment): the panel's lighting controls.
        Slider("light_intensity", "light intensity", 0.0, 100.0, format="%.3g"),
        Slider("environment_rotation", "env. rotation (°)", -180.0, 180.0),
        Slider("environment_scale", "env. scale", 1e-5, 1e5, log=True, format="%.4g"),
    )
}
