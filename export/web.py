"""``gratnet export --format web``: a self-contained viewer folder, WebGL2 or WebGPU (docs/export.md, "The web page").

Files: ``index.html`` (export/web/, copied) and ``gratnet.js``: the export's data as one ``const EXPORT = {…};`` line,
then export/web/'s ``webgl2.js`` (the WebGL2 backend), ``webgpu.js`` (the WebGPU backend, URL ``backend=webgpu``) and
``gratnet.js`` (scene, camera, URL parameters, panel: shared by both), concatenated into one module script, so that
the folder and the ``--single-file`` page (both, and every file below as base64, in one ``index.html`` that opens from
file://; ES module imports cannot be inlined) run the same script. ``meshes.bin`` (the CD disc, sphere and plane of
viewer/meshes.py, as ``gratnet render`` draws them); per material ``NAME.weights.bin`` (export/glsl.py's packed
weights: the same bytes both backends read) and ``NAME.wgsl`` (export/wgsl.py's module, as ``--format wgsl``
writes it); for a feature-grid model one ``NAME.grids.bin`` (``--format wgsl``'s buffer: each level's array in turn),
which WebGPU binds as ``gratnet_grids`` and from which WebGL2 gathers each ``u_grid[k]`` texture (the texels
viewer/renderer.py uploads, in the model's float16 or float32): the grids once, so an export stays within its model
file plus the page.

The page's network is the GLSL module of ``--format glsl`` as GLSL ES 3.00: a header of precision statements and
``#define precise`` (empty: WebGL2's GLSL ES 3.00 has no ``precise``; what that costs is measured in
tests/tools/test_export_web.py), then the module unchanged. The defaults of every view (light, camera, exposure
per mesh, and the BRDF slice's) are viewer.defaults' own, computed here at export time, so that a URL without
parameters shows what ``gratnet render`` would. As there, a mesh pixel is the module's ``gratnet_shade`` (exposure ·
A · S · XYZ, S: Smith's shadowing for the material's slope covariance) and the BRDF slice its
``gratnet_shade_unshadowed`` (no S), in both backends.

Feature-grid models: shaders/featuregrid.glsl indexes ``u_grid`` by constants only (GLSL ES 3.00 allows nothing
else for sampler arrays); the page loads each grid file as a 3D texture (R/RG/RGB/RGBA 16F or 32F, NEAREST, read with
``texelFetch``: the runtime's default path) and binds it to ``u_grid[k]``. ``u_grid_smoothstep`` and
``u_grid_hardware_filter`` are the module's constants (export/glsl.py: the model's interpolation, and 0). A model
is refused only where its grid textures and the weights exceed WebGL2's guaranteed 16 samplers per fragment shader.
"""

from __future__ import annotations

import base64
import json
import shutil
from pathlib import Path
from typing import Any

import numpy as np

from export.glsl import GlslModule, glsl_module, grid_chunks_of
from export.wgsl import WgslModule, wgsl_module
from gratnet.errors import GratNetError
from gratnet.featuregrid import CHUNK_FEATURES
from gratnet.modelfile import ModelFile
from viewer.defaults import FOV_DEGREES as _FOV_DEGREES

__all__ = ["CHROMIUM_BACKENDS", "CHROMIUM_WEBGPU", "ES_HEADER", "MESH_NAMES", "PAGE_FILES", "SCRIPT_PARTS",
           "WEBGL2_SAMPLERS", "check_web_model", "es_module", "write_web"]

#: Headless chromium's flags per WebGL2 backend that the page is tested and timed on
#: (shared/notes/browsers-and-shader-tools-here.md): Mesa llvmpipe through ANGLE, and SwiftShader.
CHROMIUM_BACKENDS = {
    "llvmpipe": ["--use-angle=gl-egl", "--ignore-gpu-blocklist"],
    "swiftshader": ["--use-angle=swiftshader", "--enable-unsafe-swiftshader"],
}

#: Headless chromium's flags for the page's WebGPU backend (``backend=webgpu``). WebGPU runs on SwiftShader's Vulkan,
#: the only adapter here (lavapipe hangs chromium's GPU process). The compositor must run on llvmpipe (ANGLE gl-egl):
#: with chromium's default SwiftShader compositing, presenting a WebGPU canvas drops the WebGPU instance
#: ("A valid external Instance reference no longer exists").
CHROMIUM_WEBGPU = ["--enable-unsafe-webgpu", "--use-angle=gl-egl", "--ignore-gpu-blocklist"]

#: The page's files in the export folder.
PAGE_FILES = ("index.html", "gratnet.js")
#: export/web/'s scripts, in the order the exported gratnet.js holds them (the backends' classes before the shared
#: code that calls them at its end).
SCRIPT_PARTS = ("webgl2.js", "webgpu.js", "gratnet.js")
#: The meshes the page offers, as ``gratnet render --mesh`` names them.
MESH_NAMES = ("cd", "sphere", "plane")
#: What turns the GLSL module into GLSL ES 3.00 for WebGL2 (the page's shaders start with ``#version 300 es``).
ES_HEADER = ("precision highp float;\nprecision highp int;\nprecision highp sampler2D;\nprecision highp sampler3D;\n"
             "#define precise\n")
#: WebGL2's minimum of MAX_TEXTURE_IMAGE_UNITS (samplers a fragment shader may use).
WEBGL2_SAMPLERS = 16
_PAGE_ROOT = Path(__file__).resolve().parent / "web"
#: gratnet render's defaults that are not the material's: size (pixels), field of view (degrees), refractive index.
_SIZE = (512, 512)
_IOR = 1.5


def check_web_model(model: ModelFile, where: str) -> None:
    """Refuse (one GratNetError) a model the web page cannot show: more grid textures than WebGL2 guarantees
    samplers to a fragment shader beside the weight texture."""
    textures = len(grid_chunks_of(model))
    if textures > WEBGL2_SAMPLERS - 1:
        raise GratNetError(f"{where} needs {textures} grid textures (levels × ceil(features/4)) beside its weight "
                           f"texture, more than the {WEBGL2_SAMPLERS} samplers WebGL2 guarantees a fragment shader: "
                           f"use --format glsl or hlsl")


def es_module(module: GlslModule) -> str:
    """The module as the page compiles it after ``#version 300 es``."""
    return ES_HEADER + module.text


def _defaults(material: str, fov: float, ior: float) -> dict[str, dict[str, object]]:
    """viewer.defaults' light, camera and exposure for each mesh and for the BRDF slice."""
    from viewer.defaults import resolve_defaults

    views: dict[str, dict[str, object]] = {}
    for view in (*MESH_NAMES, "slice"):
        found = resolve_defaults(material, "cd" if view == "slice" else view, slice_mode=view == "slice",
                                 fov_degrees=fov, ior=ior)
        views[view] = {"light": [found.light_theta_degrees, found.light_phi_degrees],
                       "camera": [found.camera_distance, found.camera_azimuth_degrees, found.camera_elevation_degrees],
                       "exposure": found.exposure}
    return views


def _meshes(folder: Path) -> dict[str, dict[str, int]]:
    """Write meshes.bin (per mesh: positions, normals, tangents as float32 xyz, then uint32 indices); the offsets."""
    from viewer.catalog import build_mesh

    table: dict[str, dict[str, int]] = {}
    chunks: list[bytes] = []
    offset = 0
    for name in MESH_NAMES:
        mesh = build_mesh(name)
        vertices = np.concatenate([mesh.positions, mesh.normals, mesh.tangents], axis=1).astype("<f4").tobytes()
        indices = mesh.indices.astype("<u4").tobytes()
        table[name] = {"vertex_offset": offset, "vertex_count": mesh.vertex_count,
                       "index_offset": offset + len(vertices), "index_count": 3 * mesh.triangle_count}
        chunks += [vertices, indices]
        offset += len(vertices) + len(indices)
    (folder / "meshes.bin").write_bytes(b"".join(chunks))
    return table


def _grids(model: ModelFile, wgsl: WgslModule, name: str) -> list[dict[str, object]]:
    """The WebGL2 backend's grid textures (``u_grid[k]``: each level's features 4k … 4k + 3, the arrays
    viewer/renderer.py uploads), each an entry that says where its texels lie in ``NAME.grids.bin``, the one grid file
    both backends read (export/wgsl.py's buffer: each level's ``(T, R, R, C)`` array in turn): file, texels (width,
    height, depth), channels, type (float16 or float32), the level's first element (``offset``), its ``features``
    per node and the chunk's ``first`` feature. The page gathers each texture from it (one copy of the grids)."""
    grids: list[dict[str, object]] = []
    for grid, level in zip(model.grids, wgsl.grid_levels, strict=True):
        depth, height, width, features = grid.shape
        for first in range(0, int(features), CHUNK_FEATURES):
            grids.append({"file": f"{name}.grids.bin", "texels": [int(width), int(height), int(depth)],
                          "channels": min(CHUNK_FEATURES, int(features) - first), "type": str(grid.dtype),
                          "offset": int(level.offset), "features": int(features), "first": first})
    return grids


def _wgsl(model: ModelFile, name: str, module: GlslModule, folder: Path) -> tuple[WgslModule, str | None]:
    """Write ``NAME.wgsl`` (the WebGPU backend's) and ``NAME.grids.bin`` (both backends' grids); the module and the
    grid file's name. The module reads the GLSL module's weight file: refused (GratNetError) should the two exporters
    ever pack the weights differently."""
    wgsl = wgsl_module(model, name)
    if not np.array_equal(wgsl.weights, module.weights):
        raise GratNetError(f"{name}: export/wgsl.py and export/glsl.py pack the weights differently; the page shares "
                           f"one NAME.weights.bin between its backends")
    (folder / f"{name}.wgsl").write_text(wgsl.text, encoding="utf-8")
    if not wgsl.grids:
        return wgsl, None
    (folder / f"{name}.grids.bin").write_bytes(wgsl.grids)
    return wgsl, f"{name}.grids.bin"


def write_web(materials: list[tuple[str, str, ModelFile]], folder: Path,
              single_file: bool = False) -> dict[str, dict[str, object]]:
    """Write the page for ``materials`` (file-name stem, the name or path the user gave, model) into ``folder``;
    the manifest entry of each material. ``single_file``: one ``index.html`` with the script and every binary
    (base64) inside it, which opens from file:// (no fetch)."""
    from viewer.renderer import xyz_to_linear_srgb_matrix

    entries: dict[str, dict[str, object]] = {}
    page_materials: dict[str, Any] = {}
    for name, given, model in materials:
        check_web_model(model, given)
        module = glsl_module(model, name)
        (folder / f"{name}.weights.bin").write_bytes(module.weights.astype("<f4").tobytes())
        width, height = module.weights_size
        wgsl_module_, wgsl_grids = _wgsl(model, name, module, folder)
        grids = _grids(model, wgsl_module_, name)
        wgsl = f"{name}.wgsl"
        page_materials[name] = {"shader": es_module(module), "weights": f"{name}.weights.bin",
                                "texels": [width, height], "grids": grids, "wgsl": wgsl, "wgsl_grids": wgsl_grids,
                                "defaults": _defaults(given, _FOV_DEGREES, _IOR)}
        entries[name] = {"weights": f"{name}.weights.bin", "weights_texels": [width, height],
                         "weights_format": "RGBA32F little-endian", "grids": grids, "wgsl": wgsl,
                         "wgsl_grids": wgsl_grids, "defaults": page_materials[name]["defaults"]}
    data = {"materials": page_materials, "meshes": _meshes(folder),
            "render": {"size": list(_SIZE), "fov": _FOV_DEGREES, "ior": _IOR},
            # The EXR of gratnet render is linear sRGB: the page's read-back is too (rows of the matrix).
            "xyz_to_linear_srgb": np.asarray(xyz_to_linear_srgb_matrix(), dtype=np.float64).tolist()}
    script = "".join(f"// ---- export/web/{part} ----\n" + (_PAGE_ROOT / part).read_text(encoding="utf-8")
                     for part in SCRIPT_PARTS)
    if not single_file:
        shutil.copyfile(_PAGE_ROOT / "index.html", folder / "index.html")
        (folder / "gratnet.js").write_text(f"const EXPORT = {json.dumps(data)};\n{script}", encoding="utf-8")
        return entries
    binaries = sorted([*folder.glob("*.bin"), *folder.glob("*.wgsl")])
    data["inline"] = {path.name: base64.b64encode(path.read_bytes()).decode("ascii") for path in binaries}
    for path in binaries:
        path.unlink()
    # "</" would end the inline <script> early wherever it stood in the data; JSON reads "<\/" as "</".
    inline = f"const EXPORT = {json.dumps(data)};\n".replace("</", "<\\/") + script
    page = (_PAGE_ROOT / "index.html").read_text(encoding="utf-8")
    tag = '<script type="module" src="gratnet.js"></script>'
    if tag not in page:
        raise GratNetError("export/web/index.html lost its script tag; the single-file page cannot be made")
    (folder / "index.html").write_text(page.replace(tag, f'<script type="module">\n{inline}</script>'),
                                       encoding="utf-8")
    for entry in entries.values():
        entry["inline"] = True  # the binaries named are inside index.html
    return entries
