"""``gratnet view``: the interactive viewer (a glfw window with an imgui panel: viewer.window over viewer.app).

    gratnet view --material blazed --mesh cd --size 512,512

- ``--material``: a shipped material (``assets/NAME/model.npz``) or a model-file path; the panel offers
  every shipped material.
- ``--mesh``: ``cd``, ``sphere``, ``plane`` or a Wavefront ``.obj`` file (metres, +z up).
- ``--size W,H``: the render area in pixels (the window adds the panel on the left).
- ``--light θ,φ``, ``--camera DIST,AZIMUTH,ELEVATION``, ``--exposure``, ``--ior``, ``--no-fresnel``,
  ``--slice``: the starting view, as in ``gratnet render``; light, camera and exposure left out are chosen
  from the material and the mesh (viewer.defaults), the same values as ``gratnet render``'s.
- ``--weights-path auto|texture|baked``: where the shader reads the weights, as in ``gratnet render``.
- ``--render-path auto|forward|deferred``: as in ``gratnet render``. In the window ``auto`` is forward on a CPU
  rasterizer (llvmpipe: the deferred path's first frames after a switch cost 0.3–0.6 s of JIT work, over the
  150 ms a frame may take); on a GPU it takes the verdict cached for this GPU and network shape, and while
  there is none renders forward and lets the compile process time both.

Mouse: drag over the picture to orbit (in BRDF-slice mode: to move the light), wheel to zoom. The
Screenshot button writes ``gratnet-view-NNN.png`` (display sRGB, full resolution) and its
``.config.json`` (the ``gratnet render`` settings) into ``--screenshot-dir``.

The window and its panel appear at once and answer input while shaders compile: a child process
compiles them (viewer.compile_worker), the panel's status line says so ("compiling the shader for cd…
12 s"), the quick texture path shows the first picture within seconds and, on a CPU rasterizer, the
faster baked program takes over once compiled (25–60 s the first time per material; Mesa's disk shader
cache makes later starts quick).

Needs a display (X11 or Wayland) and OpenGL 4.3; without one it exits with status 2 and one line.
"""

from __future__ import annotations

import argparse
from typing import TYPE_CHECKING

from gratnet.config import add_quiet_flag, parse_float, parse_int
from gratnet.errors import GratNetError
from viewer.scene_config import (
    RENDER_PATH_HELP,
    RENDER_PATHS,
    WEIGHT_PATHS,
    add_scene_arguments,
    fill_scene_defaults,
    with_fallback,
)

if TYPE_CHECKING:  # the viewer's modules load numpy and pyrr: `gratnet --help` stays quick without them
    from viewer.state import ViewerState

__all__ = ["register", "run", "starting_state"]


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``view`` subcommand."""
    parser = subparsers.add_parser(
        "view", help="interactive viewer: a material on a mesh or its BRDF slice, in a window",
        description="Open a window showing a trained material on a mesh (or its BRDF slice), with sliders for "
        "the light, camera, exposure and Fresnel term. Renders at reduced resolution while you move things "
        "and refines to full resolution when you stop. Needs a display and OpenGL 4.3.",
        epilog="typical use:\n  gratnet view --material blazed --mesh cd\n  gratnet view --material blazed --slice",
    )
    parser.add_argument("--material", default="blazed",
                        help="shipped material name (assets/NAME/model.npz) or a model-file path (default: blazed)")
    parser.add_argument("--mesh", default="cd",
                        help="cd, sphere, plane, or the path of a Wavefront .obj file (metres, +z up; default: cd)")
    add_scene_arguments(parser, size="render area in pixels")
    parser.add_argument("--ior", type=parse_float, default=1.5,
                        help="refractive index of the Fresnel factor (typical: 1.3 to 2.5; 0: no Fresnel; "
                        "default: 1.5)")
    parser.add_argument("--fresnel", action=argparse.BooleanOptionalAction, default=True,
                        help="apply the Fresnel factor (default: on)")
    parser.add_argument("--slice", action="store_true", help="start in BRDF-slice mode")
    parser.add_argument("--weights-path", choices=WEIGHT_PATHS, default="auto",
                        help="where the shader reads the network's weights: texture, baked (literals in a generated "
                        "shader) or auto (baked for nets up to 32k multiply-adds on a CPU rasterizer, else texture; "
                        "default: auto)")
    parser.add_argument("--spp", "--samples", dest="spp", type=parse_int, default=16, metavar="N",
                        help="samples per pixel accumulated while the view stands still (progressive anti-aliasing, "
                        "as gratnet render --spp; 1: off; typical: 4 to 64; the panel changes it; default: 16)")
    parser.add_argument("--render-path", choices=RENDER_PATHS, default="auto", help=f"{RENDER_PATH_HELP}; "
                        "default: auto")
    parser.add_argument("--reference", metavar="VOLUME.exr",
                        help="the material's ground-truth volume (gratnet groundtruth's EXR): the panel then shows "
                        "the network, the volume looked up per pixel, or the FLIP heat map between them")
    parser.add_argument("--reference-precision", choices=("float16", "float32"), default="float16",
                        help="storage of the --reference texture (as gratnet render; default: float16)")
    parser.add_argument("--screenshot-dir", default=".", metavar="DIR",
                        help="folder for the Screenshot button's PNGs (default: the working folder)")
    parser.add_argument("--max-frames", type=parse_int, default=0, metavar="N",
                        help="close after N frames (0: when the window is closed; for scripted runs)")
    add_quiet_flag(parser)
    parser.set_defaults(handler=run)


def _scene_numbers(arguments: argparse.Namespace) -> tuple[float, float, float, float, float]:
    """--light θ,φ, --camera DIST,AZIMUTH,ELEVATION and --size parsed, and every scene number checked as
    ``gratnet render`` checks them (one line if bad): θ, φ, distance, azimuth, elevation."""
    import dataclasses

    from viewer.scene_config import RenderConfig, check_scene, scene_fields

    config = dataclasses.replace(RenderConfig(), **scene_fields(arguments), exposure=arguments.exposure,
                                 ior=arguments.ior)
    check_scene(config)
    return (config.light_theta_degrees, config.light_phi_degrees, config.camera_distance,
            config.camera_azimuth_degrees, config.camera_elevation_degrees)


def starting_state(arguments: argparse.Namespace) -> ViewerState:
    """The starting :class:`~viewer.state.ViewerState`, every value checked before a window opens."""
    from gratnet.atomic import check_output_folder
    from gratnet.modelfile import load_model
    from viewer.catalog import MESHES, build_mesh, resolve_material
    from viewer.scene_config import MAX_SAMPLES
    from viewer.state import SLIDERS, ViewerState

    check_output_folder(arguments.screenshot_dir, "--screenshot-dir")
    if not 1 <= arguments.spp <= MAX_SAMPLES:
        raise GratNetError(f"--spp (samples per pixel) must be an integer in 1 … {MAX_SAMPLES}, got {arguments.spp}")
    _scene_numbers(with_fallback(arguments))  # the flags given are checked before the defaults read the model
    fill_scene_defaults(arguments)  # the unset --light, --camera, --exposure, from the material and mesh
    theta, phi, distance, azimuth, elevation = _scene_numbers(arguments)
    if arguments.max_frames < 0:
        raise GratNetError(f"--max-frames must be ≥ 0, got {arguments.max_frames}")
    # Read (cheaply) before a window opens: a bad model or mesh file is one line, not a broken window.
    load_model(resolve_material(arguments.material))
    if arguments.mesh not in MESHES:  # an .obj file: built now (a built-in mesh cannot fail)
        build_mesh(arguments.mesh)
    fresnel, ior = arguments.fresnel, arguments.ior
    if ior == 0:  # as in gratnet render: --ior 0 means no Fresnel factor
        fresnel, ior = False, ViewerState.ior
    values = {"light_theta": theta, "light_phi": phi, "camera_distance": distance, "camera_azimuth": azimuth,
              "camera_elevation": elevation, "exposure": arguments.exposure, "ior": ior}
    for name, value in values.items():
        values[name] = SLIDERS[name].clamp(value)
    return ViewerState(material=arguments.material, mesh=arguments.mesh, fresnel=fresnel,
                       slice_mode=arguments.slice, **values)


def run(arguments: argparse.Namespace) -> int:
    """Open the window and run it until it is closed (or ``--max-frames``)."""
    from viewer.scene_config import parse_size
    from viewer.window import ViewerWindow

    size = parse_size(arguments.size_text)
    state = starting_state(arguments)
    reference = None
    if arguments.reference:  # checked and read before a window opens
        from viewer.reference_view import LoadedReference
        from viewer.scene_config import load_reference

        volume = load_reference(arguments.reference, arguments.reference_precision, arguments.material)
        reference = LoadedReference(volume, str(arguments.reference), arguments.material,
                                    arguments.reference_precision)
    extra = [] if state.mesh in ("cd", "sphere", "plane") else [state.mesh]
    with ViewerWindow(state, size, screenshot_dir=arguments.screenshot_dir, extra_meshes=extra,
                      weights_path=arguments.weights_path, max_samples=arguments.spp,
                      render_path=arguments.render_path, reference=reference) as window:
        window.run(arguments.max_frames)
        if window.gl_errors:
            raise GratNetError(f"OpenGL reported errors: {'; '.join(window.gl_errors[:3])} (please report this)")
    return 0
