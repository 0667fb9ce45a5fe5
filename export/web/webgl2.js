// The page's WebGL2 backend (backend=webgl2, the default): the material's GLSL ES module (export/glsl.py through
// export/web.py's ES_HEADER) in a fragment shader, its weights and grids as textures. Shared scene, camera and UI
// code: gratnet.js (export/web.py puts this file before it in the exported gratnet.js).

// Texture units: the weights 0, the linear target 1, a feature-grid material's u_grid[k] GRID_UNIT + k.
const GRID_UNIT = 2;

const FULLSCREEN = `#version 300 es
void main() {
    vec2 p = vec2((gl_VertexID << 1) & 2, gl_VertexID & 2);
    gl_Position = vec4(2.0 * p - 1.0, 0.0, 1.0);
}`;

// The BRDF slice (shaders/brdf_slice.glsl's pixel mapping), as linear sRGB: exposure · A · XYZ without Smith's
// shadowing, as the runtime's slice (the module's gratnet_shade_unshadowed).
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
    out_linear = vec4(xyz_to_linear_srgb(gratnet_shade_unshadowed(u_light, wo, u_ior, u_exposure)), 1.0);
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

// shaders/surface.glsl's tangent frame for a directional light of irradiance 1, as linear sRGB: exposure · A · S ·
// XYZ with Smith's shadowing for the material's slope covariance, as gratnet render draws a mesh (gratnet_shade).
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

// One grid texture's texels gathered from the material's grid file (export/wgsl.py's buffer, shared with the WebGPU
// backend: each level's (T, R, R, C) array in turn): features first … first + channels − 1 of every node of the level
// that starts at element `offset`, x fastest, as viewer/renderer.py uploads a chunk.
function gridChunk(grid, buffer) {
  const half = grid.type === "float16";
  if (!half && grid.type !== "float32") throw new Error(`${grid.file}: unknown texel type ${grid.type}`);
  const [width, height, depth] = grid.texels;
  const nodes = width * height * depth;
  const all = half ? new Uint16Array(buffer) : new Float32Array(buffer);
  if (grid.offset + nodes * grid.features > all.length) {
    throw new Error(`${grid.file}: ${all.length} values, a level needs ${grid.offset + nodes * grid.features}`);
  }
  const chunk = half ? new Uint16Array(nodes * grid.channels) : new Float32Array(nodes * grid.channels);
  for (let node = 0; node < nodes; node++) {
    const from = grid.offset + node * grid.features + grid.first;
    for (let c = 0; c < grid.channels; c++) chunk[node * grid.channels + c] = all[from + c];
  }
  return chunk.buffer;
}

// A grid chunk as a 3D texture exactly as viewer/renderer.py uploads it (R/RG/RGB/RGBA, 16F or 32F, x fastest), with
// NEAREST filtering: featuregrid.glsl reads it with texelFetch only, and a 32F texture with a linear filter is
// incomplete (reads 0) without OES_texture_float_linear. No mipmaps; clamp to edge.
function gridTexture(gl, grid, bytes) {
  const half = grid.type === "float16";
  const [width, height, depth] = grid.texels;
  const channels = grid.channels;
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

class WebGl2Viewer {
  // The WebGL2 context of the page's canvas; one line (an Error) where the browser lacks what the page needs.
  static create(meshData, state) {
    const gl = canvas.getContext("webgl2", { antialias: false, preserveDrawingBuffer: true });
    if (!gl) throw new Error("this browser has no WebGL2");
    if (!gl.getExtension("EXT_color_buffer_float")) {
      throw new Error("this browser cannot render into float textures (EXT_color_buffer_float)");
    }
    return new WebGl2Viewer(gl, meshData, state);
  }

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
      const gridFiles = {};  // one fetch of the material's grid file for all its textures
      for (const [k, grid] of grids.entries()) {
        gridFiles[grid.file] ??= await fetchBytes(grid.file);
        gl.activeTexture(gl.TEXTURE0 + GRID_UNIT + k);
        gridTextures.push(gridTexture(gl, grid, gridChunk(grid, gridFiles[grid.file])));
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
  // gl.finish returns at once on some drivers). frame: gratnet.js's sceneFrame (light, eye, view-projection).
  async draw(frame) {
    const gl = this.gl;
    const state = this.state;
    const material = await this.material(state.material);
    this.resize(state.width, state.height);
    const start = performance.now();
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
    set("u_light", "3f", ...frame.light);
    set("u_exposure", "1f", state.exposure);
    set("u_ior", "1f", state.ior);
    if (state.slice) {
      set("u_size", "1i", state.width);
      gl.bindVertexArray(this.empty);
      gl.drawArrays(gl.TRIANGLES, 0, 3);
    } else {
      gl.uniformMatrix4fv(gl.getUniformLocation(program, "u_view_projection"), false, frame.viewProjection);
      set("u_eye", "3f", ...frame.eye);
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
