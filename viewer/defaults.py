"""The default light, camera and exposure of ``gratnet render`` and ``gratnet view``: one set, derived from the
material and the mesh, so that the first picture shows the material's diffraction.

The material's analysis (:func:`gratnet.showcase.material_display`: its brightest off-specular peaks as
key vectors ``(u, v)`` in the surface's tangent frame, and the exposure that puts the brightest at display
white) is turned into a scene for any mesh (built-in or ``.obj``):

1. **Camera.** An orbit camera at azimuth ``CAMERA_AZIMUTH_DEGREES``, at the distance that fits the
   mesh's extent around the origin into the vertical field of view; its elevation is one of
   ``CAMERA_ELEVATIONS_DEGREES`` (step 4).
2. **Light.** A directional light that puts a chosen key vector ``K`` at the surface point seen nearest
   the image centre. With ``ωo`` that point's direction to the eye, both in the point's tangent frame,
   ``K = −(ωi + ωo)`` (physics.md) fixes ``ωi``'s tangential part, ``−K − ωo,xy``; its normal part follows
   from ``|ωi| = 1``. A light more than ``MAX_LIGHT_DEGREES`` from that normal or from +z is not used.
   Candidates for ``K``: each of the ``AIMED_PEAKS`` brightest peaks, and ``AIM_FRACTIONS`` of it (between
   the specular direction and the peak, so that a mesh whose key vectors vary enough shows the specular
   highlight and the orders together). Why aiming works on every built-in mesh: on the plane the key
   vector varies only about ±0.2 across the picture, so it must be aimed; on the disc the tangent frame
   turns with the azimuth, so the aimed peak appears along a radius (the familiar rainbow streak); on the
   sphere the normals spread the key vectors widely around the aimed one.
3. **Exposure**, predicted without rendering: ``SAMPLES`` points spread over the mesh by area, those
   facing the camera inside its view weighted by the solid angle they cover (cos θo · area / d²), each
   shaded by the network (numpy, ``gratnet.modelfile.evaluate_keys``) with the A-term. The exposure maps
   the ``EXPOSURE_PERCENTILE``-th percentile of that predicted brightness (largest linear sRGB channel) to
   display white, so that only about 0.5 % of the picture saturates (no saturated blob), at most
   ``MAX_EXPOSURE_RATIO`` × the material's suggested exposure; where that leaves less than
   ``VISIBLE_PERCENT`` % of the picture ``VISIBLE_MARGIN`` display steps above black (a grating's thin
   order line on a curved mesh), it is raised until it does, up to ``MAX_VISIBLE_RATIO`` × the suggestion
   (beyond lies the network's noise floor).
4. **Choice.** Every (elevation, ``K``) candidate is scored on ``SCORE_SAMPLES`` of the samples: the
   fraction of the picture the display would show coloured (chroma ≥ ``COLOURFUL_CHROMA``, not white),
   plus ``SHOWN_WEIGHT`` × the fraction it would show at all. The best wins (a later one must beat it by
   ``SCORE_TIE``); its exposure is then computed from every sample. About 1 s per material and mesh.

A BRDF slice (``--slice``) takes a light 30° from the normal on the side opposite the brightest peak, so
that the peak lands near the slice's centre, and the exposure of step 3 predicted on the slice's own
view directions.

Explicit flags always override: ``viewer.scene_config.fill_scene_defaults`` fills only the flags left unset;
the viewer asks for a pair's defaults off its window's thread (``viewer.default_view``). Results are
rounded (0.1°, 1 mm, 3 significant digits) so that they read well in a config file and on a slider.
The algorithm only (numpy and pyrr, no GL, no flags, no processes). Runtime-side.
"""

from __future__ import annotations

import dataclasses
import functools
import math
import os
from pathlib import Path
from typing import TYPE_CHECKING, Any

from gratnet.errors import GratNetError

if TYPE_CHECKING:  # the heavy imports wait until a default is computed: `gratnet --help` stays quick
    import numpy as np

    from gratnet.modelfile import ModelFile
    from gratnet.showcase import MaterialDisplay
    from viewer.camera import Camera
    from viewer.meshes import Mesh

__all__ = [
    "CAMERA_AZIMUTH_DEGREES",
    "FALLBACK",
    "FOV_DEGREES",
    "SceneDefaults",
    "aim_light",
    "display_score",
    "framing_distance",
    "light_angles",
    "predicted_exposure",
    "resolve_defaults",
    "scene_defaults",
    "significant",
    "slice_defaults",
    "surface_samples",
]

#: The orbit camera's azimuth (degrees from +x): the eye on the −y side, looking towards +y.
CAMERA_AZIMUTH_DEGREES = -90.0
#: Camera elevations tried in order (degrees above the xy-plane) until a light can aim a peak.
CAMERA_ELEVATIONS_DEGREES = (45.0, 60.0, 30.0, 75.0)
#: Vertical field of view of the default camera (degrees), as ``--fov``'s default.
FOV_DEGREES = 40.0
#: The mesh's extent (largest distance of a vertex from the origin) fills this fraction of the half field of view.
FRAMING = 0.95
#: No default light is farther than this from the aimed point's normal or from the world's +z (degrees;
#: the viewer's light slider ends at 89°).
MAX_LIGHT_DEGREES = 80.0
#: Surface points of the exposure prediction (spread by area; deterministic).
SAMPLES = 4096
#: Percentile of the predicted brightness put at display white.
EXPOSURE_PERCENTILE = 99.5
#: The default exposure is at most this multiple of the material's suggested exposure.
MAX_EXPOSURE_RATIO = 4.0
#: The exposure is raised, if needed, until this percentage of the predicted picture reaches ``VISIBLE_MARGIN``
#: × the display's smallest step (a picture that is 99 % black draws ``gratnet render``'s warning) …
VISIBLE_PERCENT = 5.0
VISIBLE_MARGIN = 8.0
#: … but to at most this multiple of the material's suggested exposure (beyond it lies the network's noise floor).
MAX_VISIBLE_RATIO = 1000.0
#: Candidates are scored on this many of the samples (the final exposure uses all of them).
SCORE_SAMPLES = 1024
#: Candidates: the brightest peaks aimed at, …
AIMED_PEAKS = 4
#: … each at these fractions of its key vector (1: the peak itself at the aimed point; less: between the
#: specular direction and the peak, so that a mesh whose key vectors vary enough shows both).
AIM_FRACTIONS = (1.0, 0.6)
#: Scoring a candidate: display sRGB chroma (max − min channel) that counts as coloured …
COLOURFUL_CHROMA = 32.0 / 255.0
#: … and the weight of the merely visible fraction against the coloured one.
SHOWN_WEIGHT = 0.2
#: A later candidate must beat the best so far by this much (earlier ones: brighter peaks, 45° elevation).
SCORE_TIE = 0.005
#: The BRDF slice's default light: this far from the normal (degrees).
SLICE_LIGHT_DEGREES = 30.0
#: The slice's exposure is predicted on this many view directions per side.
SLICE_GRID = 96


@dataclasses.dataclass(frozen=True)
class SceneDefaults:
    """A directional light, an orbit camera and an exposure (world +z up; the flags' units).

    Attributes:
        light_theta_degrees, light_phi_degrees: direction towards the light: polar angle from +z, azimuth
            from +x (degrees).
        camera_distance: metres from the origin; camera_azimuth_degrees, camera_elevation_degrees: degrees.
        exposure: the linear factor applied to CIE XYZ before display.
        aimed_key_uv: the peak key vector the light aims at (tangent frame, dimensionless), for reports.
    """

    light_theta_degrees: float
    light_phi_degrees: float
    camera_distance: float
    camera_azimuth_degrees: float
    camera_elevation_degrees: float
    exposure: float
    aimed_key_uv: tuple[float, float] = (0.0, 0.0)

    @property
    def light_text(self) -> str:
        """``--light`` form: ``θ,φ``."""
        return f"{self.light_theta_degrees:g},{self.light_phi_degrees:g}"

    @property
    def camera_text(self) -> str:
        """``--camera`` form: ``DIST,AZIMUTH,ELEVATION``."""
        return f"{self.camera_distance:g},{self.camera_azimuth_degrees:g},{self.camera_elevation_degrees:g}"


#: The values used where no material is known (the config dataclasses' defaults): a light and camera
#: 45° off the normal, azimuths 90° apart, exposure 1 (a flat mirror's specular peak at white).
FALLBACK = SceneDefaults(light_theta_degrees=45.0, light_phi_degrees=90.0, camera_distance=0.2,
                         camera_azimuth_degrees=CAMERA_AZIMUTH_DEGREES, camera_elevation_degrees=45.0,
                         exposure=1.0)


def significant(value: float, digits: int = 3) -> float:
    """``value`` rounded to ``digits`` significant digits (reads well in a config file and on a slider)."""
    return float(f"{value:.{digits}g}")


def surface_samples(mesh: Mesh, count: int = SAMPLES, seed: int = 0) -> dict[str, np.ndarray]:
    """``count`` points spread uniformly by area over ``mesh``, with the interpolated tangent frame.

    Returns:
        ``{"positions", "normals", "tangents", "bitangents"}``, ``float64`` ``(count, 3)`` (frames unit and
        orthogonal; metres for positions), and ``"area"``, ``(count,)``: the surface area each point stands
        for (m², the mesh's area / count); empty arrays for a mesh without triangles.
    """
    import numpy as np

    triangles = mesh.indices.astype(np.int64)
    if triangles.shape[0] == 0:
        empty = np.zeros((0, 3))
        return {"positions": empty, "normals": empty, "tangents": empty, "bitangents": empty, "area": np.zeros(0)}
    corners = mesh.positions.astype(np.float64)[triangles]  # (M, 3 corners, 3)
    areas = 0.5 * np.linalg.norm(np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]), axis=1)
    if not areas.sum() > 0:
        areas = np.ones_like(areas)
    rng = np.random.default_rng(seed)
    chosen = rng.choice(len(areas), size=count, p=areas / areas.sum())
    r1, r2 = rng.random(count), rng.random(count)
    root = np.sqrt(r1)
    weights = np.stack([1.0 - root, root * (1.0 - r2), root * r2], axis=1)[:, :, None]  # uniform on a triangle

    def interpolate(values: np.ndarray) -> np.ndarray:
        return np.sum(values.astype(np.float64)[triangles[chosen]] * weights, axis=1)

    normals = interpolate(mesh.normals)
    normals /= np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-30)
    tangents = interpolate(mesh.tangents)
    tangents -= np.sum(tangents * normals, axis=1, keepdims=True) * normals
    tangents /= np.maximum(np.linalg.norm(tangents, axis=1, keepdims=True), 1e-30)
    return {"positions": interpolate(mesh.positions), "normals": normals, "tangents": tangents,
            "bitangents": np.cross(normals, tangents), "area": np.full(count, float(areas.sum()) / count)}


def framing_distance(mesh: Mesh, fov_degrees: float) -> float:
    """Camera distance (metres) at which a sphere around the origin holding every vertex fills ``FRAMING``
    of the vertical half field of view."""
    import numpy as np

    extent = float(np.max(np.linalg.norm(mesh.positions.astype(np.float64), axis=1))) if mesh.vertex_count else 0.1
    extent = extent if extent > 0 else 0.1
    return extent / (FRAMING * math.sin(math.radians(fov_degrees) / 2.0))


def _visible(samples: dict[str, np.ndarray], camera: Camera) -> tuple[np.ndarray, np.ndarray]:
    """Mask of the samples that face the camera inside its (square) view, and their normalised device
    coordinates ``(x, y)``."""
    import numpy as np

    positions = samples["positions"]
    homogeneous = np.concatenate([positions, np.ones((len(positions), 1))], axis=1) @ camera.view_projection(1.0)
    w = homogeneous[:, 3]
    with np.errstate(divide="ignore", invalid="ignore"):
        ndc = homogeneous[:, :2] / w[:, None]
    to_eye = camera.eye()[None, :] - positions
    facing = np.sum(to_eye * samples["normals"], axis=1) > 0.0
    inside = (w > 0.0) & np.all(np.abs(ndc) <= 1.0, axis=1)
    return facing & inside, ndc


def _local(vectors: np.ndarray, samples: dict[str, np.ndarray], index: Any = slice(None)) -> np.ndarray:
    """World vectors ``(…, 3)`` in the tangent frame of the samples at ``index``."""
    import numpy as np

    return np.stack([np.sum(vectors * samples[name][index], axis=-1)
                     for name in ("tangents", "bitangents", "normals")], axis=-1)


def aim_light(key_uv: tuple[float, float], view_local: np.ndarray, samples: dict[str, np.ndarray],
               index: int) -> np.ndarray | None:
    """The world direction towards a light that makes the key vector at sample ``index`` (seen along
    ``view_local``, its tangent frame) equal ``key_uv``; ``None`` when no light within ``MAX_LIGHT_DEGREES``
    of the normal and of +z can."""
    import numpy as np

    tangential = -np.asarray(key_uv, dtype=np.float64) - view_local[:2]
    sine_squared = float(np.dot(tangential, tangential))
    if sine_squared > math.sin(math.radians(MAX_LIGHT_DEGREES)) ** 2:
        return None
    local = np.array([tangential[0], tangential[1], math.sqrt(1.0 - sine_squared)])
    world = local[0] * samples["tangents"][index] + local[1] * samples["bitangents"][index] \
        + local[2] * samples["normals"][index]
    world /= np.linalg.norm(world)
    if world[2] < math.cos(math.radians(MAX_LIGHT_DEGREES)):
        return None
    return world


def light_angles(world: np.ndarray) -> tuple[float, float]:
    """A unit direction (world) as ``(θ, φ)`` in degrees, rounded to 0.1°: the ``--light`` flag's angles."""
    theta = math.degrees(math.acos(max(-1.0, min(1.0, float(world[2])))))
    phi = math.degrees(math.atan2(float(world[1]), float(world[0]))) if math.hypot(world[0], world[1]) > 1e-12 else 0.0
    return round(theta, 1) + 0.0, round(phi, 1) + 0.0  # + 0.0: no "-0" in a config file


def _predicted_colour(model: ModelFile, samples: dict[str, np.ndarray], visible: np.ndarray,
                      camera: Camera, light_world: np.ndarray, ior: float | None) -> tuple[np.ndarray, np.ndarray]:
    """Unexposed linear sRGB of A·XYZ at the visible samples (0 where the light is below the surface), and
    their pixel weights: the solid angle each covers, cos θo · area / d² (steradians)."""
    import numpy as np

    from gratnet.brdf import a_term
    from gratnet.display import xyz_to_linear_srgb
    from gratnet.modelfile import evaluate_keys

    index = np.flatnonzero(visible)
    to_eye = camera.eye()[None, :] - samples["positions"][index]
    distance = np.linalg.norm(to_eye, axis=1)
    view = _local(to_eye / distance[:, None], samples, index)
    light = _local(np.broadcast_to(light_world, view.shape), samples, index)
    key = -(light + view)
    lit = light[:, 2] > 0.0
    colour = np.zeros((len(index), 3))
    if np.any(lit):
        xyz = evaluate_keys(model, key[lit, 0], key[lit, 1], key[lit, 2])
        colour[lit] = xyz_to_linear_srgb(xyz) * a_term(light[lit], view[lit], ior)[:, None]
    return colour, view[:, 2] * samples["area"][index] / np.square(distance)


def display_score(colour: np.ndarray, weights: np.ndarray, exposure: float, field_sr: float = 1.0) -> float:
    """How well a predicted picture shows diffraction: the fraction of the picture (``field_sr``: its solid
    angle, steradians; ``weights``: each sample's) that the display shows coloured (chroma ≥
    ``COLOURFUL_CHROMA`` in display sRGB, not white), plus ``SHOWN_WEIGHT`` × the fraction it shows at all
    (≥ ``VISIBLE_MARGIN`` display steps). ``field_sr`` = 1: the solid angles themselves."""
    import numpy as np

    from gratnet.bounds import DISPLAY_SKIP_THRESHOLD

    linear = np.clip(colour * exposure, 0.0, 1.0)
    encoded = np.where(linear <= 0.0031308, 12.92 * linear, 1.055 * np.power(linear, 1.0 / 2.4) - 0.055)
    shown = linear.max(axis=1) >= VISIBLE_MARGIN * DISPLAY_SKIP_THRESHOLD
    coloured = shown & (encoded.max(axis=1) - encoded.min(axis=1) >= COLOURFUL_CHROMA) & (linear.min(axis=1) < 0.98)
    return float(np.sum(weights[coloured]) + SHOWN_WEIGHT * np.sum(weights[shown])) / field_sr


def _weighted_percentile(values: np.ndarray, weights: np.ndarray, percentile: float) -> float:
    import numpy as np

    order = np.argsort(values, kind="stable")
    cumulative = np.cumsum(weights[order])
    if cumulative.size == 0 or not cumulative[-1] > 0:
        return 0.0
    position = int(np.searchsorted(cumulative, percentile / 100.0 * cumulative[-1]))
    return float(values[order][min(position, len(order) - 1)])


def predicted_exposure(values: np.ndarray, weights: np.ndarray, suggested: float) -> float:
    """The exposure of step 3 (module docstring) from the predicted brightness and pixel weights; ``suggested``:
    the material's own (``MaterialDisplay.exposure``), which bounds it."""
    from gratnet.bounds import DISPLAY_SKIP_THRESHOLD

    reference = _weighted_percentile(values, weights, EXPOSURE_PERCENTILE)
    exposure = min(1.0 / reference, MAX_EXPOSURE_RATIO * suggested) if reference > 0 else suggested
    visible = _weighted_percentile(values, weights, 100.0 - VISIBLE_PERCENT)
    if visible > 0 and exposure * visible < VISIBLE_MARGIN * DISPLAY_SKIP_THRESHOLD:
        exposure = min(VISIBLE_MARGIN * DISPLAY_SKIP_THRESHOLD / visible, MAX_VISIBLE_RATIO * suggested)
    return exposure


def scene_defaults(model: ModelFile, mesh: Mesh, fov_degrees: float = FOV_DEGREES, ior: float | None = 1.5,
                   display: MaterialDisplay | None = None) -> SceneDefaults:
    """The default light, camera and exposure for ``model`` on ``mesh`` (module docstring, steps 1–3).

    Args:
        model: the material's network.
        mesh: the mesh it is shown on (metres, +z up; the camera orbits the origin).
        fov_degrees: the camera's vertical field of view (degrees).
        ior: the A-term's Fresnel refractive index (``None``: no Fresnel), as the render will use it.
        display: the material's analysis (default: :func:`gratnet.showcase.material_display`).
    """
    import numpy as np

    from gratnet.showcase import material_display
    from viewer.camera import Camera

    display = material_display(model) if display is None else display
    samples = surface_samples(mesh)
    distance = round(framing_distance(mesh, fov_degrees), 3)
    field_sr = (2.0 * math.tan(math.radians(fov_degrees) / 2.0)) ** 2  # a square picture, small-angle
    best: tuple[float, tuple[Any, ...]] | None = None
    for elevation in CAMERA_ELEVATIONS_DEGREES:
        camera = Camera(distance, CAMERA_AZIMUTH_DEGREES, elevation, fov_deg=fov_degrees)
        visible, ndc = _visible(samples, camera)
        if not np.any(visible):
            continue
        index = int(np.flatnonzero(visible)[np.argmin(np.sum(np.square(ndc[visible]), axis=1))])
        to_eye = camera.eye() - samples["positions"][index]
        view_local = _local(to_eye / np.linalg.norm(to_eye), samples, index)
        scoring = visible & (np.arange(len(visible)) < SCORE_SAMPLES)  # the samples are iid: a random subset
        for key in display.peak_keys_uv[:AIMED_PEAKS]:
            for fraction in AIM_FRACTIONS:
                aim = (fraction * key[0], fraction * key[1])
                light = aim_light(aim, view_local, samples, index)
                if light is None:
                    continue
                colour, weights = _predicted_colour(model, samples, scoring, camera, light, ior)
                exposure = predicted_exposure(np.max(colour, axis=1).clip(0.0), weights, display.exposure)
                score = display_score(colour, weights * (len(visible) / SCORE_SAMPLES), exposure, field_sr)
                if best is None or score > best[0] + SCORE_TIE:
                    best = (score, (elevation, camera, visible, light, aim))
    if best is None:
        return dataclasses.replace(FALLBACK, camera_distance=distance, exposure=significant(display.exposure))
    elevation, camera, visible, light, aim = best[1]
    colour, weights = _predicted_colour(model, samples, visible, camera, light, ior)  # every sample, for the exposure
    exposure = significant(predicted_exposure(np.max(colour, axis=1).clip(0.0), weights, display.exposure))
    theta, phi = light_angles(light)
    return SceneDefaults(theta, phi, distance, CAMERA_AZIMUTH_DEGREES, elevation, exposure,
                         (round(aim[0], 4), round(aim[1], 4)))


def slice_defaults(model: ModelFile, display: MaterialDisplay | None = None, ior: float | None = 1.5) -> SceneDefaults:
    """The BRDF slice's defaults: a light ``SLICE_LIGHT_DEGREES`` from the normal on the side opposite the
    brightest peak (so that the peak lands near the slice's centre), and the exposure of step 3 (module
    docstring) predicted on a ``SLICE_GRID``² grid of the slice's view directions (physics.md "BRDF slice");
    the camera fields are :data:`FALLBACK`'s (a slice has no camera)."""
    import numpy as np

    from gratnet.brdf import a_term, direction, slice_view_directions
    from gratnet.display import xyz_to_linear_srgb
    from gratnet.modelfile import evaluate_keys
    from gratnet.showcase import material_display

    display = material_display(model) if display is None else display
    u, v = display.peak_keys_uv[0]
    phi = round(math.degrees(math.atan2(-v, -u)), 1) + 0.0 if math.hypot(u, v) > 1e-9 else FALLBACK.light_phi_degrees
    views, inside = slice_view_directions(SLICE_GRID)
    views = views[inside]
    light = direction(SLICE_LIGHT_DEGREES, phi)
    key = -(light[None, :] + views)
    colour = xyz_to_linear_srgb(evaluate_keys(model, key[:, 0], key[:, 1], key[:, 2]))
    colour *= a_term(light[None, :], views, ior)[:, None]
    exposure = predicted_exposure(np.max(colour, axis=1).clip(0.0), np.ones(len(views)), display.exposure)
    return dataclasses.replace(FALLBACK, light_theta_degrees=SLICE_LIGHT_DEGREES, light_phi_degrees=phi,
                               exposure=significant(exposure), aimed_key_uv=(u, v))


@functools.lru_cache(maxsize=64)
def _resolve_cached(model_path: str, stamp: tuple[int, int], mesh_spec: str, slice_mode: bool, fov_degrees: float,
                    ior: float | None) -> SceneDefaults:
    from gratnet.modelfile import load_model

    model = load_model(model_path)
    if slice_mode:
        return slice_defaults(model, ior=ior)
    from viewer.catalog import build_mesh

    return scene_defaults(model, build_mesh(mesh_spec), fov_degrees, ior)


def resolve_defaults(material: str, mesh: str, slice_mode: bool = False, fov_degrees: float = FOV_DEGREES,
                     ior: float | None = 1.5) -> SceneDefaults:
    """The defaults for a material (shipped name or model-file path) on a mesh (``cd``, ``sphere``, ``plane``
    or an ``.obj`` path), or for its BRDF slice: what ``gratnet render`` and ``gratnet view`` both use.
    Cached per (model file and its modification time, mesh, mode, field of view, IOR).

    Raises:
        GratNetError: unknown material or mesh, unreadable model or mesh file.
    """
    from viewer.catalog import resolve_material

    path = resolve_material(material)
    try:
        status = os.stat(path)
    except OSError as error:
        raise GratNetError(f"cannot read model file {path}: {error.strerror or error}") from error
    mesh_key = mesh if slice_mode or mesh in ("cd", "sphere", "plane") else str(Path(mesh).expanduser().resolve())
    return _resolve_cached(str(path), (status.st_mtime_ns, status.st_size), "" if slice_mode else mesh_key,
                           bool(slice_mode), float(fov_degrees), ior)
