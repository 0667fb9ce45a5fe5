// Twin of shaders/featuregrid.glsl (learned feature grids, docs/physics.md eq. 6g), for a feature-grid model only
// (export/wgsl.py leaves this file out of a pure MLP's module and puts featuregrid_none.wgsl there instead).
//
// The grids are one storage buffer, `gratnet_grids` (array<u32>): level after level, each the model file's array
// (T, R_v, R_u, C) with its C features interleaved, x fastest, as float16 (two values a word, the first in the low
// half) or float32 (bit patterns). Level k starts at element GRID_OFFSET[k] and has GRID_NODES[k] = (R_u, R_v, T)
// nodes, node i of an axis of N at c = -1 + 2i/(N-1). GLSL reads the same values as 3D textures with texelFetch;
// a buffer needs no texture format for every channel count and one binding holds all levels.
//
// Interpolation: eight loads and float32 weights, exactly eq. 6g (GLSL's u_grid_hardware_filter = 0 path), after
// the smoothstep remap where the model asks for it (u_grid_smoothstep).

var<private> g_grid_features: array<f32, GRID_LEVELS * GRID_FEATURES>;  // level 0's C features first

// Element `index` of the grid buffer as float32.
fn grid_value(index: i32) -> f32 {
    if (GRID_FLOAT16) {
        return unpack2x16float(gratnet_grids[index >> 1u])[index & 1];
    }
    return bitcast<f32>(gratnet_grids[index]);
}

fn grid_level_features(level: i32, c: vec3<f32>) {
    let nodes = vec3<f32>(GRID_NODES[level]);
    var p = (clamp(c, vec3<f32>(-1.0), vec3<f32>(1.0)) + 1.0) * (0.5 * (nodes - 1.0));
    if (u_grid_smoothstep != 0) {
        let cell = clamp(floor(p), vec3<f32>(0.0), nodes - 2.0);
        let t = p - cell;
        p = cell + t * t * (3.0 - 2.0 * t);
    }
    let lower = clamp(floor(p), vec3<f32>(0.0), nodes - 2.0);  // the last cell includes its far end
    let f = p - lower;
    let g = 1.0 - f;
    let i = vec3<i32>(lower);
    let size = GRID_NODES[level];
    // Element of feature 0 at node (x, y, z): ((z * R_v + y) * R_u + x) * C, plus the level's offset.
    let base = GRID_OFFSET[level] + ((i.z * size.y + i.y) * size.x + i.x) * GRID_FEATURES;
    let dx = GRID_FEATURES;
    let dy = size.x * GRID_FEATURES;
    let dz = size.y * dy;
    // The corners and weights in featuregrid.glsl's order, so that each sum rounds as the GLSL one does.
    let w000 = g.z * g.y * g.x;
    let w100 = g.z * g.y * f.x;
    let w010 = g.z * f.y * g.x;
    let w110 = g.z * f.y * f.x;
    let w001 = f.z * g.y * g.x;
    let w101 = f.z * g.y * f.x;
    let w011 = f.z * f.y * g.x;
    let w111 = f.z * f.y * f.x;
    for (var k = 0; k < GRID_FEATURES; k++) {
        let e = base + k;
        var sum = w000 * grid_value(e);
        sum += w100 * grid_value(e + dx);
        sum += w010 * grid_value(e + dy);
        sum += w110 * grid_value(e + dx + dy);
        sum += w001 * grid_value(e + dz);
        sum += w101 * grid_value(e + dx + dz);
        sum += w011 * grid_value(e + dy + dz);
        sum += w111 * grid_value(e + dx + dy + dz);
        g_grid_features[level * GRID_FEATURES + k] = sum;
    }
}

// Every level's features at the network coordinates of the key set by encoding_set_key.
fn grid_set_key() {
    for (var level = 0; level < GRID_LEVELS; level++) {
        grid_level_features(level, g_coordinates);
    }
}

fn network_input_feature(f: i32) -> f32 {
    if (f < GRID_LEVELS * GRID_FEATURES) {
        return g_grid_features[f];
    }
    return encoded_feature(f - GRID_LEVELS * GRID_FEATURES);
}

// Input features 4*block ... 4*block+3 of the MLP: grid features, then the encoding.
fn network_input_block(block: i32) -> vec4<f32> {
    let f = 4 * block;
    return vec4<f32>(network_input_feature(f), network_input_feature(f + 1), network_input_feature(f + 2),
                     network_input_feature(f + 3));
}
