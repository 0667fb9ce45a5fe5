"""``gratnet export --format wgsl`` (export/wgsl.py, export/wgsl/; docs/export.md, "--format wgsl") in WebGPU.

- parity: the exported module, fetched with its buffers from the folder the command wrote (served on 127.0.0.1), is
  compiled in headless chromium's WebGPU (SwiftShader: ``--enable-unsafe-webgpu``) into a compute shader that calls
  its functions for 256 direction pairs. ``gratnet_reflectance`` equals the numpy evaluation of the model file
  (gratnet.modelfile.evaluate_keys, float64, at the same float32 key) within gratnet/precision.py's float32 bound
  with sin/cos taken as accurate to 2⁻¹⁰ (SwiftShader's, as tests/tools/test_export_web.py holds its WebGL2 page);
  ``gratnet_shade`` (exposure · A · S · XYZ, S: Smith's shadowing for the model's slope covariance) adds the A-term
  and shadowing tolerances of the runtime's own tests, ``gratnet_shade_unshadowed`` (exposure · A · XYZ) the
  A-term's, both exactly 0 below the horizon; ``xyz_to_linear_srgb`` and ``xyz_to_display_srgb`` equal
  colour-science's. Materials: every shipped material (pure MLPs and feature-grid models), three random MLPs (every
  hidden and output activation, scheme and range kind) and two random grid models (float16 with 5 features; float32
  with 6);
- at grazing direction pairs, where S of the steep shipped reliefs (paper-corner-cubes, paper-pits) is far below 1,
  ``gratnet_shade`` equals numpy's exposure · A · S · XYZ and its ratio to ``gratnet_shade_unshadowed`` equals S;
  brdf.wgsl's smith_lambda types the numbers of brdf.glsl's (gratnet.shadowing's erf approximation);
- the encoding's reduced phases (half-turns), written out by a second host for the keys of tests/helpers.py's
  ``parity_keys`` (the rim u² + v² → 4 included), equal float64 within 2⁻²⁰: WGSL has no ``precise``, and the
  reflectance test's 2⁻¹⁰ sin/cos bound cannot see whether the error-free transforms survived the compiler;
- a module with one call broken is rejected by chromium's WGSL compiler (so the parity test can fail);
- the constants are generated: the codes are gratnet.codes', the frequency table and the layer table the model's;
- bad input: one line, exit status 2, nothing written.

The browser tests skip, with the reason, where chromium, Playwright or a WebGPU adapter is missing (scripts/setup.sh
installs chromium and Playwright).
"""

from __future__ import annotations

import functools
import http.server
import json
import os
import re
import shutil
import threading
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from gratnet.cli import main
from gratnet.codes import HIDDEN, OUTPUT, RANGE, SCHEME
from gratnet.encoding import network_coordinates
from gratnet.modelfile import ModelFile, evaluate_keys, load_model, pack_texture, save_model
from gratnet.precision import DriverErrors, assert_within, driver_bound
from tests.helpers import (
    STEEP,
    check_grazing_shadowing,
    grazing_directions,
    parity_keys,
    random_grid_model,
    random_model,
    shade_expectations,
)
from viewer.catalog import shipped_materials

CHROMIUM = shutil.which("chromium") or ("/usr/bin/chromium" if Path("/usr/bin/chromium").exists() else None)
try:
    import playwright.sync_api as playwright_api
except ImportError:  # pragma: no cover - the dev extra installs it
    playwright_api = None  # type: ignore[assignment]

needs_browser = pytest.mark.skipif(
    CHROMIUM is None or playwright_api is None,
    reason="needs Debian's chromium and the playwright package (scripts/setup.sh installs both)")

#: WebGPU in headless chromium: SwiftShader's Vulkan (shared/notes/browsers-and-shader-tools-here.md).
WEBGPU_FLAGS = ["--enable-unsafe-webgpu"]
#: SwiftShader's sin/cos are less exact than precision.py's default (as for the WebGL2 page on SwiftShader).
SWIFTSHADER = DriverErrors(key_error=0.0, sinusoid_error=2.0**-10)
EXPOSURE = 3.0
IOR = 1.5
PAIRS = 256
#: Every shipped material (issue 44: parity "for every shipped material") and random models that cover every
#: activation, output activation, scheme, range kind and grid storage.
SHIPPED = tuple(shipped_materials())
MATERIALS = (*SHIPPED, "random0", "random1", "random2", "random-grid16", "random-grid32")

#: The host's compute shader after the module: per pair, reflectance, shade, linear and display sRGB, unshadowed
#: shade.
HOST = f"""
@group(1) @binding(0) var<storage, read> host_pairs: array<vec4<f32>>;        // wi, wo of pair n at 2n, 2n + 1
@group(1) @binding(1) var<storage, read_write> host_out: array<vec4<f32>>;    // 5 results of pair n from 5n
@compute @workgroup_size(64)
fn host_main(@builtin(global_invocation_id) id: vec3<u32>) {{
    let n = id.x;
    if (n >= arrayLength(&host_pairs) / 2u) {{
        return;
    }}
    let wi = host_pairs[2u * n].xyz;
    let wo = host_pairs[2u * n + 1u].xyz;
    let xyz = gratnet_reflectance(wi, wo);
    host_out[5u * n] = vec4<f32>(xyz, 0.0);
    host_out[5u * n + 1u] = vec4<f32>(gratnet_shade(wi, wo, {IOR!r}, {EXPOSURE!r}), 0.0);
    host_out[5u * n + 2u] = vec4<f32>(xyz_to_linear_srgb(xyz), 0.0);
    host_out[5u * n + 3u] = vec4<f32>(xyz_to_display_srgb(xyz, {EXPOSURE!r}), 0.0);
    host_out[5u * n + 4u] = vec4<f32>(gratnet_shade_unshadowed(wi, wo, {IOR!r}, {EXPOSURE!r}), 0.0);
}}
"""

#: What a WebGPU host does (docs/export.md): fetch the module and its buffers, bind them, dispatch, read back.
#: The host shader's group 1 holds its inputs (binding 0) and outputs (binding 1: ``outputs`` vec4s).
RUN_JS = """async ({module, weights, grids, host, inputs, invocations, outputs}) => {
  const adapter = await navigator.gpu.requestAdapter();
  if (!adapter) return {error: 'no WebGPU adapter'};
  const device = await adapter.requestDevice();
  const started = performance.now();
  const code = (await (await fetch(module)).text()) + host;
  const shader = device.createShaderModule({code});
  const messages = (await shader.getCompilationInfo()).messages.filter(m => m.type === 'error');
  if (messages.length) return {error: messages.map(m => `${m.lineNum}:${m.linePos} ${m.message}`).join(' | ')};
  device.pushErrorScope('validation');
  // Explicit layouts, as an engine declares them: the module's buffers in group 0, the host's in group 1.
  const layout = types => device.createBindGroupLayout({entries: types.map((type, binding) => (
    {binding, visibility: GPUShaderStage.COMPUTE, buffer: {type}}))});
  const layouts = [layout(grids ? ['read-only-storage', 'read-only-storage'] : ['read-only-storage']),
                   layout(['read-only-storage', 'storage'])];
  const pipeline = device.createComputePipeline({layout: device.createPipelineLayout({bindGroupLayouts: layouts}),
                                                 compute: {module: shader, entryPoint: 'host_main'}});
  const storage = (bytes, usage = GPUBufferUsage.STORAGE) => {
    const buffer = device.createBuffer({size: bytes.byteLength, usage: usage | GPUBufferUsage.COPY_DST});
    device.queue.writeBuffer(buffer, 0, bytes);
    return buffer;
  };
  const file = async name => new Uint8Array(await (await fetch(name)).arrayBuffer());
  const entries = [{binding: 0, resource: {buffer: storage(await file(weights))}}];
  if (grids) entries.push({binding: 1, resource: {buffer: storage(await file(grids))}});
  const size = outputs * 16;
  const out = device.createBuffer({size, usage: GPUBufferUsage.STORAGE | GPUBufferUsage.COPY_SRC});
  const read = device.createBuffer({size, usage: GPUBufferUsage.MAP_READ | GPUBufferUsage.COPY_DST});
  const groups = [
    device.createBindGroup({layout: layouts[0], entries}),
    device.createBindGroup({layout: layouts[1], entries: [
      {binding: 0, resource: {buffer: storage(new Float32Array(inputs))}}, {binding: 1, resource: {buffer: out}}]}),
  ];
  const encoder = device.createCommandEncoder();
  const pass = encoder.beginComputePass();
  pass.setPipeline(pipeline);
  groups.forEach((group, index) => pass.setBindGroup(index, group));
  pass.dispatchWorkgroups(Math.ceil(invocations / 64));
  pass.end();
  encoder.copyBufferToBuffer(out, 0, read, 0, size);
  device.queue.submit([encoder.finish()]);
  const failure = await device.popErrorScope();
  if (failure) return {error: failure.message};
  await read.mapAsync(GPUMapMode.READ);
  const values = Array.from(new Float32Array(read.getMappedRange()));
  return {values, ms: performance.now() - started};
}"""

#: A host that writes the encoding's reduced phases (half-turns) per key: for frequency j, the four spatial groups'
#: at 2jM… and (c_t's, c_u, c_v, c_t) after them, M = MAX_FREQUENCIES rows of each.
PHASE_HOST = """
@group(1) @binding(0) var<storage, read> host_keys: array<vec4<f32>>;
@group(1) @binding(1) var<storage, read_write> host_out: array<vec4<f32>>;
@compute @workgroup_size(64)
fn host_main(@builtin(global_invocation_id) id: vec3<u32>) {
    let n = i32(id.x);
    if (n >= i32(arrayLength(&host_keys))) {
        return;
    }
    gratnet_set_layers();  // as gratnet_reflectance does first: it sets encoding.wgsl's g_zero
    encoding_set_key(host_keys[n].xyz);
    for (var j = 0; j < MAX_FREQUENCIES; j++) {
        var phases: vec4<f32>;
        for (var g = 0; g < 4; g++) {
            phases[g] = reduced_half_turns(u_frequency[j].xy, g_group_grid[g], g_group_rest[g], g_group[g]);
        }
        host_out[2 * MAX_FREQUENCIES * n + j] = phases;
        host_out[2 * MAX_FREQUENCIES * n + MAX_FREQUENCIES + j] = vec4<f32>(
            reduced_half_turns(u_frequency[j].zw, g_t.y, g_t.z, g_t.x), g_coordinates);
    }
}
"""


def _random_models() -> dict[str, ModelFile]:
    models = {f"random{index}": random_model([163, 21, 13, 3], activation, output, scheme, kind, seed=index)
              for index, (activation, output, scheme, kind) in enumerate([
                  ("silu", "clamp", "regular", "power-log"), ("relu", "sigmoid", "simple", "log"),
                  ("leaky_relu", "none", "simple-max", "log1p")])}
    models["random-grid16"] = random_grid_model(5, 3, "float16", "smoothstep", seed=5)
    models["random-grid32"] = random_grid_model(6, 2, "float32", "linear", seed=6, diagonals=False)
    return models


class _QuietHandler(http.server.SimpleHTTPRequestHandler):
    def log_message(self, format: str, *args: object) -> None:  # noqa: A002 - the base class's name
        pass


@pytest.fixture(scope="module")
def exported(tmp_path_factory) -> tuple[Path, dict]:
    """Every material of :data:`MATERIALS`, exported once with the command."""
    folder = tmp_path_factory.mktemp("wgsl")
    paths = []
    for name, model in _random_models().items():
        save_model(folder / f"{name}.npz", model)
        paths.append(str(folder / f"{name}.npz"))
    out = folder / "out"
    assert main(["export", *SHIPPED, *paths, "--format", "wgsl", "--out", str(out), "--quiet"]) == 0
    return out, json.loads((out / "export.config.json").read_text(encoding="utf-8"))


@pytest.fixture(scope="module")
def page(exported) -> Iterator[object]:
    """One headless chromium with WebGPU, its profile in a temporary folder, on a page served from the export."""
    if CHROMIUM is None or playwright_api is None:
        pytest.skip("needs Debian's chromium and the playwright package (scripts/setup.sh installs both)")
    out, _ = exported
    home = out.parent / "chromium-home"
    environment = {"HOME": str(home), "XDG_CONFIG_HOME": str(home / "config"), "XDG_CACHE_HOME": str(home / "cache")}
    (out / "index.html").write_text("<!doctype html><title>wgsl</title>", encoding="utf-8")
    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), functools.partial(_QuietHandler, directory=str(out)))
    threading.Thread(target=server.serve_forever, daemon=True).start()
    try:
        with playwright_api.sync_playwright() as playwright:
            browser = playwright.chromium.launch(executable_path=CHROMIUM, headless=True, args=WEBGPU_FLAGS,
                                                 env={**os.environ, **environment})
            try:
                opened = browser.new_page()
                opened.goto(f"http://127.0.0.1:{server.server_port}/index.html")  # a secure context: WebGPU
                if not opened.evaluate("async () => !!(navigator.gpu && await navigator.gpu.requestAdapter())"):
                    pytest.skip("chromium offers no WebGPU adapter here (--enable-unsafe-webgpu, SwiftShader)")
                yield opened
            finally:
                browser.close()
    finally:
        server.shutdown()
        server.server_close()


def directions(count: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Unit direction pairs (float32) over the upper hemisphere; lights below the horizon, normal view, mirrors."""
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


def run_module(page, entry: dict, wi: np.ndarray, wo: np.ndarray, module: str | None = None) -> dict:
    """The module's functions on the pairs in WebGPU: ``values`` (pairs, 5 results, 3) or ``error``."""
    pairs = np.zeros((wi.shape[0], 2, 4), np.float32)
    pairs[:, 0, :3], pairs[:, 1, :3] = wi, wo
    result = _run(page, entry, HOST, pairs, wi.shape[0], 5 * wi.shape[0], module)
    if "values" in result:
        result["values"] = np.asarray(result["values"], np.float64).reshape(-1, 5, 4)[:, :, :3]
    return result


def run_phases(page, entry: dict, keys: np.ndarray, frequencies: int, module: str | None = None) -> dict:
    """The encoding's reduced phases per float32 key (:data:`PHASE_HOST`): ``values`` (keys, 2, M, 4) or ``error``."""
    inputs = np.zeros((keys.shape[0], 4), np.float32)
    inputs[:, :3] = keys
    result = _run(page, entry, PHASE_HOST, inputs, keys.shape[0], 2 * frequencies * keys.shape[0], module)
    if "values" in result:
        result["values"] = np.asarray(result["values"], np.float64).reshape(-1, 2, frequencies, 4)
    return result


def _run(page, entry: dict, host: str, inputs: np.ndarray, invocations: int, outputs: int,
         module: str | None) -> dict:
    return page.evaluate(RUN_JS, {"module": module or entry["module"], "weights": entry["weights"],
                                  "grids": entry.get("grids"), "host": host, "invocations": invocations,
                                  "inputs": inputs.ravel().astype(np.float64).tolist(), "outputs": outputs})


def parity(entry: dict, results: np.ndarray, wi: np.ndarray, wo: np.ndarray,
           errors: DriverErrors = SWIFTSHADER) -> dict[str, float]:
    """Assert the five results against numpy; the largest |difference| and |difference| / bound of each."""
    import colour

    from viewer.renderer import xyz_to_linear_srgb_matrix

    model = load_model(entry["model"])
    key = -(wi + wo)  # in float32, as the module forms it
    u, v, w = (key[:, i].astype(np.float64) for i in range(3))
    bound = driver_bound(model, u, v, w, errors).bound
    expected = evaluate_keys(model, u, v, w)
    assert np.abs(expected).max() > 0  # the comparison sees light
    shade = shade_expectations(model, wi, wo, expected, bound)
    found = {"xyz": float(np.abs(results[:, 0] - expected).max()),
             "xyz/bound": float((np.abs(results[:, 0] - expected) / np.maximum(bound, 1e-30)).max()),
             "shade/bound": float((np.abs(results[:, 1] - shade["shade"])
                                   / np.maximum(shade["shade_bound"], 1e-30)).max())}
    assert_within(results[:, 0], expected, bound, f"{entry['module']}: gratnet_reflectance XYZ", floor=1e-30)
    assert np.all(shade["a"][:4] == 0.0) and np.all(results[:4, 1] == 0.0) and np.all(results[:4, 4] == 0.0)
    assert_within(results[:, 1], shade["shade"], shade["shade_bound"], f"{entry['module']}: gratnet_shade",
                  floor=1e-30)
    assert_within(results[:, 4], shade["unshadowed"], shade["unshadowed_bound"],
                  f"{entry['module']}: gratnet_shade_unshadowed", floor=1e-30)
    linear = results[:, 0] @ xyz_to_linear_srgb_matrix().T
    np.testing.assert_allclose(results[:, 2], linear, rtol=1e-5, atol=1e-7 * float(np.abs(linear).max()))
    display = colour.cctf_encoding(np.clip(results[:, 2] * EXPOSURE, 0.0, 1.0), function="sRGB")
    np.testing.assert_allclose(results[:, 3], display, atol=2e-5)  # SwiftShader's pow: a few ulps near 1
    return found


@needs_browser
@pytest.mark.parametrize("name", MATERIALS)
def test_exported_wgsl_module_equals_numpy_in_webgpu(exported, page, name):
    folder, config = exported
    entry = config["materials"][name]
    wi, wo = directions(PAIRS, seed=len(name))
    result = run_module(page, entry, wi, wo)
    assert "error" not in result, result.get("error")
    parity(entry, result["values"], wi, wo)


@needs_browser
@pytest.mark.parametrize("name", STEEP)
def test_wgsl_gratnet_shade_applies_smiths_shadowing_at_grazing_angles(exported, page, name):
    """As tests/tools/test_export_shaders.py's GLSL and HLSL twins, with SwiftShader's sin/cos bound."""
    _, config = exported
    entry = config["materials"][name]
    wi, wo = grazing_directions(PAIRS, seed=7)
    result = run_module(page, entry, wi, wo)
    assert "error" not in result, result.get("error")
    values = result["values"]
    check_grazing_shadowing(name, load_model(entry["model"]), [values[:, 1], values[:, 4]], wi, wo, SWIFTSHADER)


def _numbers(text: str) -> list[float]:
    return [float(x) for x in re.findall(r"(?<![\w.])\d+\.\d+(?:[eE][+-]?\d+)?", text)]


def _function(text: str, signature: str) -> str:
    start = text.index(signature)
    return text[start:text.index("\n}\n", start)]


def test_the_wgsl_shadowing_types_brdf_glsls_numbers():
    """brdf.wgsl's smith_lambda is brdf.glsl's, number for number (A&S 7.1.26's p and coefficients, 1/√π), and
    those are gratnet.shadowing's; smith_shadowing has the same form."""
    import math

    from export.wgsl import TEMPLATE_ROOT
    from gratnet import shadowing
    from viewer.glsl import SHADER_ROOT

    glsl = (Path(SHADER_ROOT) / "brdf.glsl").read_text(encoding="utf-8")
    wgsl = (TEMPLATE_ROOT / "brdf.wgsl").read_text(encoding="utf-8")
    glsl_lambda = _numbers(_function(glsl, "float smith_lambda("))
    wgsl_lambda = _numbers(_function(wgsl, "fn smith_lambda("))
    assert glsl_lambda == wgsl_lambda
    for constant in (shadowing.ERFC_P, *(abs(a) for a in shadowing.ERFC_COEFFICIENTS), 1.0 / math.sqrt(math.pi)):
        assert any(abs(number - constant) <= 1e-15 * constant for number in wgsl_lambda), constant
    assert (_numbers(_function(glsl, "float smith_shadowing(")) == _numbers(_function(wgsl, "fn smith_shadowing("))
            == [0.0, 0.0, 0.0, 1.0, 1.0])


def test_the_module_bakes_the_models_slope_covariance(exported):
    """GRATNET_SLOPE_COVARIANCE is the GLSL module's constant (the model's covariance as float32), and gratnet_shade
    applies it while gratnet_shade_unshadowed does not."""
    from export.glsl import glsl_module

    folder, config = exported
    for name in (*STEEP, "cd", "random0"):
        entry = config["materials"][name]
        text = (folder / entry["module"]).read_text(encoding="utf-8")
        glsl = re.search(r"^const vec3 GRATNET_SLOPE_COVARIANCE = vec3\(([^()]*)\);$",
                         glsl_module(load_model(entry["model"]), name).text, re.MULTILINE)
        assert glsl is not None
        assert f"const GRATNET_SLOPE_COVARIANCE: vec3<f32> = vec3<f32>({glsl.group(1)});" in text
        assert ("let a = a_term(wi, wo, ior) * smith_shadowing(wi, wo, GRATNET_SLOPE_COVARIANCE);"
                in _function(text, "fn gratnet_shade("))
        assert "smith_shadowing" not in _function(text, "fn gratnet_shade_unshadowed(")


def phase_errors(model: ModelFile, keys: np.ndarray, values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """|phase − s^j·c| in half-turns, wrapped to [0, 1], against float64 at the float32 keys: the spatial groups'
    (keys, L, 4) and c_t's (keys, L_t)."""
    spec = model.encoding
    k = keys.astype(np.float64)
    c = network_coordinates(k[:, 0], k[:, 1], k[:, 2], model.scheme)
    groups = np.stack([c[:, 0], c[:, 1], c[:, 0] + c[:, 1], c[:, 0] - c[:, 1]], axis=-1)
    exact = (spec.scale ** np.arange(spec.frequencies))[None, :, None] * groups[:, None, :]
    exact_t = (spec.t_scale ** np.arange(spec.t_frequencies))[None, :] * c[:, 2:3]

    def wrapped(difference: np.ndarray) -> np.ndarray:
        return np.abs((difference + 1.0) % 2.0 - 1.0)

    return (wrapped(values[:, 0, :spec.frequencies, :] - exact),
            wrapped(values[:, 1, :spec.t_frequencies, 0] - exact_t))


#: The spatial phases' allowed error in half-turns: encoding.glsl's exact reduction leaves ~10⁻⁸ (the split
#: frequency's and the small terms' rounding); a plain float32 product s^j·c errs by up to ~2·10⁻⁵ at the top
#: frequency, and a compiler that reassociated the error-free transforms by as much.
PHASE_TOLERANCE = 2.0**-20


@needs_browser
@pytest.mark.parametrize("name", ["random0", "random1", "cd"])  # the schemes regular, simple, simple-max
def test_the_encodings_phases_are_reduced_exactly_without_precise(exported, page, name):
    """WGSL has no ``precise``: the error-free transforms must survive the compiler, seen in the phases themselves
    (the reflectance test's 2⁻¹⁰ sin/cos bound could not tell)."""
    from gratnet.precision import UNIT_ROUNDOFF

    _, config = exported
    entry = config["materials"][name]
    model = load_model(entry["model"])
    u, v, w = parity_keys()
    keys = np.stack([u, v, w], axis=-1).astype(np.float32)
    frequencies = max(model.encoding.frequencies, model.encoding.t_frequencies, 1)
    result = run_phases(page, entry, keys, frequencies)
    assert "error" not in result, result.get("error")
    spatial, t = phase_errors(model, keys, result["values"])
    assert spatial.max() <= PHASE_TOLERANCE, f"{name}: spatial phase off by {spatial.max():.3g} half-turns"
    # c_t = 2t − 1 comes from a float32 square root and division (precision.py's t_coordinate_error).
    allowed_t = PHASE_TOLERANCE + (model.encoding.t_scale ** np.arange(model.encoding.t_frequencies)) * (
        8.0 * UNIT_ROUNDOFF)
    assert np.all(t <= allowed_t[None, :]), f"{name}: t phase off by {t.max():.3g} half-turns"


@needs_browser
def test_chromium_rejects_a_module_with_one_call_broken(exported, page):
    folder, config = exported
    entry = config["materials"]["cd"]
    text = (folder / entry["module"]).read_text(encoding="utf-8")
    broken = text.replace("return range_inverse(mlp_evaluate());", "return range_inverse(mlp_evaluate(1));")
    assert broken != text
    (folder / "broken.wgsl").write_text(broken, encoding="utf-8")
    wi, wo = directions(64, seed=1)
    result = run_module(page, entry, wi, wo, module="broken.wgsl")
    assert "mlp_evaluate" in result.get("error", ""), result


def test_the_module_spells_the_shared_codes_and_the_models_tables(exported):
    """Codes from gratnet.codes, the frequency table and layer table from the model: generated, never typed."""
    from export.glsl import frequency_table

    folder, config = exported
    for name in ("cd", "paper-cd", "random2"):
        entry = config["materials"][name]
        text = (folder / entry["module"]).read_text(encoding="utf-8")
        model = load_model(entry["model"])
        for table in (SCHEME, HIDDEN, OUTPUT, RANGE):
            for define, code in table.defines().items():
                assert f"const {define}: i32 = {code};" in text
        assert f"const u_scheme: i32 = {SCHEME.code(model.scheme)};" in text
        assert f"const u_hidden_activation: i32 = {HIDDEN.code(model.activation)};" in text
        row = re.search(r"const u_frequency: array<vec4<f32>, \d+> = array<vec4<f32>, \d+>\((.*)\);", text)
        assert row is not None
        values = np.array([float(x) for x in re.findall(r"[-0-9.e+]+(?=[,)])", row.group(1))], np.float32)
        np.testing.assert_array_equal(values.reshape(-1, 4), frequency_table(model))
        texture, layout = pack_texture(model)
        for k, layer in enumerate(layout):
            assert (f"u_layers[{k}] = vec4<i32>({layer['row_offset']}, {layer['in_blocks']}, {layer['out_blocks']}, "
                    f"0) + zero;") in text
        assert (folder / entry["weights"]).read_bytes() == texture.astype("<f4").tobytes()
        assert ("gratnet_grids" in text) == bool(model.grids) == ("grids" in entry)


def test_the_grid_buffer_holds_every_level_in_turn(exported):
    folder, config = exported
    for name in ("paper-cd", "random-grid16", "random-grid32"):
        entry = config["materials"][name]
        model = load_model(entry["model"])
        data = (folder / entry["grids"]).read_bytes()
        assert len(data) % 4 == 0 and entry["grid_type"] == str(model.grids[0].dtype)
        values = np.frombuffer(data, dtype=np.dtype(entry["grid_type"]).newbyteorder("<"))
        for level, grid in zip(entry["grid_levels"], model.grids, strict=True):
            depth, height, width, features = grid.shape
            assert level["nodes"] == [width, height, depth] and level["features"] == features
            np.testing.assert_array_equal(values[level["offset"]:level["offset"] + grid.size], grid.ravel())


# --- the command: bad input --------------------------------------------------------------------------------------


def _one_line_error(capsys) -> str:
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "error:" in err, err
    return err


def test_bad_input_is_one_line_exit_2_and_nothing_written(tmp_path, capsys):
    occupied = tmp_path / "occupied"
    occupied.mkdir()
    (occupied / "keep.txt").write_text("mine", encoding="utf-8")
    before = sorted(p.name for p in tmp_path.iterdir())
    cases = {
        "--single-file": (["cd", "--format", "wgsl", "--single-file", "--out", str(tmp_path / "new")],
                          "--single-file"),
        "unknown material": (["no-such-material", "--format", "wgsl", "--out", str(tmp_path / "new")],
                             "unknown material"),
        "non-empty --out": (["cd", "--format", "wgsl", "--out", str(occupied)], "not empty"),
        "one name twice": (["cd", "cd", "--format", "wgsl", "--out", str(tmp_path / "new")], "one name"),
    }
    for what, (argv, words) in cases.items():
        assert main(["export", *argv]) == 2, what
        assert words in _one_line_error(capsys), what
    assert sorted(p.name for p in tmp_path.iterdir()) == before  # no output, no hidden temporary folder
    assert [p.name for p in occupied.iterdir()] == ["keep.txt"]


def test_an_empty_out_folder_is_filled_and_a_failure_leaves_nothing(tmp_path, monkeypatch, capsys):
    import export.wgsl

    empty = tmp_path / "empty"
    empty.mkdir()
    assert main(["export", "cd", "--format", "wgsl", "--out", str(empty), "--quiet"]) == 0
    assert sorted(p.name for p in empty.iterdir()) == ["README.md", "cd.weights.bin", "cd.wgsl", "export.config.json"]

    def fail(*_arguments: object) -> None:
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(export.wgsl, "wgsl_module", fail)
    assert main(["export", "cd", "--format", "wgsl", "--out", str(tmp_path / "failed")]) == 2
    assert "No space left" in _one_line_error(capsys)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["empty"]
