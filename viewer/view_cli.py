"""``gratnet view``: the interactive viewer (a glfw window with an imgui panel: viewer.window over viewer.app).

    gratnet view --material blazed --mesh cd --size 512,512

- ``--material``: a shipped material (``assets/NAME/model.npz``) or a model-file path; the panel offers
  every shipped material.
- ``--mesh``: ``cd``, ``sphere``, ``plane`` or a Wavefront ``.obj`` file (metres, +z up).
- ``--size W,H``: the render area in pixels (the window adds the panel on the left).
- ``--light θ,φ``, ``--camera DIST,AZIMUTH,ELEVATION``, ``--exposure``, ``--ior``, ``--no-fresnel``,
  ``--slice``: the starting view, as in ``gratnet render``; light, camera and exposure left out are chosen
  from the material and the mesh (viewer.defaults), the same values as ``gratnet render``'s: remembered from
  an earlier run, else a quick guess (tenths of a second) that the exact values replace when a
  worker process has them (viewer.default_view), so that the window shows without waiting for them.
- ``--quality fast|accurate|auto``: which of a shipped material's points renders it (gratnet.quality), for the
  starting material and the panel's: ``fast`` is the fast point where a material has one (a ``--material`` without
  one is refused in one line; the panel's others quietly show their only point), ``accurate`` the accurate point.
  ``auto``, the default, is meant to show the fast point while the view moves and the accurate one once it stands
  still; for now it shows the accurate point throughout (``ViewerApp.point`` says why). ``--quality`` with a
  model-file path is refused (it has no points). The default view is the material's either way (its accurate
  point's, as ``gratnet render``'s).
- ``--weights-path auto|texture|baked``: where the shader reads the weights, as in ``gratnet render``.
- ``--render-path auto|forward|deferred``: as in ``gratnet render``. In the window ``auto`` is forward on a CPU
  rasterizer (llvmpipe: the deferred path's first frames after a switch cost 0.3–0.6 s of JIT work, over the
  150 ms a frame may take); on a GPU it takes the verdict cached for this GPU and network shape, and while
  there is none renders forward and lets the compile process time both.

- ``--environment none|sky|studio|RADIANCE|R,G,B|MAP.exr|MAP.hdr``, ``--environment-rotation``,
  ``--environment-scale``, ``--light-intensity``, ``--seed``: the lighting flags of ``gratnet render``
  (viewer.scene_config.LightingConfig), with the same meanings and defaults (with an environment the light is off
  unless ``--light-intensity`` is given). A still view then keeps adding passes of the environment's estimator, up
  to ``--environment-spp`` (default 256); without ``--exposure`` the exposure comes from the first picture under
  the environment. The panel then offers none, sky, studio and the given environment, its rotation and scale.
  ``--area-light`` (repeatable) adds area lights, fixed for the session, accumulated the same way.
  Sampled light renders on the window's path (deferred on a CPU rasterizer); until the compile process has built
  the material's importance table the passes sample light directions from a flat table (unbiased, noisier).

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
import contextlib
import math
from typing import TYPE_CHECKING, Any

from gratnet.config import add_arguments, add_quiet_flag, parse_float, parse_int
from gratnet.errors import GratNetError
from gratnet.quality import ACCURATE, AUTO, QUALITY_HELP, VIEW_QUALITIES
from viewer.scene_config import (
    RENDER_PATH_HELP,
    RENDER_PATHS,
    WEIGHT_PATHS,
    LightingConfig,
    add_scene_arguments,
    environment_rotation,
    fill_scene_defaults,
    lighting_help,
    with_fallback,
)

if TYPE_CHECKING:  # the viewer's modules load numpy and pyrr: `gratnet --help` stays quick without them
    from viewer.state import ViewerState
    from viewer.window import ViewerWindow

__all__ = ["open_window", "register", "run", "starting_state", "starting_view", "view_point"]


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
    # None when not given (auto): given, it is checked against the material (a model file has no points).
    parser.add_argument("--quality", choices=VIEW_QUALITIES, default=None,
                        help=f"{QUALITY_HELP}; or auto: meant to show the fast point while the view moves and the "
                        "accurate one when it stands still, for now the accurate point throughout (default: auto)")
    parser.add_argument("--weights-path", choices=WEIGHT_PATHS, default="auto",
                        help="where the shader reads the network's weights: texture, baked (literals in a generated "
                        "shader) or auto (baked for nets up to 32k multiply-adds on a CPU rasterizer, else texture; "
                        "default: auto)")
    parser.add_argument("--spp", "--samples", dest="spp", type=parse_int, default=16, metavar="N",
                        help="samples per pixel accumulated while the view stands still (progressive anti-aliasing, "
                        "as gratnet render --spp; 1: off; typical: 4 to 64; the panel changes it; default: 16)")
    parser.add_argument("--render-path", choices=RENDER_PATHS, default="auto", help=f"{RENDER_PATH_HELP}; "
                        "default: auto")
    lighting_help(add_arguments(parser, LightingConfig))  # gratnet render's lighting flags, the same meanings
    parser.add_argument("--environment-spp", type=parse_int, default=None, metavar="N",
                        help="passes of the environment's estimator accumulated while the view stands still (1 … "
                        "4096; the panel changes it; default: 256)")
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


def view_point(arguments: argparse.Namespace) -> tuple[str, str]:
    """``--quality`` checked against ``--material`` (viewer.catalog's rules, one line before any work; ``auto``
    as the accurate point) and resolved: (the viewer's quality, the model file of the starting point, as the
    scene supply takes it)."""
    from viewer.catalog import material_point

    quality = AUTO if arguments.quality is None else arguments.quality
    path, point = material_point(arguments.material, None if arguments.quality in (None, AUTO) else quality)
    if arguments.quality == AUTO and point is None:  # auto chooses between points: a model file has none
        material_point(arguments.material, ACCURATE)  # its one-line error
    return quality, str(path) if point not in (None, ACCURATE) else arguments.material


def _guess_view(arguments: argparse.Namespace) -> tuple[str, ...]:
    """Fill the unset ``--light``, ``--camera`` and ``--exposure`` at once (issue 35: computing the exact defaults
    here took 4–6 s, colour-science's import included, before the window showed): with the exact defaults
    remembered from an earlier start or switch (:func:`viewer.default_view.remembered_view`), else with the
    fallback view, which the window replaces by its quick guess and then by the exact defaults as soon as they
    are worked out off its thread (it holds the first picture back for the guess). Returns the viewer fields
    that the window is to work out."""
    from viewer.default_view import remembered_view
    from viewer.defaults import FALLBACK, FOV_DEGREES

    unset = {"light": arguments.light_text is None, "camera": arguments.camera_text is None,
             "exposure": arguments.exposure is None}
    if not any(unset.values()):
        return ()
    ior = arguments.ior if arguments.fresnel and arguments.ior != 0 else None
    if ior is not None and not (math.isfinite(ior) and ior > 0.0):
        ior = 1.5  # an invalid --ior is reported by the checks; the defaults must not fail first
    view = remembered_view(arguments.material, arguments.mesh, arguments.slice, FOV_DEGREES, ior)
    guessed: tuple[str, ...] = ()
    if view is None:
        view = {"light_theta": FALLBACK.light_theta_degrees, "light_phi": FALLBACK.light_phi_degrees,
                "camera_distance": FALLBACK.camera_distance, "camera_azimuth": FALLBACK.camera_azimuth_degrees,
                "camera_elevation": FALLBACK.camera_elevation_degrees, "exposure": FALLBACK.exposure}
        guessed = tuple(field for flag, fields in _VIEW_FLAGS.items() if unset[flag] for field in fields)
    if unset["light"]:
        arguments.light_text = f"{view['light_theta']:g},{view['light_phi']:g}"
    if unset["camera"]:
        arguments.camera_text = f"{view['camera_distance']:g},{view['camera_azimuth']:g},{view['camera_elevation']:g}"
    if unset["exposure"]:
        arguments.exposure = view["exposure"]
    return guessed


#: The viewer fields each view flag sets.
_VIEW_FLAGS = {"light": ("light_theta", "light_phi"),
               "camera": ("camera_distance", "camera_azimuth", "camera_elevation"), "exposure": ("exposure",)}


def starting_view(arguments: argparse.Namespace, exact: bool = False) -> tuple[ViewerState, tuple[str, ...]]:
    """The starting :class:`~viewer.state.ViewerState`, every value checked before a window opens, and the
    fields of it that the window is to work out (``refine_view``: :func:`_guess_view`). With ``exact`` the
    unset view flags take the exact defaults now (``viewer.scene_config.fill_scene_defaults``, seconds) and
    nothing is left to the window."""
    from gratnet.atomic import check_output_folder
    from viewer.catalog import MESHES, build_mesh
    from viewer.scene_config import MAX_SAMPLES
    from viewer.scene_supply import load_material
    from viewer.state import SLIDERS, ViewerState

    check_output_folder(arguments.screenshot_dir, "--screenshot-dir")
    if not 1 <= arguments.spp <= MAX_SAMPLES:
        raise GratNetError(f"--spp (samples per pixel) must be an integer in 1 … {MAX_SAMPLES}, got {arguments.spp}")
    _scene_numbers(with_fallback(arguments))  # the flags given are checked before the defaults read the model
    # Read before a window opens (once: the window renders this copy): a bad model or mesh file is one line,
    # not a broken window.
    load_material(view_point(arguments)[1])
    if arguments.mesh not in MESHES:  # an .obj file: built now (a built-in mesh cannot fail)
        build_mesh(arguments.mesh)
    lighting = lighting_of(arguments)
    guessed: tuple[str, ...] = ()  # the unset --light, --camera, --exposure, from the material and mesh:
    if exact:
        fill_scene_defaults(arguments)
    else:
        guessed = _guess_view(arguments)
    theta, phi, distance, azimuth, elevation = _scene_numbers(arguments)
    if arguments.max_frames < 0:
        raise GratNetError(f"--max-frames must be ≥ 0, got {arguments.max_frames}")
    fresnel, ior = arguments.fresnel, arguments.ior
    if ior == 0:  # as in gratnet render: --ior 0 means no Fresnel factor
        fresnel, ior = False, ViewerState.ior
    values = {"light_theta": theta, "light_phi": phi, "camera_distance": distance, "camera_azimuth": azimuth,
              "camera_elevation": elevation, "exposure": arguments.exposure, "ior": ior}
    for name, value in values.items():
        values[name] = SLIDERS[name].clamp(value)
    state = ViewerState(material=arguments.material, mesh=arguments.mesh, fresnel=fresnel,
                        slice_mode=arguments.slice, light_intensity=lighting.effective_light_intensity,
                        environment=str(lighting.environment).strip() if lighting.has_environment else "none",
                        environment_rotation=environment_rotation(lighting, phi),
                        environment_scale=lighting.environment_scale, seed=lighting.seed,
                        area_light=lighting.area_light, **values)
    return state, guessed


def lighting_of(arguments: argparse.Namespace) -> LightingConfig:
    """The lighting flags checked as ``gratnet render`` checks them (one line if bad, the map read), before any
    window."""
    from gratnet.config import from_arguments
    from viewer.antialias import MAX_SAMPLES
    from viewer.scene_config import check_lighting, light_flag_given, with_given_light

    lighting = with_given_light(from_arguments(LightingConfig, arguments), light_flag_given(arguments))
    check_lighting(lighting)
    passes = getattr(arguments, "environment_spp", None)
    if passes is not None and not 1 <= passes <= MAX_SAMPLES:
        raise GratNetError(f"--environment-spp must be an integer in 1 … {MAX_SAMPLES}, got {passes}")
    return lighting


def starting_state(arguments: argparse.Namespace) -> ViewerState:
    """The starting :class:`~viewer.state.ViewerState` with the exact defaults for the unset view flags (those of
    ``gratnet render``; computed now): :func:`starting_view` with ``exact``."""
    return starting_view(arguments, exact=True)[0]


def open_window(arguments: argparse.Namespace, **window_options: Any) -> ViewerWindow:
    """The window of a ``gratnet view`` command line, open (the caller closes it): the compile child started
    first, the flags checked, the first view (:func:`starting_view`), the ``--reference`` volume read.
    ``window_options``: further :class:`~viewer.window.ViewerWindow` arguments (benchmarks/viewer_latency.py)."""
    from viewer.environment_view import ENVIRONMENT_SAMPLES, warmed_spec
    from viewer.scene_config import parse_size
    from viewer.scene_supply import SceneSupply
    from viewer.state import ViewerState
    from viewer.window import ViewerWindow

    size = parse_size(arguments.size_text)
    # Before the defaults fill --exposure: under an environment its default comes from the first picture.
    environment = str(arguments.environment).strip()
    exposure_given = arguments.exposure is not None
    # The compile child first: its Python start-up and the first shader overlap the checks, the first view and
    # the window's set-up (a bad material or environment is reported by the checks below).
    worker = None
    with contextlib.suppress(GratNetError):  # the model of the starting point (--quality), as the app asks for it
        start = ViewerState(material=view_point(arguments)[1], slice_mode=arguments.slice, environment=environment,
                            area_light=tuple(getattr(arguments, "area_light", None) or ()))
        worker = SceneSupply.start_worker(start, arguments.weights_path, arguments.render_path,
                                          warmed_spec(environment if start.has_environment else None, start.area_light))
    try:
        state, guessed = starting_view(arguments)
        reference = None
        if arguments.reference:  # checked and read before a window opens
            from viewer.reference_view import LoadedReference
            from viewer.scene_config import load_reference

            volume = load_reference(arguments.reference, arguments.reference_precision, arguments.material)
            reference = LoadedReference(volume, str(arguments.reference), arguments.material,
                                        arguments.reference_precision)
    except BaseException:
        if worker is not None:
            worker.close()
        raise
    extra = [] if state.mesh in ("cd", "sphere", "plane") else [state.mesh]
    quality = view_point(arguments)[0]
    window = ViewerWindow(state, size, screenshot_dir=arguments.screenshot_dir, extra_meshes=extra,
                          weights_path=arguments.weights_path, max_samples=arguments.spp,
                          render_path=arguments.render_path, reference=reference, worker=worker, refine_view=guessed,
                          quality=quality, auto_exposure=state.has_sampled_light and not exposure_given,
                          environment_samples=arguments.environment_spp or ENVIRONMENT_SAMPLES, **window_options)
    return window


def run(arguments: argparse.Namespace) -> int:
    """Open the window and run it until it is closed (or ``--max-frames``)."""
    with open_window(arguments) as window:
        window.run(arguments.max_frames)
        if window.gl_errors:
            raise GratNetError(f"OpenGL reported errors: {'; '.join(window.gl_errors[:3])} (please report this)")
    return 0
