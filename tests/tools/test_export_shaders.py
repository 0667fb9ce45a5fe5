"""``gratnet export --format glsl|hlsl`` (export/glsl.py, export/hlsl.py, export/cli.py; docs/export.md).

- the exported GLSL module, read back from the files the command wrote (module, weights and grid binaries, bound as
  its header says), compiles in the headless EGL context and its entry points equal the numpy evaluation of the
  model file within gratnet/precision.py's float32 driver bound, for every shipped material and random models:
  ``gratnet_shade`` is exposure · A · S · XYZ with Smith's shadowing S for the model's slope covariance
  (gratnet.shadowing), ``gratnet_shade_unshadowed`` exposure · A · XYZ;
- at grazing direction pairs, where S of the steep shipped reliefs (paper-corner-cubes, paper-pits) is far below 1,
  ``gratnet_shade`` equals numpy's exposure · A · S · XYZ and its ratio to ``gratnet_shade_unshadowed`` equals S
  (GLSL and HLSL); the module bakes the model's covariance as ``GRATNET_SLOPE_COVARIANCE``;
- the exported HLSL module, in an HLSL pixel shader, is compiled by glslang's HLSL front end to SPIR-V and by
  spirv-cross back to GLSL 4.30, and run the same way: within the same bound (a check of the HLSL text's meaning
  through glslang, not through Microsoft's compilers);
- glslangValidator accepts every exported module (GLSL 4.30; HLSL with -D) and rejects a broken one;
- the constants the module bakes are the uniforms the runtime sets (the frequency split);
- bad input: one line, exit status 2, nothing written; a failure while writing leaves nothing behind.
"""

from __future__ import annotations

import json
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from gratnet.cli import main
from gratnet.encoding import EncodingSpec
from gratnet.modelfile import evaluate_keys, load_model, save_model
from gratnet.precision import OWN_KEYS, assert_within, driver_bound
from tests.helpers import STEEP, check_grazing_shadowing, grazing_directions, random_model, shade_expectations
from viewer.catalog import resolve_material, shipped_materials

GLSLANG = shutil.which("glslangValidator")
SPIRV_CROSS = shutil.which("spirv-cross")
TOOLS_MISSING = "glslangValidator or spirv-cross not installed (Debian glslang-tools, spirv-cross: scripts/setup.sh)"
needs_glslang = pytest.mark.skipif(GLSLANG is None, reason=TOOLS_MISSING)
EXPOSURE = 3.0
IOR = 1.5
PAIRS = 256  # direction pairs per material: a 16 × 16 target

VERTEX = """#version 430 core
void main() {
    vec2 p = vec2((gl_VertexID << 1) & 2, gl_VertexID & 2);
    gl_Position = vec4(2.0 * p - 1.0, 0.0, 1.0);
}
"""
# The host's side: the module as an engine would include it, then a main that evaluates one entry point per pixel.
HOST = f"""
uniform highp sampler2D u_wi;
uniform highp sampler2D u_wo;
layout(location = 0) out vec4 out_reflectance;
layout(location = 1) out vec4 out_shade;
layout(location = 2) out vec4 out_linear_srgb;
layout(location = 3) out vec4 out_unshadowed;
void main() {{
    ivec2 p = ivec2(gl_FragCoord.xy);
    vec3 wi = texelFetch(u_wi, p, 0).xyz;
    vec3 wo = texelFetch(u_wo, p, 0).xyz;
    vec3 xyz = gratnet_reflectance(wi, wo);
    out_reflectance = vec4(xyz, 1.0);
    out_shade = vec4(gratnet_shade(wi, wo, {IOR!r}, {EXPOSURE!r}), 1.0);
    out_linear_srgb = vec4(xyz_to_linear_srgb(xyz), 1.0);
    out_unshadowed = vec4(gratnet_shade_unshadowed(wi, wo, {IOR!r}, {EXPOSURE!r}), 1.0);
}}
"""
# The same host in HLSL (registers past the module's: weights t0, grids t1…).
HLSL_HOST = f"""
Texture2D<float4> u_wi : register(t16);
Texture2D<float4> u_wo : register(t17);
struct HostOutput {{
    float4 reflectance : SV_Target0;
    float4 shade : SV_Target1;
    float4 linear_srgb : SV_Target2;
    float4 unshadowed : SV_Target3;
}};
HostOutput main(float4 position : SV_Position) {{
    int3 p = int3(int2(position.xy), 0);
    float3 wi = u_wi.Load(p).xyz;
    float3 wo = u_wo.Load(p).xyz;
    float3 xyz = gratnet_reflectance(wi, wo);
    HostOutput o;
    o.reflectance = float4(xyz, 1.0);
    o.shade = float4(gratnet_shade(wi, wo, {IOR!r}, {EXPOSURE!r}), 1.0);
    o.linear_srgb = float4(xyz_to_linear_srgb(xyz), 1.0);
    o.unshadowed = float4(gratnet_shade_unshadowed(wi, wo, {IOR!r}, {EXPOSURE!r}), 1.0);
    return o;
}}
"""


def _export(materials: list[str], out: Path, export_format: str = "glsl") -> dict:
    assert main(["export", *materials, "--format", export_format, "--out", str(out), "--quiet"]) == 0
    return json.loads((out / "export.config.json").read_text(encoding="utf-8"))


@pytest.fixture(scope="module")
def random_models(tmp_path_factory) -> list[Path]:
    """Random pure-MLP models covering the activations, output activations, schemes and range kinds, and eq. 6a."""
    folder = tmp_path_factory.mktemp("models")
    paths = []
    for index, (activation, output, scheme, kind) in enumerate([
            ("silu", "clamp", "regular", "power-log"), ("relu", "sigmoid", "simple", "log"),
            ("leaky_relu", "none", "simple-max", "log1p")]):
        path = folder / f"random{index}.npz"
        save_model(path, random_model([163, 21, 13, 3], activation, output, scheme, kind, seed=index))
        paths.append(path)
    # eq. 6a: an encoding without the diagonal groups
    axes = EncodingSpec.for_grid(101, 5, diagonals=False)
    paths.append(folder / "random3.npz")
    save_model(paths[-1], random_model([axes.features, 21, 13, 3], "silu", "clamp", "simple-max", spec=axes, seed=3))
    return paths


@pytest.fixture(scope="module")
def exported(tmp_path_factory, random_models) -> tuple[Path, dict]:
    """Every shipped material and the random models, exported once."""
    out = tmp_path_factory.mktemp("export") / "glsl"
    return out, _export([*shipped_materials(), *map(str, random_models)], out)


@pytest.fixture(scope="module")
def exported_hlsl(tmp_path_factory, random_models) -> tuple[Path, dict]:
    """The same in HLSL."""
    if GLSLANG is None or SPIRV_CROSS is None:
        pytest.skip(TOOLS_MISSING)
    out = tmp_path_factory.mktemp("export") / "hlsl"
    return out, _export([*shipped_materials(), *map(str, random_models)], out, "hlsl")


def _directions(count: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Unit direction pairs (float32) over the upper hemisphere, a few below the horizon and near grazing."""
    rng = np.random.default_rng(seed)

    def hemisphere() -> np.ndarray:
        v = rng.standard_normal((count, 3))
        v[:, 2] = np.abs(v[:, 2])
        return v / np.linalg.norm(v, axis=1, keepdims=True)

    wi, wo = hemisphere(), hemisphere()
    wi[:4, 2] *= -1.0  # light below the horizon: A = 0
    wo[4:8] = [0.0, 0.0, 1.0]  # normal view
    wi[8:12] = -wo[8:12] * np.array([1.0, 1.0, -1.0])  # mirror pairs: the specular peak, u = v = 0
    return wi.astype(np.float32), wo.astype(np.float32)


def _hlsl_to_glsl(text: str, folder: Path) -> str:
    """An HLSL pixel shader → SPIR-V (glslang's HLSL front end) → GLSL 4.30 (spirv-cross)."""
    source, spirv = folder / "host.hlsl", folder / "host.spv"
    source.write_text(text, encoding="utf-8")
    for command in ([GLSLANG, "-D", "-V", "-S", "frag", "-e", "main", str(source), "-o", str(spirv)],
                    [SPIRV_CROSS, str(spirv), "--version", "430", "--no-es", "--output", str(folder / "host.glsl")]):
        result = subprocess.run(command, capture_output=True, text=True, timeout=300)
        assert result.returncode == 0, result.stdout + result.stderr
    return (folder / "host.glsl").read_text(encoding="utf-8")


def _sampler(program, name: str) -> str:
    """The uniform that holds texture ``name``: itself, or spirv-cross's combined sampler named after it."""
    if name in program:
        return name
    found = [member for member in program if f"Combined{name}SPIRV" in member]
    assert len(found) == 1, (name, list(program))
    return found[0]


def _evaluate(ctx, folder: Path, entry: dict, wi: np.ndarray, wo: np.ndarray, work: Path | None = None
              ) -> list[np.ndarray]:
    """Compile the exported module as a host would (HLSL: through SPIR-V back to GLSL), bind its files as its
    header says, draw once: reflectance, shade, linear sRGB and unshadowed shade per direction pair."""
    import moderngl

    text = (folder / entry["module"]).read_text(encoding="utf-8")
    if entry["module"].endswith(".hlsl"):
        assert work is not None
        fragment = _hlsl_to_glsl(text + HLSL_HOST, work)
    else:
        fragment = "#version 430 core\n" + text + HOST
    program = ctx.program(vertex_shader=VERTEX, fragment_shader=fragment)
    width, height = entry["weights_texels"]
    textures = [ctx.texture((width, height), 4, (folder / entry["weights"]).read_bytes(), dtype="f4")]
    for grid in entry["grids"]:
        dtype = {"float16": "f2", "float32": "f4"}[grid["type"]]
        textures.append(ctx.texture3d(tuple(grid["texels"]), grid["channels"], (folder / grid["file"]).read_bytes(),
                                      dtype=dtype))
    side = 16
    rows = wi.shape[0] // side
    for values in (wi, wo):
        padded = np.concatenate([values, np.zeros((values.shape[0], 1), np.float32)], axis=1)
        textures.append(ctx.texture((side, rows), 4, padded.tobytes(), dtype="f4"))
    for unit, texture in enumerate(textures):
        texture.filter = (moderngl.NEAREST, moderngl.NEAREST)
        texture.use(unit)
    program[_sampler(program, "u_weights")] = 0
    if entry["grids"]:
        program[_sampler(program, "u_grid")] = list(range(1, 1 + len(entry["grids"])))
    program[_sampler(program, "u_wi")] = len(textures) - 2
    program[_sampler(program, "u_wo")] = len(textures) - 1
    targets = [ctx.texture((side, rows), 4, dtype="f4") for _ in range(4)]
    framebuffer = ctx.framebuffer(color_attachments=targets)
    vertex_array = ctx.vertex_array(program, [])
    try:
        framebuffer.use()
        vertex_array.render(moderngl.TRIANGLES, vertices=3)
        return [np.frombuffer(framebuffer.read(components=4, attachment=k, dtype="f4"), np.float32).reshape(-1, 4)[
            :, :3] for k in range(4)]
    finally:
        for resource in (vertex_array, framebuffer, *targets, program, *textures):
            resource.release()


def _names(exported_config: dict) -> list[str]:
    return sorted(exported_config["materials"])





def _check_parity(name: str, entry: dict, results: list[np.ndarray], wi: np.ndarray, wo: np.ndarray) -> None:
    from viewer.renderer import xyz_to_linear_srgb_matrix

    model = load_model(entry["model"])
    key = -(wi + wo)  # in float32, as the module forms it
    u, v, w = (key[:, i].astype(np.float64) for i in range(3))
    bound = driver_bound(model, u, v, w, OWN_KEYS)
    expected = evaluate_keys(model, u, v, w)
    assert np.abs(expected).max() > 0  # the comparison sees light
    assert_within(results[0], expected, bound.bound, f"{name}: gratnet_reflectance XYZ", floor=1e-30)
    # gratnet_shade: exposure · A · S · XYZ; gratnet_shade_unshadowed: exposure · A · XYZ.
    shade = shade_expectations(model, wi, wo, expected, bound.bound)
    assert np.all(shade["a"][:4] == 0.0) and np.all(results[1][:4] == 0.0) and np.all(results[3][:4] == 0.0)
    assert_within(results[1], shade["shade"], shade["shade_bound"], f"{name}: gratnet_shade", floor=1e-30)
    assert_within(results[3], shade["unshadowed"], shade["unshadowed_bound"], f"{name}: gratnet_shade_unshadowed",
                  floor=1e-30)
    linear = results[0].astype(np.float64) @ xyz_to_linear_srgb_matrix().T
    np.testing.assert_allclose(results[2], linear, rtol=1e-5, atol=1e-7 * float(np.abs(linear).max()))


@pytest.mark.parametrize("name", [*shipped_materials(), "random0", "random1", "random2", "random3"])
def test_exported_glsl_module_equals_numpy_in_gl(ctx, exported, name):
    folder, config = exported
    wi, wo = _directions(PAIRS, seed=len(name))
    _check_parity(name, config["materials"][name], _evaluate(ctx, folder, config["materials"][name], wi, wo), wi, wo)


#: HLSL parity on a cross-section (every shipped material compiles in the glslang test below): two pure MLPs, grid
#: models with 4, 2 and 16 features a level (1, 1 and 4 grid textures a level), the three random models.
HLSL_PARITY = ("cd", "snake", "paper-cd", "paper-pits", "paper-scratches", "random0", "random1", "random2", "random3")


@pytest.mark.parametrize("name", HLSL_PARITY)
def test_exported_hlsl_module_equals_numpy_through_spirv(ctx, exported_hlsl, name, tmp_path):
    folder, config = exported_hlsl
    wi, wo = _directions(PAIRS, seed=len(name))
    results = _evaluate(ctx, folder, config["materials"][name], wi, wo, work=tmp_path)
    _check_parity(name, config["materials"][name], results, wi, wo)





@pytest.mark.parametrize("name", STEEP)
def test_glsl_gratnet_shade_applies_smiths_shadowing_at_grazing_angles(ctx, exported, name):
    folder, config = exported
    entry = config["materials"][name]
    wi, wo = grazing_directions(PAIRS, seed=7)
    results = _evaluate(ctx, folder, entry, wi, wo)
    check_grazing_shadowing(name, load_model(entry["model"]), [results[1], results[3]], wi, wo)


@pytest.mark.parametrize("name", STEEP)
def test_hlsl_gratnet_shade_applies_smiths_shadowing_at_grazing_angles(ctx, exported_hlsl, name, tmp_path):
    folder, config = exported_hlsl
    entry = config["materials"][name]
    wi, wo = grazing_directions(PAIRS, seed=7)
    results = _evaluate(ctx, folder, entry, wi, wo, work=tmp_path)
    check_grazing_shadowing(name, load_model(entry["model"]), [results[1], results[3]], wi, wo)


def test_the_module_bakes_the_models_slope_covariance(exported):
    """GRATNET_SLOPE_COVARIANCE is the model's covariance (metadata["volume"]) as float32, for every export; a model
    without one (the random models) gets zero: S = 1."""
    import re

    from gratnet.shadowing import slope_covariance_from_metadata

    folder, config = exported
    for name, entry in config["materials"].items():
        text = (folder / entry["module"]).read_text(encoding="utf-8")
        found = re.findall(r"^const vec3 GRATNET_SLOPE_COVARIANCE = vec3\(([^()]*)\);$", text, re.MULTILINE)
        assert len(found) == 1, name
        baked = np.array([float(x) for x in found[0].split(",")], np.float32)
        model = load_model(entry["model"])
        expected = np.array(slope_covariance_from_metadata(model.metadata.get("volume") or {}), np.float32)
        np.testing.assert_array_equal(baked, expected, err_msg=name)
        assert expected.any() == (name in shipped_materials()), name  # shipped: recorded; random: none
        assert "float a = a_term(wi, wo, ior) * smith_shadowing(wi, wo, GRATNET_SLOPE_COVARIANCE);" in text
        for entry_point in ("gratnet_reflectance(vec3 wi, vec3 wo)", "gratnet_shade(vec3 wi, vec3 wo, float ior, "
                            "float exposure)", "gratnet_shade_unshadowed(vec3 wi, vec3 wo, float ior, float exposure)"):
            assert f"//   vec3 {entry_point}" in text and f"\nvec3 {entry_point} {{" in text, (name, entry_point)


def test_every_shipped_material_and_random_model_was_exported(exported):
    folder, config = exported
    assert _names(config) == sorted([*shipped_materials(), "random0", "random1", "random2", "random3"])
    grid_models = [name for name, entry in config["materials"].items() if entry["grids"]]
    assert grid_models and len(grid_models) < len(config["materials"])  # both kinds of model are covered
    for entry in config["materials"].values():
        width, height = entry["weights_texels"]
        assert (folder / entry["weights"]).stat().st_size == width * height * 16
        for grid in entry["grids"]:
            assert (folder / grid["file"]).stat().st_size == np.prod(grid["texels"]) * grid["channels"] * (
                2 if grid["type"] == "float16" else 4)
    assert (folder / "README.md").is_file()


def test_the_module_bakes_the_uniforms_the_runtime_sets(ctx):
    from export.glsl import frequency_table
    from viewer.renderer import NetworkRenderer

    for model in (load_model(resolve_material("cd")), load_model(resolve_material("paper-cd")),
                  random_model([31, 9, 3], spec=EncodingSpec(3, 2, 2.0, 1.5))):
        renderer = NetworkRenderer(ctx, model, weights_path="texture")
        try:
            program = renderer.program("evaluate_keys")
            runtime = np.array(program["u_frequency"].value, dtype=np.float32).reshape(-1, 4)
        finally:
            renderer.release()
        np.testing.assert_array_equal(frequency_table(model), runtime)


# --- glslangValidator --------------------------------------------------------------------------------------------



def _validate(path: Path, text: str) -> subprocess.CompletedProcess:
    """glslangValidator on a module in its host: GLSL 4.30 (``.frag``), or HLSL with -D (``.hlsl``)."""
    if path.suffix == ".hlsl":
        path.write_text(text + HLSL_HOST, encoding="utf-8")
        # glslang takes HLSL only when it makes SPIR-V (-V): the full front end and code generation run.
        command = [GLSLANG, "-D", "-V", "-S", "frag", "-e", "main", str(path), "-o", str(path.with_suffix(".spv"))]
    else:
        path.write_text("#version 430 core\n" + text + HOST, encoding="utf-8")
        command = [GLSLANG, str(path)]
    return subprocess.run(command, capture_output=True, text=True, timeout=120)


@needs_glslang
def test_glslang_accepts_every_exported_module_and_rejects_a_broken_one(exported, tmp_path):
    folder, config = exported
    for name, entry in config["materials"].items():
        result = _validate(tmp_path / f"{name}.frag", (folder / entry["module"]).read_text(encoding="utf-8"))
        assert result.returncode == 0, f"{name}: {result.stdout}{result.stderr}"
    broken = (folder / config["materials"]["cd"]["module"]).read_text(encoding="utf-8").replace(
        "return range_inverse(mlp_evaluate());", "return range_inverse(mlp_evaluate(1));")
    result = _validate(tmp_path / "broken.frag", broken)
    assert result.returncode != 0 and "mlp_evaluate" in result.stdout


def test_glslang_accepts_every_exported_hlsl_module_and_rejects_a_broken_one(exported_hlsl, tmp_path):
    folder, config = exported_hlsl
    for name, entry in config["materials"].items():
        text = (folder / entry["module"]).read_text(encoding="utf-8")
        assert "precise " in text  # the encoding's exact transforms keep their protection from reassociation
        result = _validate(tmp_path / f"{name}.hlsl", text)
        assert result.returncode == 0, f"{name}: {result.stdout}{result.stderr}"
    text = (folder / config["materials"]["cd"]["module"]).read_text(encoding="utf-8")
    broken = text.replace("float3 gratnet_reflectance(float3 wi, float3 wo)", "float3 gratnet_reflectance(float3 wi)")
    assert broken != text
    assert _validate(tmp_path / "broken.hlsl", broken).returncode != 0


def test_hlsl_needs_its_tools_and_says_so_in_one_line(tmp_path, monkeypatch, capsys):
    monkeypatch.setenv("PATH", str(tmp_path))  # neither glslangValidator nor spirv-cross on it
    assert main(["export", "cd", "--format", "hlsl", "--out", str(tmp_path / "out")]) == 2
    assert "glslang-tools" in _one_line_error(capsys)
    assert list(tmp_path.iterdir()) == []


# --- the command: bad input, atomic output --------------------------------------------------------------------------


def _one_line_error(capsys) -> str:
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "error:" in err, err
    return err


def test_bad_input_is_one_line_exit_2_and_nothing_written(tmp_path, capsys):
    occupied = tmp_path / "occupied"
    occupied.mkdir()
    (occupied / "keep.txt").write_text("mine", encoding="utf-8")
    a_file = tmp_path / "a_file"
    a_file.write_text("x", encoding="utf-8")
    before = sorted(p.name for p in tmp_path.iterdir())
    cases = {
        "unknown material": (["no-such-material", "--format", "glsl", "--out", str(tmp_path / "new")],
                             "unknown material"),
        "non-empty --out": (["cd", "--format", "glsl", "--out", str(occupied)], "not empty"),
        "--out is a file": (["cd", "--format", "glsl", "--out", str(a_file)], "is a file"),
        "--out under a file": (["cd", "--format", "glsl", "--out", str(a_file / "sub")], "is a file"),
        "unknown format": (["cd", "--format", "metal", "--out", str(tmp_path / "new")], "--format"),
        "one name twice": (["cd", str(resolve_material("cd")), "--format", "glsl", "--out",
                            str(tmp_path / "new")], "one name"),
        "--single-file for a shader module": (["cd", "--format", "hlsl", "--single-file", "--out",
                                               str(tmp_path / "new")], "--single-file"),
    }
    for what, (argv, words) in cases.items():
        assert main(["export", *argv]) == 2, what
        assert words in _one_line_error(capsys), what
    assert sorted(p.name for p in tmp_path.iterdir()) == before  # no output, no hidden temporary folder
    assert [p.name for p in occupied.iterdir()] == ["keep.txt"]


def test_an_empty_out_folder_is_filled_and_a_failure_leaves_nothing(tmp_path, monkeypatch, capsys):
    import export.glsl

    empty = tmp_path / "empty"
    empty.mkdir()
    assert main(["export", "cd", "--format", "glsl", "--out", str(empty), "--quiet"]) == 0
    assert sorted(p.name for p in empty.iterdir()) == ["README.md", "cd.glsl", "cd.weights.bin", "export.config.json"]

    def fail(*_arguments: object) -> None:
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(export.glsl, "glsl_module", fail)
    assert main(["export", "cd", "--format", "glsl", "--out", str(tmp_path / "failed")]) == 2
    assert "No space left" in _one_line_error(capsys)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["empty"]
