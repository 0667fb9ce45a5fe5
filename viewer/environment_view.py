"""The viewer under an environment light (issue 43; ``gratnet view --environment``): the environments it offers, the
:class:`gratnet.environment.Environment` a view state names, and the exposure a picture under one calls for.

How :class:`viewer.app.ViewerApp` uses them: a mesh view under an environment is rendered by the ``ENVIRONMENT``
variant of the surface program on the forward path; each sample is one pass of the estimator
(shaders/environment.glsl: one light sample per pixel), so the still view keeps accumulating passes up to
``environment_samples`` (default :data:`ENVIRONMENT_SAMPLES`, up to :data:`viewer.antialias.MAX_SAMPLES`), and any
change of the state (camera, light, exposure, environment, material) starts again. The compile child warms that
variant and builds the material's importance table (:mod:`viewer.compile_worker`, the ``environment`` group); until
it is ready the view is shown without the environment, lit by the directional light (intensity 1 if the state's is
0), and the status line says so. A band of rows keys its light samples by the whole picture's pixels
(``render_rgba``'s ``pixel_origin``), so the mean of N passes, drawn in any bands, is
``SceneRenderer.render_rgba(..., samples=N, environment=...)``. Without ``--exposure`` the exposure comes from the
first preview under the environment, then again from its first full-resolution pass (:func:`picture_exposure`: the
rule of ``gratnet.showcase.suggest_exposure``, as ``gratnet render --environment`` without ``--exposure``; the
picture is rescaled, not rendered again).

Rendering only: no glfw, no imgui.
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

import numpy as np

from gratnet.errors import GratNetError

__all__ = ["AREA_ONLY_WARMED", "ENVIRONMENT_CHOICES", "ENVIRONMENT_SAMPLES", "EnvironmentChoices", "picture_exposure",
           "warmed_spec"]

#: The environments the panel offers besides the one given on the command line.
ENVIRONMENT_CHOICES = ("none", "sky", "studio")
#: Passes accumulated by a still view under an environment, by default (its noise needs many).
ENVIRONMENT_SAMPLES = 256


class EnvironmentChoices:
    """The environments a viewer offers: none, sky, studio and the ones given (``gratnet view --environment``),
    each map read once at the start (the sky: 0.15 s), before the window shows, so no frame reads a map.

    Args:
        on_show: the environment of the starting state (None: none).
        offered: further environment specs to offer.

    Attributes:
        specs: the panel's choices (empty: the viewer has no environment light at all).
        warmed: the environment whose program the compile child warms first (None: none).
    """

    def __init__(self, on_show: str | None, offered: Iterable[str] = ()) -> None:
        given = [str(spec) for spec in offered]
        if on_show is not None:
            given.insert(0, on_show)
        self.specs: list[str] = list(dict.fromkeys([*ENVIRONMENT_CHOICES, *given])) if given else []
        self.warmed: str | None = given[0] if given else None
        self._maps: dict[str, Any] = {spec: _load(spec) for spec in self.specs if spec != "none"}
        self._variant: tuple[tuple[str, float, float], Any] | None = None  # (spec, rotation, scale) → Environment

    def check(self, spec: object) -> str:
        """``spec`` as one of :attr:`specs` (or ``none``), else a one-line GratNetError."""
        text = str(spec)
        if text != "none" and text not in self.specs:
            raise GratNetError(f"environment must be one of {', '.join(self.specs or ['none'])}, got {text!r}")
        return text

    def map(self, spec: str | None) -> Any:
        """The environment ``spec`` names, unturned and unscaled (None for none)."""
        if spec is None or spec == "none":
            return None
        if spec not in self._maps:
            self._maps[spec] = _load(spec)
        return self._maps[spec]

    def environment(self, spec: str, rotation_degrees: float, scale: float) -> Any:
        """The :class:`gratnet.environment.Environment` of ``spec`` turned and scaled: one object per change of them
        (the renderer uploads it once), made from the map read at the start."""
        key = (spec, float(rotation_degrees), float(scale))
        if self._variant is None or self._variant[0] != key:
            from gratnet.environment import Environment

            base = self.map(spec)
            variant = (base if (base.rotation_degrees, base.scale) == key[1:] else
                       Environment(base.name, base.radiance_map, key[1], key[2], base.source))
            self._variant = key, variant
        return self._variant[1]


#: What the compile child warms the sampled-light program with when only area lights light the view: the program
#: is the same for any environment (area lights are uniforms), so a constant one serves.
AREA_ONLY_WARMED = "1"


def warmed_spec(environment: str | None, area_lights: Iterable[str]) -> str | None:
    """The environment spec the compile child warms the sampled-light program with: ``environment`` (None: none),
    else :data:`AREA_ONLY_WARMED` when there are area lights, else None (no such program)."""
    return environment if environment is not None else (AREA_ONLY_WARMED if tuple(area_lights) else None)


def _load(spec: str) -> Any:
    """``spec``'s environment through viewer.scene_config's cache, which ``gratnet view``'s checks filled."""
    from viewer.scene_config import LightingConfig, environment_of

    return environment_of(LightingConfig(environment=spec))


def picture_exposure(xyz: np.ndarray, exposure: float) -> float | None:
    """The exposure a picture (exposed CIE XYZ rendered at ``exposure``) calls for: gratnet.showcase's rule with
    viewer.srgb's matrix (no colour-science in the window); None when nothing is lit."""
    from gratnet.showcase import exposure_for_brightness
    from viewer.srgb import linear_srgb

    brightness = np.maximum(np.max(linear_srgb(xyz[..., :3]), axis=-1), 0.0) / exposure
    return exposure_for_brightness(brightness)
