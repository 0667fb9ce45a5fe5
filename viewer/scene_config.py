"""The scene every rendering command shares: its configuration, its flags, its checks and its output.

``gratnet render``, ``gratnet view``, ``gratnet mitsuba-render``, the viewer's screenshots and the Mitsuba
plugin build on this one library module, so that a flag means the same thing everywhere:

- **Configuration**: :class:`SceneConfig` (one light, an orbit camera, a material on a mesh, exposure,
  Fresnel) and :class:`RenderConfig` (``gratnet render``'s: slice, weights and render path, ``--spp``),
  typed dataclasses whose fields are the commands' flags (``gratnet.config``) and whose resolved values
  are saved beside every output.
- **Flags**: :func:`add_scene_arguments` declares ``--light``, ``--point-light``, ``--camera``,
  ``--exposure`` and ``--size`` once; :func:`scene_fields` parses them; :func:`with_fallback` and
  :func:`fill_scene_defaults` fill the ones left out from the material and the mesh (viewer.defaults).
- **Checks**, before any work (one line, exit status 2): :func:`check_scene`, :func:`check_scene_numbers`,
  :func:`parse_size`, and :func:`resolve_scene_command`, the order every command takes.
- **Output**: :func:`write_render` (``.png``: 8-bit display sRGB; ``.exr``: linear sRGB float32 with its
  chromaticities) with its ``NAME.config.json``, landing together or not at all; :func:`warn_if_black`.

Imports nothing heavy at module level (``gratnet --help`` stays quick). Runtime-side: no torch, no GL.
"""

from __future__ import annotations

import argparse
import dataclasses
import functools
import math
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any, TypeVar

from gratnet.area_lights import AREA_FLAG, AREA_HELP, parse_area_lights
from gratnet.codes import (
    DEFAULT_ENVIRONMENT_SAMPLING,
    DEFERRED_WEIGHTS,
    ENVIRONMENT_SAMPLING,
    RENDER_PATHS,
    SCHEME,
    WEIGHTS_PATHS,
    WeightForm,
)
from gratnet.config import config_field, parse_float, parse_numbers
from gratnet.errors import GratNetError
from gratnet.lights import DISTANCE_RANGE_METRES, LIGHT_KINDS, LightFlag, light_kind
from gratnet.quality import DEFAULT_QUALITY, QUALITIES, QUALITY_HELP
from viewer.defaults import FALLBACK, FOV_DEGREES, SceneDefaults, resolve_defaults

if TYPE_CHECKING:
    import numpy as np

ConfigT = TypeVar("ConfigT")
SceneT = TypeVar("SceneT", bound="SceneConfig")

__all__ = ["DEFAULT_MATERIAL", "DEFERRED_WEIGHTS", "DEFERRED_WEIGHTS_HELP", "ENVIRONMENT_FORMS", "ENVIRONMENT_HELP",
           "MAX_SAMPLES", "RENDER_PATHS", "RENDER_PATH_HELP", "WEIGHT_PATHS", "LightingConfig", "RenderConfig",
           "check_lighting", "environment_of", "environment_rotation", "light_flag_given", "lighting_help",
           "with_given_light",
           "SceneConfig", "add_scene_arguments", "check_scene", "check_scene_numbers", "fill_scene_defaults",
           "load_reference", "parse_size", "quality_help", "read_render_exr", "resolve_point",
           "resolve_scene_command", "scene_fields", "warn_if_black", "with_fallback", "write_render"]
_OUTPUT_SUFFIXES = (".png", ".exr")
#: Largest --spp of ``gratnet render``: viewer.antialias.MAX_SAMPLES (repeated: this module defers numpy).
MAX_SAMPLES = 4096
#: ``--weights-path`` choices (gratnet.codes.WEIGHTS_PATHS; ``--render-path``'s and ``--deferred-weights``' come
#: from there too: RENDER_PATHS, DEFERRED_WEIGHTS).
WEIGHT_PATHS = WEIGHTS_PATHS
#: ``--deferred-weights`` help, shared by gratnet render and gratnet bench (there a comma-separated list).
DEFERRED_WEIGHTS_HELP = (
    "the deferred path's network kernel and where it reads the weights: texture, ssbo, shared, baked (one "
    "invocation per pixel, weights from the texture, a buffer, shared memory or baked literals), ssbo-fp16, "
    "shared-fp16 (weights stored as halves), tiled, tiled-fp16 (a work group per tile of pixels, each layer's "
    "weights staged in shared memory: a matrix product), tiled-half (that in half-precision arithmetic; needs "
    "GL_NV_gpu_shader5 or GL_AMD_gpu_shader_half_float) or auto (baked with baked weights, texture on a CPU "
    "rasterizer, else ssbo)")
#: ``--render-path`` help, shared by every command that renders a mesh.
RENDER_PATH_HELP = ("mesh renders: forward (the network in the fragment shader), deferred (a G-buffer pass, then the "
                    "network in a compute shader for the pixels that need it) or auto (the faster on this GPU for "
                    "this network's size, timed once on a small probe and cached)")
#: sRGB / Rec. 709 primaries and D65 white (x, y pairs) for the EXR ``chromaticities`` attribute.
_SRGB_CHROMATICITIES = (0.64, 0.33, 0.30, 0.60, 0.15, 0.06, 0.3127, 0.3290)


#: The material of a render or view whose --material is left out.
DEFAULT_MATERIAL = "blazed"


@dataclasses.dataclass
class SceneConfig:
    """One light, an orbit camera, a material on a mesh: what every rendering command shares."""

    material: str = config_field(DEFAULT_MATERIAL, "shipped material name (assets/NAME/model.npz) or a model-file path")
    # None when not given: the accurate point of a shipped material; in a saved config, the point that rendered (None
    # for a model-file path). gratnet.quality names the points.
    quality: str | None = config_field(None, QUALITY_HELP, choices=QUALITIES)
    mesh: str = config_field("cd", "cd, sphere, plane, or the path of a Wavefront .obj file (metres, +z up)")
    light_theta_degrees: float = config_field(FALLBACK.light_theta_degrees,
                                              "directional light: polar angle from +z, degrees", cli=False)
    light_phi_degrees: float = config_field(FALLBACK.light_phi_degrees, "directional light: azimuth from +x, degrees",
                                            cli=False)
    point_light: tuple[float, float, float] | None = config_field(
        None, "point light position, metres (replaces the directional light)", cli=False)
    camera_distance: float = config_field(FALLBACK.camera_distance, "camera distance from the origin, metres",
                                          cli=False)
    camera_azimuth_degrees: float = config_field(FALLBACK.camera_azimuth_degrees, "camera azimuth from +x, degrees",
                                                 cli=False)
    camera_elevation_degrees: float = config_field(FALLBACK.camera_elevation_degrees,
                                                   "camera elevation above the xy-plane, degrees", cli=False)
    fov_degrees: float = config_field(FOV_DEGREES, "vertical field of view, degrees (typical: 20 to 60)", flag="--fov")
    exposure: float = config_field(FALLBACK.exposure, "exposure: the linear factor applied to the rendered CIE XYZ "
                                   "(A · XYZ per unit irradiance) before display", cli=False)
    width: int = config_field(512, "image width, pixels", cli=False)
    height: int = config_field(512, "image height, pixels", cli=False)
    ior: float = config_field(1.5, "refractive index for the Fresnel factor of the A-term (typical: 1.3 to 2.5; "
                              "0: none)")
    fresnel: bool = config_field(True, "apply the Fresnel factor (--no-fresnel: R/R0 = 1)")

    @property
    def effective_ior(self) -> float | None:
        """The A-term's ``ior`` argument: ``None`` when Fresnel is off."""
        return self.ior if self.fresnel and self.ior != 0 else None


#: ``--environment`` help, shared by ``gratnet render`` and ``gratnet mitsuba-render``.
ENVIRONMENT_HELP = ("environment light: none; sky (a physically based sky, its sun 40° up with about 1.2 times the "
                    "irradiance of --light-intensity 1) or studio (three softboxes of radiance ≤ 1 on grey) from "
                    "assets/environments/; a constant radiance in linear sRGB (one number, or R,G,B); or the path of "
                    "a lat-long .exr/.hdr map in linear sRGB whose up is +z (docs/physics.md \"Environment light\")")
ENVIRONMENT_FORMS = "none|sky|studio|RADIANCE|R,G,B|MAP.exr|MAP.hdr"


@dataclasses.dataclass
class LightingConfig:
    """The light's intensity and an environment light (issue 43): what ``gratnet render`` and ``gratnet
    mitsuba-render`` add to the scene's one light, with the same flags and defaults."""

    # None when not given: 1, or 0 when an environment lights the scene (it replaces the default light).
    light_intensity: float | None = config_field(
        None, "the light's irradiance (directional, on a plane facing it) or intensity (point, W/sr: irradiance "
        "intensity/d² at d metres); 0: no light but the environment (default: 1, or 0 with --environment unless "
        "--light or --point-light is given; typical: 0 to 10)")
    environment: str = config_field("none", ENVIRONMENT_HELP)
    environment_scale: float = config_field(1.0, "factor on the environment's radiance (typical: 1e-5 to 1)")
    # None when not given: turned so that its brightest direction (a sun, a key light) stands at the light's azimuth.
    environment_rotation: float | None = config_field(
        None, "turn of the environment about +z, degrees (counter-clockwise seen from above: a feature at azimuth φ "
        "moves to φ + DEGREES); default: turned so that its brightest direction (the sky's sun, the studio's key "
        "softbox) stands at the azimuth of --light φ, the material's default light that shows its diffraction")
    seed: int = config_field(0, "random seed of the light samples (an environment's; Mitsuba's sampler)")
    # The flag's values as given (KIND:NUMBERS), parsed by gratnet.area_lights; () when none.
    area_light: tuple[str, ...] = config_field((), AREA_HELP, flag=AREA_FLAG)

    def __post_init__(self) -> None:
        self.area_light = tuple(str(text) for text in (self.area_light or ()))  # argparse and saved JSON give lists

    @property
    def has_environment(self) -> bool:
        """Whether ``environment`` names one (not ``none``, 0 or 0,0,0)."""
        return environment_of(self) is not None

    @property
    def area_lights(self) -> tuple[Any, ...]:
        """The ``--area-light`` values parsed (:class:`gratnet.area_lights.AreaLight`), or a one-line GratNetError."""
        return parse_area_lights(self.area_light)

    @property
    def has_sampled_light(self) -> bool:
        """Whether an environment or an area light lights the scene (rendered by passes of the MIS estimator)."""
        return bool(self.area_light) or self.has_environment

    @property
    def effective_light_intensity(self) -> float:
        """``light_intensity``, or its default: 1, or 0 when an environment or an area light lights the scene."""
        if self.light_intensity is not None:
            return self.light_intensity
        return 0.0 if self.has_sampled_light else 1.0


def environment_of(config: LightingConfig) -> Any:
    """The :class:`gratnet.environment.Environment` that ``config``'s ``--environment`` names (rotation, resolved by
    :func:`environment_rotation`, and scale applied), or None; a one-line GratNetError for a bad one. A file is read
    once while its size and modification time stay the same (the checks and the render share it)."""
    return _environment(config, environment_rotation(config))


def environment_rotation(config: LightingConfig, light_phi_degrees: float | None = None) -> float:
    """``config``'s ``--environment-rotation``, or when it is not given the turn that puts the environment's brightest
    direction at the azimuth of the light (``light_phi_degrees``, else the config's own; 0 for a config without a
    light or an environment)."""
    if config.environment_rotation is not None:
        return float(config.environment_rotation)
    phi = getattr(config, "light_phi_degrees", None) if light_phi_degrees is None else light_phi_degrees
    environment = _environment(config, 0.0)
    if environment is None or phi is None:
        return 0.0
    turn = (float(phi) - environment.brightest_azimuth_degrees() + 180.0) % 360.0 - 180.0
    return float(f"{turn:.6g}")


def _environment(config: LightingConfig, rotation_degrees: float) -> Any:
    """``config``'s environment turned by ``rotation_degrees`` and scaled: one read of its map (the checks, the
    default turn and the render share it), then turned and scaled in memory."""
    path = Path(str(config.environment).strip()).expanduser()
    try:
        status = path.stat()
        signature: tuple[int, int] | None = (status.st_mtime_ns, status.st_size)
    except (OSError, ValueError):
        signature = None
    base = _load_environment(str(config.environment), signature)
    if base is None or (float(rotation_degrees), float(config.environment_scale)) == (0.0, 1.0):
        return base
    return dataclasses.replace(base, rotation_degrees=float(rotation_degrees), scale=float(config.environment_scale))


@functools.lru_cache(maxsize=4)
def _load_environment(text: str, signature: tuple[int, int] | None) -> Any:
    """The environment ``text`` names, as its map is (unturned, unscaled); cached while a file's size and
    modification time (``signature``) stay the same."""
    from gratnet.environment import load_environment

    return load_environment(text, what="--environment")


def check_lighting(config: LightingConfig) -> None:
    """Refuse (one line) a light intensity or environment the renderers cannot use, reading the environment's map
    (before any GL work)."""
    if config.light_intensity is not None and not (math.isfinite(config.light_intensity)
                                                    and 0.0 <= config.light_intensity < 3e38):
        raise GratNetError(f"--light-intensity must be a finite number ≥ 0, got {config.light_intensity!r}")
    if isinstance(config.seed, bool) or not 0 <= config.seed < 2**32:
        raise GratNetError(f"--seed must be an integer in 0 … {2**32 - 1}, got {config.seed!r}")
    if not (math.isfinite(config.environment_scale) and 0.0 <= config.environment_scale < 3e38):
        raise GratNetError(f"--environment-scale must be a finite number ≥ 0, got {config.environment_scale!r}")
    if config.environment_rotation is not None and not math.isfinite(config.environment_rotation):
        raise GratNetError(f"--environment-rotation must be a finite number of degrees, got "
                           f"{config.environment_rotation!r}")
    environment_of(config)
    config.area_lights  # noqa: B018  (parsed for its checks: one line for a bad light)


def lighting_help(actions: dict[str, argparse.Action]) -> None:
    """Metavars of the lighting flags (``gratnet.config.add_arguments``' actions)."""
    actions["environment"].metavar = ENVIRONMENT_FORMS
    actions["environment_rotation"].metavar = "DEGREES"
    actions["environment_rotation"].help = (actions["environment_rotation"].help or "").replace(" (default: None)", "")
    actions["environment_scale"].metavar = "SCALE"
    actions["light_intensity"].metavar = "INTENSITY"
    actions["area_light"].metavar = "KIND:NUMBERS"
    # The field's None means "not given" (1, or 0 with --environment): its help says so in words, not "None".
    actions["light_intensity"].help = (actions["light_intensity"].help or "").replace(" (default: None)", "")


@dataclasses.dataclass
class RenderConfig(LightingConfig, SceneConfig):
    """Rendering a material on a mesh (or its BRDF slice) with one light and an orbit camera."""

    slice: bool = config_field(False, "render the network's BRDF slice for the light θ,φ instead of a mesh")
    weights_path: str = config_field(
        "auto", "where the shader reads the network's weights: texture (packed RGBA32F texture), baked "
        "(literals in a generated shader: faster on a CPU rasterizer, slower first compile) or auto (baked for "
        "nets up to 32k multiply-adds (the shipped size) on a CPU rasterizer such as Mesa llvmpipe, else texture)",
        choices=WEIGHT_PATHS)
    render_path: str = config_field("auto", RENDER_PATH_HELP, choices=RENDER_PATHS)
    deferred_weights: str = config_field("auto", DEFERRED_WEIGHTS_HELP, choices=DEFERRED_WEIGHTS)
    environment_sampling: str = config_field(
        DEFAULT_ENVIRONMENT_SAMPLING, "how an environment's light is sampled: resampled (candidates from the map's "
        "luminance and the material's own diffraction table, one kept in proportion to the expected shading: the "
        "least noise per sample), mis (one of the two, weighted by multiple importance sampling), light or material "
        "(one alone: for comparisons)",
        choices=ENVIRONMENT_SAMPLING.names)
    skip_dark: bool = config_field(
        False, "PNG only: skip the network where exposure · A · (the model's cached output bound) cannot reach the "
        "display's smallest step; the first use per model builds the bound (minutes on a CPU)")
    reference: str = config_field(
        "", "a ground-truth volume (gratnet groundtruth's EXR) to render instead of the network: the volume looked "
        "up per pixel (trilinear, exact at its samples) with the same A-term, Fresnel and exposure; with --material "
        "the volume must come from the material's surface; without it, an unset --exposure puts the 99th percentile "
        "of the lit pixels at white (raised until 3 %% of the picture shows)",
        metavar="VOLUME.exr")
    reference_precision: str = config_field(
        "float16", "storage of the --reference texture: float16 (XYZ·2^15: 11 significant bits for values down to "
        "2e-9 of a mirror's peak; 66 MB for 11 slices of 1001²) or float32 (exact, twice the memory)",
        choices=("float16", "float32"))
    spp: int = config_field(
        1, f"samples per pixel (anti-aliasing; 1 … {MAX_SAMPLES}, typical: 1, 4, 16, 64): the mean of renders at "
        "sub-pixel offsets (Halton 2,3; the first at the pixel centre); costs about spp × one render. As "
        "mitsuba-render's --spp", aliases=("--samples",))

    @property
    def weight_form(self) -> WeightForm:
        """``deferred_weights`` parsed: the deferred path's kernel and where and how it reads the weights."""
        return WeightForm.parse(self.deferred_weights)


def _numbers(text: str, count: int | tuple[int, ...], flag: str, form: str) -> list[float]:
    """Comma-separated numbers that float32 holds (``count`` of them), or a one-line GratNetError naming
    ``flag``. Negative values parse in both ``--flag -1,2`` and ``--flag=-1,2`` (gratnet.cli)."""
    return parse_numbers(text, count, flag, form)


#: Ranges of the scene's numbers that the float32 shaders handle (beyond them view matrices, 1/d² and
#: exposure · A · XYZ overflow or lose every digit); DISTANCE_RANGE_METRES (metres) is gratnet.lights'.
ANGLE_LIMIT_DEGREES = 1e6


def check_scene_numbers(light: tuple[float, float] | None, camera: tuple[float, float, float],
                        lights: dict[str, tuple[float, ...]] | None = None) -> None:
    """Refuse (one line) light, camera and other light kinds' values (``lights``: kind name → its flag's values,
    gratnet.lights) that the float32 shaders cannot use."""
    low, high = DISTANCE_RANGE_METRES
    for flag, angles in (("--light", light or ()), ("--camera", camera[1:])):
        for angle in angles:
            if abs(angle) > ANGLE_LIMIT_DEGREES:
                raise GratNetError(f"{flag} angles must lie within ±{ANGLE_LIMIT_DEGREES:g} degrees "
                                   f"(typical: 0 to 90 and −180 to 180), got {angle:g}")
    if not low <= camera[0] <= high:
        raise GratNetError(f"--camera distance must be from {low:g} to {high:g} metres (typical: 0.1 to 1), "
                           f"got {camera[0]:g}")
    for name, values in (lights or {}).items():
        light_flag = light_kind(name).flag
        if light_flag is not None:
            light_flag.check(values, light_flag.flag)


def parse_size(text: str) -> tuple[int, int]:
    """'W,H' (or 'N' for N×N) → (W, H), integers in 1 … MAX_IMAGE_SIZE."""
    from viewer.surface import MAX_IMAGE_SIZE

    form = f"W,H: two integers in 1 … {MAX_IMAGE_SIZE} such as 512,512"
    values = _numbers(text, (1, 2), "--size", form)
    if not all(value.is_integer() and 1 <= value <= MAX_IMAGE_SIZE for value in values):
        raise GratNetError(f"--size expects {form}, got {text!r}")
    width = int(values[0])
    return width, int(values[-1])


def add_scene_arguments(parser: argparse.ArgumentParser, *, lights: dict[str, str] | None = None,
                        exposure_of: str = "XYZ", size: str = "image size in pixels (typical: 256,256 to 1024,1024)"
                        ) -> None:
    """``--light``, ``--camera``, ``--exposure``, ``--size`` (and the flag of each other light kind that ``lights``
    names, with its help: ``{"point": …}`` adds ``--point-light``; gratnet.lights): one declaration for ``render``,
    ``view`` and ``mitsuba-render``, so that they mean the same and have the same defaults everywhere
    (:func:`scene_fields` parses them)."""
    shown = "chosen from the material and mesh so that the diffraction shows"
    same = "the same in render, view and mitsuba-render"
    parser.add_argument("--light", dest="light_text", default=None, metavar="θ,φ",
                        help=f"directional light in world space: polar angle from +z and azimuth from +x, degrees "
                        f"(default: {shown}; {same})")
    for name, help_text in (lights or {}).items():
        flag = light_kind(name).flag
        if flag is None:
            raise GratNetError(f"the {name} light is --light's: it has no flag of its own")
        parser.add_argument(flag.flag, dest=flag.dest, default=None, metavar=flag.metavar, help=help_text)
    parser.add_argument("--camera", dest="camera_text", default=None, metavar="DIST,AZIMUTH,ELEVATION",
                        help="orbit camera around the origin: metres, degrees, degrees (default: chosen with the "
                        "light: the distance that frames the mesh, azimuth -90)")
    parser.add_argument("--exposure", type=parse_float, default=None,
                        help=f"exposure: the factor applied to {exposure_of} before display, linear (default: {shown} "
                        f"without saturating; {same})")
    parser.add_argument("--size", dest="size_text", default="512,512", metavar="W,H", help=f"{size}; default: 512,512")


def scene_fields(arguments: argparse.Namespace) -> dict[str, Any]:
    """``--light``, the other light kinds' flags (``--point-light``), ``--camera`` and ``--size`` parsed into the
    config fields that ``render``, ``mitsuba-render`` (and ``view``) share: ``light_theta_degrees`` … ``height``
    (one line if malformed); a light kind's field is ``None`` when its flag was not given."""
    theta, phi = _numbers(arguments.light_text, 2, "--light", "θ,φ in degrees such as 45,90")
    distance, azimuth, elevation = _numbers(arguments.camera_text, 3, "--camera",
                                            "DIST,AZIMUTH,ELEVATION (metres, degrees, degrees) such as 0.25,-90,45")
    fields: dict[str, Any] = {"light_theta_degrees": theta, "light_phi_degrees": phi}
    for flag in (kind.flag for kind in LIGHT_KINDS if kind.flag is not None):
        text = getattr(arguments, flag.dest, None)
        fields[flag.field] = None if text is None else tuple(_numbers(text, flag.count, flag.flag, flag.form))
    width, height = parse_size(arguments.size_text)
    return {**fields, "camera_distance": distance, "camera_azimuth_degrees": azimuth,
            "camera_elevation_degrees": elevation, "width": width, "height": height}


def check_scene(config: Any) -> None:
    """Refuse (one line) a scene the float32 shaders cannot use: exposure, IOR, light, point light, camera
    (elevation and field of view included). ``config``: a :class:`RenderConfig` or a config with its fields."""
    from gratnet.brdf import check_exposure, check_ior
    from viewer.camera import Camera

    check_exposure(config.exposure)
    check_ior(config.ior)  # 0: no Fresnel; 1 is its limit (physics.md, "The A-term")
    camera = (config.camera_distance, config.camera_azimuth_degrees, config.camera_elevation_degrees)
    lights = {kind.name: getattr(config, kind.flag.field) for kind in LIGHT_KINDS
              if kind.flag is not None and getattr(config, kind.flag.field, None) is not None}
    check_scene_numbers((config.light_theta_degrees, config.light_phi_degrees), camera, lights)
    Camera(*camera, fov_deg=config.fov_degrees)  # checks the elevation and the field of view


def quality_help(actions: dict[str, argparse.Action]) -> None:
    """``--quality``'s help ending in its real default (the field's ``None`` means "not given": the accurate
    point), for the commands that add it from a config class (``gratnet.config.add_arguments``' actions)."""
    actions["quality"].help = f"{QUALITY_HELP} (default: {DEFAULT_QUALITY})"


def resolve_point(config: SceneT) -> tuple[Path, SceneT]:
    """The model file of ``config``'s ``material`` at its ``quality`` (viewer.catalog.material_point: one line if
    the material has no such point, or a quality is given with a model-file path), and ``config`` with the point
    that renders in ``quality`` (``None`` for a model-file path): what the saved config records. Cheap: no model
    is read."""
    from viewer.catalog import material_point

    path, quality = material_point(config.material, config.quality)
    return path, dataclasses.replace(config, quality=quality)


def resolve_scene_command(arguments: argparse.Namespace, resolve: Callable[[argparse.Namespace], ConfigT]) -> ConfigT:
    """The steps every rendering command takes before any work, in order: the output's suffix and place
    (and its config's), the flags given (``resolve`` on :func:`with_fallback`), then the
    unset ``--light``/``--camera``/``--exposure`` from the material and mesh (which reads the model), then
    ``resolve`` for real."""
    from gratnet.atomic import check_output_file
    from gratnet.config import config_path_for

    out = Path(arguments.out)
    if out.suffix.lower() not in _OUTPUT_SUFFIXES:
        raise GratNetError(f"--out must end in .png (display sRGB) or .exr (linear sRGB float), got {arguments.out}")
    check_output_file(out)
    check_output_file(config_path_for(out))
    resolve(with_fallback(arguments))  # the flags given are checked before the defaults read the model
    given = light_flag_given(arguments)  # before the defaults fill --light
    fill_scene_defaults(arguments)  # the unset --light, --camera, --exposure, from the material and mesh
    return with_given_light(resolve(arguments), given)


def light_flag_given(arguments: argparse.Namespace) -> bool:
    """Whether ``--light`` or another light kind's flag (``--point-light``) was given (not filled by the defaults)."""
    return getattr(arguments, "light_text", None) is not None or any(
        getattr(arguments, kind.flag.dest, None) is not None for kind in LIGHT_KINDS if kind.flag is not None)


def with_given_light(config: ConfigT, given: bool) -> ConfigT:
    """``config`` with ``light_intensity`` 1 where a light flag was ``given`` and no intensity: a light asked for is
    on beside an environment (which turns only the default light off)."""
    if given and isinstance(config, LightingConfig) and config.light_intensity is None:
        return dataclasses.replace(config, light_intensity=1.0)
    return config


def load_reference(path: str | Path, precision: str, material: str | None = None) -> Any:
    """The ``--reference`` volume (a :class:`~gratnet.volume.Volume`), checked from its headers first — its scheme,
    uniform slices, texture size and, with ``material``, its source and σs against the material's training
    volume — then read (pixel checksums). Every problem is one GratNetError, before any GL work. A volume that
    records no slope covariance (Smith's shadowing) takes the material's."""
    from gratnet.modelfile import load_model
    from gratnet.reference import check_uniform_slices, check_volume_matches
    from gratnet.shadowing import METADATA_KEY as SLOPE_COVARIANCE_KEY
    from gratnet.volume import read_volume, read_volume_header
    from viewer.catalog import resolve_material
    from viewer.reference import check_reference_limits

    name = f"--reference {path}"
    header = read_volume_header(path)
    if header.metadata.get("scheme") not in SCHEME:
        raise GratNetError(f"{name}: the volume names no sampling scheme ({', '.join(SCHEME.names)})")
    check_uniform_slices(header.metadata, header.slices, name)
    check_reference_limits(header.slices, header.resolution, precision, name=name)
    trained_on: dict[str, Any] = {}
    if material is not None:
        recorded = load_model(resolve_material(material)).metadata.get("volume")
        trained_on = recorded if isinstance(recorded, dict) else {}
        check_volume_matches(header.metadata, trained_on, name, material)
    volume = read_volume(path)
    if SLOPE_COVARIANCE_KEY not in volume.metadata and SLOPE_COVARIANCE_KEY in trained_on:
        # A volume made before the ground truth recorded its relief's slopes: its material's (the same field).
        volume.metadata[SLOPE_COVARIANCE_KEY] = trained_on[SLOPE_COVARIANCE_KEY]
    return volume


def read_render_exr(path: str | Path) -> Any:
    """An EXR that :func:`write_render` (or ``gratnet mitsuba-render``) wrote: linear sRGB, float64 ``(H, W, 3)``
    (channels R, G, B, or one RGB channel)."""
    import numpy as np
    import OpenEXR

    with OpenEXR.File(str(path)) as file:
        channels = file.channels()
        if "RGB" in channels:
            return np.asarray(channels["RGB"].pixels, dtype=np.float64)
        return np.stack([np.asarray(channels[name].pixels, dtype=np.float64) for name in "RGB"], axis=-1)


def write_render(out: Path, xyz: Any, *, linear_srgb: Any = None, **documents: Any) -> None:
    """The image (``.png``: 8-bit display sRGB; ``.exr``: linear sRGB float32, ``linear_srgb`` if given, else
    converted from ``xyz``) and its ``NAME.config.json`` (``documents``), landing together or not at all.

    Args:
        xyz: the exposed CIE XYZ image ``(H, W, 3)``.
    """
    import numpy as np

    from gratnet.atomic import atomic_paths
    from gratnet.config import config_path_for, config_text
    from gratnet.display import xyz_to_display_srgb8, xyz_to_linear_srgb

    xyz = np.asarray(xyz, dtype=np.float64)
    with atomic_paths(out, config_path_for(out)) as (image_temporary, config_temporary):
        if out.suffix.lower() == ".png":
            from PIL import Image

            Image.fromarray(xyz_to_display_srgb8(xyz, 1.0)).save(image_temporary, format="PNG")
        else:
            linear = xyz_to_linear_srgb(xyz) if linear_srgb is None else linear_srgb
            _write_exr(image_temporary, np.asarray(linear, dtype=np.float32), out)
        config_temporary.write_text(config_text(out, **documents), encoding="utf-8")



# ----------------------------------------------------------------------------------------------
# The flags left out: from the material and the mesh (viewer.defaults)


def with_fallback(arguments: argparse.Namespace) -> argparse.Namespace:
    """A copy of ``arguments`` whose unset ``--light``, ``--camera`` and ``--exposure`` hold :data:`FALLBACK`'s
    values: the command checks the flags the user gave on it before :func:`fill_scene_defaults` reads the
    model, so that bad input is refused before any work."""
    probe = argparse.Namespace(**vars(arguments))
    probe.light_text = FALLBACK.light_text if probe.light_text is None else probe.light_text
    probe.camera_text = FALLBACK.camera_text if probe.camera_text is None else probe.camera_text
    probe.exposure = FALLBACK.exposure if probe.exposure is None else probe.exposure
    return probe


def fill_scene_defaults(arguments: argparse.Namespace) -> SceneDefaults | None:
    """Fill the unset ``--light``, ``--camera`` and ``--exposure`` of a ``render`` or ``view`` command line
    (``arguments.light_text``, ``camera_text``, ``exposure`` left ``None``) from :func:`resolve_defaults`.

    Flags the user gave are kept as given (and checked later by the command's own validation). Nothing is
    computed when all three are given, or when another light kind's flag (``--point-light``) replaces the light
    and the camera and exposure are given. The default exposure is scaled as that light asks
    (``LightFlag.exposure_scale``: a point light's |position|²).

    Returns:
        the defaults used, or ``None`` when none were needed.
    """
    other_light = _other_light(arguments)
    if arguments.light_text is None and other_light is not None:
        arguments.light_text = FALLBACK.light_text  # unused: the other kind replaces the directional light
    if arguments.light_text is not None and arguments.camera_text is not None and arguments.exposure is not None:
        return None
    fresnel = getattr(arguments, "fresnel", True)
    ior = arguments.ior if fresnel and arguments.ior not in (None, 0) else None
    if ior is not None and not (isinstance(ior, (int, float)) and math.isfinite(ior) and ior > 0.0):
        ior = 1.5  # an invalid --ior is reported by the command's own check; the defaults must not fail first
    fov = getattr(arguments, "fov_degrees", FOV_DEGREES)
    if not (isinstance(fov, (int, float)) and 0.0 < fov < 180.0):
        fov = FOV_DEGREES
    defaults = resolve_defaults(arguments.material, arguments.mesh, bool(getattr(arguments, "slice", False)),
                                float(fov), ior)
    if arguments.light_text is None:
        arguments.light_text = defaults.light_text
    if arguments.camera_text is None:
        arguments.camera_text = defaults.camera_text
    if arguments.exposure is None:
        arguments.exposure = defaults.exposure * (_exposure_scale(other_light) or 1.0)
    return defaults


def _other_light(arguments: argparse.Namespace) -> tuple[LightFlag, str] | None:
    """``(flag, text)`` of the first other light kind's flag given (gratnet.lights), or ``None``."""
    for flag in (kind.flag for kind in LIGHT_KINDS if kind.flag is not None):
        text = getattr(arguments, flag.dest, None)
        if text is not None:
            return flag, str(text)
    return None


def _exposure_scale(other_light: tuple[LightFlag, str] | None) -> float | None:
    """The factor on the default exposure that another light kind's flag asks for (a ``--point-light X,Y,Z``'s
    |position|²: its irradiance at the origin is 1/|position|² of a directional light's); ``None`` without one,
    or when its text does not parse (the command's own check reports that)."""
    if other_light is None:
        return None
    flag, text = other_light
    try:
        values = [float(part) for part in text.split(",")]
    except ValueError:
        return None
    return flag.exposure_scale(values) if len(values) == flag.count else None


def warn_if_black(xyz: np.ndarray, exposure: float) -> None:
    """The black-picture hint (gratnet.showcase.black_image_hint) on stderr; the exit status is unchanged."""
    import sys

    from gratnet.showcase import black_image_hint

    hint = black_image_hint(xyz, exposure)
    if hint is not None:
        print(f"warning: {hint}", file=sys.stderr)


def _write_exr(path: Path, linear_srgb: object, name: Path) -> None:
    """Float32 channels R, G, B of a linear-sRGB image (row 0 at the top), ZIP-compressed, to ``path`` (a
    temporary of :func:`gratnet.atomic.atomic_paths`; ``name``: the output it becomes, for messages)."""
    import numpy as np
    import OpenEXR

    image = np.asarray(linear_srgb, dtype=np.float32)
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage,
              "chromaticities": _SRGB_CHROMATICITIES}
    channels = {channel: np.ascontiguousarray(image[..., k]) for k, channel in enumerate("RGB")}
    try:
        with OpenEXR.File(header, channels) as exr:
            exr.write(str(path))
    except Exception as error:  # OpenEXR raises plain exceptions (RuntimeError, …)
        raise GratNetError(f"cannot write {name}: {' '.join(str(error).split())}") from error
