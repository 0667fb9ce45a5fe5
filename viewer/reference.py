"""The reference material on the GPU: the ground-truth volume looked up per pixel where the network would run.

:class:`ReferenceRenderer` uploads a :class:`~gratnet.volume.Volume` as one 3D texture (``(R_u, R_v, S)`` texels,
RGB16F holding ``XYZ · 2¹⁵`` or RGB32F, :data:`gratnet.reference.PRECISIONS`) and compiles the same programs as the
network (``surface``, ``brdf_slice``) with ``REFERENCE`` defined: shaders/reference.glsl takes the key vector to
the volume's network coordinates (eq. 6, its own scheme) and interpolates trilinearly (eq. 6g), with the network's
A-term, Fresnel, irradiance and exposure around it. So a mesh render, a BRDF slice and every render option (anti-
aliasing, depth pre-pass, counters) mean the same thing for both materials; ``gratnet.reference.reference_xyz``
is the numpy twin (tests/runtime/test_reference.py).

Limits, checked by :func:`check_reference_limits` before any GL work: each side at most the context's
``GL_MAX_3D_TEXTURE_SIZE`` (2048 on llvmpipe and on NVIDIA GPUs), and the texture's bytes at most
:data:`MAX_TEXTURE_BYTES` (a 41-slice 1001² volume is 246 MB as float16, 493 MB as float32). No work is skipped:
the output bound that lets the network skip dark pixels is the network's, not the volume's.

Rendering only: no glfw, no imgui, no torch.
"""

from __future__ import annotations

import logging
from collections.abc import Mapping
from pathlib import Path

import moderngl
import numpy as np

from gratnet.codes import SCHEME
from gratnet.errors import GratNetError
from gratnet.reference import FLOAT16_SCALE, check_precision, check_uniform_slices, stored_values, texture_bytes
from gratnet.shadowing import slope_covariance_from_metadata
from gratnet.volume import Volume
from viewer.shading import MaterialTexture, ShadingPrograms, set_uniform, skip_threshold_value

__all__ = ["MAX_TEXTURE_BYTES", "REFERENCE_UNIT", "ReferenceRenderer", "check_reference_limits"]

_LOG = logging.getLogger("gratnet.reference")
#: Largest reference texture accepted (bytes): 2 GiB, twice a 41-slice 2001² volume at float16 less a margin;
#: beyond it a driver's allocation failure would surface as an incomplete texture, not a clear message.
MAX_TEXTURE_BYTES = 2 * 1024**3
#: Texture unit of ``u_reference`` (units 0–3 are the network's and the passes' inputs; 1 and 2 are evaluate_keys'
#: and accumulate's inputs, so the volume takes one no program shares).
REFERENCE_UNIT = 6
_DEFINES = {"REFERENCE": 1, "MAX_FREQUENCIES": 1}  # encoding.glsl's arrays: the look-up uses no frequency


def check_reference_limits(slices: int, resolution: int, precision: str, info: Mapping[str, object] | None = None,
                           name: str = "volume") -> None:
    """One clear error when a ``slices × resolution²`` volume cannot be a reference texture: more bytes than
    :data:`MAX_TEXTURE_BYTES`, or a side beyond the context's ``GL_MAX_3D_TEXTURE_SIZE`` (``info``: the context's
    ``ctx.info``; None: only the byte limit)."""
    check_precision(precision)
    size = texture_bytes(slices, resolution, precision)
    if size > MAX_TEXTURE_BYTES:
        raise GratNetError(f"{name} ({slices} slices of {resolution}²) needs {size / 1e6:.0f} MB as a {precision} "
                           f"reference texture, more than the {MAX_TEXTURE_BYTES / 1e6:.0f} MB limit")
    if info is not None:
        limit = info.get("GL_MAX_3D_TEXTURE_SIZE")
        if isinstance(limit, int) and max(slices, resolution) > limit:
            raise GratNetError(f"{name} ({slices} slices of {resolution}²) exceeds this OpenGL's 3D texture "
                               f"size limit of {limit}")


class ReferenceRenderer(ShadingPrograms):
    """The ground-truth volume as a material (see the module docstring).

    Args:
        ctx: an OpenGL ≥ 4.3 context.
        volume: the ground-truth volume (``gratnet.volume.read_volume``); its metadata must name its ``scheme``.
        shader_root: folder of the GLSL files (default: the repository's ``shaders/``).
        precision: ``float16`` (default) or ``float32`` storage (:data:`gratnet.reference.PRECISIONS`).

    Attributes:
        volume: the volume; ``scheme``: its sampling scheme; ``precision``: the storage;
        ``values``: the volume's XYZ as the texture holds them (``gratnet.reference.stored_values``).
    """

    def __init__(self, ctx: moderngl.Context, volume: Volume, shader_root: str | Path | None = None,
                 precision: str = "float16") -> None:
        self.precision = check_precision(precision)
        scheme = volume.metadata.get("scheme")
        if scheme not in SCHEME:
            raise GratNetError(f"the volume's metadata names no sampling scheme ({', '.join(SCHEME.names)}), got "
                               f"{scheme!r}")
        check_uniform_slices(volume.metadata, volume.slices)
        check_reference_limits(volume.slices, volume.resolution, precision, ctx.info)
        # Smith's shadowing with the volume's recorded slopes (viewer.scene_config.load_reference gives an older
        # volume its material's); none recorded: unshadowed.
        super().__init__(ctx, _DEFINES, shader_root, slope_covariance=slope_covariance_from_metadata(volume.metadata))
        self.volume = volume
        self.scheme = str(scheme)
        self.values = stored_values(volume.xyz, precision)
        scale = FLOAT16_SCALE if precision == "float16" else 1.0
        texels = (self.values * np.float32(scale)).astype(np.float16 if precision == "float16" else np.float32)
        # (S, R_v, R_u, 3) row-major is texel (j, i, s) of an (R_u, R_v, S) texture: x = u*, y = v*, z = t.
        self._texture = ctx.texture3d((volume.resolution, volume.resolution, volume.slices), 3,
                                      np.ascontiguousarray(texels).tobytes(),
                                      dtype="f2" if precision == "float16" else "f4")
        self._texture.filter = (moderngl.NEAREST, moderngl.NEAREST)  # texelFetch ignores it; be explicit
        self._texture.repeat_x = self._texture.repeat_y = self._texture.repeat_z = False
        self._scale = scale
        self._warned_skip = False

    @property
    def texture_bytes(self) -> int:
        """Bytes of the volume's texture as uploaded (before any driver padding)."""
        return texture_bytes(self.volume.slices, self.volume.resolution, self.precision)

    def configure_program(self, program: moderngl.Program, name: str) -> None:
        """The look-up's uniforms: the texture's unit, the storage scale and the volume's scheme."""
        set_uniform(program, "u_reference", REFERENCE_UNIT)
        set_uniform(program, "u_reference_scale", float(self._scale))
        set_uniform(program, SCHEME.uniform_name, SCHEME.code(self.scheme))

    def material_textures(self) -> tuple[tuple[MaterialTexture, int], ...]:
        return ((self._texture, REFERENCE_UNIT),)

    def skip_uniforms(self, program: moderngl.Program | moderngl.ComputeShader, skip_threshold: float | None
                      ) -> tuple[MaterialTexture, int]:
        """Nothing to set (reference programs never skip); returns the volume's own binding."""
        if skip_threshold_value(skip_threshold) > 0.0 and not self._warned_skip:
            _LOG.info("reference renders look up every pixel: skipping dark pixels is the network's (its output "
                      "bound)")
            self._warned_skip = True
        return self._texture, REFERENCE_UNIT

    def release(self) -> None:
        """Free the GL objects (the context itself belongs to the caller)."""
        self.release_programs()
        self._texture.release()
