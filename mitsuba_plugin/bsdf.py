"""The ``gratnet`` Mitsuba 3 BSDF: a trained GratNet network as a glossy reflection (docs/physics.md
"Path tracing: Mitsuba 3").

Plugin properties (XML / ``mi.load_dict``):

- ``filename`` (string): the model file (``assets/NAME/model.npz`` or any ``gratnet train`` output);
- ``ior`` (float, default 1.5): the A-term's Fresnel refractive index; 0 turns Fresnel off (R/R0 = 1);
- ``tangent_attribute`` (string, default ``""``): name of a per-vertex 3-vector mesh attribute holding the
  tangent (the height field's x on the surface), interpolated like the GL runtime's ``in_tangent``;
  ``mitsuba_plugin.scene`` exports meshes with ``vertex_tangent``. Empty: Mitsuba's own shading frame,
  whose first axis is ∂p/∂u of the mesh's UVs (Gram–Schmidt against the shading normal);
- ``specular_probability`` (float in [0, 1], default 0.5) and ``lobe_degrees`` (float > 0, default 2):
  the sampling mixture (``mitsuba_plugin.shading``): that share of samples from a vMF lobe of that angular
  standard deviation around the mirror direction, the rest cosine-weighted.

Values: ``eval`` = BSDF × cos θ of the light-side direction = ``A · XYZ → linear sRGB`` in radiance
transport (what the GL runtime shades per unit light). The implied BSDF, ``A · XYZ / cos θ_light``, is not
reciprocal; in importance transport (light tracing) ``eval`` returns it times cos θ of the camera side.
Only RGB variants (the colour is linear sRGB).
"""

from __future__ import annotations

import functools
import math
from pathlib import Path
from types import ModuleType
from typing import Any

import numpy as np

from gratnet.errors import GratNetError
from gratnet.modelfile import ModelFile, load_model
from mitsuba_plugin.shading import (
    eval_linear_srgb,
    kappa_for_lobe,
    mixture_pdf,
    sample_mixture,
    xyz_to_linear_srgb_matrix,
)

__all__ = ["PLUGIN_NAME", "bsdf_class", "check_ior", "register"]

PLUGIN_NAME = "gratnet"


@functools.lru_cache(maxsize=8)
def _cached_model(path: str, modified_ns: int) -> ModelFile:
    return load_model(path)


def _model(filename: str) -> ModelFile:
    path = Path(filename).expanduser()
    if not path.is_file():
        raise GratNetError(f"gratnet BSDF: model file {filename!r} does not exist")
    return _cached_model(str(path.resolve()), path.stat().st_mtime_ns)


def check_ior(ior: float) -> float | None:
    """The A-term's ``ior`` argument for a plugin/flag value: None for 0 (no Fresnel), else the value; refused
    (one GratNetError) exactly where ``gratnet render`` refuses it (``gratnet.brdf.check_ior``)."""
    from gratnet.brdf import check_ior as check

    return check(float(ior), "ior")


def _checked(value: float, name: str, low: float, high: float, low_open: bool = False) -> float:
    value = float(value)
    if not (math.isfinite(value) and (low < value if low_open else low <= value) and value <= high):
        raise GratNetError(f"gratnet BSDF: {name} must be in {'(' if low_open else '['}{low:g}, {high:g}], "
                           f"got {value!r}")
    return value


def register(mi: ModuleType) -> None:
    """Register the ``gratnet`` BSDF for Mitsuba's current variant (idempotent)."""
    cls = bsdf_class(mi.variant())
    mi.register_bsdf(PLUGIN_NAME, lambda props: cls(props))


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

    class GratNetBSDF(mi.BSDF):
        """A GratNet network as a Mitsuba BSDF (see the module docstring)."""

        def __init__(self, props: Any) -> None:
            mi.BSDF.__init__(self, props)
            self.filename = str(props.get("filename", ""))
            if not self.filename:
                raise GratNetError("gratnet BSDF: give the model file as the 'filename' property")
            self.model = _model(self.filename)
            self.ior = check_ior(props.get("ior", 1.5))
            self.tangent_attribute = str(props.get("tangent_attribute", ""))
            self.specular_probability = _checked(props.get("specular_probability", 0.5), "specular_probability",
                                                 0.0, 1.0)
            self.lobe_degrees = _checked(props.get("lobe_degrees", 2.0), "lobe_degrees", 0.0, 90.0, low_open=True)
            self.kappa = kappa_for_lobe(self.lobe_degrees)
            self.matrix = xyz_to_linear_srgb_matrix()
            self.m_flags = flags
            self.m_components = [flags]

        # -- frames -------------------------------------------------------------------------------
        def _rotation(self, si: Any, active: Any, count: int) -> np.ndarray | None:
            """(cos α, sin α) per lane: the mesh tangent in Mitsuba's shading frame, or None (use it as is)."""
            if not self.tangent_attribute:
                return None
            tangent = si.shape.eval_attribute_3(self.tangent_attribute, si, active)
            world = vectors(tangent, count)
            along_s = np.sum(world * vectors(si.sh_frame.s, count), axis=-1)
            along_t = np.sum(world * vectors(si.sh_frame.t, count), axis=-1)
            length = np.hypot(along_s, along_t)
            good = length > 1e-6  # a tangent (nearly) along the normal: keep Mitsuba's frame, as GL falls back
            cos_alpha = np.where(good, along_s / np.where(good, length, 1.0), 1.0)
            sin_alpha = np.where(good, along_t / np.where(good, length, 1.0), 0.0)
            return np.stack([cos_alpha, sin_alpha], axis=-1)

        @staticmethod
        def _to_tangent_frame(directions: np.ndarray, rotation: np.ndarray | None) -> np.ndarray:
            if rotation is None:
                return directions
            c, s = rotation[:, 0], rotation[:, 1]
            x, y = directions[:, 0], directions[:, 1]
            return np.stack([x * c + y * s, -x * s + y * c, directions[:, 2]], axis=-1)

        # -- value --------------------------------------------------------------------------------
        def _value(self, ctx: Any, si: Any, wi: np.ndarray, wo: np.ndarray, active: np.ndarray) -> np.ndarray:
            """eval for local (shading-frame) directions: si.wi = ``wi``, sampled/light direction ``wo``."""
            count = wi.shape[0]
            result = np.zeros((count, 3))
            if not ctx.is_enabled(mi.BSDFFlags.GlossyReflection) or not np.any(active):
                return result
            rotation = self._rotation(si, True, count)
            wi_t, wo_t = self._to_tangent_frame(wi, rotation), self._to_tangent_frame(wo, rotation)
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

        def eval(self, ctx: Any, si: Any, wo: Any, active: Any = True) -> Any:
            count, wi_np, wo_np, on = self._inputs(si, wo, active)
            return to_colour(self._value(ctx, si, wi_np, wo_np, on))

        def pdf(self, ctx: Any, si: Any, wo: Any, active: Any = True) -> Any:
            count, wi_np, wo_np, on = self._inputs(si, wo, active)
            density = mixture_pdf(wi_np, wo_np, self.specular_probability, self.kappa)
            return to_float(np.where(on, density, 0.0))

        def eval_pdf(self, ctx: Any, si: Any, wo: Any, active: Any = True) -> tuple[Any, Any]:
            count, wi_np, wo_np, on = self._inputs(si, wo, active)
            density = mixture_pdf(wi_np, wo_np, self.specular_probability, self.kappa)
            return to_colour(self._value(ctx, si, wi_np, wo_np, on)), to_float(np.where(on, density, 0.0))

        def sample(self, ctx: Any, si: Any, sample1: Any, sample2: Any, active: Any = True) -> tuple[Any, Any]:
            count = max(lanes(si.wi), lanes(sample1), lanes(sample2), lanes(active))
            wi_np, on = vectors(si.wi, count), mask(active, count)
            directions, valid = sample_mixture(wi_np, column(sample1, count), column(sample2.x, count),
                                               column(sample2.y, count), self.specular_probability, self.kappa)
            valid &= on
            density = np.where(valid, mixture_pdf(wi_np, directions, self.specular_probability, self.kappa), 0.0)
            valid &= density > 0.0
            value = self._value(ctx, si, wi_np, directions, valid)
            weight = np.where(valid[:, None], value / np.where(valid, density, 1.0)[:, None], 0.0)
            sample = dr.zeros(mi.BSDFSample3f) if scalar else dr.zeros(mi.BSDFSample3f, count)
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
            return (f"GratNetBSDF[filename={self.filename!r}, ior={self.ior}, tangent_attribute="
                    f"{self.tangent_attribute!r}, specular_probability={self.specular_probability}, "
                    f"lobe_degrees={self.lobe_degrees}]")

    return GratNetBSDF
