"""The tiled compute MLP's plan (issue 32; ``shaders/mlp_tiled.glsl``, the deferred path's ``tiled`` weights).

One work group evaluates a tile of list entries (pixels); each layer's weights are staged in shared memory
once per tile, the tile's activations stay there between layers, and each invocation holds 4 outputs × 4
pixels in registers. How big a tile, how many invocations and how many input blocks of a layer's weights
fit at once follow from the model's layer widths and the driver's compute limits; :func:`plan_tiles`
computes them here and the kernel receives them as ``#define``s (:meth:`TilePlan.defines`).

Shared memory, in vec4s of ``element`` bytes (16 for float32, 8 for half precision):

* activations: ``pixels · act_blocks``, ``act_blocks = max_k(in_blocks_k + out_blocks_k)`` (layer k reads
  its inputs at one end and writes its outputs at the other);
* weights: ``weight_vec4s``, the rest of the budget; a layer takes ``min(in_blocks, weight_vec4s // (4 ·
  out_blocks))`` input blocks per chunk (:meth:`TilePlan.chunk_blocks`).

The tile is the largest multiple of 4 pixels up to :data:`MAX_TILE_PIXELS` that leaves room for
:data:`MIN_CHUNK_BLOCKS` input blocks of the widest layer's weights (else for one).

``GRATNET_TILE_PLAN`` (environment; e.g. ``pixels=16,group=128,shared=24576``) overrides the largest tile, the
invocations per group and the shared memory the plan may use (at most the driver's): a GPU session can time
several plans in one run (scripts/gpu_bench.sh); a bench row records the plan it ran.

Rendering only: no glfw, no imgui, no torch.
"""

from __future__ import annotations

import ctypes
import dataclasses
import logging
import os
from collections.abc import Mapping, Sequence

import moderngl

from gratnet.errors import GratNetError

__all__ = ["GL_MINIMUM_SHARED_BYTES", "HALF_EXTENSIONS", "MAX_TILE_PIXELS", "MIN_CHUNK_BLOCKS", "PLAN_VARIABLE",
           "TilePlan", "half_extension", "max_compute_shared_bytes", "plan_for_context", "plan_tiles"]

_LOG = logging.getLogger("gratnet.deferred")
#: GL 4.3's least GL_MAX_COMPUTE_SHARED_MEMORY_SIZE (bytes): assumed when the driver cannot be asked.
GL_MINIMUM_SHARED_BYTES = 32768
_GL_MAX_COMPUTE_SHARED_MEMORY_SIZE = 0x8262
#: Largest tile: 32 pixels (8 quads). Beyond it the activations of the shipped nets no longer leave room for
#: a useful chunk of weights in NVIDIA's 48 KiB.
MAX_TILE_PIXELS = 32
#: Input blocks of the widest layer's weights the plan keeps room for before growing the tile.
MIN_CHUNK_BLOCKS = 4
#: The environment variable of plan overrides (see the module docstring).
PLAN_VARIABLE = "GRATNET_TILE_PLAN"
#: Invocations per work group (a multiple of NVIDIA's 32-wide warp and of llvmpipe's 8 lanes).
DEFAULT_GROUP = 64
#: The extensions that give GLSL half-precision arithmetic (f16vec4), in order of preference, with the define
#: that makes deferred.glsl enable each.
HALF_EXTENSIONS = {"GL_NV_gpu_shader5": "TILED_HALF_NV", "GL_AMD_gpu_shader_half_float": "TILED_HALF_AMD"}


def max_compute_shared_bytes(ctx: moderngl.Context) -> int:
    """GL_MAX_COMPUTE_SHARED_MEMORY_SIZE of the current context (32768 on llvmpipe, 49152 on NVIDIA).
    moderngl's ``ctx.info`` lacks it, so it is asked through the GL library (glvnd dispatches the call to
    the current context); GL 4.3's minimum when that fails."""
    value = ctx.info.get("GL_MAX_COMPUTE_SHARED_MEMORY_SIZE")
    if isinstance(value, int) and value > 0:
        return value
    for name in ("libOpenGL.so.0", "libGL.so.1"):
        try:
            library = ctypes.CDLL(name)
        except OSError:
            continue
        result = ctypes.c_int(0)
        library.glGetIntegerv(_GL_MAX_COMPUTE_SHARED_MEMORY_SIZE, ctypes.byref(result))
        if result.value > 0:
            return int(result.value)
    _LOG.info("GL_MAX_COMPUTE_SHARED_MEMORY_SIZE unknown: planning tiles for GL 4.3's minimum, %d bytes",
              GL_MINIMUM_SHARED_BYTES)
    return GL_MINIMUM_SHARED_BYTES


def half_extension(ctx: moderngl.Context) -> str | None:
    """The first of :data:`HALF_EXTENSIONS` the context offers, or ``None`` (llvmpipe has neither)."""
    return next((name for name in HALF_EXTENSIONS if name in ctx.extensions), None)


@dataclasses.dataclass(frozen=True)
class TilePlan:
    """Tile, blocking and shared-memory sizes of the tiled kernel for one network (see the module docstring)."""

    pixels: int  #: list entries per work group (a multiple of 4)
    group: int  #: invocations per work group
    items: int  #: (output block, pixel quad) items per invocation at most, each 4 × 4 accumulators
    act_blocks: int  #: vec4 activation blocks per pixel
    weight_vec4s: int  #: staged weight texels (vec4s)
    encode_split: int  #: invocations that encode one pixel (each every encode_split-th input block)
    element: int  #: bytes per staged vec4 (16: float32, 8: half)
    budget: int  #: the shared memory the plan was made for, bytes

    @property
    def shared_bytes(self) -> int:
        """Shared memory the kernel declares."""
        return self.element * (self.pixels * self.act_blocks + self.weight_vec4s)

    def chunk_blocks(self, in_blocks: int, out_blocks: int) -> int:
        """Input blocks per staged chunk of a layer (``tiled_chunk_blocks`` in mlp_tiled.glsl)."""
        return max(1, min(in_blocks, self.weight_vec4s // (4 * out_blocks)))

    def defines(self) -> dict[str, int | float]:
        return {"TILED_PIXELS": self.pixels, "TILED_GROUP": self.group, "TILED_ITEMS": self.items,
                "TILED_ACT_BLOCKS": self.act_blocks, "TILED_WEIGHT_VEC4S": self.weight_vec4s,
                "TILED_ENCODE_SPLIT": self.encode_split}

    def describe(self, layout: Sequence[Mapping[str, int]]) -> str:
        """One line: tile, group, blocking and each layer's chunks (for logs and bench notes)."""
        chunks = [-(-entry["in_blocks"] // self.chunk_blocks(entry["in_blocks"], entry["out_blocks"]))
                  for entry in layout]
        return (f"tile {self.pixels} pixels, {self.group} invocations × ≤ {self.items} items of 4 outputs × 4 "
                f"pixels, {self.shared_bytes} of {self.budget} bytes shared ({self.act_blocks} activation "
                f"blocks per pixel, {self.weight_vec4s} weight texels), weight chunks per layer "
                f"{'/'.join(map(str, chunks))}")


def plan_tiles(layout: Sequence[Mapping[str, int]], shared_bytes: int, max_invocations: int = 1024,
               half: bool = False, max_pixels: int = MAX_TILE_PIXELS, group: int = DEFAULT_GROUP) -> TilePlan:
    """The plan for a network of ``layout`` (``gratnet.modelfile.texture_layout``'s entries) in
    ``shared_bytes`` of shared memory (:func:`max_compute_shared_bytes`).

    Raises:
        GratNetError: not even 4 pixels and one input block of the widest layer fit.
    """
    element = 8 if half else 16
    act_blocks = max(entry["in_blocks"] + entry["out_blocks"] for entry in layout)
    widest_out = max(entry["out_blocks"] for entry in layout)
    widest_in = max(entry["in_blocks"] for entry in layout)
    capacity = shared_bytes // element
    pixels = 0
    for chunk in (min(MIN_CHUNK_BLOCKS, widest_in), 1):
        room = capacity - 4 * widest_out * chunk
        pixels = min(max_pixels, room // act_blocks if room > 0 else 0) // 4 * 4
        if pixels >= 4:
            break
    if pixels < 4:
        needed = element * (4 * act_blocks + 4 * widest_out)
        raise GratNetError(f"deferred weights 'tiled': the net needs at least {needed} bytes of compute shared memory "
                           f"(4 pixels' activations and one input block of its widest layer's weights); this "
                           f"driver offers {shared_bytes}")
    weight_vec4s = capacity - pixels * act_blocks
    group = max(4, min(group, max_invocations))
    items = -(-widest_out * (pixels // 4) // group)
    return TilePlan(pixels=pixels, group=group, items=items, act_blocks=act_blocks, weight_vec4s=weight_vec4s,
                    encode_split=max(1, group // pixels), element=element, budget=shared_bytes)


def _plan_overrides() -> dict[str, int]:
    """``GRATNET_TILE_PLAN``'s ``pixels=…,group=…,shared=…`` (any subset), checked."""
    text = os.environ.get(PLAN_VARIABLE, "").strip()
    overrides: dict[str, int] = {}
    for part in (part.strip() for part in text.split(",") if part.strip()):
        name, _, value = part.partition("=")
        if name.strip() not in ("pixels", "group", "shared") or not value.strip().isdigit():
            raise GratNetError(f"{PLAN_VARIABLE} takes pixels=N,group=N,shared=BYTES (any of them); got {text!r}")
        overrides[name.strip()] = int(value)
    if overrides.get("pixels", 4) < 4 or overrides.get("pixels", 4) % 4 or overrides.get("group", 1) < 1:
        raise GratNetError(f"{PLAN_VARIABLE}: pixels must be a multiple of 4 (≥ 4) and group ≥ 1; got {text!r}")
    return overrides


def plan_for_context(ctx: moderngl.Context, layout: Sequence[Mapping[str, int]], half: bool = False) -> TilePlan:
    """:func:`plan_tiles` for ``ctx``'s limits (shared memory, invocations per group) and ``GRATNET_TILE_PLAN``."""
    limit = max_compute_shared_bytes(ctx)
    invocations = int(ctx.info.get("GL_MAX_COMPUTE_WORK_GROUP_INVOCATIONS", 1024))
    overrides = _plan_overrides()
    if overrides.get("group", 1) > invocations or overrides.get("shared", 0) > limit:
        raise GratNetError(f"{PLAN_VARIABLE}: this driver allows {invocations} invocations per group and {limit} "
                           f"bytes of shared memory; got {os.environ.get(PLAN_VARIABLE)!r}")
    return plan_tiles(layout, overrides.get("shared", limit), invocations, half,
                      max_pixels=overrides.get("pixels", MAX_TILE_PIXELS), group=overrides.get("group", DEFAULT_GROUP))
