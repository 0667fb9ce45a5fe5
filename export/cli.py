"""``gratnet export``: materials as files for other engines (docs/export.md).

    gratnet export cd snake --format glsl --out exported/

- ``MATERIAL…``: shipped material names or model-file paths; each becomes files named after it (a shipped name,
  or the file's stem; ``model.npz`` takes its folder's name).
- ``--format glsl``: per material ``NAME.glsl`` (export/glsl.py), ``NAME.weights.bin`` and, for a feature-grid
  model, ``NAME.grid<k>.bin`` per grid texture; one ``README.md`` (the usage note) and ``export.config.json``
  (what was exported, from which files). ``--format hlsl``: the same with ``NAME.hlsl`` (export/hlsl.py: the GLSL
  module through glslangValidator and spirv-cross, which must be installed). ``--format web``: ``index.html``,
  ``gratnet.js``, ``meshes.bin`` and per material ``NAME.weights.bin`` (export/web.py). ``--format wgsl``: per
  material ``NAME.wgsl`` (export/wgsl.py: a WebGPU shader module), ``NAME.weights.bin`` and, for a feature-grid
  model, ``NAME.grids.bin`` (one storage buffer for every level).
- ``--out DIR``: a folder that does not exist yet or is empty.

Bad input (an unknown material, a format a material cannot be exported to, an ``--out`` that exists with files in
it or cannot be written, two materials with one name): one line, exit status 2, nothing written. Everything is
written into a hidden temporary folder beside ``--out`` and renamed onto it at the end, so ``--out`` appears
complete or not at all (a killed export leaves its hidden ``.NAME.HOST-PID-….tmp`` folder behind).
"""

from __future__ import annotations

import argparse
import dataclasses
import hashlib
import json
import re
from pathlib import Path
from typing import TYPE_CHECKING

from gratnet import __version__
from gratnet.atomic import atomic_folder, check_output_folder
from gratnet.errors import GratNetError
from gratnet.modelfile import ModelFile

if TYPE_CHECKING:
    from export.glsl import GlslModule

__all__ = ["FORMATS", "Material", "check_out_folder", "export_name", "register", "run"]

#: The formats ``--format`` takes, in its help's order.
FORMATS = ("glsl", "hlsl", "web", "wgsl")
_NAME = re.compile(r"[^A-Za-z0-9_.-]+")


@dataclasses.dataclass(frozen=True)
class Material:
    """One material to export: its file name stem, its model file, the loaded model and the name or path given."""

    name: str
    path: Path
    model: ModelFile
    given: str


def export_name(material: str, path: Path) -> str:
    """The file-name stem of a material: the shipped name, else the model file's stem (``model.npz``: its
    folder's name), with characters other than letters, digits, ``_``, ``.`` and ``-`` as ``_``."""
    if "/" not in material and "\\" not in material and not material.endswith(".npz"):
        stem = material
    else:
        stem = path.parent.name if path.stem == "model" and path.parent.name else path.stem
    return _NAME.sub("_", stem).strip(".") or "material"


def check_out_folder(out: str) -> Path:
    """``--out``: missing (created) or an empty folder, writable (probed); one GratNetError otherwise."""
    folder = check_output_folder(out, "--out")
    if folder.is_dir() and any(folder.iterdir()):
        raise GratNetError(f"--out {folder} exists and is not empty: give a new or empty folder")
    return folder


def _sha256(path: Path) -> str:
    digest = hashlib.sha256()
    with path.open("rb") as stream:
        for block in iter(lambda: stream.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def _load(materials: list[str]) -> list[Material]:
    """Every material resolved, loaded and checked for the export, before anything is written."""
    from gratnet.modelfile import load_model
    from viewer.catalog import resolve_material

    loaded: list[Material] = []
    for material in materials:
        path = resolve_material(material)
        loaded.append(Material(export_name(material, path), path, load_model(path), material))
    names = [item.name for item in loaded]
    twice = sorted({name for name in names if names.count(name) > 1})
    if twice:
        raise GratNetError(f"two materials would be exported under one name ({', '.join(twice)}): export them "
                           f"into separate --out folders")
    return loaded


def _write_binaries(module: GlslModule, name: str, folder: Path) -> dict[str, object]:
    """The weight and grid files of one material (the same for every shader format); their manifest entries."""
    # Little-endian whatever the host's byte order: the format docs/export.md states.
    (folder / f"{name}.weights.bin").write_bytes(module.weights.astype("<f4").tobytes())
    grids = []
    for k, chunk in enumerate(module.grids):
        (folder / f"{name}.grid{k}.bin").write_bytes(chunk.astype(chunk.dtype.newbyteorder("<")).tobytes())
        depth, height, width, channels = chunk.shape
        grids.append({"file": f"{name}.grid{k}.bin", "texels": [width, height, depth], "channels": channels,
                      "type": str(chunk.dtype)})
    width, height = module.weights_size
    return {"weights": f"{name}.weights.bin", "weights_texels": [width, height],
            "weights_format": "RGBA32F little-endian", "grids": grids}


def _write_shaders(export_format: str, materials: list[Material], folder: Path) -> dict[str, dict[str, object]]:
    """Per material the shader module of ``export_format`` and its binaries; the manifest entries."""
    from export.glsl import glsl_module
    from export.hlsl import hlsl_module

    entries: dict[str, dict[str, object]] = {}
    for material in materials:
        module = glsl_module(material.model, material.name)
        text = module.text if export_format == "glsl" else hlsl_module(module, material.name)
        (folder / f"{material.name}.{export_format}").write_text(text, encoding="utf-8")
        entries[material.name] = {"module": f"{material.name}.{export_format}",
                                  **_write_binaries(module, material.name, folder)}
    return entries


def _check_format(export_format: str) -> None:
    """What a format needs beyond the model, checked before anything is written."""
    if export_format not in FORMATS:
        raise GratNetError(f"--format {export_format} is not supported; choose {', '.join(FORMATS)}")
    if export_format == "hlsl":
        from export.hlsl import check_tools

        check_tools()


def _usage_note(export_format: str, materials: list[Material], single_file: bool = False) -> str:
    names = ", ".join(material.name for material in materials)
    if export_format == "web":
        opening = ("Open index.html in a browser with WebGL2 or WebGPU (it holds everything; file:// works)"
                   if single_file else
                   "Serve this folder over HTTP (`python3 -m http.server`; a page opened from file:// cannot fetch its "
                   "binaries) and open index.html in a browser with WebGL2 or WebGPU")
        return (f"# GratNet export (web)\n\nMaterials: {names}. Written by `gratnet export` (GratNet "
                f"{__version__}).\n\n"
                f"{opening}. URL parameters (gratnet render's meanings): "
                f"material, mesh=cd|sphere|plane, slice=1, light=THETA,PHI, camera=DIST,AZIMUTH,ELEVATION, exposure, "
                f"ior, size=N or W,H, ui=0, backend=webgl2|webgpu (default webgl2). Docs: docs/export.md in the "
                f"GratNet repository.\n")
    if export_format == "wgsl":
        return (f"# GratNet export (wgsl)\n\nMaterials: {names}. Written by `gratnet export` (GratNet "
                f"{__version__}).\n\nEach `NAME.wgsl` is one WGSL shader module for WebGPU, without an entry point: "
                f"put it before your WGSL. Its header says how to bind `NAME.weights.bin` (and a feature-grid model's "
                f"`NAME.grids.bin`) as read-only storage buffers and what its functions compute:\n\n"
                f"- `gratnet_reflectance(wi: vec3<f32>, wo: vec3<f32>) -> vec3<f32>`: CIE XYZ reflectance, unit "
                f"vectors in the tangent frame;\n"
                f"- `gratnet_shade(wi, wo, ior: f32, exposure: f32) -> vec3<f32>`: exposure · A · S · reflectance, S "
                f"Smith's shadowing for the material's slope covariance (a mesh pixel of `gratnet render`);\n"
                f"- `gratnet_shade_unshadowed(wi, wo, ior: f32, exposure: f32) -> vec3<f32>`: exposure · A · "
                f"reflectance, without S (a BRDF slice).\n\n"
                f"`export.config.json` lists every file, its bindings and the model it came from. Docs: "
                f"docs/export.md in the GratNet repository.\n")
    vec, kind = ("vec3", "GLSL") if export_format == "glsl" else ("float3", "HLSL (shader model 5.0)")
    return (f"# GratNet export ({export_format})\n\nMaterials: {names}. Written by `gratnet export` (GratNet "
            f"{__version__}).\n\nEach `NAME.{export_format}` is one {kind} function module; its header says how to "
            f"bind `NAME.weights.bin` (and a feature-grid model's `NAME.grid<k>.bin`) and what its entry points "
            f"compute:\n\n"
            f"- `{vec} gratnet_reflectance({vec} wi, {vec} wo)`: CIE XYZ reflectance, unit vectors in the tangent "
            f"frame;\n"
            f"- `{vec} gratnet_shade({vec} wi, {vec} wo, float ior, float exposure)`: exposure · A · S · reflectance, "
            f"S Smith's shadowing for the material's slope covariance (a mesh pixel of `gratnet render`);\n"
            f"- `{vec} gratnet_shade_unshadowed({vec} wi, {vec} wo, float ior, float exposure)`: exposure · A · "
            f"reflectance, without S (a BRDF slice).\n\n"
            f"`export.config.json` lists every file and the model it came from. Per-engine notes: docs/export.md in "
            f"the GratNet repository.\n")


def run(arguments: argparse.Namespace) -> int:
    """Check everything, then write every file of the export into a temporary folder renamed onto ``--out``."""
    export_format = arguments.format
    _check_format(export_format)
    if arguments.single_file and export_format != "web":
        raise GratNetError(f"--single-file makes one web page; --format {export_format} writes shader modules")
    out = check_out_folder(arguments.out)
    materials = _load(list(arguments.material))
    if export_format == "web":
        from export.web import check_web_model

        for material in materials:
            check_web_model(material.model, material.given)

    def write(folder: Path) -> None:
        if export_format == "web":
            from export.web import write_web

            entries = write_web([(m.name, m.given, m.model) for m in materials], folder, arguments.single_file)
        elif export_format == "wgsl":
            from export.wgsl import write_wgsl

            entries = write_wgsl([(m.name, m.model) for m in materials], folder)
        else:
            entries = _write_shaders(export_format, materials, folder)
        (folder / "README.md").write_text(_usage_note(export_format, materials, arguments.single_file),
                                          encoding="utf-8")
        config = {"format": export_format, "gratnet_version": __version__, "single_file": arguments.single_file,
                  "materials": {material.name: {"model": str(material.path), "model_sha256": _sha256(material.path),
                                                **entries[material.name]}
                                for material in materials}}
        (folder / "export.config.json").write_text(json.dumps(config, indent=2) + "\n", encoding="utf-8")

    atomic_folder(out, write, flag="--out")
    if not arguments.quiet:
        print(f"gratnet export: wrote {out} ({export_format}: {', '.join(m.name for m in materials)})")
    return 0


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``export`` subcommand."""
    from gratnet.config import add_quiet_flag

    parser = subparsers.add_parser(
        "export", help="write materials as shader modules for other engines (GLSL, HLSL, WGSL) or a WebGL2/WebGPU page",
        description="Write each material's network as a GLSL function module made from the runtime's own shaders "
        "(or that module cross-compiled to HLSL, or its hand-written WGSL twin for WebGPU), with its weights as binary "
        "files, or a WebGL2/WebGPU viewer page (docs/export.md).",
        epilog="typical use:\n  gratnet export cd snake --format glsl --out exported",
    )
    parser.add_argument("material", metavar="MATERIAL", nargs="+", help="shipped material names or model-file paths")
    parser.add_argument("--format", required=True, choices=FORMATS, help="what to write")
    parser.add_argument("--out", required=True, metavar="DIR", help="output folder: new or empty")
    parser.add_argument("--single-file", action="store_true",
                        help="web: one index.html holding the script and every binary (base64), which opens from "
                        "file:// (no server needed; about a third larger)")
    add_quiet_flag(parser)
    parser.set_defaults(handler=run)

