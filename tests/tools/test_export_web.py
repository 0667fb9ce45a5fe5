"""``gratnet export --format web`` (export/web.py, export/web/; docs/export.md, "The web page") in a real browser.

Debian's chromium, headless, driven by Playwright (PyPI ``playwright``, no browser download: the system chromium by
``executable_path``); the page is served from 127.0.0.1 (a page from file:// cannot fetch its binaries). Three
browsers: WebGL2 on Mesa llvmpipe through ANGLE (``--use-angle=gl-egl``) and on SwiftShader, and the page's WebGPU
backend (``backend=webgpu``, the exported WGSL module) on SwiftShader's Vulkan (``--enable-unsafe-webgpu``), whose
URLs get ``backend=webgpu`` added. The tests of what the backends do differently (pixels, files, redraws) run on all
three; those of the shared parameter, defaults and panel code on the WebGL2 two, to keep the suite short. Frames are
64 px a side, the every-material slices 32.

- a BRDF slice (``slice=1``) read back with ``window.gratnetReadPixels()`` equals the numpy evaluation of the model
  file (exposure · A · XYZ, as linear sRGB: no Smith shadowing, as the runtime's slice; the steep shipped reliefs
  among the shipped slices would be off by 1/S with it) within gratnet/precision.py's float32 driver bound: the
  default bound
  on llvmpipe, and on SwiftShader (WebGL2 and WebGPU) the bound with its sin/cos taken as accurate to 2⁻¹⁰
  (measured: its 2⁻¹² bound is exceeded);
- a page without parameters takes gratnet render's defaults (viewer.defaults), on every mesh and the slice;
- a mesh render (the CD disc, the sphere) at the default view equals ``gratnet render``'s EXR of the same view, and
  the canvas its PNG within LDR-FLIP 0.005 (llvmpipe; SwiftShader is held to its measured, looser level): exposure ·
  A · S · XYZ with Smith's shadowing S for the material's slope covariance, as gratnet render draws it, seen most on
  paper-pits' sphere (rms slope 0.73: S falls from 1 at the centre to near 0 at the rim);
- a mesh render is drawn (finite, lit pixels, black background); ``ui=0`` shows the picture alone, ``ui=1`` the
  panel;
- a bad URL parameter shows one line and no picture; so does ``backend=webgpu`` in a browser without WebGPU;
- the slice of every shipped material (viewer.catalog.shipped_materials(), 32²) equals numpy on llvmpipe's WebGL2;
  SwiftShader's WebGL2 sees the representative set above (pure MLP, float16 and float32 grids, 12 grid textures),
  WebGPU a smaller one (cd, paper-cd, the float32 grid model: tests/tools/test_export_wgsl.py holds its module to
  numpy for every shipped material already);
- the export writes each material's WGSL module and grid buffer as ``--format wgsl`` does.

Feature-grid models (the ``paper-*`` materials; featuregrid.glsl's ``u_grid`` indexed by constants only) are held
to the same bounds: the slice of paper-cd (4 features a level: one RGBA16F texture), paper-scratches (16: four
textures a level, 12 in all) and two random grid models (float16 with a last R16F chunk of odd width and smoothstep
interpolation; float32 with a last RG32F chunk), and paper-cd's mesh render against gratnet render's (WebGL2).

Skipped, with the reason, where chromium or Playwright is missing (scripts/setup.sh installs both).
"""

from __future__ import annotations

import contextlib
import functools
import http.server
import json
import os
import shutil
import threading
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from export.web import CHROMIUM_BACKENDS, CHROMIUM_WEBGPU
from gratnet.brdf import a_term, slice_view_directions
from gratnet.cli import main
from gratnet.modelfile import evaluate_keys, load_model, save_model
from gratnet.precision import OWN_KEYS, DriverErrors, assert_within, driver_bound
from tests.helpers import RELATIVE, random_grid_model, random_model
from viewer.catalog import shipped_materials

CHROMIUM = shutil.which("chromium") or ("/usr/bin/chromium" if Path("/usr/bin/chromium").exists() else None)
try:
    import playwright.sync_api as playwright_api
except ImportError:  # pragma: no cover - the dev extra installs it
    playwright_api = None  # type: ignore[assignment]

needs_browser = pytest.mark.skipif(
    CHROMIUM is None or playwright_api is None,
    reason="needs Debian's chromium and the playwright package (scripts/setup.sh installs both)")

#: chromium's flags per browser the page is tested in (export.web, shared/notes/browsers-and-shader-tools-here.md):
#: the two WebGL2 backends, and WebGPU on SwiftShader.
BACKENDS = {**CHROMIUM_BACKENDS, "webgpu": CHROMIUM_WEBGPU}
#: The page's ``backend`` parameter per browser (WebGL2, the page's default, needs none).
PAGE_BACKEND = {"webgpu": "webgpu"}
_SWIFTSHADER = DriverErrors(key_error=0.0, sinusoid_error=2.0**-10)
#: The float32 error each backend is held to: llvmpipe the default; SwiftShader's sin/cos are less exact, through
#: WebGL2 and WebGPU alike (tests/tools/test_export_wgsl.py holds the WGSL module to the same bound).
BACKEND_ERRORS = {"llvmpipe": OWN_KEYS, "swiftshader": _SWIFTSHADER, "webgpu": _SWIFTSHADER}
SIZE = 64
#: A mesh render against gratnet render's, per backend: the share of pixels allowed beyond 10⁻³ of the peak, and the
#: largest LDR-FLIP of the canvas against its PNG (test_a_mesh_render_equals_gratnet_renders_exr_and_its_png…).
MESH_TOLERANCE = {"llvmpipe": (0.0, 0.005), "swiftshader": (0.06, 0.02), "webgpu": (0.06, 0.02)}
WEBGL2_BROWSERS = sorted(CHROMIUM_BACKENDS)
#: The 64² slice's materials, and those of them the WebGPU browser sees too.
SLICE_MATERIALS = ("cd", "random-simple", "paper-cd", "paper-scratches", "random-grid16", "random-grid32")
WEBGPU_SLICE_MATERIALS = ("cd", "paper-cd", "random-grid32")
#: Every shipped material (issue 44: parity "for every shipped material") the 64² slice does not already cover, at a
#: small slice on llvmpipe.
SHIPPED = tuple(name for name in shipped_materials() if name not in SLICE_MATERIALS)
SHIPPED_SIZE = 32


class _QuietHandler(http.server.SimpleHTTPRequestHandler):
    def log_message(self, format: str, *args: object) -> None:  # noqa: A002 - the base class's name
        pass


@pytest.fixture(scope="module")
def site(tmp_path_factory) -> Iterator[tuple[str, Path]]:
    """cd, paper-cd, paper-scratches, paper-pits (a steep relief: Smith's shadowing), a random model (simple scheme,
    log range) and two random grid models exported once, served on 127.0.0.1."""
    folder = tmp_path_factory.mktemp("web")
    models = {"random-simple": random_model([163, 21, 13, 3], "relu", "sigmoid", "simple", "log", seed=3),
              "random-grid16": random_grid_model(5, 3, "float16", "smoothstep", seed=5),
              "random-grid32": random_grid_model(6, 2, "float32", "linear", seed=6, diagonals=False)}
    for name, model in models.items():
        save_model(folder / f"{name}.npz", model)
    out = folder / "site"
    assert main(["export", "cd", *(str(folder / f"{name}.npz") for name in models), "paper-cd", "paper-scratches",
                 "paper-pits", "--format", "web", "--out", str(out), "--quiet"]) == 0
    server, url = _serve(out)
    try:
        yield url, out
    finally:
        server.shutdown()
        server.server_close()


def _serve(folder: Path) -> tuple[http.server.ThreadingHTTPServer, str]:
    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), functools.partial(_QuietHandler, directory=str(folder)))
    threading.Thread(target=server.serve_forever, daemon=True).start()
    return server, f"http://127.0.0.1:{server.server_port}/index.html"


@pytest.fixture(scope="module")
def shipped_site(tmp_path_factory) -> Iterator[tuple[str, Path]]:
    """Every shipped material exported once, served on 127.0.0.1. The default views are not computed (the slice
    tests give light, exposure and IOR; the defaults' own test uses ``site``): they cost seconds per material."""
    import export.web

    out = tmp_path_factory.mktemp("web-shipped") / "site"
    fixed = {"light": [30.0, 20.0], "camera": [0.2, 0.0, 45.0], "exposure": 1.0}
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(export.web, "_defaults", lambda *_: dict.fromkeys(("cd", "sphere", "plane", "slice"), fixed))
        assert main(["export", *SHIPPED, "--format", "web", "--out", str(out), "--quiet"]) == 0
    server, url = _serve(out)
    try:
        yield url, out
    finally:
        server.shutdown()
        server.server_close()


@pytest.fixture(scope="module", params=sorted(BACKENDS))
def browser(request, tmp_path_factory) -> Iterator[tuple[str, object]]:
    """One headless chromium per backend, its profile and caches in a temporary folder."""
    home = tmp_path_factory.mktemp("chromium-home")
    environment = {"HOME": str(home), "XDG_CONFIG_HOME": str(home / "config"), "XDG_CACHE_HOME": str(home / "cache")}
    with playwright_api.sync_playwright() as playwright:
        launched = playwright.chromium.launch(executable_path=CHROMIUM, headless=True, args=BACKENDS[request.param],
                                              env={**os.environ, **environment})
        try:
            yield request.param, launched
        finally:
            launched.close()


@contextlib.contextmanager
def _page(browser, url: str) -> Iterator[object]:
    """The page at ``url`` in ``browser``, with its ``backend`` (PAGE_BACKEND) unless the URL names one, once drawn
    or failed."""
    backend = PAGE_BACKEND.get(browser[0])
    if backend and "backend=" not in url:
        url += f"{'&' if '?' in url else '?'}backend={backend}"
    page = browser[1].new_page()
    try:
        page.goto(url)
        page.wait_for_function("window.gratnetReady === true || window.gratnetError !== undefined", timeout=240_000)
        yield page
    finally:
        page.close()


def _read(page) -> np.ndarray:
    result = page.evaluate("window.gratnetReadPixels()")
    return np.asarray(result["data"], dtype=np.float64).reshape(result["height"], result["width"], 3)


def _slice_parity(site: tuple[str, Path], browser: tuple[str, Any], material: str, size: int) -> None:
    """The page's slice of ``material`` (light 30°, 20°, exposure 2, IOR 1.5) against numpy within the backend's
    bound (BACKEND_ERRORS), in linear sRGB."""
    from viewer.renderer import xyz_to_linear_srgb_matrix

    url, out = site
    exposure, ior = 2.0, 1.5
    with _page(browser, f"{url}?material={material}&slice=1&ui=0&size={size}&light=30,20&exposure={exposure}"
                        f"&ior={ior}") as page:
        assert page.evaluate("window.gratnetError") is None
        actual = _read(page)
        config = page.evaluate("window.gratnetConfig")
    assert config["backend"] == PAGE_BACKEND.get(browser[0], "webgl2")
    config_file = json.loads((out / "export.config.json").read_text(encoding="utf-8"))
    model = load_model(config_file["materials"][material]["model"])
    light = np.asarray(config["light_vector"], dtype=np.float32)  # the float32 uniform the page set
    view, inside = slice_view_directions(size)
    view = view.astype(np.float32)
    key = -(light + view)  # float32, as the shader forms it
    u, v, w = (key[..., i].astype(np.float64) for i in range(3))
    a = a_term(np.broadcast_to(light.astype(np.float64), view.shape), view.astype(np.float64), ior)
    factor = np.where(inside, exposure * a, 0.0)[..., None]
    xyz = evaluate_keys(model, u, v, w)
    matrix = xyz_to_linear_srgb_matrix()
    expected = (factor * xyz) @ matrix.T
    assert np.count_nonzero(inside & (a > 0)) > size * size // 2 and np.abs(expected).max() > 0
    bound_xyz = factor * (driver_bound(model, u, v, w, BACKEND_ERRORS[browser[0]]).bound + RELATIVE * np.abs(xyz))
    bound = bound_xyz @ np.abs(matrix).T  # |M d| ≤ |M| |d| per channel
    assert np.all(actual[~inside] == 0.0)
    assert_within(actual, expected, bound, f"{material} slice on {browser[0]} (linear sRGB)", floor=1e-30)


@needs_browser
@pytest.mark.parametrize(("browser", "material"), [
    *((name, material) for name in WEBGL2_BROWSERS for material in SLICE_MATERIALS),
    *(("webgpu", material) for material in WEBGPU_SLICE_MATERIALS)], indirect=["browser"])
def test_brdf_slice_equals_numpy_within_the_float32_bound(site, browser, material):
    _slice_parity(site, browser, material, SIZE)


@needs_browser
@pytest.mark.parametrize("browser", ["llvmpipe"], indirect=True)
@pytest.mark.parametrize("material", SHIPPED)
def test_every_shipped_materials_slice_equals_numpy(shipped_site, browser, material):
    """The shipped materials that test_brdf_slice_equals_numpy_within_the_float32_bound leaves out, on llvmpipe's
    WebGL2 at 32² (about 6 s each here, most of it the shader's JIT): every shipped material is then covered there."""
    _slice_parity(shipped_site, browser, material, SHIPPED_SIZE)


@needs_browser
def test_a_single_file_page_opens_from_file_and_draws_what_the_folder_draws(site, browser, tmp_path):
    """``--single-file``: one index.html (script and binaries inside) opened from file:// gives the served folder's
    floats exactly, for a BRDF slice and a mesh render."""
    url, out = site
    single = tmp_path / "single"
    model = json.loads((out / "export.config.json").read_text(encoding="utf-8"))["materials"]["random-simple"]["model"]
    assert main(["export", model, "cd", "--format", "web", "--single-file", "--out", str(single), "--quiet"]) == 0
    assert sorted(path.name for path in single.iterdir()) == ["README.md", "export.config.json", "index.html"]
    queries = [f"?material=random-simple&slice=1&ui=0&size={SIZE}&light=30,20",
               f"?material=cd&mesh=sphere&ui=0&size={SIZE}"]
    # WebGPU: the slice, which loads the inline NAME.wgsl and weights; meshes.bin is inlined for both backends alike.
    for query in queries[:1] if browser[0] in PAGE_BACKEND else queries:
        with _page(browser, (single / "index.html").as_uri() + query) as page:
            assert page.evaluate("window.gratnetError") is None
            inline = _read(page)
        with _page(browser, url + query) as page:
            served = _read(page)
        assert np.abs(served).max() > 0
        np.testing.assert_array_equal(inline, served)


@needs_browser
@pytest.mark.parametrize("browser", WEBGL2_BROWSERS, indirect=True)
def test_without_parameters_the_page_takes_gratnet_renders_defaults(site, browser):
    from viewer.defaults import resolve_defaults

    url, _ = site
    for query, mesh, slice_mode in (("", "cd", False), ("?mesh=sphere", "sphere", False),
                                    ("?mesh=plane", "plane", False), ("?slice=1&size=8", "cd", True)):
        suffix = "&" if query else "?"
        small = "" if "size" in query else f"{suffix}size=8"  # keep the frame cheap; the size is not a default here
        with _page(browser, url + query + small) as page:
            config = page.evaluate("window.gratnetConfig")
        expected = resolve_defaults("cd", mesh, slice_mode=slice_mode)
        assert config["material"] == "cd" and config["slice"] is slice_mode
        assert config["light"] == [expected.light_theta_degrees, expected.light_phi_degrees]
        assert config["exposure"] == expected.exposure and config["ior"] == 1.5
        if not slice_mode:
            assert config["mesh"] == mesh
            assert config["camera"] == [expected.camera_distance, expected.camera_azimuth_degrees,
                                        expected.camera_elevation_degrees]


@needs_browser
@pytest.mark.parametrize("browser", WEBGL2_BROWSERS, indirect=True)
def test_a_mesh_render_is_drawn_and_ui_0_hides_the_panel(site, browser):
    url, _ = site
    with _page(browser, f"{url}?material=cd&mesh=cd&ui=0&size={SIZE},48") as page:
        image = _read(page)
        assert page.evaluate("document.getElementById('panel').hidden") is True
        frame_ms = page.evaluate("window.gratnetFrameMs")
    assert image.shape == (48, SIZE, 3) and np.all(np.isfinite(image))
    assert np.count_nonzero(image.max(axis=-1) > 0) > 50  # the disc is lit: not a black frame
    assert np.all(image[0, 0] == 0.0)  # the corner is background
    assert frame_ms > 0
    with _page(browser, f"{url}?mesh=sphere&size=16") as page:
        assert page.evaluate("document.getElementById('panel').hidden") is False
        assert page.evaluate("document.getElementById('frame-time').textContent").startswith("frame: ")


@needs_browser
def test_sliders_drag_wheel_and_mesh_picker_redraw(site, browser):
    url, _ = site
    with _page(browser, f"{url}?material=cd&mesh=plane&size=24") as page:
        before = page.evaluate("window.gratnetConfig")

        def change(selector: str, value: str) -> None:
            page.evaluate("([s, v]) => { const e = document.querySelector(s); e.value = v; "
                          "e.dispatchEvent(new Event('input')); }", [selector, value])

        change("#theta", "45")
        change("#phi", "-30")
        change("#exposure", "1")  # log10: exposure 10
        change("#ior", "2")
        page.wait_for_function("window.gratnetConfig.light[0] === 45 && window.gratnetConfig.ior === 2")
        after = page.evaluate("window.gratnetConfig")
        assert after["light"] == [45, -30] and abs(after["exposure"] - 10.0) < 1e-9
        box = page.locator("#view").bounding_box()
        page.mouse.move(box["x"] + 12, box["y"] + 12)
        page.mouse.down()
        page.mouse.move(box["x"] + 22, box["y"] + 2)
        page.mouse.up()
        page.mouse.wheel(0, 200)
        page.wait_for_function(f"window.gratnetConfig.camera[0] > {before['camera'][0]}")
        camera = page.evaluate("window.gratnetConfig.camera")
        assert camera[1] != before["camera"][1] and camera[2] != before["camera"][2]
        change("#mesh", "slice")
        page.wait_for_function("window.gratnetConfig.slice === true")
        assert "frame: " in page.evaluate("document.getElementById('frame-time').textContent")
        assert page.evaluate("window.gratnetError") is None


def _exr_rgb(path: Path) -> np.ndarray:
    import OpenEXR

    with OpenEXR.File(str(path)) as file:
        return np.asarray(file.parts[0].channels["RGB"].pixels, dtype=np.float64)


@needs_browser
@pytest.mark.parametrize(("browser", "material", "mesh"), [
    *((name, material, mesh) for name in WEBGL2_BROWSERS
      for material, mesh in (("cd", "cd"), ("cd", "sphere"), ("paper-cd", "cd"))),
    # Smith's shadowing of a steep relief (gratnet render's S · A: the page's gratnet_shade, not the unshadowed slice
    # value), through both backends' mesh shaders.
    ("llvmpipe", "paper-pits", "sphere"), ("webgpu", "paper-pits", "sphere"),
    ("webgpu", "cd", "cd")], indirect=["browser"])
def test_a_mesh_render_equals_gratnet_renders_exr_and_its_png_within_flip(site, browser, material, mesh, tmp_path):
    """The page's default view of a mesh against ``gratnet render`` of the same material and mesh (its defaults too):
    the linear floats against the EXR, the canvas against the PNG (LDR-FLIP ≤ 0.005, issue 44's target)."""
    import io

    from PIL import Image

    from gratnet.display import ldr_flip

    url, _ = site
    size = 64
    for suffix in ("exr", "png"):
        assert main(["render", "--material", material, "--mesh", mesh, "--size", f"{size},{size}", "--out",
                     str(tmp_path / f"render.{suffix}"), "--quiet"]) == 0
    with _page(browser, f"{url}?material={material}&mesh={mesh}&size={size}&ui=0") as page:
        linear = _read(page)
        shot = np.asarray(Image.open(io.BytesIO(page.locator("#view").screenshot())).convert("RGB"), np.float64)
    reference = _exr_rgb(tmp_path / "render.exr")
    peak = float(np.abs(reference).max())
    covered = reference.max(axis=-1) > 0, linear.max(axis=-1) > 0
    # The edges of the mesh may rasterize differently on another driver: at most 1 % of the covered pixels.
    assert np.count_nonzero(covered[0] ^ covered[1]) <= 0.01 * np.count_nonzero(covered[0])
    both = covered[0] & covered[1]
    over = np.abs(linear - reference)[both].max(axis=-1) > 1e-3 * peak
    # llvmpipe rasterizes as gratnet render's llvmpipe does: every pixel agrees, and FLIP meets issue 44's 0.005.
    # SwiftShader does not at this size: its interpolated and normalised directions differ, and on sharp diffraction
    # lines a slightly different key is a visibly different value (docs/export.md: 3.3 % of the sphere's pixels
    # beyond 10⁻³ of the peak, FLIP 0.010 on the CD at 64²; FLIP 0.002–0.004 at 256² and 512²). There the test holds
    # the measured level with a margin, a guard against getting worse, not the target.
    outliers, flip_target = MESH_TOLERANCE[browser[0]]
    assert np.count_nonzero(over) <= outliers * np.count_nonzero(both), (
        f"{mesh}: {np.count_nonzero(over)} of {np.count_nonzero(both)} pixels beyond 1e-3 of the peak")
    png = np.asarray(Image.open(tmp_path / "render.png").convert("RGB"), np.float64)
    assert shot.shape == png.shape
    flip, _ = ldr_flip(png / 255.0, shot / 255.0)
    assert flip <= flip_target, f"{mesh}: LDR-FLIP {flip:.4f}"



def _refused(browser, url: str) -> tuple[str, str]:
    """A page that refuses its URL: no picture on show and never ready; its error (window.gratnetError) and the line
    it shows."""
    with _page(browser, url) as page:
        error = page.evaluate("window.gratnetError")
        line = page.evaluate("document.getElementById('error').textContent")
        assert page.evaluate("document.getElementById('view').hidden") is True
        assert page.evaluate("window.gratnetReady") is None
    return error, line

@needs_browser
@pytest.mark.parametrize("browser", WEBGL2_BROWSERS, indirect=True)
@pytest.mark.parametrize(("query", "words"), [
    ("exposure=abc", "exposure=abc"), ("mesh=teapot", "mesh=teapot"), ("material=nothing", "material=nothing"),
    ("slice=1&size=64,32", "square"), ("camera=0,0,30", "camera distance"), ("colour=red", "unknown parameter"),
    ("backend=vulkan", "backend=vulkan"),
])
def test_a_bad_url_parameter_shows_one_line_and_no_picture(site, browser, query, words):
    url, _ = site
    error, line = _refused(browser, f"{url}?{query}")
    assert words in error and "\n" not in line and line.startswith("gratnet: ")


@needs_browser
@pytest.mark.parametrize("browser", WEBGL2_BROWSERS, indirect=True)
def test_backend_webgpu_in_a_browser_without_webgpu_shows_one_line(site, browser):
    """chromium without --enable-unsafe-webgpu offers no WebGPU adapter on Linux: the WebGL2 browsers show that."""
    url, _ = site
    error, line = _refused(browser, f"{url}?backend=webgpu&size=8")
    assert "no WebGPU" in error and "backend=webgl2" in error and "\n" not in line


def test_the_export_writes_each_materials_wgsl_module_and_grid_buffer(site):
    """The WebGPU backend's files are --format wgsl's: the module's text, the grid buffer, the shared weights."""
    from export.wgsl import wgsl_module

    _, out = site
    config = json.loads((out / "export.config.json").read_text(encoding="utf-8"))
    for name in ("cd", "paper-cd", "random-grid32"):
        entry = config["materials"][name]
        module = wgsl_module(load_model(entry["model"]), name)
        assert (out / entry["wgsl"]).read_text(encoding="utf-8") == module.text
        assert (out / entry["weights"]).read_bytes() == module.weights.astype("<f4").tobytes()
        if module.grids:
            assert (out / entry["wgsl_grids"]).read_bytes() == module.grids
        else:
            assert entry["wgsl_grids"] is None and name == "cd"


def test_a_feature_grid_export_describes_the_grid_textures_the_runtime_uploads(site):
    """Every grid texture, gathered from the one grid file as the page's gridChunk gathers it (the level's first
    element, its features per node, the chunk's first feature), is the texels viewer/renderer.py uploads
    (export/glsl.py's chunks); the grids are in the export once (the browser slices check the gather itself)."""
    from export.glsl import grid_chunks_of

    _, out = site
    config = json.loads((out / "export.config.json").read_text(encoding="utf-8"))
    for name in ("paper-cd", "paper-scratches", "random-grid16", "random-grid32"):
        entry = config["materials"][name]
        chunks = grid_chunks_of(load_model(entry["model"]))
        assert len(entry["grids"]) == len(chunks) > 0
        assert {grid["file"] for grid in entry["grids"]} == {entry["wgsl_grids"]}
        assert not list(out.glob(f"{name}.grid[0-9]*.bin"))  # no second copy
        for grid, chunk in zip(entry["grids"], chunks, strict=True):
            depth, height, width, channels = chunk.shape
            assert grid["texels"] == [width, height, depth] and grid["channels"] == channels
            values = np.frombuffer((out / grid["file"]).read_bytes(), dtype=np.dtype(grid["type"]).newbyteorder("<"))
            nodes = width * height * depth
            level = values[grid["offset"]:grid["offset"] + nodes * grid["features"]].reshape(nodes, grid["features"])
            gathered = level[:, grid["first"]:grid["first"] + grid["channels"]].reshape(chunk.shape)
            np.testing.assert_array_equal(gathered, chunk)


def test_too_many_grid_textures_for_webgl2_are_refused_in_one_line(tmp_path, capsys):
    """16 textures (4 levels of 16 features) beside the weights exceed WebGL2's guaranteed 16 samplers."""
    model_path = tmp_path / "wide.npz"
    model = random_grid_model(16, 3, "float16", "linear", seed=1)
    model.grids.append(model.grids[-1].copy())
    model.layer_sizes[0] += 16
    model.weights[0] = np.concatenate([model.weights[0], np.zeros((21, 16), np.float32)], axis=1)
    save_model(model_path, model)
    assert main(["export", str(model_path), "--format", "web", "--out", str(tmp_path / "site")]) == 2
    err = capsys.readouterr().err.strip()
    assert "16 grid textures" in err and "\n" not in err
    assert sorted(path.name for path in tmp_path.iterdir()) == ["wide.npz"]
