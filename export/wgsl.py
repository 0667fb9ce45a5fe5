"""``gratnet export --format wgsl``: one WGSL shader module per material, for WebGPU, and its weights.

WGSL cannot be made from the runtime's GLSL here: no GLSL or SPIR-V → WGSL translator (naga, Tint) is installed.
So the functions are written by hand in export/wgsl/, one file per runtime file they twin (``encoding.wgsl`` is
``shaders/encoding.glsl``, and so on), line for line where WGSL allows; tests/tools/test_export_wgsl.py runs the
exported module in chromium's WebGPU and holds it to the numpy evaluation of the model file. What the hand-written
text must not do is type a number that Python owns. Everything of that kind is generated above it:

- the codes (``SCHEME_*``, ``HIDDEN_*``, ``OUTPUT_*``, ``RANGE_*``) from gratnet.codes' tables, as ``codes.glsl``;
- the model's constants: every value of export/glsl.py's :func:`~export.glsl.uniform_values` (the very initializers
  the GLSL module bakes, re-spelled in WGSL; a value this module cannot spell is an error) and viewer.renderer's
  ``model_defines`` (array sizes, ``LEAKY_RELU_SLOPE``, the grid shape);
- the A-term's limits from gratnet.brdf (``W_EPSILON``, ``A_MAX``) and ``PI``;
- the material's slope covariance of Smith's shadowing, ``GRATNET_SLOPE_COVARIANCE`` (the GLSL module's constant,
  export/glsl.py's :func:`~export.glsl.slope_covariance_value`);
- the layer table that fills the loop bounds (``gratnet_set_layers``, as the GLSL module's ``GRATNET_LAYERS``).

Weights: storage buffers, not textures. ``NAME.weights.bin`` is the GLSL module's file byte for byte (the packed
RGBA32F texels, row-major), read as ``array<vec4<f32>>`` the way mlp.glsl's ``WEIGHTS_SSBO`` form reads it. A
feature-grid model's grids are one buffer, ``NAME.grids.bin`` (``array<u32>``: each level's array of the model file
in turn, float16 pairs or float32 bits): WebGPU has no three-channel texture format, and one binding for all levels
keeps a model with many grid textures (paper-scratches: 12) under WebGPU's 8 storage buffers a stage.

Entry points (as the GLSL module's): ``gratnet_reflectance(wi, wo)`` (CIE XYZ, no A-term), ``gratnet_shade(wi, wo,
ior, exposure)`` (``exposure · A · S · gratnet_reflectance``, S: Smith's shadowing–masking for the material's slope
covariance: a mesh pixel of ``gratnet render``) and ``gratnet_shade_unshadowed(wi, wo, ior, exposure)`` (``exposure ·
A · gratnet_reflectance``: a BRDF slice's value), plus ``xyz_to_linear_srgb`` and ``xyz_to_display_srgb``.
"""

from __future__ import annotations

import dataclasses
import math
import re
from pathlib import Path

import numpy as np

from export.glsl import SLOPE_COVARIANCE, slope_covariance_value, uniform_values
from gratnet import __version__
from gratnet.brdf import A_MAX, W_EPSILON
from gratnet.codes import TABLES
from gratnet.errors import GratNetError
from gratnet.modelfile import ModelFile, pack_texture
from viewer.renderer import model_defines

__all__ = ["BIND_GROUP", "GRIDS_BINDING", "TEMPLATE_ROOT", "WEIGHTS_BINDING", "GridLevel", "WgslModule",
           "wgsl_constant", "wgsl_module", "write_wgsl"]

#: The hand-written twins of the runtime's GLSL (export/wgsl/), in module order; ``{grid}`` is featuregrid.wgsl for
#: a feature-grid model and featuregrid_none.wgsl for a pure MLP.
TEMPLATE_ROOT = Path(__file__).resolve().parent / "wgsl"
_PARTS = ("encoding.wgsl", "{grid}", "mlp.wgsl", "range.wgsl", "brdf.wgsl", "colour.wgsl", "entry.wgsl")
#: Where the module declares its buffers (a host with other bindings there edits the two declaration lines).
BIND_GROUP = 0
WEIGHTS_BINDING = 0
GRIDS_BINDING = 1
_INT = re.compile(r"-?\d+")
_FLOAT = re.compile(r"-?(?:\d+\.\d*|\.\d+|\d+)(?:[eE][+-]?\d+)?")
_CONSTRUCTOR = re.compile(r"(?P<kind>i?vec[234]|mat[234])\((?P<arguments>[^()]*)\)")
_ARRAY = re.compile(r"(?P<kind>i?vec[234])\[\]\((?P<elements>.*)\)")
_WGSL_TYPES = {"vec2": "vec2<f32>", "vec3": "vec3<f32>", "vec4": "vec4<f32>", "ivec2": "vec2<i32>",
               "ivec3": "vec3<i32>", "ivec4": "vec4<i32>", "mat2": "mat2x2<f32>", "mat3": "mat3x3<f32>",
               "mat4": "mat4x4<f32>"}


@dataclasses.dataclass(frozen=True)
class GridLevel:
    """One level of the grid buffer: its first element, nodes (R_u, R_v, T) and features C per node."""

    offset: int
    nodes: tuple[int, int, int]
    features: int


@dataclasses.dataclass(frozen=True)
class WgslModule:
    """One material's WGSL module and its buffers.

    Attributes:
        text: the module (WGSL, no entry point of its own: the host's shader calls its functions).
        weights: the packed weight texels, ``float32`` ``(H, W, 4)`` (``gratnet_weights``, row-major).
        grids: a feature-grid model's grid buffer (``gratnet_grids``), little-endian, a multiple of 4 bytes; b"" for a
            pure MLP.
        grid_levels: the grid buffer's levels, in order.
        grid_type: ``float16`` or ``float32`` (a pure MLP: ``""``).
    """

    text: str
    weights: np.ndarray
    grids: bytes = b""
    grid_levels: tuple[GridLevel, ...] = ()
    grid_type: str = ""

    @property
    def weights_size(self) -> tuple[int, int]:
        """(width, height) of the packed weights in texels."""
        return int(self.weights.shape[1]), int(self.weights.shape[0])


def _f32(value: float) -> str:
    """A WGSL float literal that reads back as the same float32 (9 significant digits round-trip)."""
    if not math.isfinite(float(value)):
        raise GratNetError(f"cannot write the non-finite value {value!r} as a WGSL constant")
    text = f"{float(np.float32(value)):.9g}"
    return text if any(c in text for c in ".e") else text + ".0"


def wgsl_constant(name: str, glsl: str) -> str:
    """``const NAME: TYPE = VALUE;`` for a GLSL ``const`` initializer of export/glsl.py (``2``, ``1.5``,
    ``vec3(…)``, ``mat3(…)``, ``vec4[](vec4(…), …)``), its numbers kept as written.

    Raises:
        GratNetError: a form this function cannot spell in WGSL (export/glsl.py learned a new one).
    """
    text = glsl.strip()
    if _INT.fullmatch(text):
        return f"const {name}: i32 = {text};"
    if _FLOAT.fullmatch(text):
        return f"const {name}: f32 = {text};"
    single = _CONSTRUCTOR.fullmatch(text)
    if single:
        kind = _WGSL_TYPES[single["kind"]]
        return f"const {name}: {kind} = {kind}({single['arguments']});"
    array = _ARRAY.fullmatch(text)
    if array:
        kind = _WGSL_TYPES[array["kind"]]
        elements = [match["arguments"] for match in _CONSTRUCTOR.finditer(array["elements"])
                    if match["kind"] == array["kind"]]
        if not elements or _CONSTRUCTOR.sub("", array["elements"]).replace(",", "").strip():
            raise GratNetError(f"export/wgsl.py cannot read the array initializer of {name}: {glsl[:80]}")
        items = ", ".join(f"{kind}({item})" for item in elements)
        return f"const {name}: array<{kind}, {len(elements)}> = array<{kind}, {len(elements)}>({items});"
    raise GratNetError(f"export/wgsl.py cannot spell the GLSL initializer of {name} in WGSL: {glsl[:80]}")


def _model_constants(model: ModelFile) -> list[str]:
    """The generated constants (module docstring): codes, defines, the GLSL module's uniform values, brdf's limits."""
    values = uniform_values(model)
    lines = ["// Codes shared with Python and the GLSL (gratnet/codes.py, as codes.glsl):"]
    lines += [f"const {define}: i32 = {code};" for table in TABLES if table.uniform in values
              for define, code in table.defines().items()]
    lines.append("// Array sizes and constants of the model (viewer/renderer.py model_defines):")
    for name, value in model_defines(model).items():
        lines.append(f"const {name}: f32 = {_f32(value)};" if isinstance(value, float)
                     else f"const {name}: i32 = {int(value)};")
    if values.get("u_grid_hardware_filter") != "0":
        raise GratNetError("export/wgsl.py interpolates the grids with eight loads only (u_grid_hardware_filter 0)")
    lines.append("// The model's values, as the GLSL module bakes them (export/glsl.py uniform_values):")
    lines += [wgsl_constant(name, glsl) for name, glsl in values.items()]
    lines += ["// The A-term's limits (gratnet/brdf.py W_EPSILON, A_MAX) and pi:",
              f"const A_TERM_MIN_W: f32 = {_f32(W_EPSILON)};", f"const A_TERM_MAX: f32 = {_f32(A_MAX)};",
              f"const PI: f32 = {_f32(math.pi)};",
              "// The relief's slope covariance (Sxx, Sxy, Syy) of Smith's shadowing in gratnet_shade (export/glsl.py "
              "slope_covariance_value):",
              wgsl_constant(SLOPE_COVARIANCE, slope_covariance_value(model))]
    return lines


def _grid_buffer(model: ModelFile) -> tuple[bytes, tuple[GridLevel, ...], str]:
    """The grid buffer (every level's array in turn, little-endian, padded to 4 bytes), its levels and type."""
    if not model.grids:
        return b"", (), ""
    dtype = np.dtype(model.grids[0].dtype)
    if dtype not in (np.dtype(np.float16), np.dtype(np.float32)):
        raise GratNetError(f"export/wgsl.py reads float16 or float32 grids, not {dtype}")
    levels: list[GridLevel] = []
    chunks: list[bytes] = []
    offset = 0
    for grid in model.grids:
        depth, height, width, features = (int(n) for n in grid.shape)
        levels.append(GridLevel(offset, (width, height, depth), features))
        chunks.append(np.ascontiguousarray(grid, dtype=dtype.newbyteorder("<")).tobytes())
        offset += int(grid.size)
    data = b"".join(chunks)
    return data + b"\0" * (-len(data) % 4), tuple(levels), str(dtype)


def _grid_constants(levels: tuple[GridLevel, ...], grid_type: str) -> list[str]:
    nodes = ", ".join(f"vec3<i32>({', '.join(str(n) for n in level.nodes)})" for level in levels)
    offsets = ", ".join(str(level.offset) for level in levels)
    count = len(levels)
    return ["// The grid buffer's levels: nodes (R_u, R_v, T) and first element of each.",
            f"const GRID_FLOAT16: bool = {'true' if grid_type == 'float16' else 'false'};",
            f"const GRID_NODES: array<vec3<i32>, {count}> = array<vec3<i32>, {count}>({nodes});",
            f"const GRID_OFFSET: array<i32, {count}> = array<i32, {count}>({offsets});"]


def _set_layers(layout: list[dict[str, int]]) -> str:
    """gratnet_set_layers(): the loop bounds from the layer table plus a zero the compiler cannot fold (mlp.wgsl)."""
    rows = "".join(f"    u_layers[{k}] = vec4<i32>({entry['row_offset']}, {entry['in_blocks']}, "
                   f"{entry['out_blocks']}, 0) + zero;\n" for k, entry in enumerate(layout))
    return (f"\nconst GRATNET_LAYER_COUNT: i32 = {len(layout)};\n\n"
            "// Fill the loop bounds of mlp.wgsl and encoding.wgsl's g_zero: arrayLength is known only at run\n"
            "// time, so the loops stay rolled and no literal of an error-free transform can be folded.\n"
            "fn gratnet_set_layers() {\n"
            "    let zero = min(i32(arrayLength(&gratnet_weights)), 0);\n"
            "    g_zero = f32(zero);\n"
            "    u_layer_count = GRATNET_LAYER_COUNT + zero;\n"
            f"{rows}}}\n")


def _header(model: ModelFile, material: str, module: WgslModule) -> str:
    width, height = module.weights_size
    covariance = slope_covariance_value(model).removeprefix("vec3(").removesuffix(")")
    levels = f", {len(model.grids)} feature-grid levels" if model.grids else ""
    grid_note = ""
    if module.grid_levels:
        sizes = "".join(f"//     level {k}: {' x '.join(str(n) for n in level.nodes)} nodes (R_u x R_v x T), from "
                        f"element {level.offset}\n" for k, level in enumerate(module.grid_levels))
        grid_note = (
            f"//   @group({BIND_GROUP}) @binding({GRIDS_BINDING}) gratnet_grids: array<u32>, a storage buffer of the "
            f"file\n//     {material}.grids.bin ({len(module.grids)} bytes): each level's (T, R_v, R_u, C = "
            f"{module.grid_levels[0].features}) array in turn,\n//     {module.grid_type} little-endian"
            f"{', two a word (the first in the low half)' if module.grid_type == 'float16' else ''}:\n{sizes}")
    return f"""// GratNet material "{material}": a neural BRDF of a diffractive surface, as one WGSL shader module.
// Written by `gratnet export --format wgsl` (GratNet {__version__}): export/wgsl/*.wgsl, hand-written twins of the
// runtime's shaders/*.glsl, under constants generated from the model file and gratnet's codes; do not edit.
// Network {'-'.join(str(s) for s in model.layer_sizes)}, {model.activation}/{model.output_activation}, \
scheme {model.scheme}, range {model.range.kind}{levels}.
//
// Put this text before your own WGSL in one shader module (it has no entry point of its own) and call its
// functions from any stage. It defines module-scope names of its own (PI, sigmoid, a_term, smith_shadowing,
// encoding_set_key, mlp_evaluate, range_inverse, the SCHEME_*/HIDDEN_*/OUTPUT_*/RANGE_*, u_* and GRATNET_*
// constants, ...): two materials cannot share one module.
//
// Buffers (read-only storage; change the @group/@binding numbers below to fit your layout):
//   @group({BIND_GROUP}) @binding({WEIGHTS_BINDING}) gratnet_weights: array<vec4<f32>>, a storage buffer of the \
file
//     {material}.weights.bin ({width * height * 16} bytes: {width} x {height} RGBA float32 texels, little-endian, \
row-major).
{grid_note}//
// Functions (wi: unit vector towards the light, wo: towards the viewer, both in the tangent frame, z along the
// normal):
//   gratnet_reflectance(wi: vec3<f32>, wo: vec3<f32>) -> vec3<f32>
//       CIE XYZ reflectance (network, eq. 7 inverted; no A-term)
//   gratnet_shade(wi: vec3<f32>, wo: vec3<f32>, ior: f32, exposure: f32) -> vec3<f32>
//       exposure * A(wi, wo) * S(wi, wo) * reflectance (what gratnet render draws on a mesh for a directional light
//       of irradiance 1; S: Smith's shadowing-masking for this material's slope covariance
//       {SLOPE_COVARIANCE} = vec3<f32>({covariance}))
//   gratnet_shade_unshadowed(wi: vec3<f32>, wo: vec3<f32>, ior: f32, exposure: f32) -> vec3<f32>
//       exposure * A(wi, wo) * reflectance, without S (a BRDF slice, as gratnet render --slice)
//   xyz_to_linear_srgb(xyz: vec3<f32>) -> vec3<f32>, xyz_to_display_srgb(xyz: vec3<f32>, exposure: f32) -> vec3<f32>
// Physics and conventions: docs/physics.md; this module: docs/export.md.

"""


def wgsl_module(model: ModelFile, material: str) -> WgslModule:
    """The WGSL module of ``model`` (named ``material`` in its header) and its buffers.

    Raises:
        GratNetError: a constant this exporter cannot spell in WGSL, or grids of another dtype.
    """
    texture, layout = pack_texture(model)
    grids, grid_levels, grid_type = _grid_buffer(model)
    lines = _model_constants(model)
    if grid_levels:
        lines += _grid_constants(grid_levels, grid_type)
    lines += ["", "// ---- buffers ----",
              f"@group({BIND_GROUP}) @binding({WEIGHTS_BINDING}) var<storage, read> gratnet_weights: array<vec4<f32>>;"]
    if grid_levels:
        lines.append(f"@group({BIND_GROUP}) @binding({GRIDS_BINDING}) var<storage, read> gratnet_grids: array<u32>;")
    parts = []
    for part in _PARTS:
        name = part.format(grid="featuregrid.wgsl" if grid_levels else "featuregrid_none.wgsl")
        parts.append(f"\n// ---- export/wgsl/{name} ----\n" + (TEMPLATE_ROOT / name).read_text(encoding="utf-8"))
        if name == "mlp.wgsl":
            parts.append(_set_layers(layout))
    weights = np.ascontiguousarray(texture, np.float32)
    module = WgslModule("", weights, grids, grid_levels, grid_type)
    text = _header(model, material, module) + "\n".join(lines) + "\n" + "".join(parts)
    return dataclasses.replace(module, text=text)


def write_wgsl(materials: list[tuple[str, ModelFile]], folder: Path) -> dict[str, dict[str, object]]:
    """Write ``NAME.wgsl``, ``NAME.weights.bin`` and (grid models) ``NAME.grids.bin`` per material into ``folder``;
    the manifest entry of each."""
    entries: dict[str, dict[str, object]] = {}
    for name, model in materials:
        module = wgsl_module(model, name)
        (folder / f"{name}.wgsl").write_text(module.text, encoding="utf-8")
        (folder / f"{name}.weights.bin").write_bytes(module.weights.astype("<f4").tobytes())
        width, height = module.weights_size
        entry: dict[str, object] = {"module": f"{name}.wgsl", "weights": f"{name}.weights.bin",
                                    "weights_texels": [width, height], "weights_format": "RGBA32F little-endian",
                                    "bindings": {"group": BIND_GROUP, "gratnet_weights": WEIGHTS_BINDING}}
        if module.grid_levels:
            (folder / f"{name}.grids.bin").write_bytes(module.grids)
            entry.update({"grids": f"{name}.grids.bin", "grid_type": module.grid_type,
                          "grid_levels": [dataclasses.asdict(level) for level in module.grid_levels]})
            entry["bindings"] = {"group": BIND_GROUP, "gratnet_weights": WEIGHTS_BINDING,
                                 "gratnet_grids": GRIDS_BINDING}
        entries[name] = entry
    return entries
