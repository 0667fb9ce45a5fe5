// Twin of shaders/mlp.glsl (the funnel MLP; docs/formats.md, "Weight texture layout"), reading its weights as
// mlp.glsl's WEIGHTS_SSBO form does: `gratnet_weights` holds the packed texture's RGBA32F texels row-major,
// u_weights_width texels a row. Each step multiplies a mat4x4 of four texels by a vec4, as the GLSL does.
//
// u_layer_count and u_layers bound the loops. They are private variables that gratnet_set_layers() (entry.wgsl)
// fills from the generated constants plus a zero the compiler cannot see, as the GLSL module does: with constant
// bounds a JIT may unroll the whole network and take minutes to compile it.

var<private> u_layer_count: i32;                               // linear layers
var<private> u_layers: array<vec4<i32>, MAX_LAYERS>;           // per layer: (row_offset, in_blocks, out_blocks, 0)

fn weight_texel(column: i32, row: i32) -> vec4<f32> {
    return gratnet_weights[row * u_weights_width + column];
}

fn sigmoid(x: vec4<f32>) -> vec4<f32> {
    return 1.0 / (1.0 + exp(-clamp(x, vec4<f32>(-80.0), vec4<f32>(80.0))));  // clamp before exp: no overflow
}

fn hidden_activation(x: vec4<f32>) -> vec4<f32> {
    if (u_hidden_activation == HIDDEN_RELU) {
        return max(x, vec4<f32>(0.0));
    }
    if (u_hidden_activation == HIDDEN_LEAKY_RELU) {
        return max(x, LEAKY_RELU_SLOPE * x);  // equals x > 0 ? x : slope * x for 0 < slope < 1
    }
    return x * sigmoid(x);  // HIDDEN_SILU
}

fn output_activation(x: vec4<f32>) -> vec4<f32> {
    if (u_output_activation == OUTPUT_CLAMP) {
        return clamp(x, vec4<f32>(0.0), vec4<f32>(1.0));
    }
    if (u_output_activation == OUTPUT_SIGMOID) {
        return sigmoid(x);
    }
    return x;  // OUTPUT_NONE
}

// The network's three outputs (range-transformed XYZ, eq. 7 domain) for the key set by encoding_set_key.
fn mlp_evaluate() -> vec3<f32> {
    var x: array<vec4<f32>, MAX_BLOCKS>;  // the current layer's inputs, whole vec4 blocks
    var y: array<vec4<f32>, MAX_BLOCKS>;  // its outputs, copied back into x for the next layer
    let input_blocks = u_layers[0].y;
    grid_set_key();  // a feature-grid model's features (featuregrid.wgsl); nothing for the pure MLP
    for (var i = 0; i < input_blocks; i++) {
        x[i] = network_input_block(i);  // encode once per invocation, not once per output block
    }
    for (var k = 0; k < u_layer_count; k++) {
        let layer = u_layers[k];
        let last = k == u_layer_count - 1;
        for (var o = 0; o < layer.z; o++) {
            let row = layer.x + o;
            var acc = weight_texel(4 * layer.y, row);  // bias
            for (var i = 0; i < layer.y; i++) {
                let c = 4 * i;
                acc += mat4x4<f32>(weight_texel(c, row), weight_texel(c + 1, row), weight_texel(c + 2, row),
                                   weight_texel(c + 3, row)) * x[i];
            }
            if (last) {
                y[o] = output_activation(acc);
            } else {
                y[o] = hidden_activation(acc);
            }
        }
        for (var o = 0; o < layer.z; o++) {
            x[o] = y[o];
        }
    }
    return x[0].xyz;
}
