"""``gratnet render``: a shipped material (or any model file) on a mesh, or its BRDF slice, to PNG or EXR.

    gratnet render --material blazed --mesh cd --size 512,512 --out cd.png

- ``--light``, ``--camera``, ``--exposure`` left out: chosen from the material and the mesh so that the
  diffraction shows (viewer.defaults; the same values as ``gratnet view``). A picture that is 99 % black on
  the display draws a warning on stderr with an exposure that would show it (exit status unchanged).

- ``--mesh``: ``cd`` (viewer.meshes.compact_disc), ``sphere``, ``plane`` or a Wavefront ``.obj`` file
  (metres); the world is +z up and the built-in meshes face +z.
- ``--light θ,φ``: a directional light in world space (degrees; physics.md's convention with +z up), or
  ``--point-light X,Y,Z`` (metres; irradiance 1 at 1 m, falling as 1/d²).
- ``--camera DIST,AZIMUTH,ELEVATION``: an orbit camera around the origin (metres, degrees).
- ``--slice``: instead of a mesh, the network's BRDF slice for the light θ,φ (physics.md "BRDF slice").
- ``--spp N``: N samples per pixel (anti-aliasing: the mean of N renders at sub-pixel offsets, each its own
  key vector; the same flag and meaning as ``gratnet mitsuba-render``); default 1.
- Output: ``.png`` = display sRGB, 8-bit (``gratnet.display``, like every GratNet PNG); ``.exr`` = linear
  sRGB, float32 channels R, G, B, exposure applied, unclipped. The resolved config is saved beside it
  (``NAME.config.json``); both are written atomically.

Runtime-side: no torch, no glfw, no imgui.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
from collections.abc import Callable
from pathlib import Path
from typing import Any, TypeVar

from gratnet.config import add_arguments, add_quiet_flag, config_field, from_arguments, parse_float, parse_numbers
from gratnet.errors import GratNetError
from viewer.defaults import FALLBACK, FOV_DEGREES, fill_scene_defaults, with_fallback

ConfigT = TypeVar("ConfigT")

__all__ = ["ASSETS", "MESHES", "RenderConfig", "SceneConfig", "check_scene", "register", "resolve_material",
           "resolve_scene_command", "run", "scene_fields", "shipped_materials", "warn_if_black", "write_render"]

#: Shipped materials: ``assets/NAME/model.npz``.
ASSETS = Path(__file__).resolve().parents[1] / "assets"
#: Built-in meshes for ``--mesh``.
MESHES = ("cd", "sphere", "plane")
_OUTPUT_SUFFIXES = (".png", ".exr")
#: Largest --spp of ``gratnet render``: viewer.antialias.MAX_SAMPLES (repeated: this module defers numpy).
MAX_SAMPLES = 1024
#: ``--weights-path`` choices: viewer.renderer.WEIGHTS_PATHS (repeated here: importing it loads moderngl).
WEIGHT_PATHS = ("auto", "texture", "baked")
#: ``--render-path`` choices: viewer.deferred.RENDER_PATHS (repeated here for the same reason).
RENDER_PATHS = ("auto", "forward", "deferred")
#: ``--render-path`` help, shared by every command that renders a mesh.
RENDER_PATH_HELP = ("mesh renders: forward (the network in the fragment shader), deferred (a G-buffer pass, then the "
                    "network in a compute shader for the pixels that need it) or auto (the faster on this GPU for "
                    "this network's size, timed once on a small probe and cached)")
#: sRGB / Rec. 709 primaries and D65 white (x, y pairs) for the EXR ``chromaticities`` attribute.
_SRGB_CHROMATICITIES = (0.64, 0.33, 0.30, 0.60, 0.15, 0.06, 0.3127, 0.3290)


@dataclasses.dataclass
class SceneConfig:
    """One light, an orbit camera, a material on a mesh: what every rendering command shares."""

    material: str = config_field("blazed", "shipped material name (assets/NAME/model.npz) or a model-file path")
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


@dataclasses.dataclass
class RenderConfig(SceneConfig):
    """Rendering a material on a mesh (or its BRDF slice) with one light and an orbit camera."""

    slice: bool = config_field(False, "render the network's BRDF slice for the light θ,φ instead of a mesh")
    weights_path: str = config_field(
        "auto", "where the shader reads the network's weights: texture (packed RGBA32F texture), baked "
        "(literals in a generated shader: faster on a CPU rasterizer, slower first compile) or auto (baked for "
        "nets up to 32k multiply-adds (the shipped size) on a CPU rasterizer such as Mesa llvmpipe, else texture)",
        choices=WEIGHT_PATHS)
    render_path: str = config_field("auto", RENDER_PATH_HELP, choices=RENDER_PATHS)
    skip_dark: bool = config_field(
        False, "PNG only: skip the network where exposure · A · (the model's cached output bound) cannot reach the "
        "display's smallest step; the first use per model builds the bound (minutes on a CPU)")
    spp: int = config_field(
        1, f"samples per pixel (anti-aliasing; 1 … {MAX_SAMPLES}, typical: 1, 4, 16, 64): the mean of renders at "
        "sub-pixel offsets (Halton 2,3; the first at the pixel centre); costs about spp × one render. As "
        "mitsuba-render's --spp", aliases=("--samples",))


def _numbers(text: str, count: int | tuple[int, ...], flag: str, form: str) -> list[float]:
    """Comma-separated numbers that float32 holds (``count`` of them), or a one-line GratNetError naming
    ``flag``. Negative values parse in both ``--flag -1,2`` and ``--flag=-1,2`` (gratnet.cli)."""
    return parse_numbers(text, count, flag, form)


#: Ranges of the scene's numbers that the float32 shaders handle (beyond them view matrices, 1/d² and
#: exposure · A · XYZ overflow or lose every digit).
ANGLE_LIMIT_DEGREES = 1e6
DISTANCE_RANGE_METRES = (1e-6, 1e6)


def check_scene_numbers(light: tuple[float, float] | None, point: tuple[float, ...] | None,
                        camera: tuple[float, float, float]) -> None:
    """Refuse (one line) light, point-light and camera values the float32 shaders cannot use."""
    low, high = DISTANCE_RANGE_METRES
    for flag, angles in (("--light", light or ()), ("--camera", camera[1:])):
        for angle in angles:
            if abs(angle) > ANGLE_LIMIT_DEGREES:
                raise GratNetError(f"{flag} angles must lie within ±{ANGLE_LIMIT_DEGREES:g} degrees "
                                   f"(typical: 0 to 90 and −180 to 180), got {angle:g}")
    if not low <= camera[0] <= high:
        raise GratNetError(f"--camera distance must be from {low:g} to {high:g} metres (typical: 0.1 to 1), "
                           f"got {camera[0]:g}")
    if point is not None:
        if max(abs(value) for value in point) > high:
            raise GratNetError(f"--point-light coordinates must lie within ±{high:g} metres, got {point}")
        if math.hypot(*point) < low:
            raise GratNetError(f"--point-light must be at least {low:g} m from the origin, got {point}")


def parse_size(text: str) -> tuple[int, int]:
    """'W,H' (or 'N' for N×N) → (W, H), integers in 1 … MAX_IMAGE_SIZE."""
    from viewer.scene import MAX_IMAGE_SIZE

    form = f"W,H: two integers in 1 … {MAX_IMAGE_SIZE} such as 512,512"
    values = _numbers(text, (1, 2), "--size", form)
    if not all(value.is_integer() and 1 <= value <= MAX_IMAGE_SIZE for value in values):
        raise GratNetError(f"--size expects {form}, got {text!r}")
    width = int(values[0])
    return width, int(values[-1])


def shipped_materials() -> list[str]:
    """Names of the shipped materials (folders of ``assets/`` holding a ``model.npz``)."""
    return sorted(path.parent.name for path in ASSETS.glob("*/model.npz"))


def resolve_material(material: str) -> Path:
    """A shipped material's model file, or ``material`` itself when it names a file."""
    shipped = ASSETS / material / "model.npz"
    if "/" not in material and "\\" not in material and shipped.is_file():
        return shipped
    path = Path(material).expanduser()
    if path.is_file():
        return path
    names = ", ".join(shipped_materials()) or "none"
    raise GratNetError(
        f"unknown material {material!r}: neither a shipped material (choose {names}) nor an existing model file"
    )


def build_mesh(spec: str) -> object:
    """The mesh named by ``--mesh``: a built-in name or an .obj path."""
    from viewer import meshes

    builders = {"cd": meshes.compact_disc, "sphere": meshes.sphere, "plane": meshes.plane}
    if spec in builders:
        return builders[spec]()
    path = Path(spec).expanduser()
    if path.suffix.lower() != ".obj":
        raise GratNetError(f"unknown mesh {spec!r}: choose {', '.join(MESHES)} or the path of a Wavefront .obj file")
    if not path.is_file():
        raise GratNetError(f"mesh file {spec} does not exist")
    return meshes.load_obj(path)


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``render`` subcommand."""
    parser = subparsers.add_parser(
        "render", help="render a material on a mesh (cd, sphere, plane, .obj) or its BRDF slice to PNG/EXR",
        description="Rasterize a mesh lit by one light and shade every pixel with the trained network "
        "(exposure · A · XYZ of the key vector in the surface's tangent frame); or, with --slice, the "
        "network's BRDF slice. Headless OpenGL (EGL).",
        epilog="typical use:\n"
        "  gratnet render --material blazed --mesh cd --size 512,512 --out cd.png\n"
        "  gratnet render --material blazed --slice --light 30,0 --size 256,256 --out slice.exr",
    )
    parser.add_argument("--out", required=True, metavar="IMAGE.png|IMAGE.exr",
                        help="output: .png (display sRGB, 8-bit) or .exr (linear sRGB float, R G B)")
    add_scene_arguments(parser, point_light="point light position in metres instead of --light (irradiance 1 at 1 m)")
    add_quiet_flag(parser)
    add_arguments(parser, RenderConfig)
    parser.set_defaults(handler=run)


def add_scene_arguments(parser: argparse.ArgumentParser, *, point_light: str | None = None,
                        exposure_of: str = "XYZ", size: str = "image size in pixels (typical: 256,256 to 1024,1024)"
                        ) -> None:
    """``--light``, ``--camera``, ``--exposure``, ``--size`` (and ``--point-light`` where ``point_light`` gives its
    help): one declaration for ``render``, ``view`` and ``mitsuba-render``, so that they mean the same and have
    the same defaults everywhere (:func:`scene_fields` parses them)."""
    shown = "chosen from the material and mesh so that the diffraction shows"
    same = "the same in render, view and mitsuba-render"
    parser.add_argument("--light", dest="light_text", default=None, metavar="θ,φ",
                        help=f"directional light in world space: polar angle from +z and azimuth from +x, degrees "
                        f"(default: {shown}; {same})")
    if point_light is not None:
        parser.add_argument("--point-light", dest="point_light_text", default=None, metavar="X,Y,Z", help=point_light)
    parser.add_argument("--camera", dest="camera_text", default=None, metavar="DIST,AZIMUTH,ELEVATION",
                        help="orbit camera around the origin: metres, degrees, degrees (default: chosen with the "
                        "light: the distance that frames the mesh, azimuth -90)")
    parser.add_argument("--exposure", type=parse_float, default=None,
                        help=f"exposure: the factor applied to {exposure_of} before display, linear (default: {shown} "
                        f"without saturating; {same})")
    parser.add_argument("--size", dest="size_text", default="512,512", metavar="W,H", help=f"{size}; default: 512,512")


def scene_fields(arguments: argparse.Namespace) -> dict[str, Any]:
    """``--light``, ``--point-light``, ``--camera`` and ``--size`` parsed into the config fields that ``render``,
    ``mitsuba-render`` (and ``view``) share: ``light_theta_degrees`` … ``height`` (one line if malformed)."""
    theta, phi = _numbers(arguments.light_text, 2, "--light", "θ,φ in degrees such as 45,90")
    distance, azimuth, elevation = _numbers(arguments.camera_text, 3, "--camera",
                                            "DIST,AZIMUTH,ELEVATION (metres, degrees, degrees) such as 0.25,-90,45")
    point = None
    if getattr(arguments, "point_light_text", None) is not None:
        point = tuple(_numbers(arguments.point_light_text, 3, "--point-light", "X,Y,Z in metres such as 0,0.1,0.2"))
    width, height = parse_size(arguments.size_text)
    return {"light_theta_degrees": theta, "light_phi_degrees": phi, "point_light": point,
            "camera_distance": distance, "camera_azimuth_degrees": azimuth, "camera_elevation_degrees": elevation,
            "width": width, "height": height}


def check_scene(config: Any) -> None:
    """Refuse (one line) a scene the float32 shaders cannot use: exposure, IOR, light, point light, camera
    (elevation and field of view included). ``config``: a :class:`RenderConfig` or a config with its fields."""
    from gratnet.brdf import check_exposure, check_ior
    from viewer.camera import Camera

    check_exposure(config.exposure)
    check_ior(config.ior)  # 0: no Fresnel; 1 is its limit (physics.md, "The A-term")
    camera = (config.camera_distance, config.camera_azimuth_degrees, config.camera_elevation_degrees)
    check_scene_numbers((config.light_theta_degrees, config.light_phi_degrees), config.point_light, camera)
    Camera(*camera, fov_deg=config.fov_degrees)  # checks the elevation and the field of view


def resolve_scene_command(arguments: argparse.Namespace, resolve: Callable[[argparse.Namespace], ConfigT]) -> ConfigT:
    """The steps every rendering command takes before any work, in order: the output's suffix and place
    (and its config's), the flags given (``resolve`` on :func:`viewer.defaults.with_fallback`), then the
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
    fill_scene_defaults(arguments)  # the unset --light, --camera, --exposure, from the material and mesh
    return resolve(arguments)


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


def _resolve_config(arguments: argparse.Namespace) -> RenderConfig:
    """The config from the flags, every compound flag parsed and every value checked (no GL yet)."""
    config = dataclasses.replace(from_arguments(RenderConfig, arguments), **scene_fields(arguments))
    check_scene(config)
    if config.slice and config.width != config.height:
        raise GratNetError(f"--slice renders a square image; give --size N,N (got {config.width},{config.height})")
    if config.slice and config.point_light is not None:
        raise GratNetError("--slice takes a directional light (--light θ,φ), not --point-light")
    if isinstance(config.spp, bool) or not 1 <= config.spp <= MAX_SAMPLES:
        raise GratNetError(f"--spp (samples per pixel) must be an integer in 1 … {MAX_SAMPLES}, got {config.spp}")
    if config.slice and config.spp != 1:
        raise GratNetError("--spp applies to mesh renders; --slice renders the BRDF slice at one sample per pixel")
    return config


def run(arguments: argparse.Namespace) -> int:
    """Check every input, render, write the image and its config atomically."""
    import numpy as np

    from gratnet.modelfile import load_model
    from viewer.camera import Camera, Light

    out = Path(arguments.out)
    config = resolve_scene_command(arguments, _resolve_config)
    if config.skip_dark and out.suffix.lower() != ".png":
        raise GratNetError("--skip-dark applies to .png output only: an EXR keeps values below the display's step")
    camera = Camera(config.camera_distance, config.camera_azimuth_degrees, config.camera_elevation_degrees,
                    fov_deg=config.fov_degrees)
    light = (Light.point(config.point_light) if config.point_light is not None
             else Light.directional(config.light_theta_degrees, config.light_phi_degrees))
    model_path = resolve_material(config.material)
    model = load_model(model_path)
    mesh = None if config.slice else build_mesh(config.mesh)

    from gratnet.bounds import DISPLAY_SKIP_THRESHOLD
    from viewer.context import create_headless_context
    from viewer.scene import SceneRenderer

    # Skipping is exact only for an 8-bit display image; EXR keeps every value the network gives.
    skip_threshold = DISPLAY_SKIP_THRESHOLD if config.skip_dark else None
    ctx = create_headless_context()
    try:
        with SceneRenderer(ctx, model, weights_path=config.weights_path, render_path=config.render_path) as renderer:
            # A BRDF slice has one path (a full-screen fragment pass); a mesh takes the one chosen.
            resolved = ({"path": "forward", "reason": "BRDF slices are rendered by the fragment pass only"}
                        if config.slice else {"path": renderer.render_path, "reason": renderer.render_path_reason})
            if config.slice:
                xyz = renderer.network.render_brdf_slice(config.light_theta_degrees, config.light_phi_degrees,
                                                         config.width, config.exposure, config.effective_ior,
                                                         skip_threshold=skip_threshold)
            else:
                xyz = renderer.render(mesh, camera, light, (config.width, config.height), config.exposure,
                                      config.effective_ior, skip_threshold=skip_threshold, samples=config.spp)
    finally:
        ctx.release()
    if not np.all(np.isfinite(xyz)):
        raise GratNetError("the render contains NaN or inf; nothing was written (please report this)")

    write_render(out, xyz, render=config, model_file=str(model_path), render_path=resolved)
    what = (f"BRDF slice, light θ={config.light_theta_degrees:g}° φ={config.light_phi_degrees:g}°" if config.slice
            else f"mesh {config.mesh}")
    samples = "" if config.slice else f", {config.spp} spp"
    print(f"wrote {out}: {Path(model_path).parent.name if model_path.name == 'model.npz' else model_path.name}, "
          f"{what}, {config.width}×{config.height}{samples}, exposure {config.exposure:g}")
    warn_if_black(xyz, config.exposure)
    return 0


def warn_if_black(xyz: object, exposure: float) -> None:
    """The black-picture hint (gratnet.showcase.black_image_hint) on stderr; the exit status is unchanged."""
    import sys

    from gratnet.showcase import black_image_hint

    hint = black_image_hint(xyz, exposure)  # type: ignore[arg-type]
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
