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
- ``--reference VOLUME.exr``: the ground-truth volume looked up instead of the network (viewer.reference); with
  ``--material`` it must be that material's surface (source and σs) and the view is the material's; alone, the
  fallback view and an exposure that puts the brightest 0.5 % of the lit pixels at white.
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
from typing import TYPE_CHECKING

from gratnet.config import add_arguments, add_quiet_flag, from_arguments
from gratnet.errors import GratNetError
from viewer.scene_config import (
    DEFAULT_MATERIAL,
    MAX_SAMPLES,
    RenderConfig,
    add_scene_arguments,
    check_scene,
    load_reference,
    resolve_scene_command,
    scene_fields,
    warn_if_black,
    with_fallback,
    write_render,
)

if TYPE_CHECKING:
    import numpy as np

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
        "  gratnet render --material blazed --slice --light 30,0 --size 256,256 --out slice.exr\n"
        "  gratnet render --material paper-cd --reference paper-cd.exr --mesh cd --out truth.png",
    )
    parser.add_argument("--out", required=True, metavar="IMAGE.png|IMAGE.exr",
                        help="output: .png (display sRGB, 8-bit) or .exr (linear sRGB float, R G B)")
    add_scene_arguments(parser, point_light="point light position in metres instead of --light (irradiance 1 at 1 m)")
    add_quiet_flag(parser)
    actions = add_arguments(parser, RenderConfig)
    # None when left out: --reference without --material renders the volume alone (no network, no model).
    actions["material"].default = None
    actions["material"].help = (f"{actions['material'].help.rsplit(' (default', 1)[0]} (default: "
                                f"{DEFAULT_MATERIAL}; none with --reference)")
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
    if config.reference and config.skip_dark:
        raise GratNetError("--skip-dark skips the network by its output bound; a --reference render looks up every "
                           "pixel")
    return config


def _auto_exposure(xyz: np.ndarray) -> float:
    """The exposure that puts the brightest 0.5 % of the lit pixels at display white (largest linear sRGB
    channel), for a picture rendered at exposure 1; 1 when nothing is lit."""
    import numpy as np

    from gratnet.display import xyz_to_linear_srgb

    peak = np.max(xyz_to_linear_srgb(np.asarray(xyz, dtype=np.float64)), axis=-1)
    lit = peak[peak > 0.0]
    if lit.size == 0:
        return 1.0
    exposure = 1.0 / float(np.percentile(lit, 99.5))
    return float(f"{exposure:.3g}") if np.isfinite(exposure) and exposure > 0.0 else 1.0


def run(arguments: argparse.Namespace) -> int:
    """Check every input, render, write the image and its config atomically."""
    import numpy as np

    from gratnet.modelfile import load_model
    from viewer.camera import Camera, Light
    from viewer.catalog import build_mesh, resolve_material

    out = Path(arguments.out)
    reference_only = bool(arguments.reference) and arguments.material is None
    if arguments.material is None:
        arguments.material = DEFAULT_MATERIAL
    auto_exposure = reference_only and arguments.exposure is None
    if reference_only:  # no material to derive the defaults from: the fallback view, exposure from the picture
        probe = with_fallback(arguments)
        arguments.light_text, arguments.camera_text, arguments.exposure = (probe.light_text, probe.camera_text,
                                                                            probe.exposure)
    config = resolve_scene_command(arguments, resolve_config)
    if config.skip_dark and out.suffix.lower() != ".png":
        raise GratNetError("--skip-dark applies to .png output only: an EXR keeps values below the display's step")
    camera = Camera(config.camera_distance, config.camera_azimuth_degrees, config.camera_elevation_degrees,
                    fov_deg=config.fov_degrees)
    light = (Light.point(config.point_light) if config.point_light is not None
             else Light.directional(config.light_theta_degrees, config.light_phi_degrees))
    model_path = None if reference_only else resolve_material(config.material)
    volume = (load_reference(config.reference, config.reference_precision,
                             None if reference_only else config.material) if config.reference else None)
    model = volume if volume is not None else load_model(model_path)
    mesh = None if config.slice else build_mesh(config.mesh)

    from gratnet.bounds import DISPLAY_SKIP_THRESHOLD
    from viewer.context import create_headless_context
    from viewer.scene import SceneRenderer

    # Skipping is exact only for an 8-bit display image; EXR keeps every value the network gives.
    skip_threshold = DISPLAY_SKIP_THRESHOLD if config.skip_dark else None
    ctx = create_headless_context()
    try:
        with SceneRenderer(ctx, model, weights_path=config.weights_path, render_path=config.render_path,
                           reference_precision=config.reference_precision) as renderer:
            # A BRDF slice has one path (a full-screen fragment pass); a mesh takes the one chosen.
            resolved = ({"path": "forward", "reason": "BRDF slices are rendered by the fragment pass only"}
                        if config.slice else {"path": renderer.render_path, "reason": renderer.render_path_reason})
            if config.slice:
                xyz = renderer.shading.render_brdf_slice(config.light_theta_degrees, config.light_phi_degrees,
                                                         config.width, config.exposure, config.effective_ior,
                                                         skip_threshold=skip_threshold)
            else:
                xyz = renderer.render(mesh, camera, light, (config.width, config.height), config.exposure,
                                      config.effective_ior, skip_threshold=skip_threshold, samples=config.spp)
    finally:
        ctx.release()
    if not np.all(np.isfinite(xyz)):
        raise GratNetError("the render contains NaN or inf; nothing was written (please report this)")
    if auto_exposure:  # rendered at exposure 1; the picture is linear in it
        exposure = _auto_exposure(xyz)
        xyz = xyz * exposure
        config = dataclasses.replace(config, exposure=exposure)
    if reference_only:
        config = dataclasses.replace(config, material="")

    documents: dict[str, object] = {"render": config, "render_path": resolved}
    if model_path is not None:
        documents["model_file"] = str(model_path)
    if volume is not None:
        documents["reference"] = {"file": str(Path(config.reference).resolve()), "slices": volume.slices,
                                  "resolution": volume.resolution, "scheme": volume.metadata.get("scheme"),
                                  "source": volume.metadata.get("source"), "precision": config.reference_precision}
    write_render(out, xyz, **documents)
    what = (f"BRDF slice, light θ={config.light_theta_degrees:g}° φ={config.light_phi_degrees:g}°" if config.slice
            else f"mesh {config.mesh}")
    samples = "" if config.slice else f", {config.spp} spp"
    if model_path is None:
        source = f"reference {Path(config.reference).name}"
    else:
        source = model_path.parent.name if model_path.name == "model.npz" else model_path.name
        source += f" (reference {Path(config.reference).name})" if volume is not None else ""
    print(f"wrote {out}: {source}, {what}, {config.width}×{config.height}{samples}, exposure {config.exposure:g}")
    warn_if_black(xyz, config.exposure)
    return 0
