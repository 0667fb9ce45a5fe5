"""GratNet scenes for Mitsuba 3: a ``viewer.meshes.Mesh``, the orbit camera, the lights and an environment.

- **Mesh**: positions, normals, UVs and faces go to a ``mi.Mesh`` as they are; the per-vertex tangents go
  along as the mesh attribute ``vertex_tangent``, which the BSDF interpolates (barycentrically, like the
  GL rasterizer's ``in_tangent``) and Gram–Schmidts against the shading normal, as shaders/surface.glsl
  does. So the CD's tangents run along its tracks exactly, not along each triangle's ∂p/∂u chord. A mesh with
  triangles whose UVs are missing or degenerate (an .obj without ``vt``) has arbitrary tangents there
  (viewer.meshes.load_obj): one warning on the ``gratnet.mitsuba`` logger says so.
- **The built-in sphere** is traced finer than the GL runtime draws it (:func:`traced_mesh`,
  :data:`TRACED_SPHERE`): Mitsuba's rays to a light meet the mesh's flat facets, so a direction above the
  shading normal's horizon but below its facet's is blocked (the shadow terminator), while the GL runtime, which
  has no visibility, lights it. Under an environment that band held 3–5 % of a 64 × 32 sphere's light; at
  256 × 128 (facets of 1.4°) the two renderers' means agree within their noise (about 1 %). The picture is the
  same sphere.
- **Camera**: ``viewer.camera.Camera`` as Mitsuba's ``perspective`` sensor (same eye, target, up, vertical
  field of view, clip range), or an ``orthographic`` one looking along the same axis.
- **Lights**: ``viewer.camera.Light``, as its kind's entry of gratnet.lights says (``LightKind.mitsuba``):
  directional → ``directional`` with ``irradiance`` = its intensity (irradiance on a plane facing the light);
  point → ``point`` with ``intensity`` = its intensity (W/sr, so the irradiance at d metres is intensity/d², as
  the GL runtime's 1/d² falloff). White (1, 1, 1).
- **Environment**: a ``gratnet.environment.Environment`` (a shipped map, a constant, an .exr or .hdr file) as
  Mitsuba's ``envmap`` built from its in-memory map (``mi.Bitmap``), with its ``scale`` and ``to_world =
  Rz(rotation) · Rx(90°)`` (Rx turns Mitsuba's +y up into GratNet's +z): the placement that
  ``Environment.radiance`` reproduces (tests/runtime/test_mitsuba_environment.py). A constant is an envmap too.
- **Film**: ``hdrfilm`` with a box filter (each pixel the mean over its area), linear sRGB float.
- **Rendering** (:func:`render_passes`): passes of a few samples per pixel, with progress between them; a
  Ctrl-C inside one comes out as a plain KeyboardInterrupt (not Dr.Jit's RuntimeError around it).
"""

from __future__ import annotations

import math
from pathlib import Path
from types import ModuleType
from typing import Any

import numpy as np

from gratnet.area_lights import AreaLight
from gratnet.environment import Environment, constant_environment, load_environment
from gratnet.errors import GratNetError
from gratnet.lights import light_kind
from mitsuba_plugin.bsdf import LOGGER, no_tangent_warning
from mitsuba_plugin.runtime import interrupted, plugin_errors
from viewer.camera import Camera, Light
from viewer.meshes import Mesh

__all__ = ["TANGENT_ATTRIBUTE", "TRACED_SPHERE", "bsdf_dict", "build_scene", "emitters", "environment_emitter",
           "mitsuba_mesh", "render_passes", "sensor", "traced_mesh", "unmapped_triangles"]

#: Name of the per-vertex tangent attribute of exported meshes.
TANGENT_ATTRIBUTE = "vertex_tangent"
#: ``(segments, rings)`` of the built-in sphere as Mitsuba traces it (viewer.meshes.sphere; the GL runtime draws
#: 64 × 32). Measured (docs/experiments/2026-11-28-environment-agreement.md): paper-snake on the sphere in the studio,
#: 1,024 spp, Mitsuba's mean over the covered pixels 3–6 % under GL's at 64 × 32 and within 0.05 % of it at 256 × 128.
TRACED_SPHERE = (256, 128)


def traced_mesh(spec: str) -> Mesh:
    """The mesh ``--mesh`` names (viewer.catalog.build_mesh), as Mitsuba is to trace it: the built-in sphere at
    :data:`TRACED_SPHERE` (module docstring: the shadow terminator), every other mesh as it is. An .obj's own facets
    block grazing light in Mitsuba, not in the GL runtime: tessellate a curved .obj finely for both to agree."""
    from viewer import meshes
    from viewer.catalog import build_mesh

    if spec == "sphere":
        return meshes.sphere(segments=TRACED_SPHERE[0], rings=TRACED_SPHERE[1])
    return build_mesh(spec)


def bsdf_dict(model_path: str | Path, ior: float | None, *, tangent_attribute: str = TANGENT_ATTRIBUTE,
              specular_probability: float = 0.5, lobe_degrees: float = 2.0, sampler: str = "table") -> dict[str, Any]:
    """The ``gratnet`` BSDF's ``load_dict`` entry (``ior`` None: Fresnel off; ``sampler``: ``table`` or
    ``mixture``, mitsuba_plugin.bsdf)."""
    return {"type": "gratnet", "filename": str(model_path), "ior": 0.0 if ior is None else float(ior),
            "tangent_attribute": tangent_attribute, "specular_probability": float(specular_probability),
            "lobe_degrees": float(lobe_degrees), "sampler": str(sampler)}


def unmapped_triangles(mesh: Mesh) -> int:
    """How many triangles have no usable UVs (missing, stored as 0, or not spanning a triangle): where
    viewer.meshes.load_obj gives an .obj arbitrary tangents (its test, on the same numbers)."""
    uv = mesh.uvs[mesh.indices].astype(np.float64)
    first, second = uv[:, 1] - uv[:, 0], uv[:, 2] - uv[:, 0]
    det = first[:, 0] * second[:, 1] - second[:, 0] * first[:, 1]
    mapped = np.abs(det) > 1e-12 * (np.sum(first**2, axis=1) + np.sum(second**2, axis=1))
    return int(np.count_nonzero(~mapped))


def mitsuba_mesh(mi: ModuleType, mesh: Mesh, bsdf: Any, name: str = "gratnet_mesh") -> Any:
    """``mesh`` as a ``mi.Mesh`` with ``bsdf`` (a loaded BSDF) and the ``vertex_tangent`` attribute; warns
    (``gratnet.mitsuba`` logger) when some of its triangles have no usable UVs, so arbitrary tangents."""
    if mesh.triangle_count == 0:
        raise GratNetError("the mesh has no triangles")
    unmapped = unmapped_triangles(mesh)
    if unmapped:
        reason = ("has no UV coordinates" if unmapped == mesh.triangle_count else
                  f"has no usable UV coordinates on {unmapped} of its {mesh.triangle_count} triangles")
        LOGGER.warning(no_tangent_warning(name, reason))
    props = mi.Properties()
    props["bsdf"] = bsdf
    result = mi.Mesh(name, mesh.vertex_count, mesh.triangle_count, props=props, has_vertex_normals=True,
                     has_vertex_texcoords=True)
    params = mi.traverse(result)
    params["vertex_positions"] = np.ascontiguousarray(mesh.positions, dtype=np.float32).ravel()
    params["vertex_normals"] = np.ascontiguousarray(mesh.normals, dtype=np.float32).ravel()
    params["vertex_texcoords"] = np.ascontiguousarray(mesh.uvs, dtype=np.float32).ravel()
    params["faces"] = np.ascontiguousarray(mesh.indices, dtype=np.uint32).ravel()
    params.update()
    result.add_attribute(TANGENT_ATTRIBUTE, 3, np.ascontiguousarray(mesh.tangents, dtype=np.float32).ravel())
    return result


def _film(width: int, height: int) -> dict[str, Any]:
    return {"type": "hdrfilm", "width": int(width), "height": int(height), "rfilter": {"type": "box"},
            "pixel_format": "rgb", "component_format": "float32", "sample_border": False}


def sensor(mi: ModuleType, camera: Camera, width: int, height: int, spp: int,
           orthographic_half_height: float | None = None) -> dict[str, Any]:
    """Mitsuba's sensor for ``camera``: ``perspective`` (vertical FOV ``camera.fov_deg``), or with
    ``orthographic_half_height`` (metres) an ``orthographic`` sensor seeing that half height around the
    target along the same viewing axis."""
    look = mi.ScalarTransform4f().look_at(origin=[float(c) for c in camera.eye()],
                                          target=[float(c) for c in camera.target],
                                          up=[float(c) for c in camera.up()])
    near, far = camera.clip_range()
    result: dict[str, Any] = {"film": _film(width, height),
                              "sampler": {"type": "independent", "sample_count": int(spp)},
                              "near_clip": float(near), "far_clip": float(far)}
    if orthographic_half_height is None:
        result.update(type="perspective", fov=float(camera.fov_deg), fov_axis="y", to_world=look)
    else:
        # Mitsuba's orthographic sensor sees x ∈ [−1, 1], y ∈ [−1/aspect, 1/aspect] in camera space.
        scale = float(orthographic_half_height) * width / height
        result.update(type="orthographic", to_world=look @ mi.ScalarTransform4f().scale([scale, scale, 1.0]))
    return result


def emitters(light: Light | None,
             environment: Environment | float | tuple[float, float, float] | str | Path | None = None,
             area_lights: tuple[AreaLight, ...] = (), environment_scale: float = 1.0) -> dict[str, dict[str, Any]]:
    """Mitsuba emitter entries: the light (if any), the environment (if any) as :func:`environment_emitter`, and
    each area light as its shape with an ``area`` emitter (gratnet.area_lights).

    ``environment``: an :class:`~gratnet.environment.Environment`, or what ``load_environment`` reads: a grey
    radiance, a linear sRGB triple, a shipped map's name or a map's path. ``environment_scale``: a further factor
    on its radiance (an Environment carries its own ``scale``)."""
    result: dict[str, dict[str, Any]] = {}
    if light is not None:
        white = {"type": "rgb", "value": [float(light.intensity)] * 3}
        result["light"] = light_kind(light.kind).mitsuba(light.vector, white)  # gratnet/lights.py
    if environment is not None and not isinstance(environment, Environment):
        if isinstance(environment, (str, Path)):
            environment = load_environment(str(environment))
        else:
            rgb = tuple(float(v) for v in environment) if isinstance(environment, tuple) else (float(environment),) * 3
            environment = None if max(rgb) == 0.0 else constant_environment((rgb[0], rgb[1], rgb[2]))
    if environment is not None:
        result["environment"] = environment_emitter(environment, environment_scale)
    if area_lights:
        import mitsuba as mi

        for index, area in enumerate(area_lights):
            result[f"area_light_{index}"] = area.mitsuba(mi)
    return result


def environment_emitter(environment: Environment, scale: float = 1.0) -> dict[str, Any]:
    """The ``envmap`` entry of ``environment``: its map as a ``mi.Bitmap`` (float32 linear sRGB), ``scale`` =
    its scale × ``scale``, ``to_world = Rz(rotation_degrees) · Rx(90°)``. Needs a Mitsuba variant set."""
    import mitsuba as mi

    to_world = (mi.ScalarTransform4f().rotate([0.0, 0.0, 1.0], environment.rotation_degrees)
                @ mi.ScalarTransform4f().rotate([1.0, 0.0, 0.0], 90.0))
    pixels = np.array(environment.radiance_map, dtype=np.float32, order="C")  # a writable copy: nanobind wants one
    return {"type": "envmap", "bitmap": mi.Bitmap(pixels), "scale": float(environment.scale) * float(scale),
            "to_world": to_world}


def build_scene(mi: ModuleType, mesh: Mesh, bsdf: dict[str, Any], sensor_dict: dict[str, Any],
                emitter_dicts: dict[str, dict[str, Any]], integrator: str = "path", max_depth: int = 8,
                mesh_name: str = "gratnet_mesh") -> Any:
    """A loaded ``mi.Scene``: the mesh (called ``mesh_name``) with the BSDF, the sensor, the emitters and the
    integrator (``direct``: emitter and BSDF sampling with MIS, one bounce; ``path``: up to ``max_depth``
    bounces), emitters hidden from camera rays (the background is black, as in gratnet render). The BSDF's own
    errors come out as its one line (``runtime.plugin_errors``)."""
    if integrator not in ("direct", "path"):
        raise GratNetError(f"unknown integrator {integrator!r}; choose direct or path")
    # hide_emitters: camera rays that miss the mesh see black, as gratnet render's background (an environment
    # still lights the mesh).
    integrator_dict: dict[str, Any] = {"type": integrator, "hide_emitters": True}
    if integrator == "path":
        integrator_dict["max_depth"] = int(max_depth)
    with plugin_errors():
        loaded = mi.load_dict(bsdf)
    shape = mitsuba_mesh(mi, mesh, loaded, mesh_name)
    return mi.load_dict({"type": "scene", "integrator": integrator_dict, "sensor": sensor_dict, "mesh": shape,
                         **emitter_dicts})


def render_passes(mi: ModuleType, scene: Any, spp: int, seed: int = 0, samples_per_pass: int = 1 << 19,
                  progress: Any = None) -> np.ndarray:
    """Render ``spp`` samples per pixel in passes of at most ``samples_per_pass`` samples (bounded memory,
    and progress between passes); returns the mean, linear sRGB ``float32`` ``(H, W, 3)``, row 0 at the top.
    ``progress``: called with the number of samples per pixel done so far after each pass.

    Ctrl-C: Mitsuba's handler cancels the render and hands the signal on to Python, whose KeyboardInterrupt
    then rises in the next BSDF call (within a fraction of a second: the plugin runs per bounce) and reaches
    here wrapped in Dr.Jit's RuntimeError; it leaves as a plain KeyboardInterrupt. Mitsuba's log is held at
    Error level meanwhile: its "Received interrupt signal" warning (on stdout) would be a second report, and the
    scalar image block would warn once per out-of-gamut sample (negative linear sRGB, kept as gratnet render's
    EXR keeps it)."""
    width, height = (int(v) for v in scene.sensors()[0].film().size())
    per_pass = max(1, min(int(spp), samples_per_pass // max(width * height, 1)))
    total = np.zeros((height, width, 3), dtype=np.float64)
    done = 0
    pass_index = 0
    previous_level = mi.log_level()
    mi.set_log_level(mi.LogLevel.Error)
    try:
        while done < spp:
            count = min(per_pass, spp - done)
            try:
                rendered = mi.render(scene, seed=int(seed) * 1_000_003 + pass_index, spp=count)
            except RuntimeError as error:
                if interrupted(error):
                    raise KeyboardInterrupt from None
                raise
            image = np.asarray(rendered, dtype=np.float64)
            total += image[..., :3] * count
            done += count
            pass_index += 1
            if progress is not None:
                progress(done)
    finally:
        mi.set_log_level(previous_level)
    result = total / max(done, 1)
    if not math.isfinite(float(np.sum(result))):
        raise GratNetError("the Mitsuba render contains NaN or inf; nothing was written (please report this)")
    return result.astype(np.float32)
