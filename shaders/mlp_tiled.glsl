// The funnel MLP as a tiled matrix product (issue 32): one work group evaluates a tile of TILED_PIXELS list
// entries at once, so that each weight is read from the buffer once per tile instead of once per pixel.
// The arithmetic is mlp.glsl's (docs/formats.md "Weight texture layout", physics.md eq. 6 -> eq. 7 domain):
// per output block, the bias, then mat4(4 texels of input block i) * x_i added for i = 0, 1, ... in order,
// then the activation -- the same summation order as mlp_evaluate, only the operands come from shared memory.
//
// Shared memory (sizes from viewer/tiled.py's plan: the model's layer widths and the driver's
// GL_MAX_COMPUTE_SHARED_MEMORY_SIZE):
//   s_tiled_act   the tile's activations, TILED_ACT_BLOCKS vec4 blocks per pixel (the most any layer needs
//                 for its inputs and outputs together), laid out [block][pixel]. Layer k reads its inputs
//                 at one end and writes its outputs at the other (even k: inputs from block 0, outputs ending
//                 at the top; odd k: the reverse), so inputs and outputs never overlap and the activations
//                 stay on chip from the encoding to the last layer.
//   s_tiled_w     one chunk of a layer's weights: every output block's 4 texels of each of `chunk` input
//                 blocks ([out block][input block][column j]); a layer whose weights do not fit is staged in
//                 chunks of input blocks (tiled_chunk_blocks).
// Register blocking: invocation n takes items n, n + TILED_GROUP, ... (at most TILED_ITEMS); item = (output
// block o, pixel set q), q fastest, so neighbouring invocations read the same weights (a broadcast on a GPU).
// Set q is pixels q, q + Q, q + 2Q, q + 3Q (Q = TILED_QUADS): neighbouring invocations read neighbouring
// vec4s of the activations (consecutive banks; 4 consecutive pixels each would put every other invocation of
// a quarter warp on the same banks). Each item holds 4 outputs x 4 pixels as four vec4 accumulators: per
// input block, 4 weight texels and 4 activation vec4s from shared memory feed 64 multiply-adds.
//
// Needs mlp.glsl compiled with WEIGHTS_SSBO (weight_texel, the activations, u_layers), encoding.glsl /
// featuregrid.glsl (network_input_block), the list and u_gbuffer of deferred.glsl, and the defines
// TILED_PIXELS (a multiple of 4), TILED_GROUP, TILED_ITEMS, TILED_ACT_BLOCKS, TILED_WEIGHT_VEC4S,
// TILED_ENCODE_SPLIT (without TILED_PIXELS the file compiles to nothing: deferred.glsl includes it for both
// shading kernels).
//
// TILED_HALF: activations, staged weights and the products within one chunk in half precision (f16vec4;
// deferred.glsl enables GL_NV_gpu_shader5 or GL_AMD_gpu_shader_half_float), each chunk's partial sum added to
// float32 accumulators (a chunk holds at most 4 * chunk terms, so fp16's 2^-11 rounding does not grow with the
// layer's width). TILED_HALF_AS_FLOAT compiles that same code with float types (a compile and parity check of
// the half path's structure on drivers without half arithmetic, such as llvmpipe).

#include "mlp.glsl"

#ifdef TILED_PIXELS
#if defined(TILED_HALF) && !defined(TILED_HALF_AS_FLOAT)
#define TILED_VEC4 f16vec4
#else
#define TILED_VEC4 vec4
#endif

shared TILED_VEC4 s_tiled_act[TILED_ACT_BLOCKS * TILED_PIXELS];
shared TILED_VEC4 s_tiled_w[TILED_WEIGHT_VEC4S];

const int TILED_QUADS = TILED_PIXELS / 4;

// Four outputs of one input block: column j of the 4x4 block times input j (mat4 * vec4 in float).
TILED_VEC4 tiled_product(TILED_VEC4 w0, TILED_VEC4 w1, TILED_VEC4 w2, TILED_VEC4 w3, TILED_VEC4 x) {
#ifdef TILED_HALF
    return w0 * x.x + w1 * x.y + w2 * x.z + w3 * x.w;
#else
    return mat4(w0, w1, w2, w3) * x;
#endif
}

// Input blocks per staged chunk of a layer with `out_blocks` output blocks: as many as s_tiled_w holds.
int tiled_chunk_blocks(int in_blocks, int out_blocks) {
    return clamp(TILED_WEIGHT_VEC4S / (4 * out_blocks), 1, in_blocks);
}

// Block `block` of pixel `pixel` in the activations.
int tiled_act_index(int block, int pixel) {
    return block * TILED_PIXELS + pixel;
}

// The network's inputs for the tile's pixels (list entries first_entry, first_entry + 1, ...) into blocks
// 0 ... in_blocks - 1; pixels past entry_count get 0 inputs (finite, never stored). Each pixel is encoded by
// TILED_ENCODE_SPLIT invocations, each writing every TILED_ENCODE_SPLIT-th block.
void tiled_encode(uint first_entry, uint entry_count) {
    int in_blocks = u_layers[0].y;
    int local = int(gl_LocalInvocationIndex);
    for (int n = local; n < TILED_PIXELS * TILED_ENCODE_SPLIT; n += TILED_GROUP) {
        int pixel = n % TILED_PIXELS;
        int part = n / TILED_PIXELS;
        uint entry = first_entry + uint(pixel);
        if (entry < entry_count) {
            uint position = entries[entry];
            encoding_set_key(imageLoad(u_gbuffer, ivec2(int(position & 0xffffu), int(position >> 16))).xyz);
            grid_set_key();  // a feature-grid model's features (featuregrid.glsl); nothing for the pure MLP
            for (int i = part; i < in_blocks; i += TILED_ENCODE_SPLIT) {
                s_tiled_act[tiled_act_index(i, pixel)] = TILED_VEC4(network_input_block(i));
            }
        } else {
            for (int i = part; i < in_blocks; i += TILED_ENCODE_SPLIT) {
                s_tiled_act[tiled_act_index(i, pixel)] = TILED_VEC4(0.0);
            }
        }
    }
}

// Defined by the kernel: pixel `pixel`'s network outputs (output activation applied; float32, straight from
// the accumulators), called once per pixel of the tile (pixels past the list included: the kernel skips them).
void tiled_store(int pixel, vec3 outputs);

// Every layer over the tile, then tiled_store per pixel. Every invocation of the group must call it (barriers).
void tiled_layers() {
    int local = int(gl_LocalInvocationIndex);
    for (int k = 0; k < u_layer_count; ++k) {
        ivec4 layer = u_layers[k];
        int in_blocks = layer.y;
        int out_blocks = layer.z;
        bool even = k % 2 == 0;
        int in_first = even ? 0 : TILED_ACT_BLOCKS - in_blocks;
        int out_first = even ? TILED_ACT_BLOCKS - out_blocks : 0;
        int items = out_blocks * TILED_QUADS;
        int chunk = tiled_chunk_blocks(in_blocks, out_blocks);
        bool last = k == u_layer_count - 1;
        vec4 acc[4 * TILED_ITEMS];
        for (int t = 0; t < TILED_ITEMS; ++t) {
            int item = local + t * TILED_GROUP;
            int o = item / TILED_QUADS;
            vec4 bias = item < items ? weight_texel(4 * in_blocks, layer.x + o) : vec4(0.0);
            for (int p = 0; p < 4; ++p) {
                acc[4 * t + p] = bias;
            }
        }
        for (int start = 0; start < in_blocks; start += chunk) {
            int count = min(chunk, in_blocks - start);
            int texels = 4 * count;
            // The previous chunk's (or layer's) readers are done with s_tiled_w, and the previous layer's
            // outputs (this layer's inputs) are written.
            memoryBarrierShared();
            barrier();
            for (int n = local; n < out_blocks * texels; n += TILED_GROUP) {
                int o = n / texels;
                s_tiled_w[n] = TILED_VEC4(weight_texel(4 * start + (n - o * texels), layer.x + o));
            }
            memoryBarrierShared();
            barrier();
            for (int t = 0; t < TILED_ITEMS; ++t) {
                int item = local + t * TILED_GROUP;
                if (item < items) {
                    int o = item / TILED_QUADS;
                    int w = o * texels;
                    int a = tiled_act_index(in_first + start, item - o * TILED_QUADS);
#ifdef TILED_HALF
                    TILED_VEC4 part[4] = TILED_VEC4[4](TILED_VEC4(0.0), TILED_VEC4(0.0), TILED_VEC4(0.0),
                                                       TILED_VEC4(0.0));
#endif
                    for (int i = 0; i < count; ++i) {
                        TILED_VEC4 w0 = s_tiled_w[w];
                        TILED_VEC4 w1 = s_tiled_w[w + 1];
                        TILED_VEC4 w2 = s_tiled_w[w + 2];
                        TILED_VEC4 w3 = s_tiled_w[w + 3];
                        for (int p = 0; p < 4; ++p) {
#ifdef TILED_HALF
                            part[p] += tiled_product(w0, w1, w2, w3, s_tiled_act[a + p * TILED_QUADS]);
#else
                            acc[4 * t + p] += tiled_product(w0, w1, w2, w3, s_tiled_act[a + p * TILED_QUADS]);
#endif
                        }
                        w += 4;
                        a += TILED_PIXELS;
                    }
#ifdef TILED_HALF
                    for (int p = 0; p < 4; ++p) {
                        acc[4 * t + p] += vec4(part[p]);
                    }
#endif
                }
            }
        }
        // Outputs go to the other end of the activations: no reader of this layer's inputs is disturbed. The
        // last layer's block 0 (XYZ, eq. 7 domain) goes to the kernel from the accumulators, in float32.
        for (int t = 0; t < TILED_ITEMS; ++t) {
            int item = local + t * TILED_GROUP;
            if (item < items) {
                int o = item / TILED_QUADS;
                int q = item - o * TILED_QUADS;
                int a = tiled_act_index(out_first + o, q);
                for (int p = 0; p < 4; ++p) {
                    if (!last) {
                        s_tiled_act[a + p * TILED_QUADS] = TILED_VEC4(hidden_activation(acc[4 * t + p]));
                    } else if (o == 0) {
                        tiled_store(q + p * TILED_QUADS, output_activation(acc[4 * t + p]).xyz);
                    }
                }
            }
        }
    }
}
#endif
