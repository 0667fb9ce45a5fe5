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
  fallback view and the exposure the black-picture hint would suggest (gratnet.showcase.suggest_exposure: the
  99th percentile of the lit pixels at white, raised until 3 % of the picture shows).
- ``--quality fast|accurate``: which of a shipped material's points renders (gratnet.quality; default: the
  accurate one, ``assets/NAME/model.npz``). A material without the point asked for, or ``--quality`` with a
  model-file path, is one line before any work. The default view (light, camera, exposure) is the material's,
  worked out from its accurate point, so that both points render the same scene. The saved config records the
  point (``render.quality``) and its model file (``model_file``).
- ``--spp N``: N samples per pixel (anti-aliasing: the mean of N renders at sub-pixel offsets, each its own
  key vector; the same flag and meaning as ``gratnet mitsuba-render``); default 1.
- Output: ``.png`` = display sRGB, 8-bit (``gratnet.display``, like every GratNet PNG); ``.exr`` = linear
  sRGB, float32 channels R, G, B, exposure applied, unclipped. The resolved config is saved beside it
  (``NAME.config.json``); both are written atomically.
- Long renders: a progress bar on stderr once a render has run 2 s (``--quiet``: none), cleared at the end.
  Ctrl-C: exit status 130 within a second (the GPU work goes in short calls, :mod:`viewer.pacing`; inside a
  shader's first compile on a cold Mesa cache, one long call, the command's supervisor stops it:
  gratnet/interrupts.py) and one line; nothing is written (no image, no config, no temporary), or the line says
  the output had landed already.
- ``--size``: a size this machine cannot render (the GL limits, a render target the driver does not allocate,
  more memory than is available) is refused in one line that names the largest size that fits, before any
  shader compiles (:func:`check_render_size`).

The command only: its config, flags, checks and output writing are viewer.scene_config's (shared with
``gratnet view`` and ``gratnet mitsuba-render``); materials and meshes are viewer.catalog's. Runtime-side:
no torch, no glfw, no imgui.
"""

from __future__ import annotations

import argparse
import atexit
import contextlib
import dataclasses
import gc
import sys
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import TYPE_CHECKING

from gratnet.config import add_arguments, add_quiet_flag, from_arguments
from gratnet.errors import GratNetError
from gratnet.lights import POINT, chosen_kind
from viewer.scene_config import (
    DEFAULT_MATERIAL,
    MAX_SAMPLES,
    RenderConfig,
    add_scene_arguments,
    check_lighting,
    check_scene,
    environment_of,
    environment_rotation,
    lighting_help,
    load_reference,
    quality_help,
    resolve_point,
    resolve_scene_command,
    scene_fields,
    warn_if_black,
    with_fallback,
    write_render,
)

if TYPE_CHECKING:
    import moderngl

    from viewer.pacing import Progress

__all__ = ["PROGRESS_DELAY", "available_memory", "check_render_size", "register", "render_bytes", "resolve_config",
           "run"]

#: A render shows its progress bar once it has run this long (seconds): short renders print nothing more.
PROGRESS_DELAY = 2.0
_PROGRESS_STEPS = 1000
#: Memory per pixel of the image on the CPU, besides the render targets (bytes; measured: 200 per pixel in
#: all at 2048² on llvmpipe, of which 20 the forward path's targets): the float32 read-back and its flip, the
#: XYZ, and the writer's float64 conversions (viewer.scene_config.write_render, gratnet.display).
_CPU_BYTES_PER_PIXEL = 192
_SIZE_LIMITS = ("GL_MAX_TEXTURE_SIZE", "GL_MAX_RENDERBUFFER_SIZE", "GL_MAX_VIEWPORT_DIMS")
_UNPROBED_BYTES = 1 << 26  # RGBA32F render targets up to 64 MiB (2048²) are not probed
_REFINING_PROBES = 4  # allocations that refine the largest size the driver takes, after halving found one


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
    add_scene_arguments(parser, lights={POINT.name: "point light position in metres instead of --light (irradiance 1 "
                                                    "at 1 m)"})
    add_quiet_flag(parser)
    actions = add_arguments(parser, RenderConfig)
    lighting_help(actions)
    # None when left out: --reference without --material renders the volume alone (no network, no model).
    actions["material"].default = None
    actions["material"].help = (f"{(actions['material'].help or '').rsplit(' (default', 1)[0]} (default: "
                                f"{DEFAULT_MATERIAL}; none with --reference)")
    quality_help(actions)
    parser.set_defaults(handler=run)


def resolve_config(arguments: argparse.Namespace) -> RenderConfig:
    """The config from the flags, every compound flag parsed and every value checked (no GL yet)."""
    config = dataclasses.replace(from_arguments(RenderConfig, arguments), **scene_fields(arguments))
    check_scene(config)
    if config.material:  # None until _render fills the default: the point asked for exists (before any model is read)
        resolve_point(config)
    if config.slice and config.width != config.height:
        raise GratNetError(f"--slice renders a square image; give --size N,N (got {config.width},{config.height})")
    light_flag = chosen_kind(config).flag
    if config.slice and light_flag is not None:
        raise GratNetError(f"--slice takes a directional light (--light θ,φ), not {light_flag.flag}")
    if isinstance(config.spp, bool) or not 1 <= config.spp <= MAX_SAMPLES:
        raise GratNetError(f"--spp (samples per pixel) must be an integer in 1 … {MAX_SAMPLES}, got {config.spp}")
    if config.slice and config.spp != 1:
        raise GratNetError("--spp applies to mesh renders; --slice renders the BRDF slice at one sample per pixel")
    if config.reference and config.skip_dark:
        raise GratNetError("--skip-dark skips the network by its output bound; a --reference render looks up every "
                           "pixel")
    if config.reference and config.render_path == "deferred":
        raise GratNetError("--render-path deferred evaluates the network in a compute pass; a --reference render "
                           "takes the forward path (auto or forward)")
    check_lighting(config)
    if config.has_sampled_light:
        flag = "--environment" if config.has_environment else "--area-light"
        if config.slice:
            raise GratNetError(f"--slice renders the BRDF slice under one directional light; {flag} lights "
                               "mesh renders")
        if config.skip_dark:
            raise GratNetError(f"--skip-dark bounds one light's pixel; under {flag} every sample counts")
    return config


@contextlib.contextmanager
def _progress_bar(quiet: bool) -> Iterator[Progress]:
    """A progress bar on stderr for the render (tqdm, as the other commands), shown once it has run for
    :data:`PROGRESS_DELAY` seconds, cleared when it ends; ``quiet``: none. Yields the renderers' report."""
    from tqdm import tqdm

    from viewer.pacing import sigint_deferred

    with tqdm(total=_PROGRESS_STEPS, desc="gratnet render", delay=PROGRESS_DELAY, leave=False, disable=quiet,
              file=sys.stderr, bar_format="{desc}: {percentage:3.0f}%|{bar}| {elapsed}<{remaining}") as bar:
        def report(fraction: float) -> None:
            with sigint_deferred():  # a Ctrl-C inside tqdm's refresh would leave the bar on the screen
                bar.update(max(0, round(_PROGRESS_STEPS * min(1.0, fraction)) - bar.n))

        yield report


def run(arguments: argparse.Namespace) -> int:
    """Check every input, render, write the image and its config atomically. Ctrl-C: exit status 130 and one
    line saying whether the output was written (it lands whole or not at all; the render answers within a
    second, :mod:`viewer.pacing`)."""
    out = Path(arguments.out)
    before = _file_state(out)
    try:
        return _render(arguments, out)
    except (KeyboardInterrupt, ImportError) as error:
        from gratnet.cli import is_interrupt

        if not is_interrupt(error):  # an ImportError of its own
            raise
        landed = _file_state(out) not in (before, None)
        what = f"{out} and its config were written before it" if landed else "nothing was written"
        print(f"gratnet render: interrupted; {what}", file=sys.stderr)
        # The interpreter's own teardown then spends 0.4 s collecting colour-science's objects (measured on
        # llvmpipe's 2-core machine); frozen at exit, nothing is collected: the process ends within ~0.05 s.
        atexit.register(gc.freeze)
        return 130


def _file_state(path: Path) -> tuple[int, int] | None:
    """``(inode, mtime_ns)`` of the file at ``path``, or None: a new file landed there if this changed."""
    try:
        status = path.stat()
    except OSError:
        return None
    return status.st_ino, status.st_mtime_ns


def _render(arguments: argparse.Namespace, out: Path) -> int:
    """:func:`run` up to Ctrl-C's handling."""
    import numpy as np

    from gratnet.modelfile import load_model
    from viewer.camera import Camera, Light
    from viewer.catalog import build_mesh, model_label

    reference_only = bool(arguments.reference) and arguments.material is None
    exposure_given = arguments.exposure is not None
    if reference_only and arguments.quality is not None:
        raise GratNetError("--quality chooses a shipped material's point; a --reference render without --material "
                           "has no network")
    if arguments.material is None:
        arguments.material = DEFAULT_MATERIAL
    auto_exposure = reference_only and arguments.exposure is None
    if reference_only:  # no material to derive the defaults from: the fallback view, exposure from the picture
        probe = with_fallback(arguments)
        arguments.light_text, arguments.camera_text, arguments.exposure = (probe.light_text, probe.camera_text,
                                                                            probe.exposure)
    config = resolve_scene_command(arguments, resolve_config)
    config = dataclasses.replace(config, environment_rotation=environment_rotation(config))  # saved as resolved
    environment = environment_of(config)
    area_lights = config.area_lights
    # Under sampled light the unit light's default exposure means nothing: the exposure comes from the picture.
    auto_exposure = auto_exposure or (config.has_sampled_light and not exposure_given)
    if auto_exposure:
        config = dataclasses.replace(config, exposure=1.0)
    if config.skip_dark and out.suffix.lower() != ".png":
        raise GratNetError("--skip-dark applies to .png output only: an EXR keeps values below the display's step")
    camera = Camera(config.camera_distance, config.camera_azimuth_degrees, config.camera_elevation_degrees,
                    fov_deg=config.fov_degrees)
    light = Light.from_config(config, config.effective_light_intensity)
    model_path = None
    if not reference_only:
        model_path, config = resolve_point(config)
    volume = (load_reference(config.reference, config.reference_precision,
                             None if reference_only else config.material) if config.reference else None)
    if volume is not None:
        model = volume
    else:
        assert model_path is not None  # None only for --reference alone, whose volume was loaded
        model = load_model(model_path)
    mesh = None if config.slice else build_mesh(config.mesh)

    from gratnet.bounds import DISPLAY_SKIP_THRESHOLD
    from gratnet.showcase import suggest_exposure
    from viewer.context import create_headless_context
    from viewer.scene import SceneRenderer

    # Skipping is exact only for an 8-bit display image; EXR keeps every value the network gives.
    skip_threshold = DISPLAY_SKIP_THRESHOLD if config.skip_dark else None
    ctx = create_headless_context()
    try:
        check_render_size(ctx, config)  # before any program compiles: a size this machine cannot render is refused
        with SceneRenderer(ctx, model, weights_path=config.weights_path, render_path=config.render_path,
                           deferred_weights=config.weight_form,
                           reference_precision=config.reference_precision) as renderer:
            # A BRDF slice has one path (a full-screen fragment pass); a mesh takes the one chosen.
            asked = None if config.render_path == "auto" or config.reference else config.render_path
            path, reason = renderer.path_for_render(config.has_sampled_light, asked) if not config.slice else (
                "forward", "BRDF slices are rendered by the fragment pass only")
            resolved = {"path": path, "reason": reason}
            # The deferred path's kernel and weights as resolved (auto: by the rasterizer), beside the path.
            deferred_weights = (renderer.deferred.weights if resolved["path"] == "deferred"
                                and renderer.deferred is not None else None)
            with _progress_bar(arguments.quiet) as progress:
                if mesh is None:  # --slice
                    xyz = renderer.shading.render_brdf_slice(config.light_theta_degrees, config.light_phi_degrees,
                                                             config.width, config.exposure, config.effective_ior,
                                                             skip_threshold=skip_threshold, progress=progress)
                else:
                    renderer.forward.progress = progress  # set after the path is chosen: not its probe's renders
                    if renderer.deferred is not None:
                        renderer.deferred.progress = progress
                    xyz = renderer.render(mesh, camera, light, (config.width, config.height), config.exposure,
                                          config.effective_ior, skip_threshold=skip_threshold, samples=config.spp,
                                          environment=environment, seed=config.seed,
                                          sampling=config.environment_sampling, area_lights=area_lights,
                                          render_path=path)
    finally:
        ctx.release()
    if not np.all(np.isfinite(xyz)):
        raise GratNetError("the render contains NaN or inf; nothing was written (please report this)")
    if auto_exposure:  # rendered at exposure 1; the picture is linear in it
        exposure = suggest_exposure(xyz, 1.0) or 1.0  # the black-image hint's rule; 1 when nothing is lit
        xyz = xyz * exposure
        config = dataclasses.replace(config, exposure=exposure)
    if reference_only:
        config = dataclasses.replace(config, material="")

    documents: dict[str, object] = {"render": config, "render_path": resolved}
    if deferred_weights is not None:
        documents["deferred_weights"] = deferred_weights
    if model_path is not None:
        documents["model_file"] = str(model_path)
    if environment is not None:
        documents["environment"] = {"name": environment.name, "source": environment.source,
                                    "texels": list(environment.shape)}
    if volume is not None:
        documents["reference"] = {"file": str(Path(config.reference).resolve()), "slices": volume.slices,
                                  "resolution": volume.resolution, "scheme": volume.metadata.get("scheme"),
                                  "source": volume.metadata.get("source"), "precision": config.reference_precision}
    write_render(out, xyz, **documents)
    what = (f"BRDF slice, light θ={config.light_theta_degrees:g}° φ={config.light_phi_degrees:g}°" if config.slice
            else f"mesh {config.mesh}")
    samples = "" if config.slice else f", {config.spp} spp"
    samples += f", environment {environment.name}" if environment is not None else ""
    samples += f", {len(area_lights)} area light{'s' if len(area_lights) > 1 else ''}" if area_lights else ""
    if model_path is None:
        source = f"reference {Path(config.reference).name}"
    else:
        source = model_label(model_path)
        source += f" (reference {Path(config.reference).name})" if volume is not None else ""
    print(f"wrote {out}: {source}, {what}, {config.width}×{config.height}{samples}, exposure {config.exposure:g}")
    warn_if_black(xyz, config.exposure)
    return 0


def available_memory() -> int | None:
    """Bytes of memory available to a new allocation (``MemAvailable`` of ``/proc/meminfo``), or None where
    that file is missing (the memory check is then skipped)."""
    try:
        with open("/proc/meminfo", encoding="ascii") as meminfo:
            for line in meminfo:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        return None
    return None


def check_render_size(ctx: moderngl.Context, config: RenderConfig) -> None:
    """Refuse, in one :class:`GratNetError` naming the largest size that would do, a ``--size`` this machine
    cannot render, before any program compiles: beyond the GL limits (``GL_MAX_TEXTURE_SIZE``,
    ``GL_MAX_RENDERBUFFER_SIZE``, ``GL_MAX_VIEWPORT_DIMS``), more memory than ``MemAvailable``
    (:func:`render_bytes`), or a float32 render target the driver does not allocate (probed: llvmpipe refuses
    single textures over about 1.5 GiB, e.g. 12000×12000 RGBA32F).

    The largest size is searched at the same aspect ratio: first by the limits and the memory (free to ask),
    then by a few allocations (a refused one costs nothing; an accepted one about a second per GiB on llvmpipe,
    which clears its textures)."""
    width, height = config.width, config.height
    problem = _size_problem(ctx, config, width, height)
    if problem is None:
        problem = None if _allocates(ctx, width, height) else (
            f"the GPU ({ctx.info.get('GL_RENDERER', '?')}) cannot allocate a {width}×{height} float32 RGBA render "
            f"target ({16 * width * height / 2**30:.1f} GiB)")
    if problem is None:
        return
    low = _largest(lambda side: _size_problem(ctx, config, side, _scaled_height(width, height, side)) is None, 0,
                   width)
    if low and not _allocates(ctx, low, _scaled_height(width, height, low)):
        high = low
        while low and not _allocates(ctx, low, _scaled_height(width, height, low)):  # halve the bytes
            high, low = low, int(low / 2**0.5)
        low = _largest(lambda side: _allocates(ctx, side, _scaled_height(width, height, side)), low, high,
                       _REFINING_PROBES)
    fits = f"; at most {low},{_scaled_height(width, height, low)} at this aspect ratio" if low else ""
    raise GratNetError(f"--size {width},{height} is too large for this machine: {problem}{fits}")


def _largest(fits: Callable[[int], bool], low: int, high: int, steps: int | None = None) -> int:
    """The largest ``side`` in ``low … high − 1`` that ``fits`` (``low`` is known to, or is 0; ``high`` is known
    not to), by bisection, at most ``steps`` steps (None: to the end)."""
    while high - low > 1 and (steps is None or steps > 0):
        middle = (low + high) // 2
        low, high = (middle, high) if fits(middle) else (low, middle)
        steps = None if steps is None else steps - 1
    return low


def _scaled_height(width: int, height: int, scaled_width: int) -> int:
    return max(1, height * scaled_width // width)


def render_bytes(config: RenderConfig, width: int, height: int, software: bool) -> int:
    """The memory a render of ``width`` × ``height`` pixels takes at its peak, in bytes: the image on the CPU
    (the read-back, its flip, the XYZ and the float64 conversions of the writer: :data:`_CPU_BYTES_PER_PIXEL`)
    and, on a software rasterizer, whose "GPU" memory is this memory, the render targets of the path that
    takes the most (forward: RGBA32F targets, a sum per layer for several samples, float32 depth; deferred:
    the stacked G-buffer, its depth and list, the tint's stack under sampled light, the resolved mean; a slice:
    two RGBA32F targets)."""
    from viewer.deferred import CHUNK_TEXELS

    pixels = width * height
    several = config.spp > 1
    if config.slice:
        targets = 32
    else:
        stacked = max(1, min(config.spp, CHUNK_TEXELS // max(1, pixels)))
        forward = 16 * (2 if several else 1) + 4
        deferred = (24 + (16 if config.has_sampled_light else 0)) * stacked + (16 if several else 0)
        targets = max(forward, deferred)
    return pixels * (_CPU_BYTES_PER_PIXEL + (targets if software else 0))


def _size_problem(ctx: moderngl.Context, config: RenderConfig, width: int, height: int) -> str | None:
    """Why a ``width`` × ``height`` render cannot be made here by the GL limits or the memory, or None."""
    from viewer.renderer import is_software_rasterizer

    for name in _SIZE_LIMITS:
        value = ctx.info.get(name)  # an int, or (width, height) for the viewport
        most = (value, value) if isinstance(value, int) else tuple(value) if isinstance(value, tuple) else None
        if most is not None and len(most) == 2 and (width > most[0] or height > most[1]):
            return f"{name} is {value} here"
    available = available_memory()
    needed = render_bytes(config, width, height, is_software_rasterizer(ctx))
    if available is not None and needed > available:
        return (f"the render needs about {needed / 2**30:.1f} GiB of memory and {available / 2**30:.1f} GiB is "
                f"available")
    return None


def _allocates(ctx: moderngl.Context, width: int, height: int) -> bool:
    """Whether the driver makes a complete framebuffer of a ``width`` × ``height`` RGBA32F texture and a depth
    renderbuffer (what every path renders into; nothing is drawn). Up to :data:`_UNPROBED_BYTES` per texture
    the answer is yes without asking (every GL 4.3 driver allocates that)."""
    import moderngl

    if 16 * width * height <= _UNPROBED_BYTES:
        return True

    owned: list[moderngl.Texture | moderngl.Renderbuffer | moderngl.Framebuffer] = []
    try:
        texture = ctx.texture((width, height), 4, dtype="f4")
        owned.append(texture)
        depth = ctx.depth_renderbuffer((width, height))
        owned.append(depth)
        owned.append(ctx.framebuffer(color_attachments=[texture], depth_attachment=depth))
    except moderngl.Error:
        return False
    finally:
        for resource in reversed(owned):
            resource.release()
    return True
