"""``gratnet export --format hlsl``: the GLSL module (export/glsl.py) cross-compiled to an HLSL function module.

No HLSL is typed here: the GLSL module, wrapped in a Vulkan GLSL 4.50 compute shader whose ``main`` calls every
entry point of export.glsl's ``ENTRY_POINTS`` (so that none is dropped; the export checks that each is there), goes
through ``glslangValidator -V`` (SPIR-V, with debug names) and ``spirv-cross --hlsl --shader-model 50``. From
spirv-cross's HLSL the wrapper's own parts are cut: its work-group size, its output buffer, ``comp_main`` and
``main``. What is left is the functions (``gratnet_reflectance``, ``gratnet_shade``, ``gratnet_shade_unshadowed``,
``xyz_to_linear_srgb``, ``xyz_to_display_srgb`` and the runtime's functions under them, ``smith_shadowing`` among
them) and the texture declarations. ``precise`` survives: SPIR-V's NoContraction becomes HLSL's ``precise``. The
material's slope covariance is the GLSL module's constant, folded into the functions by the compilers.

Needs the Debian packages ``glslang-tools`` and ``spirv-cross`` at export time (scripts/setup.sh installs them);
without them the format is refused in one line.
"""

from __future__ import annotations

import re
import shutil
import subprocess
import tempfile
from pathlib import Path

from export.glsl import ENTRY_POINTS, GRID_SAMPLER, SAMPLER, SLOPE_COVARIANCE, GlslModule
from gratnet import __version__
from gratnet.errors import GratNetError

__all__ = ["TOOLS", "check_tools", "hlsl_module", "vulkan_wrapper"]

#: The programs the cross-compilation runs (Debian glslang-tools, spirv-cross).
TOOLS = ("glslangValidator", "spirv-cross")
_TIMEOUT_S = 300  # glslang and spirv-cross take well under a second on the shipped models
_CUT_LINES = ("static const uint3 gl_WorkGroupSize", "RWByteAddressBuffer ")
_CUT_FROM = "void comp_main()"

#: A compute shader that calls every entry point, writing into a buffer; only its functions are kept.
_WRAPPER_MAIN = """
layout(local_size_x = 1) in;
layout(std430, binding = 31) buffer GratnetExportCalls { vec4 gratnet_calls[]; };
void main() {
    vec3 wi = gratnet_calls[0].xyz;
    vec3 wo = gratnet_calls[1].xyz;
    gratnet_calls[2].xyz = gratnet_shade(wi, wo, gratnet_calls[3].x, gratnet_calls[3].y);
    vec3 xyz = gratnet_reflectance(wi, wo);
    gratnet_calls[4].xyz = xyz_to_linear_srgb(xyz);
    gratnet_calls[5].xyz = xyz_to_display_srgb(xyz, gratnet_calls[3].y);
    gratnet_calls[6].xyz = gratnet_shade_unshadowed(wi, wo, gratnet_calls[3].x, gratnet_calls[3].y);
}
"""


def check_tools() -> dict[str, str]:
    """Tool name → its path; one GratNetError naming the missing ones and their Debian packages."""
    found = {tool: shutil.which(tool) for tool in TOOLS}
    missing = [tool for tool, path in found.items() if path is None]
    if missing:
        raise GratNetError(f"--format hlsl needs {' and '.join(missing)} (Debian packages glslang-tools and "
                           f"spirv-cross; scripts/setup.sh installs them)")
    return {tool: str(path) for tool, path in found.items()}


def vulkan_wrapper(module: GlslModule) -> str:
    """The Vulkan GLSL 4.50 compute shader that is cross-compiled: the module and a main calling its entry points.

    The textures get explicit bindings, which spirv-cross turns into registers: the weights t0/s0, the grids from
    t1/s1 on. An HLSL array takes one register per element (a Vulkan array one binding), so automatic bindings
    put the weights inside the grids' registers."""
    text = module.text
    for name, binding in ((SAMPLER, 0), (GRID_SAMPLER, 1)):
        declaration = re.compile(rf"^uniform (highp sampler\w+ {name}\b)", re.MULTILINE)
        text, count = declaration.subn(rf"layout(binding = {binding}) uniform \1", text)
        if name == SAMPLER and count != 1:
            raise GratNetError(f"the GLSL module declares {SAMPLER} {count} times; export/hlsl.py expects once")
    return "#version 450\n" + text + _WRAPPER_MAIN


def _run(command: list[str], what: str) -> None:
    try:
        result = subprocess.run(command, capture_output=True, text=True, timeout=_TIMEOUT_S, check=False)
    except (OSError, subprocess.TimeoutExpired) as error:
        raise GratNetError(f"{what} failed: {error}") from error
    if result.returncode != 0:
        log = " ".join((result.stdout + result.stderr).split())[:400]
        raise GratNetError(f"{what} failed (exit {result.returncode}): {log}")


def _functions_only(hlsl: str) -> str:
    """spirv-cross's HLSL without the wrapper's work-group size, buffer, ``comp_main`` and ``main``."""
    lines = hlsl.splitlines()
    if _CUT_FROM not in lines:
        raise GratNetError(f"spirv-cross's HLSL has no line {_CUT_FROM!r}: its output changed; export/hlsl.py must "
                           f"learn the new form")
    kept = [line for line in lines[:lines.index(_CUT_FROM)] if not line.startswith(_CUT_LINES)]
    return "\n".join(kept).rstrip() + "\n"


def _header(module: GlslModule, material: str) -> str:
    width, height = module.weights_size
    baked = re.search(rf"^const vec3 {SLOPE_COVARIANCE} = vec3\((.*)\);$", module.text, re.MULTILINE)
    if baked is None:
        raise GratNetError(f"the GLSL module has no {SLOPE_COVARIANCE}; export/hlsl.py expects one")
    covariance = f"({baked.group(1)})"
    grids = "".join(
        f"//   u_grid[{k}]: {material}.grid{k}.bin, {chunk.shape[2]} x {chunk.shape[1]} x {chunk.shape[0]} texels, "
        f"{chunk.shape[3]} channel(s) of {chunk.dtype}\n" for k, chunk in enumerate(module.grids))
    grid_note = (f"// Feature grids: Texture3D<float4> u_grid[{len(module.grids)}], from (raw little-endian, x "
                 f"fastest, channels interleaved):\n{grids}") if module.grids else ""
    return f"""// GratNet material "{material}" as an HLSL function module (shader model 5.0).
// Written by `gratnet export --format hlsl` (GratNet {__version__}): the GLSL module of `--format glsl`, compiled
// by glslangValidator to SPIR-V and by spirv-cross to HLSL; do not edit.
//
// Weights: Texture2D<float4> u_weights, an R32G32B32A32_FLOAT texture of {width} x {height} texels from
// {material}.weights.bin (raw little-endian float32, RGBA per texel, row 0 first). Read with Load only.
{grid_note}// Each texture has a SamplerState beside it (spirv-cross declares one per texture): bind a point-clamp
// sampler. Registers: u_weights t0/s0, u_grid[k] t(1+k)/s(1+k); change them to your layout.
//
// Entry points (wi: unit vector towards the light, wo: towards the viewer, both in the tangent frame, z along
// the normal):
//   float3 gratnet_reflectance(float3 wi, float3 wo)   CIE XYZ reflectance (network, eq. 7 inverted; no A-term)
//   float3 gratnet_shade(float3 wi, float3 wo, float ior, float exposure)
//                              exposure * A(wi, wo) * S(wi, wo) * reflectance (what gratnet render draws on a mesh;
//                              S: Smith's shadowing-masking for this material's slope covariance
//                              (Sxx, Sxy, Syy) = {covariance})
//   float3 gratnet_shade_unshadowed(float3 wi, float3 wo, float ior, float exposure)
//                              exposure * A(wi, wo) * reflectance, without S (a BRDF slice, as gratnet render --slice)
//   float3 xyz_to_linear_srgb(float3 xyz), float3 xyz_to_display_srgb(float3 xyz, float exposure)
// Docs: docs/export.md in the GratNet repository.

"""


def hlsl_module(module: GlslModule, material: str) -> str:
    """The HLSL function module of ``module`` (see the module docstring).

    Raises:
        GratNetError: a tool is missing or fails (its message, shortened to one line).
    """
    tools = check_tools()
    with tempfile.TemporaryDirectory(prefix="gratnet-hlsl-") as folder:
        source = Path(folder) / "module.comp"
        spirv = Path(folder) / "module.spv"
        hlsl = Path(folder) / "module.hlsl"
        source.write_text(vulkan_wrapper(module), encoding="utf-8")
        _run([tools["glslangValidator"], "-V", "-g", "-S", "comp", str(source), "-o",
              str(spirv)], "glslangValidator (GLSL module → SPIR-V)")
        _run([tools["spirv-cross"], str(spirv), "--hlsl", "--shader-model", "50", "--output", str(hlsl)],
             "spirv-cross (SPIR-V → HLSL)")
        text = hlsl.read_text(encoding="utf-8")
    functions = _functions_only(text)
    dropped = [name for name in ENTRY_POINTS if not re.search(rf"^float3 {name}\(", functions, re.MULTILINE)]
    if dropped:
        raise GratNetError(f"spirv-cross's HLSL lacks the entry point(s) {', '.join(dropped)}: export/hlsl.py's "
                           f"wrapper must call every one")
    return _header(module, material) + functions
