"""The ``gratnet`` Mitsuba 3 BSDF: a trained GratNet network as a glossy reflection (docs/physics.md
"Path tracing: Mitsuba 3").

Plugin properties (XML / ``mi.load_dict``):

- ``filename`` (string): the material, as ``gratnet render --material`` takes it: a shipped name (``cd``,
  ``paper-cd``: ``assets/NAME/model.npz``) or a model file (any ``gratnet train`` output). A relative path is
  looked up as Mitsuba looks up its own files (``mi.file_resolver()``: the scene file's folder first while
  ``mi.load_file`` reads it), then in the current directory;
- ``ior`` (float, default 1.5): the A-term's Fresnel refractive index; 0 turns Fresnel off (R/R0 = 1);
- ``tangent_attribute`` (string, default ``""``): name of a per-vertex 3-vector mesh attribute holding the
  tangent (the height field's x on the surface), interpolated like the GL runtime's ``in_tangent``;
  ``mitsuba_plugin.scene`` exports meshes with ``vertex_tangent``. Empty: Mitsuba's own shading frame,
  whose first axis is ∂p/∂u of the mesh's UVs (Gram–Schmidt against the shading normal);
- ``sampler`` (string, default ``"table"``): how ``sample()`` draws the light direction. ``table``: from the
  material's own diffraction, its luminance over the key's (u, v) (``gratnet.importance.material_table``,
  built from the model on first use, a few seconds, then cached in memory and on disk), with
  ``gratnet.importance.DEFENSIVE_SHARE`` of the samples cosine-weighted; ``mixture``: the earlier sampler, kept
  for comparison;
- ``specular_probability`` (float in [0, 1], default 0.5) and ``lobe_degrees`` (float > 0, default 2):
  the ``mixture`` sampler (``mitsuba_plugin.shading``): that share of samples from a vMF lobe of that angular
  standard deviation around the mirror direction, the rest cosine-weighted.

Tangent: the height field's x follows ``tangent_attribute`` where the mesh has it, else ∂p/∂u of the mesh's
UVs; a mesh with neither gets an arbitrary tangent, so an arbitrary diffraction direction: the plugin warns
once per mesh (the ``gratnet.mitsuba`` logger: ``gratnet mitsuba-render`` prints it on one line; a script
without logging set up gets it on stderr).

Errors: bad properties, an unknown material or a missing file raise one GratNetError line starting with
:data:`MESSAGE_PREFIX`; Mitsuba wraps it ("failed to instantiate ... plugin of type gratnet", and a short Python
traceback), and :func:`plugin_message` takes the plugin's line back out (``mitsuba_plugin.runtime.plugin_errors``).

Values: ``eval`` = BSDF × cos θ of the light-side direction = ``A · XYZ → linear sRGB`` in radiance
transport (what the GL runtime shades per unit light). The implied BSDF, ``A · XYZ / cos θ_light``, is not
reciprocal; in importance transport (light tracing) ``eval`` returns it times cos θ of the camera side.
Only RGB variants (the colour is linear sRGB).
"""

from __future__ import annotations

import functools
import logging
import math
import re
import threading
from pathlib import Path
from types import ModuleType
from typing import Any

import numpy as np

from gratnet.errors import GratNetError
from gratnet.importance import material_table
from gratnet.modelfile import ModelFile, load_model
from mitsuba_plugin.shading import (
    DEFAULT_SAMPLER,
    SAMPLERS,
    eval_linear_srgb,
    from_tangent_frame,
    kappa_for_lobe,
    mixture_pdf,
    sample_mixture,
    to_tangent_frame,
    xyz_to_linear_srgb_matrix,
)

__all__ = ["MESSAGE_PREFIX", "LOGGER", "PLUGIN_NAME", "PROPERTIES", "bsdf_class", "check_ior", "file_resolver",
           "no_tangent_warning", "plugin_message", "register", "resolve_model", "search_folders",
           "shape_label"]

PLUGIN_NAME = "gratnet"
#: The properties the plugin takes (any other is refused, with this list).
PROPERTIES = ("filename", "ior", "tangent_attribute", "sampler", "specular_probability", "lobe_degrees")
#: Start of the plugin's errors and warnings (what :func:`plugin_message` looks for in Mitsuba's wrapping).
MESSAGE_PREFIX = "gratnet BSDF: "
#: Where the plugin's warnings go (``gratnet`` commands print the ``gratnet`` loggers on stderr, one line each).
LOGGER = logging.getLogger("gratnet.mitsuba")


@functools.lru_cache(maxsize=8)
def _cached_model(path: str, modified_ns: int) -> ModelFile:
    return load_model(path)


def search_folders(resolver: Any = None) -> list[str]:
    """The folders a relative ``filename`` is looked up in: the file resolver's (the scene file's folder first
    while Mitsuba loads it), then the current directory, without repeats."""
    folders = [str(folder) for folder in resolver] if resolver is not None else []
    folders.append(str(Path.cwd()))
    return list(dict.fromkeys(folders))


def resolve_model(name: str, resolver: Any = None) -> Path:
    """The model file that the ``filename`` property names: a shipped material (``cd``, ``paper-cd``), else a
    file, relative ones looked up through ``resolver`` (a ``mi.FileResolver``, or None) and then the current
    directory (viewer.catalog.resolve_material, as ``gratnet render --material``). One GratNetError line
    otherwise: an unknown name lists the shipped materials, a missing file the folders searched."""
    from viewer.catalog import resolve_material, shipped_materials

    text = name.strip()
    shipped = shipped_materials()
    if not text:
        raise GratNetError(f"give the material as the 'filename' property: a shipped name ({', '.join(shipped)}) "
                           "or a model file")
    if text in shipped:
        return resolve_material(text)
    path = Path(text).expanduser()
    if resolver is not None and not path.is_absolute():
        found = Path(str(resolver.resolve(str(path))))
        if found.is_file():
            path = found
    if path.is_file():
        return resolve_material(str(path))
    where = "" if path.is_absolute() else f" (looked in {', '.join(search_folders(resolver))})"
    if path.is_dir():
        raise GratNetError(f"model file {text!r} is a folder, not a file{where}")
    if any(mark in text for mark in ("/", "\\")) or path.suffix:
        raise GratNetError(f"model file {text!r} not found{where}")
    raise GratNetError(f"unknown material {text!r}: neither a shipped material (choose {', '.join(shipped)}) nor a "
                       f"model file{where}")


def _model(path: Path) -> ModelFile:
    return _cached_model(str(path.resolve()), path.stat().st_mtime_ns)


def check_ior(ior: float) -> float | None:
    """The A-term's ``ior`` argument for a plugin/flag value: None for 0 (no Fresnel), else the value; refused
    (one GratNetError) exactly where ``gratnet render`` refuses it (``gratnet.brdf.check_ior``)."""
    from gratnet.brdf import check_ior as check

    return check(float(ior), "ior")


def _checked(value: float, name: str, low: float, high: float, low_open: bool = False) -> float:
    if not (math.isfinite(value) and (low < value if low_open else low <= value) and value <= high):
        raise GratNetError(f"{name} must be in {'(' if low_open else '['}{low:g}, {high:g}], got {value!r}")
    return value


def _number(props: Any, name: str, default: float) -> float:
    value = props.get(name, default)
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise GratNetError(f"property {name!r} must be a number (<float name=\"{name}\" value=\"...\"/>), "
                           f"got {value!r}")
    return float(value)


def _string(props: Any, name: str, default: str) -> str:
    value = props.get(name, default)
    if not isinstance(value, str):
        raise GratNetError(f"property {name!r} must be a string (<string name=\"{name}\" value=\"...\"/>), "
                           f"got {value!r}")
    return value


def plugin_message(error: BaseException) -> str | None:
    """The plugin's own one-line message inside an error Mitsuba raised while instantiating it (Mitsuba
    wraps it in "failed to instantiate ... plugin of type gratnet" and a Python traceback), or None when the
    error is not the plugin's."""
    text = str(error)
    start = text.rfind(MESSAGE_PREFIX)
    if start < 0:
        return None
    return text[start:].splitlines()[0].strip()


def file_resolver(mi: ModuleType) -> Any:
    """Mitsuba's file resolver for this thread (``mi.file_resolver()``; ``mi.Thread.thread().file_resolver()``
    in older Mitsuba 3 releases, deprecated in 3.9), or None."""
    if hasattr(mi, "file_resolver"):
        return mi.file_resolver()
    thread = mi.Thread.thread()
    return thread.file_resolver() if thread is not None else None


def shape_label(shape: Any) -> str:
    """What to call a Mitsuba shape in a message: its id, else a mesh's name (an .obj's file name), else its class."""
    found = re.search(r'\bname = "([^"]*)"', str(shape)) if not shape.id() else None
    return shape.id() or (found.group(1) if found else shape.class_name())


def no_tangent_warning(mesh: str, reason: str) -> str:
    """The warning for a mesh whose tangent is arbitrary (``reason``: why, e.g. "has no UV coordinates")."""
    return (f"mesh {mesh!r} {reason}: its tangent, and so the direction of the diffraction, is arbitrary there; "
            "give it UV coordinates (the tangent follows ∂p/∂u) or a per-vertex tangent attribute")


def register(mi: ModuleType) -> None:
    """Register the ``gratnet`` BSDF for Mitsuba's current variant (idempotent)."""
    cls = bsdf_class(mi.variant())

    def create(props: Any) -> Any:
        try:
            return cls(props)
        except GratNetError as error:  # one line, and the shortest traceback Mitsuba's wrapping can show
            raise GratNetError(MESSAGE_PREFIX + " ".join(str(error).split())) from None

    mi.register_bsdf(PLUGIN_NAME, create)


@functools.cache
def bsdf_class(variant: str) -> type:
    """The BSDF class for ``variant`` (Mitsuba's base classes differ per variant, so one class each)."""
    import drjit as dr
    import mitsuba as mi

    if mi.variant() != variant:
        raise GratNetError(f"set the Mitsuba variant {variant} before asking for its BSDF class")
    if not mi.is_rgb:
        raise GratNetError(f"the gratnet BSDF needs an RGB variant (llvm_ad_rgb, scalar_rgb), not {variant}")
    scalar = not dr.is_jit_v(mi.Float)
    flags = mi.BSDFFlags.GlossyReflection | mi.BSDFFlags.FrontSide

    def lanes(value: Any) -> int:
        return 1 if scalar else max(dr.width(value), 1)

    def column(value: Any, count: int) -> np.ndarray:
        return np.broadcast_to(np.asarray(value, dtype=np.float64).reshape(-1), (count,))

    def vectors(value: Any, count: int) -> np.ndarray:
        return np.stack([column(value.x, count), column(value.y, count), column(value.z, count)], axis=-1)

    def mask(value: Any, count: int) -> np.ndarray:
        return np.broadcast_to(np.asarray(value, dtype=bool).reshape(-1), (count,))

    def to_float(values: np.ndarray) -> Any:
        return float(values[0]) if scalar else mi.Float(np.ascontiguousarray(values, dtype=np.float32))

    def to_vector(values: np.ndarray) -> Any:
        return mi.Vector3f(*(to_float(values[:, k]) for k in range(3)))

    def to_colour(values: np.ndarray) -> Any:
        return mi.Color3f(*(to_float(values[:, k]) for k in range(3)))

    def has_uvs(shape: Any) -> bool:
        """False for a mesh without texture coordinates (its ∂p/∂u, so Mitsuba's tangent, is arbitrary)."""
        if not shape.is_mesh():
            return True  # Mitsuba's analytic shapes have their own parameterisation
        method = getattr(shape, "has_vertex_texcoords", None)
        if method is not None:
            return bool(method())
        # JIT variants hand a lane's shape over as mi.Shape, without the Mesh methods: read its parameters.
        params = mi.traverse(shape)
        return "vertex_texcoords" not in params or dr.width(params["vertex_texcoords"]) > 0

    class GratNetBSDF(mi.BSDF):
        """A GratNet network as a Mitsuba BSDF (see the module docstring)."""

        def __init__(self, props: Any) -> None:
            mi.BSDF.__init__(self, props)
            self.filename = _string(props, "filename", "")
            self.model_path = resolve_model(self.filename, file_resolver(mi))
            self.model = _model(self.model_path)
            self.ior = check_ior(_number(props, "ior", 1.5))
            self.tangent_attribute = _string(props, "tangent_attribute", "")
            self.sampler = _string(props, "sampler", DEFAULT_SAMPLER)
            if self.sampler not in SAMPLERS:
                raise GratNetError(f"property 'sampler' must be one of {', '.join(SAMPLERS)}, got {self.sampler!r}")
            self.specular_probability = _checked(_number(props, "specular_probability", 0.5),
                                                 "specular_probability", 0.0, 1.0)
            self.lobe_degrees = _checked(_number(props, "lobe_degrees", 2.0), "lobe_degrees", 0.0, 90.0,
                                         low_open=True)
            unknown = [name for name in props.unqueried() if name not in PROPERTIES]
            if unknown:
                raise GratNetError(f"unknown propert{'ies' if len(unknown) > 1 else 'y'} "
                                   f"{', '.join(map(repr, unknown))}; the gratnet BSDF takes {', '.join(PROPERTIES)}")
            self.kappa = kappa_for_lobe(self.lobe_degrees)
            # The table is anisotropic (it follows the tracks): it samples in the tangent frame, like the value.
            self.table = material_table(self.model) if self.sampler == "table" else None
            self.matrix = xyz_to_linear_srgb_matrix()
            self.m_flags = flags
            self.m_components = [flags]
            # Shapes seen so far (registry id, or the object's address in scalar variants) → whether they carry
            # the tangent attribute; a lock because scalar variants call from Mitsuba's render threads.
            self.shapes_seen: dict[int, bool] = {}
            self.shapes_lock = threading.Lock()

        # -- frames -------------------------------------------------------------------------------
        def _distinct_shapes(self, si: Any) -> dict[int, int]:
            """Key (registry id; the object's address in scalar variants) → one lane, for each shape behind
            ``si``'s lanes (none for interactions without a shape)."""
            if scalar:
                return {} if si.shape is None else {int(si.shape.ptr): 0}
            ids = np.asarray(dr.reinterpret_array(mi.UInt32, si.shape)).reshape(-1)
            if ids.size == 0:
                return {}
            keys, lanes = ([ids[:1], np.zeros(1, dtype=np.int64)] if np.all(ids == ids[0]) else
                           np.unique(ids, return_index=True))
            return {int(key): int(lane) for key, lane in zip(keys, lanes, strict=True) if key != 0}

        def _with_tangents(self, si: Any) -> bool:
            """Whether a shape behind ``si`` has the tangent attribute; the first time a mesh with neither it nor
            UVs shows up, one warning: its tangent, so the diffraction's direction, is Mitsuba's arbitrary one."""
            shapes = self._distinct_shapes(si)
            for key, lane in shapes.items():
                if key in self.shapes_seen:
                    continue
                shape = si.shape if scalar else si.shape[lane]
                has = bool(self.tangent_attribute) and bool(shape.has_attribute(self.tangent_attribute))
                with self.shapes_lock:
                    first = key not in self.shapes_seen
                    self.shapes_seen[key] = has
                if first and not has and not has_uvs(shape):
                    reason = "has no UV coordinates" + (f" and no {self.tangent_attribute!r} attribute"
                                                        if self.tangent_attribute else "")
                    LOGGER.warning(MESSAGE_PREFIX + no_tangent_warning(shape_label(shape), reason))
            return any(self.shapes_seen[key] for key in shapes)

        def _rotation(self, si: Any, count: int) -> np.ndarray | None:
            """(cos α, sin α) per lane: the mesh tangent in Mitsuba's shading frame, or None (use it as is)."""
            if not self._with_tangents(si) or not self.tangent_attribute:
                return None
            tangent = si.shape.eval_attribute_3(self.tangent_attribute, si, True)  # 0 on shapes without it
            world = vectors(tangent, count)
            along_s = np.sum(world * vectors(si.sh_frame.s, count), axis=-1)
            along_t = np.sum(world * vectors(si.sh_frame.t, count), axis=-1)
            length = np.hypot(along_s, along_t)
            good = length > 1e-6  # a tangent (nearly) along the normal: keep Mitsuba's frame, as GL falls back
            cos_alpha = np.where(good, along_s / np.where(good, length, 1.0), 1.0)
            sin_alpha = np.where(good, along_t / np.where(good, length, 1.0), 0.0)
            return np.stack([cos_alpha, sin_alpha], axis=-1)

        # -- value --------------------------------------------------------------------------------
        def _value(self, ctx: Any, si: Any, wi: np.ndarray, wo: np.ndarray, active: np.ndarray,
                   rotation: np.ndarray | None) -> np.ndarray:
            """eval for local (shading-frame) directions: si.wi = ``wi``, sampled/light direction ``wo``;
            ``rotation``: :meth:`_rotation`'s for ``si``."""
            count = wi.shape[0]
            result = np.zeros((count, 3))
            if not ctx.is_enabled(mi.BSDFFlags.GlossyReflection) or not np.any(active):
                return result
            wi_t, wo_t = to_tangent_frame(wi, rotation), to_tangent_frame(wo, rotation)
            lanes_on = np.flatnonzero(active)
            if ctx.mode == mi.TransportMode.Importance:  # si.wi is the light side
                light, view = wi_t[lanes_on], wo_t[lanes_on]
                value = eval_linear_srgb(self.model, light, view, self.ior, self.matrix)
                with np.errstate(divide="ignore", invalid="ignore"):
                    ratio = np.where(light[:, 2] > 0.0, view[:, 2] / light[:, 2], 0.0)
                value *= ratio[:, None]
            else:
                value = eval_linear_srgb(self.model, wo_t[lanes_on], wi_t[lanes_on], self.ior, self.matrix)
            result[lanes_on] = value
            return result

        def _inputs(self, si: Any, wo: Any, active: Any) -> tuple[int, np.ndarray, np.ndarray, np.ndarray]:
            count = max(lanes(si.wi), lanes(wo), lanes(active))
            return count, vectors(si.wi, count), vectors(wo, count), mask(active, count)

        # -- sampling -----------------------------------------------------------------------------
        def _density(self, wi: np.ndarray, wo: np.ndarray, rotation: np.ndarray | None) -> np.ndarray:
            """The sampler's density (sr⁻¹) of the sampled direction ``wo`` given ``si.wi`` = ``wi`` (shading
            frame). The table's (u, v) ↔ direction map is the same whichever side is the light, so importance
            transport (``si.wi`` towards the light) samples the camera side by the same density."""
            if self.table is None:
                return mixture_pdf(wi, wo, self.specular_probability, self.kappa)
            return self.table.pdf(to_tangent_frame(wi, rotation), to_tangent_frame(wo, rotation))

        def _frame(self, ctx: Any, si: Any, count: int, on: np.ndarray) -> np.ndarray | None:
            """:meth:`_rotation` where it is needed: for the value (glossy reflection asked for) or for the
            (anisotropic) table's density, on some active lane."""
            needed = bool(ctx.is_enabled(mi.BSDFFlags.GlossyReflection)) or self.table is not None
            return self._rotation(si, count) if needed and np.any(on) else None

        def eval(self, ctx: Any, si: Any, wo: Any, active: Any = True) -> Any:
            count, wi_np, wo_np, on = self._inputs(si, wo, active)
            return to_colour(self._value(ctx, si, wi_np, wo_np, on, self._frame(ctx, si, count, on)))

        def pdf(self, ctx: Any, si: Any, wo: Any, active: Any = True) -> Any:
            count, wi_np, wo_np, on = self._inputs(si, wo, active)
            rotation = self._rotation(si, count) if self.table is not None and np.any(on) else None
            return to_float(np.where(on, self._density(wi_np, wo_np, rotation), 0.0))

        def eval_pdf(self, ctx: Any, si: Any, wo: Any, active: Any = True) -> tuple[Any, Any]:
            count, wi_np, wo_np, on = self._inputs(si, wo, active)
            rotation = self._frame(ctx, si, count, on)
            density = np.where(on, self._density(wi_np, wo_np, rotation), 0.0)
            return to_colour(self._value(ctx, si, wi_np, wo_np, on, rotation)), to_float(density)

        def sample(self, ctx: Any, si: Any, sample1: Any, sample2: Any, active: Any = True) -> tuple[Any, Any]:
            count = max(lanes(si.wi), lanes(sample1), lanes(sample2), lanes(active))
            wi_np, on = vectors(si.wi, count), mask(active, count)
            rotation = self._frame(ctx, si, count, on)
            xi0, xi1, xi2 = column(sample1, count), column(sample2.x, count), column(sample2.y, count)
            if self.table is None:
                directions, valid = sample_mixture(wi_np, xi0, xi1, xi2, self.specular_probability, self.kappa)
                valid &= on
                density = np.where(valid, mixture_pdf(wi_np, directions, self.specular_probability, self.kappa),
                                   0.0)
            else:
                # gratnet.importance: its wo is the view (si.wi), its wi the sampled light direction (Mitsuba's wo).
                sampled, density, valid = self.table.sample(to_tangent_frame(wi_np, rotation), xi0, xi1, xi2)
                directions = from_tangent_frame(sampled, rotation)
                valid &= on
            valid &= density > 0.0
            value = self._value(ctx, si, wi_np, directions, valid, rotation)
            weight = np.where(valid[:, None], value / np.where(valid, density, 1.0)[:, None], 0.0)
            # The variant's BSDFSample3f: the stubs type its fields as one generic variant's (eta: Float, …).
            sample: Any = dr.zeros(mi.BSDFSample3f) if scalar else dr.zeros(mi.BSDFSample3f, count)
            sample.wo = to_vector(directions)
            sample.pdf = to_float(np.where(valid, density, 0.0))
            sample.eta = 1.0
            sample.sampled_type = mi.UInt32(+flags)
            sample.sampled_component = mi.UInt32(0)
            return sample, to_colour(weight)

        def traverse(self, callback: Any) -> None:
            pass

        def parameters_changed(self, keys: Any = None) -> None:
            pass

        def to_string(self) -> str:
            return (f"GratNetBSDF[filename={self.filename!r} ({self.model_path}), ior={self.ior}, tangent_attribute="
                    f"{self.tangent_attribute!r}, sampler={self.sampler!r}, specular_probability="
                    f"{self.specular_probability}, lobe_degrees={self.lobe_degrees}]")

    return GratNetBSDF
