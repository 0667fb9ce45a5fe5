// GratNet's WebGL2 viewer, written by `gratnet export --format web` (docs/export.md, "The web page").
// EXPORT (the line above, written at export time): per material its GLSL ES module (the runtime's shaders/*.glsl
// through export/glsl.py), weight texture and the default views of gratnet render (viewer/defaults.py); the meshes'
// offsets in meshes.bin; gratnet render's size, field of view and IOR; the XYZ -> linear sRGB matrix. A feature-grid
// material also lists its grid files (u_grid[k]: NAME.grid<k>.bin, texels, channels, float16 or float32).
//
// URL parameters, with gratnet render's meanings: material=NAME, mesh=cd|sphere|plane, slice=1 (the BRDF slice),
// light=THETA,PHI (degrees), camera=DIST,AZIMUTH,ELEVATION (metres, degrees), exposure=X, ior=N (0: no Fresnel),
// size=N or W,H (pixels), ui=0 (the picture alone). A bad one: one line instead of the picture.
// For tests: window.gratnetReady (true once the first frame is drawn), window.gratnetReadPixels() (that frame's
// linear sRGB, exposure applied, before display encoding: {width, height, data} with rows top first, RGB floats),
// window.gratnetConfig (the resolved parameters), window.gratnetError (the one line, if any).

const canvas = document.getElementById("view");
const panel = document.getElementById("panel");
const MESHES = ["cd", "sphere", "plane"];
// Texture units: the weights 0, the linear target 1, a feature-grid material's u_grid[k] GRID_UNIT + k.
const GRID_UNIT = 2;
const PARAMETERS = ["material", "mesh", "slice", "light", "camera", "exposure", "ior", "size", "ui"];

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
  return { material, mesh, slice, ui, light, camera, exposure, ior, width, height };
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

const FULLSCREEN = `#version 300 es
void main() {
    vec2 p = vec2((gl_VertexID << 1) & 2, gl_VertexID & 2);
    gl_Position = vec4(2.0 * p - 1.0, 0.0, 1.0);
}`;

// The BRDF slice (shaders/brdf_slice.glsl's pixel mapping), as linear sRGB.
const SLICE_MAIN = `
uniform int u_size;
uniform vec3 u_light;
uniform float u_exposure;
uniform float u_ior;
out vec4 out_linear;
void main() {
    ivec2 pixel = ivec2(gl_FragCoord.xy);
    vec2 p = vec2(2 * pixel + 1) / float(u_size) - 1.0;
    float radius_squared = dot(p, p);
    if (!(radius_squared < 1.0)) {
        out_linear = vec4(0.0);
        return;
    }
    vec3 wo = vec3(p, sqrt(max(1.0 - radius_squared, 0.0)));
    out_linear = vec4(xyz_to_linear_srgb(gratnet_shade(u_light, wo, u_ior, u_exposure)), 1.0);
}`;

const SURFACE_VERTEX = `#version 300 es
in vec3 in_position;
in vec3 in_normal;
in vec3 in_tangent;
uniform mat4 u_view_projection;
out vec3 v_position;
out vec3 v_normal;
out vec3 v_tangent;
void main() {
    v_position = in_position;
    v_normal = in_normal;
    v_tangent = in_tangent;
    gl_Position = u_view_projection * vec4(in_position, 1.0);
}`;

// shaders/surface.glsl's tangent frame for a directional light of irradiance 1, as linear sRGB.
const SURFACE_MAIN = `
uniform vec3 u_eye;
uniform vec3 u_light;
uniform float u_exposure;
uniform float u_ior;
in vec3 v_position;
in vec3 v_normal;
in vec3 v_tangent;
out vec4 out_linear;
vec3 arbitrary_tangent(vec3 n) {
    float s = n.z >= 0.0 ? 1.0 : -1.0;
    float a = -1.0 / (s + n.z);
    return normalize(vec3(1.0 + s * n.x * n.x * a, s * n.x * n.y * a, -s * n.x));
}
vec3 safe_normalize(vec3 v) {
    float length_squared = dot(v, v);
    return length_squared > 1e-30 && length_squared < 1e30 ? v * inversesqrt(length_squared) : vec3(0.0);
}
void main() {
    out_linear = vec4(0.0, 0.0, 0.0, 1.0);
    vec3 n = safe_normalize(v_normal);
    if (!gl_FrontFacing || n == vec3(0.0)) {
        return;
    }
    vec3 t = v_tangent - dot(v_tangent, n) * n;
    t = dot(t, t) > 1e-12 ? normalize(t) : arbitrary_tangent(n);
    mat3 world_to_tangent = transpose(mat3(t, cross(n, t), n));
    vec3 wi = world_to_tangent * u_light;
    vec3 wo = world_to_tangent * safe_normalize(u_eye - v_position);
    out_linear = vec4(xyz_to_linear_srgb(gratnet_shade(wi, wo, u_ior, u_exposure)), 1.0);
}`;

// Linear sRGB -> display sRGB (clip, IEC 61966-2-1), as colour.glsl's srgb_encode.
const DISPLAY_MAIN = `#version 300 es
precision highp float;
uniform highp sampler2D u_linear;
out vec4 out_colour;
float encode(float linear) {
    float c = clamp(linear, 0.0, 1.0);
    return c <= 0.0031308 ? 12.92 * c : 1.055 * pow(c, 1.0 / 2.4) - 0.055;
}
void main() {
    vec3 linear = texelFetch(u_linear, ivec2(gl_FragCoord.xy), 0).rgb;
    out_colour = vec4(encode(linear.r), encode(linear.g), encode(linear.b), 1.0);
}`;

function compile(gl, vertex, fragment) {
  const program = gl.createProgram();
  for (const [kind, source] of [[gl.VERTEX_SHADER, vertex], [gl.FRAGMENT_SHADER, fragment]]) {
    const shader = gl.createShader(kind);
    gl.shaderSource(shader, source);
    gl.compileShader(shader);
    if (!gl.getShaderParameter(shader, gl.COMPILE_STATUS)) {
      throw new Error(`shader compile failed: ${gl.getShaderInfoLog(shader).split("\n")[0]}`);
    }
    gl.attachShader(program, shader);
  }
  gl.linkProgram(program);
  if (!gl.getProgramParameter(program, gl.LINK_STATUS)) throw new Error(`shader link failed: ${gl.getProgramInfoLog(program)}`);
  return program;
}

// A grid file as a 3D texture exactly as viewer/renderer.py uploads it (R/RG/RGB/RGBA, 16F or 32F, x fastest), with
// NEAREST filtering: featuregrid.glsl reads it with texelFetch only, and a 32F texture with a linear filter is
// incomplete (reads 0) without OES_texture_float_linear. No mipmaps; clamp to edge.
function gridTexture(gl, grid, bytes) {
  const half = grid.type === "float16";
  if (!half && grid.type !== "float32") throw new Error(`${grid.file}: unknown texel type ${grid.type}`);
  const [width, height, depth] = grid.texels;
  const channels = grid.channels;
  const expected = width * height * depth * channels * (half ? 2 : 4);
  if (bytes.byteLength !== expected) throw new Error(`${grid.file}: ${bytes.byteLength} bytes, expected ${expected}`);
  const format = [gl.RED, gl.RG, gl.RGB, gl.RGBA][channels - 1];
  const internal = half ? [gl.R16F, gl.RG16F, gl.RGB16F, gl.RGBA16F][channels - 1]
    : [gl.R32F, gl.RG32F, gl.RGB32F, gl.RGBA32F][channels - 1];
  const texture = gl.createTexture();
  gl.bindTexture(gl.TEXTURE_3D, texture);
  gl.texStorage3D(gl.TEXTURE_3D, 1, internal, width, height, depth);
  gl.pixelStorei(gl.UNPACK_ALIGNMENT, 1);  // rows of an odd width of R16F are not 4-byte aligned
  gl.texSubImage3D(gl.TEXTURE_3D, 0, 0, 0, 0, width, height, depth, format, half ? gl.HALF_FLOAT : gl.FLOAT,
    half ? new Uint16Array(bytes) : new Float32Array(bytes));
  gl.pixelStorei(gl.UNPACK_ALIGNMENT, 4);
  gl.texParameteri(gl.TEXTURE_3D, gl.TEXTURE_MIN_FILTER, gl.NEAREST);
  gl.texParameteri(gl.TEXTURE_3D, gl.TEXTURE_MAG_FILTER, gl.NEAREST);
  for (const wrap of [gl.TEXTURE_WRAP_S, gl.TEXTURE_WRAP_T, gl.TEXTURE_WRAP_R]) {
    gl.texParameteri(gl.TEXTURE_3D, wrap, gl.CLAMP_TO_EDGE);
  }
  return texture;
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

class Viewer {
  constructor(gl, meshData, state) {
    this.gl = gl;
    this.state = state;
    this.materials = {};  // name -> {slice, surface programs, weights texture}
    this.display = compile(gl, FULLSCREEN, DISPLAY_MAIN);
    this.empty = gl.createVertexArray();
    this.meshes = {};
    for (const name of MESHES) {
      const entry = EXPORT.meshes[name];
      const vertexArray = gl.createVertexArray();
      gl.bindVertexArray(vertexArray);
      const vertices = gl.createBuffer();
      gl.bindBuffer(gl.ARRAY_BUFFER, vertices);
      gl.bufferData(gl.ARRAY_BUFFER, new Float32Array(meshData, entry.vertex_offset, entry.vertex_count * 9), gl.STATIC_DRAW);
      for (let attribute = 0; attribute < 3; ++attribute) {
        gl.enableVertexAttribArray(attribute);
        gl.vertexAttribPointer(attribute, 3, gl.FLOAT, false, 36, 12 * attribute);
      }
      const indices = gl.createBuffer();
      gl.bindBuffer(gl.ELEMENT_ARRAY_BUFFER, indices);
      gl.bufferData(gl.ELEMENT_ARRAY_BUFFER, new Uint32Array(meshData, entry.index_offset, entry.index_count), gl.STATIC_DRAW);
      this.meshes[name] = { vertexArray, count: entry.index_count };
    }
    gl.bindVertexArray(null);
  }

  async material(name) {
    if (!this.materials[name]) {
      const gl = this.gl;
      const entry = EXPORT.materials[name];
      const weights = new Float32Array(await fetchBytes(entry.weights));
      const texture = gl.createTexture();
      gl.activeTexture(gl.TEXTURE0);
      gl.bindTexture(gl.TEXTURE_2D, texture);
      gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_MIN_FILTER, gl.NEAREST);
      gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_MAG_FILTER, gl.NEAREST);
      gl.texImage2D(gl.TEXTURE_2D, 0, gl.RGBA32F, entry.texels[0], entry.texels[1], 0, gl.RGBA, gl.FLOAT, weights);
      const grids = entry.grids ?? [];
      if (1 + grids.length > gl.getParameter(gl.MAX_TEXTURE_IMAGE_UNITS)) {
        throw new Error(`${name} needs ${grids.length} grid textures and its weights: more than this browser's ` +
          `${gl.getParameter(gl.MAX_TEXTURE_IMAGE_UNITS)} samplers per shader`);
      }
      const gridTextures = [];
      for (const [k, grid] of grids.entries()) {
        gl.activeTexture(gl.TEXTURE0 + GRID_UNIT + k);
        gridTextures.push(gridTexture(gl, grid, await fetchBytes(grid.file)));
      }
      gl.activeTexture(gl.TEXTURE0);
      const header = "#version 300 es\n" + entry.shader;
      const surface = compile(gl, SURFACE_VERTEX, header + SURFACE_MAIN);
      for (const [index, attribute] of ["in_position", "in_normal", "in_tangent"].entries()) {
        gl.bindAttribLocation(surface, index, attribute);
      }
      gl.linkProgram(surface);  // again, with the attribute locations the vertex arrays use
      this.materials[name] = { texture, gridTextures, slice: compile(gl, FULLSCREEN, header + SLICE_MAIN), surface };
    }
    return this.materials[name];
  }

  resize(width, height) {
    const gl = this.gl;
    if (this.target && this.width === width && this.height === height) return;
    this.width = width;
    this.height = height;
    canvas.width = width;
    canvas.height = height;
    this.linear = gl.createTexture();
    gl.activeTexture(gl.TEXTURE1);
    gl.bindTexture(gl.TEXTURE_2D, this.linear);
    gl.texStorage2D(gl.TEXTURE_2D, 1, gl.RGBA32F, width, height);
    // NEAREST: a float32 texture with a linear filter is incomplete without OES_texture_float_linear (reads 0).
    gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_MIN_FILTER, gl.NEAREST);
    gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_MAG_FILTER, gl.NEAREST);
    const depth = gl.createRenderbuffer();
    gl.bindRenderbuffer(gl.RENDERBUFFER, depth);
    gl.renderbufferStorage(gl.RENDERBUFFER, gl.DEPTH_COMPONENT24, width, height);
    this.target = gl.createFramebuffer();
    gl.bindFramebuffer(gl.FRAMEBUFFER, this.target);
    gl.framebufferTexture2D(gl.FRAMEBUFFER, gl.COLOR_ATTACHMENT0, gl.TEXTURE_2D, this.linear, 0);
    gl.framebufferRenderbuffer(gl.FRAMEBUFFER, gl.DEPTH_ATTACHMENT, gl.RENDERBUFFER, depth);
    if (gl.checkFramebufferStatus(gl.FRAMEBUFFER) !== gl.FRAMEBUFFER_COMPLETE) {
      throw new Error("this browser cannot render into a float (RGBA32F) framebuffer");
    }
  }

  // Draw the state into the linear target, then to the canvas; the frame's time in ms (to a 1-pixel read-back:
  // gl.finish returns at once on some drivers).
  async draw() {
    const gl = this.gl;
    const state = this.state;
    const material = await this.material(state.material);
    this.resize(state.width, state.height);
    const start = performance.now();
    const light = direction(state.light[0], state.light[1]);
    gl.bindFramebuffer(gl.FRAMEBUFFER, this.target);
    gl.viewport(0, 0, state.width, state.height);
    gl.clearColor(0, 0, 0, 0);
    gl.clear(gl.COLOR_BUFFER_BIT | gl.DEPTH_BUFFER_BIT);
    gl.activeTexture(gl.TEXTURE0);
    gl.bindTexture(gl.TEXTURE_2D, material.texture);
    for (const [k, grid] of material.gridTextures.entries()) {
      gl.activeTexture(gl.TEXTURE0 + GRID_UNIT + k);
      gl.bindTexture(gl.TEXTURE_3D, grid);
    }
    const program = state.slice ? material.slice : material.surface;
    gl.useProgram(program);
    const set = (name, kind, ...values) => gl[`uniform${kind}`](gl.getUniformLocation(program, name), ...values);
    set("u_weights", "1i", 0);
    if (material.gridTextures.length > 0) {  // u_grid[k] on unit GRID_UNIT + k (u_grid_* are the module's constants)
      set("u_grid[0]", "1iv", material.gridTextures.map((_, k) => GRID_UNIT + k));
    }
    set("u_light", "3f", ...light);
    set("u_exposure", "1f", state.exposure);
    set("u_ior", "1f", state.ior);
    let eye = null;
    if (state.slice) {
      set("u_size", "1i", state.width);
      gl.bindVertexArray(this.empty);
      gl.drawArrays(gl.TRIANGLES, 0, 3);
    } else {
      const matrices = cameraMatrices(state.camera, EXPORT.render.fov, state.width / state.height);
      eye = matrices.eye;
      gl.uniformMatrix4fv(gl.getUniformLocation(program, "u_view_projection"), false, matrices.viewProjection);
      set("u_eye", "3f", ...eye);
      gl.enable(gl.DEPTH_TEST);
      gl.enable(gl.CULL_FACE);  // back faces are black in gratnet render too (A = 0)
      const mesh = this.meshes[state.mesh];
      gl.bindVertexArray(mesh.vertexArray);
      gl.drawElements(gl.TRIANGLES, mesh.count, gl.UNSIGNED_INT, 0);
      gl.disable(gl.DEPTH_TEST);
      gl.disable(gl.CULL_FACE);
    }
    gl.readPixels(0, 0, 1, 1, gl.RGBA, gl.FLOAT, new Float32Array(4));
    const milliseconds = performance.now() - start;
    gl.bindFramebuffer(gl.FRAMEBUFFER, null);
    gl.useProgram(this.display);
    gl.activeTexture(gl.TEXTURE1);
    gl.bindTexture(gl.TEXTURE_2D, this.linear);
    gl.uniform1i(gl.getUniformLocation(this.display, "u_linear"), 1);
    gl.bindVertexArray(this.empty);
    gl.drawArrays(gl.TRIANGLES, 0, 3);
    window.gratnetConfig = { ...state, light_vector: Array.from(new Float32Array(light)), eye };
    return milliseconds;
  }

  readPixels() {
    const gl = this.gl;
    const { width, height } = this;
    const rgba = new Float32Array(width * height * 4);
    gl.bindFramebuffer(gl.FRAMEBUFFER, this.target);
    gl.readPixels(0, 0, width, height, gl.RGBA, gl.FLOAT, rgba);
    gl.bindFramebuffer(gl.FRAMEBUFFER, null);
    const data = new Array(width * height * 3);
    for (let row = 0; row < height; ++row) {  // GL rows count from the bottom; the result's from the top
      for (let column = 0; column < width; ++column) {
        for (let channel = 0; channel < 3; ++channel) {
          data[(row * width + column) * 3 + channel] = rgba[((height - 1 - row) * width + column) * 4 + channel];
        }
      }
    }
    return { width, height, data };
  }
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
  const gl = canvas.getContext("webgl2", { antialias: false, preserveDrawingBuffer: true });
  if (!gl) { fail("this browser has no WebGL2"); return; }
  if (!gl.getExtension("EXT_color_buffer_float")) { fail("this browser cannot render into float textures (EXT_color_buffer_float)"); return; }
  try {
    const viewer = new Viewer(gl, await fetchBytes("meshes.bin"), state);
    let pending = false;
    const frameTime = document.getElementById("frame-time");
    const redraw = () => {
      if (pending) return;
      pending = true;
      requestAnimationFrame(async () => {
        pending = false;
        try {
          frameTime.textContent = `frame: ${(await viewer.draw()).toFixed(1)} ms (${state.width}×${state.height})`;
        } catch (error) {
          fail(error.message);
        }
      });
    };
    const milliseconds = await viewer.draw();
    frameTime.textContent = `frame: ${milliseconds.toFixed(1)} ms (${state.width}×${state.height})`;
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
