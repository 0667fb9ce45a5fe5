// The page's WebGPU backend (backend=webgpu): the material's WGSL module, exactly as `gratnet export --format wgsl`
// writes it (export/wgsl.py: NAME.wgsl, fetched, with NAME.weights.bin and a grid model's NAME.grids.bin as its
// read-only storage buffers in group 0), under the page's own small WGSL below (group 1: the frame's uniforms) in
// one shader module. A render pipeline with the module in the fragment stage: the meshes are rasterized as the
// WebGL2 backend rasterizes them (same vertex data, depth test, back faces culled), so the two differ only in the
// shader arithmetic. Shared scene, camera and UI code: gratnet.js (export/web.py puts this file before it).

// The page's WGSL after the module: twins of webgl2.js's SLICE_MAIN and SURFACE_MAIN (host code: pixel mapping and
// tangent frame); the model's arithmetic is the module's gratnet_shade (the mesh: with Smith's shadowing),
// gratnet_shade_unshadowed (the BRDF slice: without it) and xyz_to_linear_srgb. Names start with page_ so that they
// cannot meet the module's (u_*, g_*, gratnet_*, GRATNET_*, ...).
const PAGE_WGSL = `
struct PageFrame {
    view_projection: mat4x4<f32>,
    eye: vec3<f32>,
    exposure: f32,
    light: vec3<f32>,
    ior: f32,
    size: i32,
}
@group(1) @binding(0) var<uniform> page: PageFrame;

@vertex fn page_fullscreen(@builtin(vertex_index) index: u32) -> @builtin(position) vec4<f32> {
    let p = vec2<f32>(f32((index << 1u) & 2u), f32(index & 2u));
    return vec4<f32>(2.0 * p - 1.0, 0.0, 1.0);
}

// The BRDF slice (shaders/brdf_slice.glsl's pixel mapping), as linear sRGB: exposure · A · XYZ without Smith's
// shadowing, as the runtime's slice (the module's gratnet_shade_unshadowed). WebGPU counts pixel rows from the top,
// GL (whose mapping this is) from the bottom.
@fragment fn page_slice(@builtin(position) position: vec4<f32>) -> @location(0) vec4<f32> {
    let pixel = vec2<i32>(i32(position.x), page.size - 1 - i32(position.y));
    let p = vec2<f32>(2 * pixel + 1) / f32(page.size) - 1.0;
    let radius_squared = dot(p, p);
    if (!(radius_squared < 1.0)) {
        return vec4<f32>(0.0);
    }
    let wo = vec3<f32>(p, sqrt(max(1.0 - radius_squared, 0.0)));
    return vec4<f32>(xyz_to_linear_srgb(gratnet_shade_unshadowed(page.light, wo, page.ior, page.exposure)), 1.0);
}

struct PageVarying {
    @builtin(position) position: vec4<f32>,
    @location(0) world: vec3<f32>,
    @location(1) normal: vec3<f32>,
    @location(2) tangent: vec3<f32>,
}

@vertex fn page_surface_vertex(@location(0) position: vec3<f32>, @location(1) normal: vec3<f32>,
                               @location(2) tangent: vec3<f32>) -> PageVarying {
    var out: PageVarying;
    out.world = position;
    out.normal = normal;
    out.tangent = tangent;
    let clip = page.view_projection * vec4<f32>(position, 1.0);
    // gratnet.js's projection is GL's (depth -w..w); WebGPU clips depth to 0..w. x, y and w, which place the
    // pixels, stay as they are.
    out.position = vec4<f32>(clip.xy, 0.5 * (clip.z + clip.w), clip.w);
    return out;
}

fn page_arbitrary_tangent(n: vec3<f32>) -> vec3<f32> {
    let s = select(-1.0, 1.0, n.z >= 0.0);
    let a = -1.0 / (s + n.z);
    return normalize(vec3<f32>(1.0 + s * n.x * n.x * a, s * n.x * n.y * a, -s * n.x));
}

fn page_safe_normalize(v: vec3<f32>) -> vec3<f32> {
    let length_squared = dot(v, v);
    if (length_squared > 1e-30 && length_squared < 1e30) {
        return v * inverseSqrt(length_squared);
    }
    return vec3<f32>(0.0);
}

// shaders/surface.glsl's tangent frame for a directional light of irradiance 1, as linear sRGB: exposure · A · S ·
// XYZ with Smith's shadowing for the material's slope covariance, as gratnet render draws a mesh (gratnet_shade).
@fragment fn page_surface(in: PageVarying, @builtin(front_facing) front: bool) -> @location(0) vec4<f32> {
    let n = page_safe_normalize(in.normal);
    if (!front || all(n == vec3<f32>(0.0))) {
        return vec4<f32>(0.0, 0.0, 0.0, 1.0);
    }
    var t = in.tangent - dot(in.tangent, n) * n;
    if (dot(t, t) > 1e-12) {
        t = normalize(t);
    } else {
        t = page_arbitrary_tangent(n);
    }
    let world_to_tangent = transpose(mat3x3<f32>(t, cross(n, t), n));
    let wi = world_to_tangent * page.light;
    let wo = world_to_tangent * page_safe_normalize(page.eye - in.world);
    return vec4<f32>(xyz_to_linear_srgb(gratnet_shade(wi, wo, page.ior, page.exposure)), 1.0);
}
`;

// Linear sRGB -> display sRGB (clip, IEC 61966-2-1), as webgl2.js's DISPLAY_MAIN.
const PAGE_DISPLAY_WGSL = `
@group(0) @binding(0) var linear_frame: texture_2d<f32>;

@vertex fn fullscreen(@builtin(vertex_index) index: u32) -> @builtin(position) vec4<f32> {
    let p = vec2<f32>(f32((index << 1u) & 2u), f32(index & 2u));
    return vec4<f32>(2.0 * p - 1.0, 0.0, 1.0);
}

fn encode(linear: f32) -> f32 {
    let c = clamp(linear, 0.0, 1.0);
    return select(1.055 * pow(c, 1.0 / 2.4) - 0.055, 12.92 * c, c <= 0.0031308);
}

@fragment fn display(@builtin(position) position: vec4<f32>) -> @location(0) vec4<f32> {
    let linear = textureLoad(linear_frame, vec2<i32>(position.xy), 0).rgb;
    return vec4<f32>(encode(linear.r), encode(linear.g), encode(linear.b), 1.0);
}
`;

// The uniform buffer of PageFrame: view_projection 0-15, eye 16-18, exposure 19, light 20-22, ior 23, size 24
// (i32); 112 bytes (the struct's size, a multiple of its 16-byte alignment).
const FRAME_FLOATS = 28;

// One line for a shader module that does not compile (the first error, with its line in module + page WGSL).
async function compiledModule(device, code, what) {
  const module = device.createShaderModule({ code });
  const errors = (await module.getCompilationInfo()).messages.filter((message) => message.type === "error");
  if (errors.length > 0) {
    const first = errors[0];
    throw new Error(`${what}: WGSL compile failed at ${first.lineNum}:${first.linePos}: ${first.message.split("\n")[0]}`);
  }
  return module;
}

class WebGpuViewer {
  // The adapter, device and canvas context; one line (an Error) where this browser offers no WebGPU.
  static async create(meshData, state) {
    const adapter = navigator.gpu ? await navigator.gpu.requestAdapter() : null;
    if (!adapter) {
      throw new Error("backend=webgpu: this browser offers no WebGPU adapter (chromium on Linux: " +
        "--enable-unsafe-webgpu); use backend=webgl2");
    }
    const device = await adapter.requestDevice();
    // A lost device (its GPU process gone) draws nothing more: say so in one line rather than freeze the picture.
    device.lost.then((info) => fail(`WebGPU device lost: ${(info.message || info.reason).split("\n")[0]}`));
    const context = canvas.getContext("webgpu");
    if (!context) throw new Error("backend=webgpu: the canvas has no WebGPU context; use backend=webgl2");
    const viewer = new WebGpuViewer(device, context, meshData, state);
    await viewer.prepareDisplay();
    return viewer;
  }

  constructor(device, context, meshData, state) {
    this.device = device;
    this.context = context;
    this.state = state;
    this.format = navigator.gpu.getPreferredCanvasFormat();
    this.materials = {};  // name -> {slice, surface pipelines, group 0 (the module's buffers)}
    this.frameBuffer = device.createBuffer({ size: FRAME_FLOATS * 4, usage: GPUBufferUsage.UNIFORM | GPUBufferUsage.COPY_DST });
    // Group 0: the module's buffers (gratnet_weights, and gratnet_grids for a grid model); group 1: the frame.
    const storage = (binding) => ({ binding, visibility: GPUShaderStage.FRAGMENT, buffer: { type: "read-only-storage" } });
    this.moduleLayouts = [device.createBindGroupLayout({ entries: [storage(0)] }),
      device.createBindGroupLayout({ entries: [storage(0), storage(1)] })];
    this.frameLayout = device.createBindGroupLayout({ entries: [
      { binding: 0, visibility: GPUShaderStage.VERTEX | GPUShaderStage.FRAGMENT, buffer: { type: "uniform" } }] });
    this.frameGroup = device.createBindGroup({ layout: this.frameLayout,
      entries: [{ binding: 0, resource: { buffer: this.frameBuffer } }] });
    this.meshes = {};
    for (const name of MESHES) {
      const entry = EXPORT.meshes[name];
      const upload = (usage, array) => {
        const buffer = device.createBuffer({ size: array.byteLength, usage: usage | GPUBufferUsage.COPY_DST });
        device.queue.writeBuffer(buffer, 0, array);
        return buffer;
      };
      this.meshes[name] = {
        vertices: upload(GPUBufferUsage.VERTEX, new Float32Array(meshData, entry.vertex_offset, entry.vertex_count * 9)),
        indices: upload(GPUBufferUsage.INDEX, new Uint32Array(meshData, entry.index_offset, entry.index_count)),
        count: entry.index_count,
      };
    }
  }

  async prepareDisplay() {
    const device = this.device;
    this.context.configure({ device, format: this.format, alphaMode: "opaque" });
    const module = await compiledModule(device, PAGE_DISPLAY_WGSL, "display shader");
    this.displayLayout = device.createBindGroupLayout({ entries: [
      { binding: 0, visibility: GPUShaderStage.FRAGMENT, texture: { sampleType: "unfilterable-float" } }] });
    this.display = await device.createRenderPipelineAsync({
      layout: device.createPipelineLayout({ bindGroupLayouts: [this.displayLayout] }),
      vertex: { module, entryPoint: "fullscreen" },
      fragment: { module, entryPoint: "display", targets: [{ format: this.format }] },
      primitive: { topology: "triangle-list" },
    });
  }

  async material(name) {
    if (!this.materials[name]) {
      const device = this.device;
      const entry = EXPORT.materials[name];
      const storage = async (file) => {
        const bytes = await fetchBytes(file);
        const buffer = device.createBuffer({ size: bytes.byteLength, usage: GPUBufferUsage.STORAGE | GPUBufferUsage.COPY_DST });
        device.queue.writeBuffer(buffer, 0, bytes);
        return buffer;
      };
      const grids = Boolean(entry.wgsl_grids);
      const buffers = [await storage(entry.weights), ...(grids ? [await storage(entry.wgsl_grids)] : [])];
      const largest = Math.max(...buffers.map((buffer) => buffer.size));
      if (largest > device.limits.maxStorageBufferBindingSize) {
        throw new Error(`${name}: a ${largest}-byte buffer exceeds this device's storage buffer binding size ` +
          `(${device.limits.maxStorageBufferBindingSize})`);
      }
      const moduleLayout = this.moduleLayouts[grids ? 1 : 0];
      const group = device.createBindGroup({ layout: moduleLayout,
        entries: buffers.map((buffer, binding) => ({ binding, resource: { buffer } })) });
      const module = await compiledModule(device, (await fetchText(entry.wgsl)) + PAGE_WGSL, entry.wgsl);
      const layout = device.createPipelineLayout({ bindGroupLayouts: [moduleLayout, this.frameLayout] });
      const target = [{ format: "rgba32float" }];
      const [slice, surface] = await Promise.all([
        device.createRenderPipelineAsync({
          layout,
          vertex: { module, entryPoint: "page_fullscreen" },
          fragment: { module, entryPoint: "page_slice", targets: target },
          primitive: { topology: "triangle-list" },
        }),
        device.createRenderPipelineAsync({
          layout,
          vertex: {
            module, entryPoint: "page_surface_vertex",
            buffers: [{ arrayStride: 36, attributes: [0, 1, 2].map((location) => (
              { shaderLocation: location, offset: 12 * location, format: "float32x3" }))}],
          },
          fragment: { module, entryPoint: "page_surface", targets: target },
          // Back faces are black in gratnet render too (A = 0); counter-clockwise is front, as in WebGL2.
          primitive: { topology: "triangle-list", frontFace: "ccw", cullMode: "back" },
          depthStencil: { format: "depth24plus", depthWriteEnabled: true, depthCompare: "less" },
        }),
      ]);
      this.materials[name] = { group, slice, surface };
    }
    return this.materials[name];
  }

  resize(width, height) {
    if (this.linear && this.width === width && this.height === height) return;
    const device = this.device;
    this.width = width;
    this.height = height;
    canvas.width = width;
    canvas.height = height;
    this.linear = device.createTexture({ size: [width, height], format: "rgba32float",
      usage: GPUTextureUsage.RENDER_ATTACHMENT | GPUTextureUsage.COPY_SRC | GPUTextureUsage.TEXTURE_BINDING });
    this.depth = device.createTexture({ size: [width, height], format: "depth24plus",
      usage: GPUTextureUsage.RENDER_ATTACHMENT });
    this.rowBytes = Math.ceil((width * 16) / 256) * 256;  // copyTextureToBuffer's row alignment
    this.readback = device.createBuffer({ size: this.rowBytes * height, usage: GPUBufferUsage.MAP_READ | GPUBufferUsage.COPY_DST });
    this.displayGroup = device.createBindGroup({ layout: this.displayLayout,
      entries: [{ binding: 0, resource: this.linear.createView() }] });
    this.pixels = null;
  }

  // Draw the state into the linear target, read it back (readPixels() returns that copy) and show it on the canvas;
  // the frame's time in ms, to the whole frame's read-back.
  async draw(frame) {
    const device = this.device;
    const state = this.state;
    const material = await this.material(state.material);
    this.resize(state.width, state.height);
    const start = performance.now();
    device.pushErrorScope("validation");
    const values = new Float32Array(FRAME_FLOATS);
    if (frame.viewProjection) values.set(frame.viewProjection, 0);
    if (frame.eye) values.set(frame.eye, 16);
    values[19] = state.exposure;
    values.set(frame.light, 20);
    values[23] = state.ior;
    new Int32Array(values.buffer)[24] = state.width;
    device.queue.writeBuffer(this.frameBuffer, 0, values);
    const encoder = device.createCommandEncoder();
    const pass = encoder.beginRenderPass({
      colorAttachments: [{ view: this.linear.createView(), clearValue: [0, 0, 0, 0], loadOp: "clear", storeOp: "store" }],
      depthStencilAttachment: state.slice ? undefined
        : { view: this.depth.createView(), depthClearValue: 1, depthLoadOp: "clear", depthStoreOp: "discard" },
    });
    pass.setBindGroup(0, material.group);
    pass.setBindGroup(1, this.frameGroup);
    if (state.slice) {
      pass.setPipeline(material.slice);
      pass.draw(3);
    } else {
      const mesh = this.meshes[state.mesh];
      pass.setPipeline(material.surface);
      pass.setVertexBuffer(0, mesh.vertices);
      pass.setIndexBuffer(mesh.indices, "uint32");
      pass.drawIndexed(mesh.count);
    }
    pass.end();
    encoder.copyTextureToBuffer({ texture: this.linear }, { buffer: this.readback, bytesPerRow: this.rowBytes },
      [state.width, state.height]);
    const display = encoder.beginRenderPass({ colorAttachments: [
      { view: this.context.getCurrentTexture().createView(), clearValue: [0, 0, 0, 1], loadOp: "clear", storeOp: "store" }] });
    display.setPipeline(this.display);
    display.setBindGroup(0, this.displayGroup);
    display.draw(3);
    display.end();
    device.queue.submit([encoder.finish()]);
    const invalid = await device.popErrorScope();
    if (invalid) throw new Error(`WebGPU: ${invalid.message.split("\n")[0]}`);
    await this.readback.mapAsync(GPUMapMode.READ);
    const milliseconds = performance.now() - start;
    const mapped = new Float32Array(this.readback.getMappedRange());
    const rowFloats = this.rowBytes / 4;
    this.pixels = new Float32Array(state.width * state.height * 4);
    for (let row = 0; row < state.height; ++row) {  // WebGPU's rows, like the result's, count from the top
      this.pixels.set(mapped.subarray(row * rowFloats, row * rowFloats + state.width * 4), row * state.width * 4);
    }
    this.readback.unmap();
    return milliseconds;
  }

  readPixels() {
    const { width, height, pixels } = this;
    const data = new Array(width * height * 3);
    for (let pixel = 0; pixel < width * height; ++pixel) {
      for (let channel = 0; channel < 3; ++channel) data[pixel * 3 + channel] = pixels[pixel * 4 + channel];
    }
    return { width, height, data };
  }
}
