"""Rendering a trained material on a mesh: one light, one camera, the network per pixel.

:class:`SceneRenderer` rasterizes a :class:`~viewer.meshes.Mesh` with ``shaders/surface.glsl``: each
covered pixel takes the light direction ωi and the view direction ωo into the surface's tangent frame
(x = tangent, y = bitangent, z = normal), evaluates the network at the key vector ``−(ωi + ωo)``
(docs/physics.md eq. 6–7) and multiplies by the A-term (eq. 5), the light's irradiance and the exposure.
The output is **exposed CIE XYZ**, linear, ``float32`` ``(H, W, 3)`` with row 0 at the top; pixels the
mesh does not cover are 0 (``render_rgba``'s alpha is the coverage, 1 or 0). The depth test is on, face
culling off (back faces are covered but black).

Two render paths (issue 12, ``render_path``) with the same output: :mod:`viewer.forward` (the network in
the fragment shader) and :mod:`viewer.deferred` (a G-buffer pass, then the network in a compute shader over
the pixels that need it). Both take sub-pixel sample offsets and share the mesh buffers and surface
uniforms of :mod:`viewer.surface`; :meth:`SceneRenderer.render_rgba` dispatches between them in one place,
and :func:`choose_render_path` (``auto``) times both once per GPU and network shape on a probe scene (the
CD disc at :data:`PROBE_SIZE`) and caches the verdict in ``$XDG_CACHE_HOME/gratnet/render_path.json``
(else ``~/.cache/…``), keyed by ``GL_RENDERER`` and the network shape.

Work skipped (issue 5): the forward path's depth pre-pass (on by default) draws the mesh's depth first, so
that the shading pass runs the network once per visible pixel (no overdraw); back faces and A = 0 never run it; with a
``skip_threshold`` (:data:`~gratnet.bounds.DISPLAY_SKIP_THRESHOLD` for 8-bit display output, as
``gratnet render --skip-dark`` passes) pixels whose output bound (``gratnet.bounds``) cannot reach the
display's smallest step are 0 without running it. Nothing skips by default: exact linear values for EXR
files and comparisons, and the bound costs minutes to build on first use per model (then it is cached).
A ``statistics`` dict receives the work counters.

The network's weight texture, the model uniforms and the shader defines are those of
:class:`~viewer.renderer.NetworkRenderer`, which this class owns; its BRDF slices are available too.

Display: :meth:`SceneRenderer.display_srgb8` and :meth:`SceneRenderer.linear_srgb` use ``gratnet.display``
(colour-science, float64), the path that the trainer's PNGs (``gratnet brdfslice``, evaluation reports)
take, so a render and a ground-truth image of the same XYZ are byte-identical. The GLSL ``display``
program that an interactive window would use agrees with it to 2e-6 before the 8-bit rounding
(tests/runtime/test_shader_parity.py), i.e. at most one level where a value sits on a rounding boundary.

Rendering only: no glfw, no imgui, no torch.
"""

from __future__ import annotations

import json
import logging
import math
import time
from collections.abc import Callable
from pathlib import Path

import moderngl
import numpy as np

from gratnet.area_lights import AreaLight
from gratnet.atomic import cache_folder
from gratnet.codes import DEFAULT_ENVIRONMENT_SAMPLING, RENDER_PATHS, WeightForm
from gratnet.display import xyz_to_display_srgb8, xyz_to_linear_srgb
from gratnet.environment import Environment
from gratnet.errors import GratNetError
from gratnet.importance import MaterialTable, cached_material_table, flat_table, material_table, volume_table
from gratnet.modelfile import ModelFile
from gratnet.volume import Volume
from viewer.antialias import check_offsets, sample_range_offsets
from viewer.camera import Camera, Light
from viewer.deferred import DeferredRenderer
from viewer.environment_light import EnvironmentLighting, EnvironmentPass
from viewer.forward import ForwardRenderer
from viewer.meshes import Mesh
from viewer.reference import ReferenceRenderer
from viewer.renderer import NetworkRenderer, is_software_rasterizer
from viewer.shading import ShadingPrograms, skip_threshold_value
from viewer.surface import MeshBuffers, check_size, upload_mesh

__all__ = ["PROBE_SIZE", "RENDER_PATHS", "SceneRenderer", "check_render_path", "choose_render_path",
           "render_path_cache_file"]

_LOG = logging.getLogger("gratnet.scene")  # the gratnet command shows its INFO lines (gratnet/cli.py)
# RENDER_PATHS (gratnet.codes): ``render_path`` values of SceneRenderer and ``--render-path``.

#: The ``auto`` probe: the CD disc at this size (pixels), each path timed as the best of two renders (one
#: when it is already 1.5× slower than the other's best), after one untimed render that compiles it.
PROBE_SIZE = (128, 128)
_PROBE_RENDERS = 2
_PROBE_CLEAR_RATIO = 1.5
_CACHE_VERSION = 2  # 2: the key names a feature-grid model's levels


def check_render_path(render_path: object) -> str:
    """``render_path`` if it is one of :data:`RENDER_PATHS`, else :class:`GratNetError` (one line)."""
    if not isinstance(render_path, str) or render_path not in RENDER_PATHS:
        raise GratNetError(f"render path must be one of {', '.join(RENDER_PATHS)}, got {render_path!r}")
    return render_path


class SceneRenderer:
    """Renders meshes shaded by a trained network (see the module docstring).

    Args:
        ctx: an OpenGL ≥ 4.3 context (:func:`viewer.context.create_headless_context`).
        model: the trained network.
        shader_root: folder of the GLSL files (default: the repository's ``shaders/``).
        weights_path: ``auto``, ``texture`` or ``baked``: where the shader reads the weights
            (:class:`~viewer.renderer.NetworkRenderer`; the choice is ``self.network.weights_path``).
        baked_source: as :class:`~viewer.renderer.NetworkRenderer` (a baked ``mlp.glsl`` made earlier).
        render_path: ``forward`` (:mod:`viewer.forward`), ``deferred`` (:mod:`viewer.deferred`) or ``auto``
            (:func:`choose_render_path`: measured once per GPU and network shape, cached). Both give the same
            images; :meth:`render_layers` (key vectors and A) and BRDF slices always run forward, and
            ``depth_prepass`` only concerns the forward path.
        deferred_weights: where the deferred path's compute shader reads the weights
            (:data:`viewer.deferred.DEFERRED_WEIGHTS`, or its :class:`~gratnet.codes.WeightForm`).
        measure_render_path: ``auto`` may time both paths when nothing is cached (False: ``forward`` then;
            the viewer, whose compile process measures off the window's thread).

        reference_precision: a reference scene's texture storage (:data:`gratnet.reference.PRECISIONS`).

    ``model`` may also be a ground-truth :class:`~gratnet.volume.Volume`: a *reference* scene, the volume looked
    up where the network would run (:mod:`viewer.reference`), on the forward path only.

    Attributes:
        network: the :class:`~viewer.renderer.NetworkRenderer` (weights, programs, BRDF slices); None in a
            reference scene.
        reference: the :class:`~viewer.reference.ReferenceRenderer` of a reference scene, else None.
        shading: whichever of the two this scene draws with.
        model: the network's model file (None in a reference scene).
        forward, deferred: the two paths (:class:`~viewer.forward.ForwardRenderer`,
            :class:`~viewer.deferred.DeferredRenderer`, None in a reference scene); each compiles nothing until used.
    """

    def __init__(self, ctx: moderngl.Context, model: ModelFile | Volume, shader_root: str | Path | None = None,
                 weights_path: str = "auto", baked_source: str | None = None, render_path: str = "auto",
                 deferred_weights: str | WeightForm = "auto", measure_render_path: bool = True,
                 reference_precision: str = "float16") -> None:
        self._requested_path = check_render_path(render_path)
        self.ctx = ctx
        self.network: NetworkRenderer | None = None
        self.reference: ReferenceRenderer | None = None
        self.deferred: DeferredRenderer | None = None
        self.shading: ShadingPrograms
        if isinstance(model, Volume):  # the reference: the forward path's programs with the look-up for the MLP
            self.reference = ReferenceRenderer(ctx, model, shader_root, reference_precision)
            self.shading = self.reference
            self._requested_path = "forward"
            self.model = None
        else:
            self.network = NetworkRenderer(ctx, model, shader_root, weights_path, baked_source)
            self.shading = self.network
            self.model = model
            self.deferred = DeferredRenderer(self.network, deferred_weights)
        self.forward = ForwardRenderer(self.shading)
        self._source = model
        self._importance: MaterialTable | None = None  # the material's importance table (environment light)
        #: Sample with :func:`gratnet.importance.flat_table` while the material's own table is not built yet (the
        #: viewer's window, whose compile child builds it) instead of building it here: each pass stays unbiased.
        self.provisional_importance = False
        self._lighting: EnvironmentLighting | None = None  # the last environment's textures
        self._render_path: tuple[str, str] | None = None
        self._measure_render_path = measure_render_path

    @property
    def render_path(self) -> str:
        """The path mesh renders take, ``forward`` or ``deferred`` (``auto`` measures on first use)."""
        return self._resolved_path()[0]

    @property
    def render_path_reason(self) -> str:
        """Why :attr:`render_path` was taken, e.g. ``requested`` or ``deferred: 12.1 ms vs forward 31.0 ms …``."""
        return self._resolved_path()[1]

    def _resolved_path(self) -> tuple[str, str]:
        if self._render_path is None:
            if self.reference is not None:
                self._render_path = "forward", "reference: the look-up runs on the forward path"
            else:
                self._render_path = choose_render_path(self, self._requested_path, self._measure_render_path)
        return self._render_path

    def path_for_render(self, sampled_light: bool, render_path: str | None = None) -> tuple[str, str]:
        """``(path, reason)`` of a mesh render: ``render_path`` if it names one; else :attr:`render_path`, but with
        sampled light (an environment or area lights) ``deferred`` on a software rasterizer when the scene's path is
        ``auto`` (a pass there costs a fraction of a forward one: docs/benchmarks.md "Environment light") and
        ``forward`` otherwise (a GPU's measured verdict was taken for one light)."""
        if render_path is not None:
            return render_path, "requested"  # render_rgba refuses deferred in a reference scene
        if sampled_light and self.reference is None:
            if self._requested_path == "auto" and is_software_rasterizer(self.ctx):
                return "deferred", ("auto: sampled light on a software rasterizer renders deferred (the network once "
                                    "per covered pixel, not per block of fragments)")
            return "forward", "sampled light renders forward unless the render asks for deferred"
        return self._resolved_path()

    @property
    def program(self) -> moderngl.Program:
        """The forward path's ``surface`` program, compiled on first use (the buffers of :meth:`upload` bind to it)."""
        return self.forward.program

    def upload(self, mesh: Mesh) -> MeshBuffers:
        """Upload ``mesh`` for drawing on either path (the caller releases the result)."""
        return upload_mesh(self.ctx, self.program, mesh)

    def render_layers(self, mesh: Mesh | MeshBuffers, camera: Camera, light: Light,
                      size: tuple[int, int] = (256, 256), exposure: float = 1.0,
                      ior: float | None = 1.5, *, skip_threshold: float | None = None, depth_prepass: bool = True,
                      statistics: dict[str, int] | None = None, samples: int = 1,
                      first_sample: int = 0, environment: Environment | None = None,
                      seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`render_rgba` and, per pixel, the key vector and the A-term behind it (forward path).

        Returns:
            ``(rgba, key_a)``, both ``float32`` ``(H, W, 4)`` with row 0 at the top: ``rgba`` as
            :meth:`render_rgba`; ``key_a[..., :3]`` = ``−(ωi + ωo)`` in the tangent frame (float32, as the
            network saw it) and ``key_a[..., 3]`` = A(ωi, ωo); 0 for back faces and uncovered pixels.
            With ``samples`` > 1 both are means over the samples (as :meth:`render_rgba`).
        """
        rgba, key_a = self._render(mesh, camera, light, size, exposure, ior, 2, skip_threshold, depth_prepass,
                                   statistics, self._offsets(samples, first_sample, None), "forward", first_sample,
                                   environment, seed)
        return rgba, key_a

    def render_rgba(self, mesh: Mesh | MeshBuffers, camera: Camera, light: Light, size: tuple[int, int] = (256, 256),
                    exposure: float = 1.0, ior: float | None = 1.5, *, skip_threshold: float | None = None,
                    depth_prepass: bool = True, statistics: dict[str, int] | None = None, samples: int = 1,
                    first_sample: int = 0, offsets_px: np.ndarray | None = None,
                    render_path: str | None = None, environment: Environment | None = None,
                    seed: int = 0, sampling: str = DEFAULT_ENVIRONMENT_SAMPLING, pixel_origin: tuple[int, int] = (0, 0),
                    area_lights: tuple[AreaLight, ...] = ()) -> np.ndarray:
        """Exposed CIE XYZ and coverage, ``float32`` ``(H, W, 4)``, row 0 at the top.

        Channels 0–2: ``exposure · irradiance · A(ωi, ωo) · XYZ(−(ωi + ωo))`` (physics.md eq. 5–7) with
        ωi, ωo in the tangent frame at the pixel's surface point; 0 for back faces, directions below the
        surface's horizon, and uncovered pixels. Channel 3: 1 where the mesh covers the pixel centre.
        ``ior`` is the Fresnel refractive index (``None`` or 0: no Fresnel).

        ``skip_threshold``: exposed linear sRGB below which the display shows 0 (``DISPLAY_SKIP_THRESHOLD``
        for 8-bit display output): the network is skipped (pixel 0) where its bound cannot reach it;
        ``None``/0: off (exact). ``depth_prepass``: draw the depth first so each visible pixel runs the
        network once (False: one shading pass, occluded fragments drawn earlier still run it).
        ``statistics``: a dict to fill with the work counters (``viewer.renderer.STATISTICS_KEYS``), from a
        counting variant of the program (slower: time renders without it).

        Anti-aliasing (issue 12): ``samples`` per pixel (1 … :data:`viewer.antialias.MAX_SAMPLES`), each a full
        render with the view-projection moved by a sub-pixel offset (:func:`viewer.antialias.sample_offsets`:
        Halton (2, 3), the first at the pixel centre), so each sample has its own surface point, ωi, ωo and
        key vector; the result is their mean in float32, coverage included (the fraction of the samples that
        hit the mesh). ``first_sample``: start at that index of the sequence (progressive accumulation adds
        samples k, k + 1, … one render at a time; the mean of samples 0 … N−1 so rendered is the N-sample
        render). ``samples=1`` (the default) is the render without anti-aliasing, bit for bit.
        ``offsets_px``: explicit sub-pixel offsets instead (pixels, ``(N, 2)``, x right, y up).

        ``render_path``: ``forward`` or ``deferred`` for this render only (default: :attr:`render_path`).

        ``environment``: an environment light besides ``light`` (issue 43; a ``light`` of intensity 0 is none),
        integrated by shaders/environment.glsl: each sample is one pass of its estimator, pass
        ``first_sample + k`` for sample k, with random numbers from ``seed``; the mean over samples converges to
        the integral (physics.md "Environment light"), so more samples mean less noise. Both paths give the same
        estimate, on the path :meth:`path_for_render` gives (deferred on a software rasterizer unless asked otherwise).
        ``sampling``: gratnet.codes.ENVIRONMENT_SAMPLING: ``resampled`` (the default), ``mis``, or ``light`` /
        ``material`` alone.
        ``pixel_origin``: this image's lower-left pixel in a larger picture (GL pixels, y up), when it is a band of
        one: the light samples are keyed by the whole picture's pixels, so the bands of N passes make the picture of
        one N-pass render of the whole.
        ``area_lights``: area lights (gratnet.area_lights) besides ``light`` and the environment, sampled by the same
        estimator (physics.md "Area lights"; either path, as ``environment``).
        """
        offsets = self._offsets(samples, first_sample, offsets_px)
        path = self.path_for_render(environment is not None or bool(area_lights), render_path)[0]
        if path not in ("forward", "deferred"):
            raise GratNetError(f"a render takes the forward or the deferred path, got {render_path!r}")
        if path == "deferred" and self.deferred is None:
            raise GratNetError("a reference render takes the forward path only")
        return self._render(mesh, camera, light, size, exposure, ior, 1, skip_threshold, depth_prepass,
                            statistics, offsets, path, first_sample, environment, seed, sampling, pixel_origin,
                            area_lights)[0]

    @staticmethod
    def _offsets(samples: int, first_sample: int, offsets_px: np.ndarray | None) -> np.ndarray:
        """The sub-pixel offsets of samples ``first_sample`` … ``first_sample + samples − 1``
        (:func:`viewer.antialias.sample_offsets`), or ``offsets_px`` checked."""
        return sample_range_offsets(samples, first_sample) if offsets_px is None else check_offsets(offsets_px)

    def _render(self, mesh: Mesh | MeshBuffers, camera: Camera, light: Light, size: tuple[int, int],
                exposure: float, ior: float | None, layers: int, skip_threshold: float | None,
                depth_prepass: bool, statistics: dict[str, int] | None, offsets: np.ndarray,
                path: str, first_sample: int = 0, environment: Environment | None = None,
                seed: int = 0, sampling: str = DEFAULT_ENVIRONMENT_SAMPLING, pixel_origin: tuple[int, int] = (0, 0),
                area_lights: tuple[AreaLight, ...] = ()) -> list[np.ndarray]:
        """Every render method's checks (before any GL work), then ``path``; a :class:`Mesh` is uploaded for
        this render only."""
        width, height = check_size(size)
        skip_threshold_value(skip_threshold)
        lighting = None
        if environment is not None or area_lights:
            if environment is not None and not isinstance(environment, Environment):
                raise GratNetError(f"expected a gratnet.environment.Environment, got {type(environment).__name__}")
            lighting = EnvironmentPass(self.environment_lighting(environment, tuple(area_lights)),
                                       light.intensity > 0.0, seed, sampling, pixel_origin)
            skip_threshold = None  # a pass's sample is not the pixel: the output bound says nothing of the mean
        uploaded = mesh if isinstance(mesh, MeshBuffers) else self.upload(mesh)
        try:
            if path == "deferred" and self.deferred is not None:  # all samples in one list; render_layers: forward
                return [self.deferred.render(uploaded, camera, light, (width, height), exposure, ior, skip_threshold,
                                             statistics, offsets, first_sample, lighting)]
            return self.forward.render(uploaded, camera, light, (width, height), exposure, ior, layers,
                                       skip_threshold, depth_prepass, statistics, offsets, first_sample, lighting)
        finally:
            if uploaded is not mesh:
                uploaded.release()

    def render(self, mesh: Mesh | MeshBuffers, camera: Camera, light: Light, size: tuple[int, int] = (256, 256),
               exposure: float = 1.0, ior: float | None = 1.5, *, skip_threshold: float | None = None,
               depth_prepass: bool = True, statistics: dict[str, int] | None = None, samples: int = 1,
               first_sample: int = 0, environment: Environment | None = None, seed: int = 0,
               sampling: str = DEFAULT_ENVIRONMENT_SAMPLING, area_lights: tuple[AreaLight, ...] = (),
               render_path: str | None = None) -> np.ndarray:
        """Exposed CIE XYZ, ``float32`` ``(H, W, 3)``, row 0 at the top (see :meth:`render_rgba`)."""
        rgba = self.render_rgba(mesh, camera, light, size, exposure, ior, skip_threshold=skip_threshold,
                                depth_prepass=depth_prepass, statistics=statistics, samples=samples,
                                first_sample=first_sample, environment=environment, seed=seed, sampling=sampling,
                                area_lights=area_lights, render_path=render_path)
        return np.ascontiguousarray(rgba[..., :3])

    def importance_table(self) -> MaterialTable:
        """The material's importance table (gratnet.importance: the network's, or the ground-truth volume's in a
        reference scene), built on first use (cached on disk by gratnet.importance)."""
        if self._importance is None:
            if isinstance(self._source, Volume):
                self._importance = volume_table(self._source)
            else:
                self._importance = material_table(self._source)
        return self._importance

    def importance_table_ready(self) -> bool:
        """Whether the material's own importance table is at hand (in this scene, in memory or in the disk cache: a
        look that never builds it); once found it replaces a provisional flat table at the next environment pass."""
        if self._importance is None and self.model is not None:
            self._importance = cached_material_table(self.model)
        return self._importance is not None

    @property
    def importance_provisional(self) -> bool:
        """Whether environment passes now sample with the flat table (:attr:`provisional_importance`, no own table
        yet)."""
        return self.provisional_importance and self._importance is None

    def environment_lighting(self, environment: Environment | None,
                             area_lights: tuple[AreaLight, ...] = ()) -> EnvironmentLighting:
        """``environment``'s textures and ``area_lights`` on this context with the material's importance table (kept
        for the next render with the same environment object, equal area lights and the same table); the flat table
        while :attr:`importance_provisional`."""
        table = flat_table() if self.importance_provisional else self.importance_table()
        if (self._lighting is not None and self._lighting.matches(environment, area_lights)
                and self._lighting.table.digest == table.digest):
            return self._lighting
        if self._lighting is not None:
            self._lighting.release()
            self._lighting = None
        self._lighting = EnvironmentLighting(self.ctx, environment, table, area_lights)
        return self._lighting

    def render_srgb8(self, mesh: Mesh | MeshBuffers, camera: Camera, light: Light,
                     size: tuple[int, int] = (256, 256), exposure: float = 1.0, ior: float | None = 1.5, *,
                     skip_threshold: float | None = None, depth_prepass: bool = True,
                     statistics: dict[str, int] | None = None, samples: int = 1, first_sample: int = 0) -> np.ndarray:
        """8-bit display sRGB ``(H, W, 3)`` (``gratnet.display``) of :meth:`render`; with
        ``skip_threshold=gratnet.bounds.DISPLAY_SKIP_THRESHOLD`` the network is skipped where the display
        would show 0 (off by default: the first use per model builds its output bound, minutes on a CPU)."""
        xyz = self.render(mesh, camera, light, size, exposure, ior, skip_threshold=skip_threshold,
                          depth_prepass=depth_prepass, statistics=statistics, samples=samples,
                          first_sample=first_sample)
        return self.display_srgb8(xyz)

    def render_brdf_slice(self, theta_deg: float, phi_deg: float, size: int, exposure: float = 1.0,
                          ior: float | None = 1.5, skip_threshold: float | None = None,
                          statistics: dict[str, int] | None = None, rows: tuple[int, int] | None = None) -> np.ndarray:
        """The material's BRDF slice (``ShadingPrograms.render_brdf_slice``): exposed XYZ ``(size, size, 3)``."""
        return self.shading.render_brdf_slice(theta_deg, phi_deg, size, exposure, ior, skip_threshold, statistics,
                                              rows)

    # ---------------------------------------------------------------------------------------------
    # Display (gratnet.display: the same numbers as every other PNG GratNet writes)

    @staticmethod
    def display_srgb8(xyz: np.ndarray) -> np.ndarray:
        """8-bit display sRGB ``(H, W, 3)`` of an exposed XYZ image (exposure already applied):
        linear sRGB, clipped to [0, 1], sRGB transfer function, rounded (``gratnet.display``)."""
        return xyz_to_display_srgb8(np.asarray(xyz, dtype=np.float64), 1.0)

    @staticmethod
    def linear_srgb(xyz: np.ndarray) -> np.ndarray:
        """Linear sRGB ``float32`` ``(H, W, 3)`` of an exposed XYZ image, unclipped (for EXR files)."""
        return xyz_to_linear_srgb(np.asarray(xyz, dtype=np.float64)).astype(np.float32)

    def __enter__(self) -> SceneRenderer:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.release()

    def release(self) -> None:
        """Free the GL objects (the context belongs to the caller)."""
        if self._lighting is not None:
            self._lighting.release()
            self._lighting = None
        self.forward.release()
        if self.deferred is not None:
            self.deferred.release()
        self.shading.release()


# -------------------------------------------------------------------------------------------------
# Choosing the path by measurement


def render_path_cache_file() -> Path:
    """The JSON file of measured ``auto`` verdicts: ``$XDG_CACHE_HOME/gratnet/render_path.json`` (else
    ``~/.cache/gratnet/render_path.json``)."""
    return cache_folder("render_path.json")


def _cache_key(scene: SceneRenderer) -> str:
    """GL_RENDERER, the network's shape and where both paths read the weights: what the verdict depends on."""
    network, deferred = scene.network, scene.deferred
    if network is None or deferred is None:
        raise GratNetError("a reference scene has one render path: nothing to measure")
    model = network.model
    return (f"v{_CACHE_VERSION}|{scene.ctx.info.get('GL_RENDERER', '?')}|{'-'.join(map(str, model.layer_sizes))}|"
            f"{model.activation}|{model.encoding.frequencies},{model.encoding.t_frequencies}|{network.weights_path}|"
            f"{deferred.weights}|{_grid_signature(model)}")


def _grid_signature(model: ModelFile) -> str:
    """A feature-grid model's levels (their fetches cost both paths alike, but not alike to a pure MLP); each
    level's shape names its C, hence its ceil(C/4) textures."""
    if not model.grids:
        return "mlp"
    return "grid:" + ",".join("x".join(map(str, np.shape(grid))) for grid in model.grids)


def _read_cache(path: Path) -> dict[str, dict[str, object]]:
    try:
        entries = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return {}
    return entries if isinstance(entries, dict) else {}


def _write_cache(path: Path, key: str, entry: dict[str, object]) -> None:
    """Add ``entry`` under ``key``, atomically; a cache that cannot be written only costs a later probe."""
    from gratnet.atomic import write_text_atomic

    entries = _read_cache(path)
    entries[key] = entry
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        write_text_atomic(path, json.dumps(entries, indent=1, sort_keys=True) + "\n")
    except (OSError, GratNetError) as error:
        _LOG.info("cannot write the render-path cache %s: %s", path, error)


def _probe_ms(render: Callable[[], None], rival_ms: float = math.inf) -> float:
    """Best wall time (ms) of up to :data:`_PROBE_RENDERS` renders after one untimed render that compiles the
    programs; stops early once a render is clearly slower than ``rival_ms`` (the verdict is clear)."""
    render()
    best = math.inf
    for _ in range(_PROBE_RENDERS):
        start = time.perf_counter()
        render()
        best = min(best, 1e3 * (time.perf_counter() - start))
        if best > _PROBE_CLEAR_RATIO * rival_ms:
            break
    return best


def choose_render_path(scene: SceneRenderer, render_path: str = "auto", measure: bool = True) -> tuple[str, str]:
    """``(path, reason)``: ``render_path`` itself unless ``auto``, which takes the cached verdict for this
    ``GL_RENDERER`` and network shape, or measures both paths on the probe scene (the CD disc at
    :data:`PROBE_SIZE`, default light and camera) and caches the faster (:func:`render_path_cache_file`).
    ``measure=False``: no probe; ``forward`` while nothing is cached (the viewer: its compile process measures)."""
    check_render_path(render_path)
    if render_path != "auto":
        return render_path, "requested"
    cache = render_path_cache_file()
    key = _cache_key(scene)
    entry = _read_cache(cache).get(key)
    if isinstance(entry, dict) and entry.get("path") in ("forward", "deferred") and isinstance(entry.get("reason"),
                                                                                               str):
        return str(entry["path"]), f"{entry['reason']} (cached)"
    if not measure:
        return "forward", "auto: not measured yet on this GPU for this network shape (forward until it is)"

    from viewer.defaults import FALLBACK
    from viewer.meshes import compact_disc

    _LOG.info("render path auto: timing the forward and deferred paths on a %d×%d probe (once per GPU and network "
              "shape; cached in %s)", *PROBE_SIZE, cache)
    camera = Camera(FALLBACK.camera_distance, FALLBACK.camera_azimuth_degrees, FALLBACK.camera_elevation_degrees)
    light = Light.directional(FALLBACK.light_theta_degrees, FALLBACK.light_phi_degrees)
    uploaded = scene.upload(compact_disc())
    times: dict[str, float] = {}
    try:
        for path in ("deferred", "forward"):
            def render(path: str = path) -> None:
                scene.render_rgba(uploaded, camera, light, PROBE_SIZE, render_path=path)
                scene.ctx.finish()

            times[path] = _probe_ms(render, min(times.values(), default=math.inf))
    finally:
        uploaded.release()
    path = min(times, key=lambda name: times[name])
    other = "forward" if path == "deferred" else "deferred"
    renderer = scene.ctx.info.get("GL_RENDERER", "?")
    reason = (f"{path}: {times[path]:.1f} ms vs {other} {times[other]:.1f} ms at {PROBE_SIZE[0]}×{PROBE_SIZE[1]} "
              f"(CD disc probe) on {renderer}")
    _write_cache(cache, key, {"path": path, "reason": reason, "forward_ms": round(times["forward"], 3),
                              "deferred_ms": round(times["deferred"], 3)})
    return path, reason
