// The funnel MLP, weights read from the packed RGBA32F texture exactly per docs/formats.md
// ("Weight texture layout"), on encoded inputs from encoding.glsl (physics.md eq. 6 -> eq. 7 domain).
//
// Needs #define MAX_BLOCKS (the widest layer's vec4 count, inputs included), MAX_LAYERS and
// LEAKY_RELU_SLOPE, all set from the model file. Every loop is bounded by a uniform: constant bounds
// make Mesa unroll everything and its JIT then takes minutes. Each step multiplies a mat4 built from
// four texelFetches by a vec4, writing whole vec4s: llvmpipe miscompiles a scalar float[] scratch
// array written at a variable index (shared/notes/opengl-on-this-machine.md).
//
// Where the weights live (the texels are the same in every case: texel (column, row) of the packed texture):
//   default          the RGBA32F texture u_weights (texelFetch), any stage;
//   WEIGHTS_SSBO     a std430 buffer of vec4 at binding WEIGHTS_BINDING, row-major, u_weights_width texels a
//                    row (compute and fragment stages);
//   WEIGHTS_SHARED   that buffer copied into the work group's shared memory by mlp_load_shared_weights()
//                    (compute stage only; #define WEIGHTS_SHARED to the texel count, which must fit
//                    GL_MAX_COMPUTE_SHARED_MEMORY_SIZE; every invocation of the group must call it).
//   WEIGHTS_FP16     with either buffer: each texel stored as four IEEE halves (uvec2, packHalf2x16 order),
//                    unpacked to float32 before the arithmetic (fp16 storage, fp32 sums).

#include "codes.glsl"  // HIDDEN_*, OUTPUT_* (each branch below computes the name's expression in gratnet/codes.py)
#include "featuregrid.glsl"

#if defined(WEIGHTS_SSBO) || defined(WEIGHTS_SHARED)
#ifdef WEIGHTS_FP16
#define WEIGHT_STORAGE uvec2
vec4 weight_value(uvec2 halves) {
    return vec4(unpackHalf2x16(halves.x), unpackHalf2x16(halves.y));
}
#else
#define WEIGHT_STORAGE vec4
vec4 weight_value(vec4 texel) {
    return texel;
}
#endif
layout(std430, binding = WEIGHTS_BINDING) readonly buffer MlpWeights {
    WEIGHT_STORAGE mlp_weights[];  // the packed texture's texels, row-major
};
uniform int u_weights_width;           // texels per row of the packed texture
#ifdef WEIGHTS_SHARED
shared WEIGHT_STORAGE mlp_shared_weights[WEIGHTS_SHARED];

// Copy the weights into shared memory, each invocation a strided share, then wait for the whole group.
void mlp_load_shared_weights() {
    uint stride = gl_WorkGroupSize.x * gl_WorkGroupSize.y * gl_WorkGroupSize.z;
    for (uint i = gl_LocalInvocationIndex; i < uint(WEIGHTS_SHARED); i += stride) {
        mlp_shared_weights[i] = mlp_weights[i];
    }
    memoryBarrierShared();
    barrier();
}

vec4 weight_texel(int column, int row) {
    return weight_value(mlp_shared_weights[row * u_weights_width + column]);
}
#else
vec4 weight_texel(int column, int row) {
    return weight_value(mlp_weights[row * u_weights_width + column]);
}
#endif
#else
uniform highp sampler2D u_weights;     // RGBA32F, NEAREST, no mipmaps: the model file's `texture`

vec4 weight_texel(int column, int row) {
    return texelFetch(u_weights, ivec2(column, row), 0);
}
#endif
uniform int u_layer_count;             // linear layers
uniform ivec4 u_layers[MAX_LAYERS];    // per layer: (row_offset, in_blocks, out_blocks, 0)
uniform int u_hidden_activation;       // HIDDEN_*
uniform int u_output_activation;       // OUTPUT_*

vec4 sigmoid(vec4 x) {
    return 1.0 / (1.0 + exp(-clamp(x, -80.0, 80.0)));  // clamp before exp: no overflow to inf
}

vec4 hidden_activation(vec4 x) {
    if (u_hidden_activation == HIDDEN_RELU) {
        return max(x, 0.0);
    }
    if (u_hidden_activation == HIDDEN_LEAKY_RELU) {
        return max(x, LEAKY_RELU_SLOPE * x);  // equals x > 0 ? x : slope * x for 0 < slope < 1
    }
    return x * sigmoid(x);  // HIDDEN_SILU
}

vec4 output_activation(vec4 x) {
    if (u_output_activation == OUTPUT_CLAMP) {
        return clamp(x, 0.0, 1.0);
    }
    if (u_output_activation == OUTPUT_SIGMOID) {
        return sigmoid(x);
    }
    return x;  // OUTPUT_NONE
}

// The network's three outputs (range-transformed XYZ, eq. 7 domain) for the key set by encoding_set_key.
vec3 mlp_evaluate() {
    vec4 x[MAX_BLOCKS];  // the current layer's inputs, whole vec4 blocks
    vec4 y[MAX_BLOCKS];  // its outputs, copied back into x for the next layer
    int input_blocks = u_layers[0].y;
    grid_set_key();  // a feature-grid model's features (featuregrid.glsl); nothing for the pure MLP
    for (int i = 0; i < input_blocks; ++i) {
        x[i] = network_input_block(i);  // encode once per fragment, not once per output block
    }
    for (int k = 0; k < u_layer_count; ++k) {
        ivec4 layer = u_layers[k];
        bool last = k == u_layer_count - 1;
        for (int o = 0; o < layer.z; ++o) {
            int row = layer.x + o;
            vec4 acc = weight_texel(4 * layer.y, row);  // bias
            for (int i = 0; i < layer.y; ++i) {
                int c = 4 * i;
                acc += mat4(weight_texel(c, row), weight_texel(c + 1, row), weight_texel(c + 2, row),
                            weight_texel(c + 3, row)) * x[i];
            }
            y[o] = last ? output_activation(acc) : hidden_activation(acc);
        }
        for (int o = 0; o < layer.z; ++o) {
            x[o] = y[o];
        }
    }
    return x[0].xyz;
}
