"""``gratnet mitsuba-render``: a shipped material (or any model file) on a mesh, path-traced by Mitsuba 3.

    gratnet mitsuba-render --material cd --mesh cd --environment 2e-5 --spp 64 --size 512,512 --out cd_mitsuba.png

The flags mean what they mean for ``gratnet render`` (same names: --material, --mesh, --light θ,φ,
--point-light X,Y,Z, --camera DIST,AZIMUTH,ELEVATION, --fov, --exposure, --ior, --no-fresnel, --size, --out,
--quiet, --quality) and are checked by the same functions, so the two renderers show the same scene: --light, --camera
and --exposure left out take ``gratnet render``'s defaults for the material and mesh (viewer.defaults), and a
picture that is 99 % black on the display draws the same warning. With one light, no environment and
``--integrator direct`` the two agree up to Monte Carlo noise (tests/runtime/test_mitsuba.py). Added: --spp,
--environment (sky, studio, a constant radiance or a lat-long .exr/.hdr: gratnet.environment.load_environment)
with --environment-rotation and --environment-scale, --light-intensity, --integrator, --max-depth, --variant,
--seed, the sampling mixture.

Output: ``.png`` = display sRGB, 8-bit (``gratnet.display``); ``.exr`` = linear sRGB float32 R, G, B,
exposure applied, unclipped. The resolved config is saved beside it (``NAME.config.json``); the two land
together (gratnet.atomic), and both are checked before any work.
Progress: a bar (stderr; off with --quiet) advancing after each pass of a few samples per pixel. Ctrl-C
stops within a fraction of a second (the next BSDF call), writes nothing and exits 130 with one line.
Needs the ``mitsuba`` extra (``pip install -e '.[mitsuba]'``).
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import sys
import time
from pathlib import Path

from gratnet.config import add_arguments, add_quiet_flag, config_field, from_arguments
from gratnet.errors import GratNetError
from gratnet.lights import POINT
from viewer.scene_config import (
    LightingConfig,
    SceneConfig,
    add_scene_arguments,
    check_lighting,
    environment_of,
    environment_rotation,
    lighting_help,
    quality_help,
    resolve_point,
)

__all__ = ["MitsubaRenderConfig", "register", "run"]

_OUTPUT_SUFFIXES = (".png", ".exr")
#: Largest --spp (a typo such as 1e9 would otherwise run for days).
MAX_SPP = 1 << 16


@dataclasses.dataclass
class MitsubaRenderConfig(LightingConfig, SceneConfig):
    """Path-tracing a material on a mesh with Mitsuba 3: lights, environment, camera and sampling."""

    spp: int = config_field(64, f"samples per pixel (1 … {MAX_SPP}; typical: 16 to 256)")
    integrator: str = config_field("path", "direct (one bounce, emitter + BSDF sampling) or path",
                                   choices=["direct", "path"])
    max_depth: int = config_field(8, "path: longest path, in segments (2 = direct lighting; typical: 3 to 16)")
    variant: str = config_field("auto", "Mitsuba variant: llvm_ad_rgb (wide, needs LLVM ≥ 18), scalar_rgb (one "
                                "lookup at a time) or auto", choices=["auto", "llvm_ad_rgb", "scalar_rgb"])
    sampler: str = config_field(
        "table", "how the BSDF samples light directions: table (the material's own diffraction over the key's (u, v), "
        "docs/physics.md \"Environment light\") or mixture (a lobe around the mirror direction plus cosine: "
        "--specular-probability, --lobe-degrees)", choices=["table", "mixture"])
    specular_probability: float = config_field(0.5, "mixture sampler: share of BSDF samples drawn around the mirror "
                                               "direction (0 to 1)")
    lobe_degrees: float = config_field(2.0, "mixture sampler: angular standard deviation of that lobe, degrees "
                                       "(typical: 0.5 to 10)")


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``mitsuba-render`` subcommand."""
    parser = subparsers.add_parser(
        "mitsuba-render", help="path-trace a material on a mesh (cd, sphere, plane, .obj) with Mitsuba 3",
        description="Path-trace a mesh shaded by the trained network (the gratnet BSDF plugin: the same "
        "A · XYZ as gratnet render) under a directional or point light and an environment, with Mitsuba 3 "
        "(the mitsuba extra). Flags shared with gratnet render mean the same and have the same defaults.",
        epilog="typical use:\n"
        "  gratnet mitsuba-render --material cd --mesh cd --spp 64 --size 512,512 --out cd_mitsuba.png\n"
        "  gratnet mitsuba-render --material blazed --mesh sphere --environment 1e-4 --integrator path "
        "--out sphere.exr\n"
        "  gratnet mitsuba-render --material cd --mesh cd --environment sky --environment-rotation 30 "
        "--light-intensity 0 --out cd_sky.png",
    )
    parser.add_argument("--out", required=True, metavar="IMAGE.png|IMAGE.exr",
                        help="output: .png (display sRGB, 8-bit) or .exr (linear sRGB float, R G B)")
    add_scene_arguments(parser, lights={POINT.name: "point light position in metres instead of --light (intensity "
                                                    "--light-intensity)"},
                        exposure_of="the radiance (made for --light-intensity 1 without an environment)")
    add_quiet_flag(parser)
    actions = add_arguments(parser, MitsubaRenderConfig)
    lighting_help(actions)
    quality_help(actions)
    parser.set_defaults(handler=run)


def _resolve_config(arguments: argparse.Namespace) -> MitsubaRenderConfig:
    """The config from the flags, every value checked as ``gratnet render`` checks it (nothing rendered,
    Mitsuba not loaded yet)."""
    from viewer.scene_config import check_scene, scene_fields

    config = dataclasses.replace(from_arguments(MitsubaRenderConfig, arguments), **scene_fields(arguments))
    check_scene(config)
    resolve_point(config)  # the material has the point asked for (gratnet render's rule)
    check_lighting(config)
    if not 1 <= config.spp <= MAX_SPP:
        raise GratNetError(f"--spp must be an integer in 1 … {MAX_SPP}, got {config.spp}")
    if not 1 <= config.max_depth <= 1024:
        raise GratNetError(f"--max-depth must be an integer in 1 … 1024, got {config.max_depth}")
    if not (math.isfinite(config.specular_probability) and 0.0 <= config.specular_probability <= 1.0):
        raise GratNetError(f"--specular-probability must be in [0, 1], got {config.specular_probability!r}")
    if not (math.isfinite(config.lobe_degrees) and 0.0 < config.lobe_degrees <= 90.0):
        raise GratNetError(f"--lobe-degrees must be in (0, 90], got {config.lobe_degrees!r}")
    return config


def run(arguments: argparse.Namespace) -> int:
    """Check the outputs and every input, path-trace, write the image and its config together."""
    import numpy as np

    from gratnet.modelfile import load_model
    from mitsuba_plugin.runtime import resolve_variant
    from mitsuba_plugin.scene import traced_mesh
    from viewer.camera import Camera, Light
    from viewer.catalog import model_label
    from viewer.scene_config import resolve_scene_command, warn_if_black, write_render

    out = Path(arguments.out)
    exposure_given = arguments.exposure is not None

    def resolve(flags: argparse.Namespace) -> MitsubaRenderConfig:
        config = _resolve_config(flags)
        resolve_variant(config.variant)  # a missing Mitsuba is one line before the defaults' work
        return config

    config = resolve_scene_command(arguments, resolve)
    camera = Camera(config.camera_distance, config.camera_azimuth_degrees, config.camera_elevation_degrees,
                    fov_deg=config.fov_degrees)
    light = None
    if config.effective_light_intensity > 0.0:
        light = Light.from_config(config, config.effective_light_intensity)
    model_path, config = resolve_point(config)  # the saved config records the point that renders
    load_model(model_path)  # a corrupt model file: one line now, not a Mitsuba traceback later
    mesh = traced_mesh(config.mesh)  # Mitsuba's sphere is finer than GL's (mitsuba_plugin.scene.TRACED_SPHERE)
    config = dataclasses.replace(config, environment_rotation=environment_rotation(config))  # saved as resolved
    environment = environment_of(config)
    # Under an environment the unit light's default exposure means nothing: the exposure comes from the picture
    # (gratnet render's rule).
    auto_exposure = config.has_sampled_light and not exposure_given

    from mitsuba_plugin import scene as mitsuba_scene
    from mitsuba_plugin.runtime import set_variant
    from mitsuba_plugin.shading import xyz_to_linear_srgb_matrix

    variant = resolve_variant(config.variant)
    mi = set_variant(variant)
    started = time.perf_counter()
    scene = mitsuba_scene.build_scene(
        mi, mesh,
        mitsuba_scene.bsdf_dict(model_path, config.effective_ior, specular_probability=config.specular_probability,
                                lobe_degrees=config.lobe_degrees, sampler=config.sampler),
        mitsuba_scene.sensor(mi, camera, config.width, config.height, config.spp),
        mitsuba_scene.emitters(light, environment, config.area_lights),  # the environment carries its turn, scale
        integrator=config.integrator, max_depth=config.max_depth, mesh_name=Path(config.mesh).name)
    from tqdm import tqdm

    with tqdm(total=config.spp, desc=f"mitsuba-render ({variant})", unit="spp", file=sys.stderr,
              disable=arguments.quiet) as bar:
        try:
            image = mitsuba_scene.render_passes(mi, scene, config.spp, config.seed,
                                                progress=lambda done: bar.update(done - bar.n))
        except KeyboardInterrupt:
            bar.leave = False  # the bar goes; gratnet.cli's one "interrupted" line stays (exit 130)
            raise
    seconds = time.perf_counter() - started
    if auto_exposure:
        from gratnet.showcase import suggest_exposure

        unexposed = image.astype(np.float64) @ np.linalg.inv(xyz_to_linear_srgb_matrix())  # as below
        config = dataclasses.replace(config, exposure=suggest_exposure(unexposed, 1.0) or 1.0)
    linear = image.astype(np.float64) * config.exposure
    if not np.all(np.isfinite(linear)):
        raise GratNetError("the render contains NaN or inf after the exposure; nothing was written")
    xyz = linear @ np.linalg.inv(xyz_to_linear_srgb_matrix())  # the display pipeline and the black check take XYZ

    write_render(out, xyz, linear_srgb=linear, mitsuba_render=config, model_file=str(model_path), variant=variant,
                 render_seconds=round(seconds, 3))
    print(f"wrote {out}: {model_label(model_path)}, "
          f"mesh {config.mesh}, {config.width}×{config.height}, {config.spp} spp, {variant}, "
          f"exposure {config.exposure:g}, {seconds:.1f} s")
    warn_if_black(xyz, config.exposure)
    return 0
