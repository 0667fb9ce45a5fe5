// GratNet's web viewer, written by `gratnet export --format web` (docs/export.md, "The web page"): the scene, camera,
// URL parameters and panel shared by its two backends, webgl2.js (WebGL2, the default) and webgpu.js (WebGPU), which
// export/web.py puts before this file in the exported gratnet.js. Each backend is a class with create(meshData,
// state) (async), draw(frame) -> milliseconds and readPixels() -> {width, height, data}.
// EXPORT (the first line, written at export time): per material its GLSL ES module (the runtime's shaders/*.glsl
// through export/glsl.py), its WGSL module file (export/wgsl.py), weights and the default views of gratnet render
// (viewer/defaults.py); the meshes' offsets in meshes.bin; gratnet render's size, field of view and IOR; the XYZ ->
// linear sRGB matrix. A feature-grid material also lists its grid files (WebGL2: u_grid[k], NAME.grid<k>.bin, texels,
// channels, float16 or float32; WebGPU: NAME.grids.bin, every level in one storage buffer).
//
// URL parameters, with gratnet render's meanings: material=NAME, mesh=cd|sphere|plane, slice=1 (the BRDF slice),
// light=THETA,PHI (degrees), camera=DIST,AZIMUTH,ELEVATION (metres, degrees), exposure=X, ior=N (0: no Fresnel),
// size=N or W,H (pixels), ui=0 (the picture alone), backend=webgl2|webgpu. A bad one, or a backend this browser
// lacks: one line instead of the picture.
// For tests: window.gratnetReady (true once the first frame is drawn), window.gratnetReadPixels() (that frame's
// linear sRGB, exposure applied, before display encoding: {width, height, data} with rows top first, RGB floats),
// window.gratnetConfig (the resolved parameters), window.gratnetError (the one line, if any).

const canvas = document.getElementById("view");
const panel = document.getElementById("panel");
const MESHES = ["cd", "sphere", "plane"];
const BACKENDS = ["webgl2", "webgpu"];
const PARAMETERS = ["material", "mesh", "slice", "light", "camera", "exposure", "ior", "size", "ui", "backend"];

function fail(message) {
  const line = document.getElementById("error");
  line.textContent = `gratnet: ${message}`;
  line.hidden = false;
  canvas.hidden = true;
  panel.hidden = true;
  window.gratnetError = message;
}

function numbers(text, count, name, form) {
  const parts = text.split(",");
  const values = parts.map((part) => (part.trim() === "" ? NaN : Number(part)));
  if (!count.includes(parts.length) || values.some((value) => !Number.isFinite(value))) {
    throw new Error(`${name}=${text}: expected ${form}`);
  }
  return values;
}

// The parameters of the URL, checked as gratnet render checks its flags; the defaults of the chosen view.
function parseParameters(search) {
  const query = new URLSearchParams(search);
  for (const key of query.keys()) {
    if (!PARAMETERS.includes(key)) throw new Error(`unknown parameter ${key} (known: ${PARAMETERS.join(", ")})`);
  }
  const names = Object.keys(EXPORT.materials);
  const material = query.get("material") ?? names[0];
  if (!names.includes(material)) throw new Error(`material=${material}: not in this export (${names.join(", ")})`);
  const mesh = query.get("mesh") ?? "cd";
  if (!MESHES.includes(mesh)) throw new Error(`mesh=${mesh}: choose ${MESHES.join(", ")}`);
  const flag = (key) => {
    const value = query.get(key) ?? (key === "ui" ? "1" : "0");
    if (value !== "0" && value !== "1") throw new Error(`${key}=${value}: expected 0 or 1`);
    return value === "1";
  };
  const slice = flag("slice");
  const ui = flag("ui");
  const view = EXPORT.materials[material].defaults[slice ? "slice" : mesh];
  const light = query.has("light") ? numbers(query.get("light"), [2], "light", "THETA,PHI in degrees") : view.light;
  const camera = query.has("camera")
    ? numbers(query.get("camera"), [3], "camera", "DIST,AZIMUTH,ELEVATION (metres, degrees)") : view.camera;
  if (!(camera[0] > 0)) throw new Error(`camera distance must be > 0 metres, got ${camera[0]}`);
  if (!(camera[2] >= -90 && camera[2] <= 90)) throw new Error(`camera elevation must be in -90 … 90, got ${camera[2]}`);
  const exposure = query.has("exposure") ? numbers(query.get("exposure"), [1], "exposure", "a number")[0] : view.exposure;
  if (!(exposure > 0)) throw new Error(`exposure must be > 0, got ${exposure}`);
  const ior = query.has("ior") ? numbers(query.get("ior"), [1], "ior", "a number")[0] : EXPORT.render.ior;
  if (!(ior >= 0)) throw new Error(`ior must be ≥ 0 (0: no Fresnel), got ${ior}`);
  const size = query.has("size") ? numbers(query.get("size"), [1, 2], "size", "N or W,H in pixels") : EXPORT.render.size;
  const [width, height] = size.length === 1 ? [size[0], size[0]] : size;
  for (const side of [width, height]) {
    if (!Number.isInteger(side) || side < 1 || side > 4096) throw new Error(`size sides must be integers in 1 … 4096`);
  }
  if (slice && width !== height) throw new Error(`slice=1 renders a square image; give size=N (got ${width},${height})`);
  const backend = query.get("backend") ?? "webgl2";
  if (!BACKENDS.includes(backend)) throw new Error(`backend=${backend}: choose ${BACKENDS.join(", ")}`);
  return { material, mesh, slice, ui, light, camera, exposure, ior, width, height, backend };
}

// Unit vector at polar angle theta from +z and azimuth phi from +x (degrees), exact at multiples of 90° (as
// gratnet.brdf.direction).
function cosSin(degrees) {
  const quarter = degrees / 90;
  if (Number.isInteger(quarter)) return [[1, 0], [0, 1], [-1, 0], [0, -1]][((quarter % 4) + 4) % 4];
  const radians = (degrees * Math.PI) / 180;
  return [Math.cos(radians), Math.sin(radians)];
}

function direction(theta, phi) {
  const [ct, st] = cosSin(theta);
  const [cp, sp] = cosSin(phi);
  return [st * cp, st * sp, ct];
}

// viewer/camera.py's orbit camera, as column-major matrices.
function cameraMatrices(camera, fov, aspect) {
  const [distance, azimuth, elevation] = camera;
  const [ca, sa] = cosSin(azimuth);
  const [ce, se] = cosSin(elevation);
  const eye = [distance * ce * ca, distance * ce * sa, distance * se];
  const up = [-se * ca, -se * sa, ce];
  const f = eye.map((value) => -value / distance);  // towards the target (the origin)
  const cross = (a, b) => [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];
  const dot = (a, b) => a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
  const normalize = (a) => a.map((value) => value / Math.hypot(...a));
  const s = normalize(cross(f, up));
  const u = cross(s, f);
  const view = [s[0], u[0], -f[0], 0, s[1], u[1], -f[1], 0, s[2], u[2], -f[2], 0, -dot(s, eye), -dot(u, eye), dot(f, eye), 1];
  const near = distance / 100;
  const far = distance * 100;
  const t = 1 / Math.tan((fov * Math.PI) / 360);
  const projection = [t / aspect, 0, 0, 0, 0, t, 0, 0, 0, 0, (far + near) / (near - far), -1, 0, 0, (2 * far * near) / (near - far), 0];
  const product = new Float32Array(16);
  for (let column = 0; column < 4; ++column) {
    for (let row = 0; row < 4; ++row) {
      let sum = 0;
      for (let k = 0; k < 4; ++k) sum += projection[k * 4 + row] * view[column * 4 + k];
      product[column * 4 + row] = sum;
    }
  }
  return { eye, viewProjection: product };
}

// What both backends draw from: the light as the float32 vector the shader gets, and for a mesh the eye and the
// view-projection matrix (GL clip space; webgpu.js maps its depth).
function sceneFrame(state) {
  const light = new Float32Array(direction(state.light[0], state.light[1]));
  if (state.slice) return { light, eye: null, viewProjection: null };
  const { eye, viewProjection } = cameraMatrices(state.camera, EXPORT.render.fov, state.width / state.height);
  return { light, eye, viewProjection };
}

// Draw the state with the backend; window.gratnetConfig as drawn; the frame's time in ms.
async function drawFrame(viewer) {
  const state = viewer.state;
  const frame = sceneFrame(state);
  const milliseconds = await viewer.draw(frame);
  window.gratnetConfig = { ...state, light_vector: Array.from(frame.light), eye: frame.eye };
  return milliseconds;
}

async function fetchBytes(name) {
  if (EXPORT.inline && name in EXPORT.inline) {  // a single-file page (gratnet export --single-file): no fetch
    const text = atob(EXPORT.inline[name]);
    const bytes = new Uint8Array(text.length);
    for (let i = 0; i < text.length; i++) bytes[i] = text.charCodeAt(i);
    return bytes.buffer;
  }
  const response = await fetch(name);
  if (!response.ok) throw new Error(`cannot load ${name}: HTTP ${response.status}`);
  return response.arrayBuffer();
}

async function fetchText(name) {
  return new TextDecoder().decode(await fetchBytes(name));
}

function bindPanel(viewer, redraw) {
  const state = viewer.state;
  const select = document.getElementById("material");
  for (const name of Object.keys(EXPORT.materials)) select.add(new Option(name, name));
  const controls = {
    material: [select, () => state.material, (value) => { state.material = value; }],
    mesh: [document.getElementById("mesh"), () => (state.slice ? "slice" : state.mesh),
      (value) => { state.slice = value === "slice"; if (!state.slice) state.mesh = value; }],
    theta: [document.getElementById("theta"), () => state.light[0], (value) => { state.light[0] = Number(value); }],
    phi: [document.getElementById("phi"), () => state.light[1], (value) => { state.light[1] = Number(value); }],
    exposure: [document.getElementById("exposure"), () => Math.log10(state.exposure),
      (value) => { state.exposure = 10 ** Number(value); }],
    ior: [document.getElementById("ior"), () => state.ior, (value) => { state.ior = Number(value); }],
  };
  const show = () => {
    for (const [name, [element, get]] of Object.entries(controls)) {
      element.value = get();
      const label = document.getElementById(`${name}-value`);
      if (label) label.textContent = name === "exposure" ? state.exposure.toPrecision(3) : Number(get()).toFixed(name === "ior" ? 2 : 1);
    }
  };
  for (const [element, , put] of Object.values(controls)) {
    element.addEventListener("input", () => { put(element.value); show(); redraw(); });
  }
  let drag = null;
  canvas.addEventListener("pointerdown", (event) => { drag = [event.clientX, event.clientY]; canvas.setPointerCapture(event.pointerId); });
  canvas.addEventListener("pointerup", () => { drag = null; });
  canvas.addEventListener("pointermove", (event) => {
    if (!drag || state.slice) return;
    state.camera[1] -= 0.3 * (event.clientX - drag[0]);
    state.camera[2] = Math.max(-90, Math.min(90, state.camera[2] + 0.3 * (event.clientY - drag[1])));
    drag = [event.clientX, event.clientY];
    redraw();
  });
  canvas.addEventListener("wheel", (event) => {
    event.preventDefault();
    state.camera[0] *= Math.exp(0.001 * event.deltaY);
    redraw();
  }, { passive: false });
  show();
}

async function main() {
  let state;
  try {
    state = parseParameters(location.search);
  } catch (error) {
    fail(error.message);
    return;
  }
  try {
    const meshData = await fetchBytes("meshes.bin");
    const viewer = state.backend === "webgpu" ? await WebGpuViewer.create(meshData, state)
      : WebGl2Viewer.create(meshData, state);
    const frameTime = document.getElementById("frame-time");
    const show = (milliseconds) => {
      frameTime.textContent = `frame: ${milliseconds.toFixed(1)} ms (${state.width}×${state.height}, ${state.backend})`;
    };
    // One draw at a time (a WebGPU frame awaits its read-back); input during a draw queues one more.
    let pending = false;
    let drawing = Promise.resolve();
    const redraw = () => {
      if (pending) return;
      pending = true;
      requestAnimationFrame(() => {
        drawing = drawing.then(async () => {
          pending = false;
          try {
            show(await drawFrame(viewer));
          } catch (error) {
            fail(error.message);
          }
        });
      });
    };
    const milliseconds = await drawFrame(viewer);
    show(milliseconds);
    window.gratnetReadPixels = () => viewer.readPixels();
    window.gratnetFrameMs = milliseconds;
    window.gratnetReady = true;
    if (state.ui) {
      panel.hidden = false;
      bindPanel(viewer, redraw);
    }
  } catch (error) {
    fail(error.message);
  }
}

main();
