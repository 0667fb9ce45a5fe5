"""``gratnet export --format glsl``: one self-contained GLSL function module per material, and its weights.

The module is the runtime's own GLSL, not a copy typed again: a small template ``#include``s
``shaders/encoding.glsl``, ``featuregrid.glsl``, ``mlp.glsl``, ``range.glsl``, ``brdf.glsl`` and ``colour.glsl``,
and viewer/glsl.py's preprocessor expands it exactly as for a runtime program (``codes.glsl`` included). Then
three mechanical edits turn the program text into a module an engine can include:

1. the ``#version`` and stage lines go (the host shader has its own), and each ``#line`` directive becomes a
   ``// ---- shaders/NAME.glsl ----`` comment where a file starts (the runtime's encoded file numbers would mean
   nothing in an engine's error log);
2. every model uniform becomes a ``const`` with the model's value (:func:`uniform_values`), so that the host sets
   nothing but the weight texture; an uniform this module does not know is an error (a new runtime uniform must
   not go unset silently);
3. the two uniforms that bound the MLP's loops (``u_layer_count``, ``u_layers``) become plain globals that the
   entry points fill at run time from constants plus a zero the compiler cannot see (``min(textureSize(…).x,
   0)``). Why: with constant bounds Mesa unrolls the whole network and its JIT then takes minutes (the reason the
   runtime keeps them uniforms: docs/architecture.md, "Uniforms, not constants"); ANGLE's WebGL on llvmpipe would
   pay the same.

The weights stay in the runtime's packed RGBA32F texture (docs/formats.md, "Weight texture layout"), shipped as a
raw little-endian float32 file: ``mlp.glsl`` reads them with ``texelFetch`` unchanged, and the shipped nets'
~28k weights as GLSL ``const`` arrays would be ~7k ``vec4`` literals that every host recompiles with the shader.

Entry points (documented in the module's header and docs/export.md), all for unit vectors in the tangent frame (z
along the normal): ``gratnet_reflectance(wi, wo)`` (CIE XYZ of the D65-normalised reflectance, the network after
eq. 7's inverse, no A-term); ``gratnet_shade(wi, wo, ior, exposure)`` (``exposure · A(wi, wo) · S(wi, wo) ·
gratnet_reflectance``, what ``gratnet render`` writes per pixel for a directional light: eq. 5's A-term times Smith's
shadowing–masking S of brdf.glsl's ``smith_shadowing`` for the material's slope covariance, baked as
``GRATNET_SLOPE_COVARIANCE``; docs/physics.md, "Shadowing and masking"); ``gratnet_shade_unshadowed(wi, wo, ior,
exposure)`` (``exposure · A · gratnet_reflectance`` without S: a BRDF slice's value, as ``gratnet render --slice``
and the paper's evaluation draw it); plus colour.glsl's ``xyz_to_linear_srgb`` and ``xyz_to_display_srgb``.
"""

from __future__ import annotations

import dataclasses
import math
import re
import tempfile
from pathlib import Path

import numpy as np

from gratnet import __version__
from gratnet.codes import HIDDEN, OUTPUT, RANGE, SCHEME
from gratnet.errors import GratNetError
from gratnet.featuregrid import CHUNK_FEATURES
from gratnet.modelfile import ModelFile, pack_texture
from gratnet.shadowing import model_slope_covariance
from viewer.glsl import LINE_STRIDE, SHADER_ROOT, preprocess
from viewer.renderer import frequency_table as runtime_frequency_table
from viewer.renderer import model_defines, xyz_to_linear_srgb_matrix

__all__ = ["ENTRY_POINTS", "GRID_SAMPLER", "MODULE_INCLUDES", "SAMPLER", "SLOPE_COVARIANCE", "GlslModule",
           "frequency_table", "glsl_module", "grid_chunks_of", "slope_covariance_value",
           "uniform_values"]

#: The runtime's files the module is made of, in include order (featuregrid.glsl before mlp.glsl, as in the
#: runtime's programs; for a pure MLP it compiles to two empty stand-ins).
MODULE_INCLUDES = ("encoding.glsl", "featuregrid.glsl", "mlp.glsl", "range.glsl", "brdf.glsl", "colour.glsl")
#: The one uniform every host sets: the packed weight texture (RGBA32F, NEAREST, no mipmaps).
SAMPLER = "u_weights"
#: A feature-grid model's grid textures (an array of sampler3D, featuregrid.glsl): set by the host too.
GRID_SAMPLER = "u_grid"
#: The uniforms that bound loops: globals filled at run time (module docstring, item 3).
LOOP_BOUNDS = ("u_layer_count", "u_layers")
#: The constant that holds the material's slope covariance (Σxx, Σxy, Σyy) of Smith's shadowing in gratnet_shade.
SLOPE_COVARIANCE = "GRATNET_SLOPE_COVARIANCE"
#: The module's own functions (besides colour.glsl's), in the header's order: every one is kept by export/hlsl.py.
ENTRY_POINTS = ("gratnet_reflectance", "gratnet_shade", "gratnet_shade_unshadowed")
_UNIFORM = re.compile(r"^\s*uniform\s+(?:highp\s+)?(?P<type>\w+)\s+(?P<name>\w+)\s*(?P<array>\[[^\]]*\])?\s*;"
                      r"(?P<comment>.*)$")
_LINE = re.compile(r"^\s*#\s*line\s+(\d+)\s+(\d+)\s*$")
_DROPPED = re.compile(r"^\s*#\s*(?:version\b|define\s+FRAGMENT_SHADER\s*$)")

_ENTRY_FUNCTIONS = """
// ---- entry points (gratnet export) ------------------------------------------------------------------------

// Fill the loop bounds (see the header): a zero the compiler cannot fold keeps the loops rolled.
void gratnet_set_layers() {
    int zero = min(textureSize(u_weights, 0).x, 0);
    u_layer_count = GRATNET_LAYER_COUNT + zero;
    for (int k = 0; k < MAX_LAYERS; ++k) {
        u_layers[k] = GRATNET_LAYERS[k] + ivec4(zero);
    }
}

// CIE XYZ of the D65-normalised reflectance (a flat mirror's specular peak has Y = 1) for unit vectors wi
// (towards the light) and wo (towards the viewer) in the tangent frame, z along the normal: the network at the
// key vector -(wi + wo), eq. 7's inverse applied; no A-term.
vec3 gratnet_reflectance(vec3 wi, vec3 wo) {
    gratnet_set_layers();
    encoding_set_key(-(wi + wo));
    return range_inverse(mlp_evaluate());
}

// exposure * A(wi, wo) * S(wi, wo) * gratnet_reflectance(wi, wo): gratnet render's exposed XYZ of a mesh pixel for
// a directional light of irradiance 1, S being Smith's shadowing-masking for the material's slope covariance
// (brdf.glsl's smith_shadowing, GRATNET_SLOPE_COVARIANCE; docs/physics.md "Shadowing and masking"). ior: the
// refractive index of the Fresnel factor (gratnet render's default 1.5; <= 0: no Fresnel). 0, without evaluating
// the network, where A * S = 0 (either direction at or below the horizon).
vec3 gratnet_shade(vec3 wi, vec3 wo, float ior, float exposure) {
    float a = a_term(wi, wo, ior) * smith_shadowing(wi, wo, GRATNET_SLOPE_COVARIANCE);
    if (!(a > 0.0)) {
        return vec3(0.0);
    }
    return exposure * a * gratnet_reflectance(wi, wo);
}

// exposure * A(wi, wo) * gratnet_reflectance(wi, wo), without Smith's shadowing: the value of a BRDF slice
// (shaders/brdf_slice.glsl, gratnet render --slice, the paper's evaluation), which has no S. Same arguments and
// zeros as gratnet_shade.
vec3 gratnet_shade_unshadowed(vec3 wi, vec3 wo, float ior, float exposure) {
    float a = a_term(wi, wo, ior);
    if (!(a > 0.0)) {
        return vec3(0.0);
    }
    return exposure * a * gratnet_reflectance(wi, wo);
}
"""


@dataclasses.dataclass(frozen=True)
class GlslModule:
    """One material's GLSL module and its weights.

    Attributes:
        text: the module (no ``#version``; GLSL 4.00+ or GLSL ES 3.20 for ``precise``; see docs/export.md).
        weights: the packed weight texture, ``float32`` ``(H, W, 4)``: row 0 is ``texelFetch`` row 0.
        grids: a feature-grid model's grid textures, ``u_grid[k]`` in order (level by level, ⌈C/4⌉ chunks a level,
            as viewer/renderer.py uploads them): ``(T, R_v, R_u, c)`` arrays of the model's dtype, c ≤ 4 channels,
            a 3D texture of width R_u, height R_v and depth T each.
    """

    text: str
    weights: np.ndarray
    grids: tuple[np.ndarray, ...] = ()

    @property
    def weights_size(self) -> tuple[int, int]:
        """(width, height) of the weight texture in texels."""
        return int(self.weights.shape[1]), int(self.weights.shape[0])


def grid_chunks_of(model: ModelFile) -> tuple[np.ndarray, ...]:
    """The grid textures of ``u_grid``, in order: each level's features 4k … 4k + 3 (a last chunk only the channels
    it has), exactly the arrays viewer/renderer.py uploads."""
    chunks = []
    for grid in model.grids:
        for first in range(0, int(grid.shape[3]), CHUNK_FEATURES):
            chunks.append(np.ascontiguousarray(grid[..., first:first + CHUNK_FEATURES]))
    return tuple(chunks)


def frequency_table(model: ModelFile) -> np.ndarray:
    """``u_frequency``: rows (a_j, b_j, a_t_j, b_t_j) of s^j and s_t^j, ``MAX_FREQUENCIES`` rows, zero-padded: the
    runtime's own table (viewer.renderer.frequency_table)."""
    return runtime_frequency_table(model, int(model_defines(model)["MAX_FREQUENCIES"]))


def _float(value: float) -> str:
    """A GLSL float literal that reads back as the same float32 (9 significant digits round-trip)."""
    if not math.isfinite(float(value)):
        raise GratNetError(f"cannot write the non-finite value {value!r} as a GLSL constant")
    text = f"{float(np.float32(value)):.9g}"
    return text if any(c in text for c in ".e") else text + ".0"


def _vector(kind: str, values: np.ndarray | list[float] | tuple[float, ...]) -> str:
    items = [str(int(v)) for v in values] if kind.startswith("i") else [_float(v) for v in values]
    return f"{kind}({', '.join(items)})"


def uniform_values(model: ModelFile) -> dict[str, str]:
    """Uniform name → the GLSL initializer of its ``const`` (the values viewer/renderer.py's ``model_uniforms``
    sets), for every model uniform of :data:`MODULE_INCLUDES` except the sampler and the loop bounds."""
    matrix = xyz_to_linear_srgb_matrix()
    frequencies = frequency_table(model)
    return {
        SCHEME.uniform_name: str(SCHEME.code(model.scheme)),
        "u_frequencies": str(model.encoding.frequencies),
        "u_t_frequencies": str(model.encoding.t_frequencies),
        "u_spatial_groups": str(model.encoding.groups),
        "u_frequency": "vec4[](" + ", ".join(_vector("vec4", row) for row in frequencies) + ")",
        HIDDEN.uniform_name: str(HIDDEN.code(model.activation)),
        OUTPUT.uniform_name: str(OUTPUT.code(model.output_activation)),
        RANGE.uniform_name: str(RANGE.code(model.range.kind)),
        "u_range_bits": _float(model.range.bits),
        "u_range_power": _float(model.range.power),
        "u_range_white": _vector("vec3", [float(c) for c in model.range.white]),
        # Only in branches this module leaves out (the weight buffers, the grids of a pure MLP), or fixed here: the
        # grids are interpolated by eight texelFetches (eq. 6g exactly), not by the texture unit's filter.
        "u_weights_width": str(int(pack_texture(model)[0].shape[1])),
        "u_grid_hardware_filter": "0",
        "u_grid_smoothstep": str(int(model.grid_interpolation == "smoothstep")),
        # GLSL's mat3 constructor takes columns: the matrix's transpose, row by row.
        "u_xyz_to_linear_srgb": _vector("mat3", np.asarray(matrix, dtype=np.float64).T.ravel().tolist()),
    }


def _preprocessed(defines: dict[str, int | float]) -> tuple[str, tuple[Path | str, ...]]:
    """The runtime includes through viewer/glsl.py's preprocessor (a template program naming them by path)."""
    with tempfile.TemporaryDirectory(prefix="gratnet-export-") as folder:
        template = Path(folder) / "module.glsl"
        template.write_text("".join(f'#include "{(SHADER_ROOT / name).resolve()}"\n' for name in MODULE_INCLUDES),
                            encoding="utf-8")
        source = preprocess("module", "fragment", defines, shader_root=folder)
    return source.text, source.files


def _file_name(files: tuple[Path | str, ...], file_id: int) -> str | None:
    """How the module names where a stretch of text comes from; None for the template itself."""
    entry = files[file_id - 1] if 1 <= file_id <= len(files) else f"<source {file_id}>"
    if not isinstance(entry, Path):
        return entry
    return f"shaders/{entry.name}" if entry.parent == Path(SHADER_ROOT).resolve() else None


def _module_body(model: ModelFile) -> str:
    """The preprocessed runtime text with the three edits of the module docstring."""
    text, files = _preprocessed(model_defines(model))
    values = uniform_values(model)
    used: set[str] = set()
    lines: list[str] = []
    for line in text.splitlines():
        if _DROPPED.match(line):
            continue
        directive = _LINE.match(line)
        if directive:
            encoded, file_id = int(directive.group(1)), int(directive.group(2))
            name = _file_name(files, file_id)
            if encoded % LINE_STRIDE == 1 and name is not None:  # a file starts (not a return from an include)
                lines.append(f"// ---- {name} ----")
            continue
        uniform = _UNIFORM.match(line)
        if uniform is None:
            lines.append(line)
            continue
        kind, name, array, comment = uniform["type"], uniform["name"], uniform["array"] or "", uniform["comment"]
        if name in (SAMPLER, GRID_SAMPLER):
            lines.append(line)
        elif name in LOOP_BOUNDS:
            lines.append(f"{kind} {name}{array};  // set by gratnet_set_layers(){comment}")
        elif name in values:
            lines.append(f"const {kind} {name}{array} = {values[name]};{comment}")
            used.add(name)
        else:
            raise GratNetError(f"the runtime's GLSL has a uniform {name} that gratnet export does not know: "
                               f"export/glsl.py must give it a value")
    missing = sorted(set(values) - used)
    if missing:
        raise GratNetError(f"gratnet export sets uniforms the runtime's GLSL no longer has: {', '.join(missing)}")
    return "\n".join(lines) + "\n"


def _header(model: ModelFile, material: str, width: int, height: int) -> str:
    levels = f", {len(model.grids)} feature-grid levels" if model.grids else ""
    covariance = slope_covariance_value(model)
    return f"""// GratNet material "{material}": a neural BRDF of a diffractive surface, as one GLSL function module.
// Written by `gratnet export --format glsl` (GratNet {__version__}) from the runtime's shaders/*.glsl; do not edit.
// Network {'-'.join(str(s) for s in model.layer_sizes)}, {model.activation}/{model.output_activation}, \
scheme {model.scheme}, range {model.range.kind}{levels}.
//
// Needs GLSL 4.00+ (desktop) or GLSL ES 3.20 (`precise`); in GLSL ES declare `precision highp float;` and
// `precision highp int;` before it. Include it once, before your code; it defines the names of the runtime's
// includes (encoding_set_key, mlp_evaluate, range_inverse, a_term, smith_shadowing, sigmoid, PI, the SCHEME_*/
// HIDDEN_*/OUTPUT_*/RANGE_* defines, u_* constants, GRATNET_* constants, ...).
//
// Weights: bind the texture `uniform highp sampler2D {SAMPLER}` to an RGBA32F texture of {width} x {height}
// texels made from the file {material}.weights.bin (raw little-endian float32, RGBA per texel, row 0 first,
// {width} texels a row; NEAREST filtering, no mipmaps). It is read with texelFetch only.
{_grid_note(model, material)}//
// Entry points (wi: unit vector towards the light, wo: towards the viewer, both in the tangent frame, z along
// the normal):
//   vec3 gratnet_reflectance(vec3 wi, vec3 wo)   CIE XYZ reflectance (network, eq. 7 inverted; no A-term)
//   vec3 gratnet_shade(vec3 wi, vec3 wo, float ior, float exposure)
//                              exposure * A(wi, wo) * S(wi, wo) * reflectance (what gratnet render draws on a mesh;
//                              S: Smith's shadowing-masking for this material's slope covariance
//                              {SLOPE_COVARIANCE} = {covariance})
//   vec3 gratnet_shade_unshadowed(vec3 wi, vec3 wo, float ior, float exposure)
//                              exposure * A(wi, wo) * reflectance, without S (a BRDF slice, as gratnet render --slice)
//   vec3 xyz_to_linear_srgb(vec3 xyz), vec3 xyz_to_display_srgb(vec3 xyz, float exposure)
// Physics and conventions: docs/physics.md; this module: docs/export.md.

"""


def _grid_note(model: ModelFile, material: str) -> str:
    """The header's lines on a feature-grid model's textures (none for a pure MLP)."""
    chunks = grid_chunks_of(model)
    if not chunks:
        return ""
    kind = "float16" if chunks[0].dtype == np.float16 else "float32"
    lines = [f"// Feature grids: bind `uniform highp sampler3D {GRID_SAMPLER}[{len(chunks)}]`, element k to a 3D "
             f"texture made from",
             f"// {material}.grid<k>.bin (raw little-endian {kind}, texel (x, y, z) at index (z * height + y) * width "
             f"+ x, its channels", "// interleaved; read with texelFetch only, clamp to edge):"]
    for k, chunk in enumerate(chunks):
        depth, height, width, channels = chunk.shape
        lines.append(f"//   {GRID_SAMPLER}[{k}]: {material}.grid{k}.bin, {width} x {height} x {depth} texels, "
                     f"{channels} channel{'s' if channels > 1 else ''}")
    return "\n".join(lines) + "\n"


def slope_covariance_value(model: ModelFile) -> str:
    """The GLSL initializer of :data:`SLOPE_COVARIANCE`: ``vec3(Σxx, Σxy, Σyy)``, float32 round-trip literals (the
    float32 uniform the runtime sets)."""
    return _vector("vec3", list(model_slope_covariance(model)))


def _material_constants(model: ModelFile) -> str:
    """The constants of the entry points that are not runtime uniforms of :data:`MODULE_INCLUDES`."""
    return ("\n// The relief's slope covariance (Sxx, Sxy, Syy) of Smith's shadowing in gratnet_shade (the model's "
            "metadata;\n// docs/physics.md \"Shadowing and masking\"); vec3(0.0) renders unshadowed.\n"
            f"const vec3 {SLOPE_COVARIANCE} = {slope_covariance_value(model)};\n")


def _layer_constants(layout: list[dict[str, int]]) -> str:
    """The loop bounds' values (``u_layers`` rows: row offset, input blocks, output blocks, 0)."""
    rows = ", ".join(_vector("ivec4", [entry["row_offset"], entry["in_blocks"], entry["out_blocks"], 0])
                     for entry in layout)
    return (f"\nconst int GRATNET_LAYER_COUNT = {len(layout)};\n"
            f"const ivec4 GRATNET_LAYERS[MAX_LAYERS] = ivec4[]({rows});\n")


def glsl_module(model: ModelFile, material: str) -> GlslModule:
    """The GLSL module of ``model`` (named ``material`` in its header) and its packed weights.

    Raises:
        GratNetError: the runtime's GLSL has a uniform this exporter does not know.
    """
    texture, layout = pack_texture(model)
    text = (_header(model, material, int(texture.shape[1]), int(texture.shape[0])) + _module_body(model)
            + _layer_constants(layout) + _material_constants(model) + _ENTRY_FUNCTIONS)
    return GlslModule(text, np.ascontiguousarray(texture, np.float32), grid_chunks_of(model))
