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

The command only: its config, flags, checks and output writing are viewer.scene_config's (shared with
``gratnet view`` and ``gratnet mitsuba-render``); materials and meshes are viewer.catalog's. Runtime-side:
no torch, no glfw, no imgui.
"""

from __future__ import annotations

import argparse
import dataclasses
from pathlib import Path

from gratnet.config import add_arguments, add_quiet_flag, from_arguments
from gratnet.errors import GratNetError
from viewer.scene_config import (
    MAX_SAMPLES,
    RenderConfig,
    add_scene_arguments,
    check_scene,
    resolve_scene_command,
    scene_fields,
    warn_if_black,
    write_render,
)

__all__ = ["register", "resolve_config", "run"]


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


def resolve_config(arguments: argparse.Namespace) -> RenderConfig:
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
    from viewer.catalog import build_mesh, resolve_material

    out = Path(arguments.out)
    config = resolve_scene_command(arguments, resolve_config)
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
