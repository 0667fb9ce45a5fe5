// Learned feature grids (docs/physics.md "Feature-grid network", eq. 6g); mirrors gratnet/featuregrid.py.
//
// Compiled in only with #define GRID_LEVELS (levels), GRID_FEATURES (C, 1..16) and GRID_CHUNKS (ceil(C/4)), set
// from the model file: GRID_CHUNKS 3D textures per level ("chunks"; u_grid[level * GRID_CHUNKS + k] holds
// features 4k..4k+3 of the level), each (R_u, R_v, T) texels of up to 4 channels (R16F.. RGBA16F or 32F; the
// last chunk has only the channels it needs, C - 4k), node i of an axis of N nodes at c = -1 + 2i/(N-1), i.e.
// at the texel centre (i + 0.5)/N. The MLP's input is the L*C grid features, level 0 first, then the encoding
// (encoding.glsl).
//
// u_grid_smoothstep (the model file's grid interpolation): 1 moves p within its cell so that linear
// interpolation there is smoothstep interpolation (f -> f^2 (3 - 2f) per axis; gratnet.featuregrid
// smoothstep_coordinates), before either way of interpolating.
//
// Two ways to interpolate, chosen by u_grid_hardware_filter:
//   0: eight texelFetches and float32 weights, exactly the formula of eq. 6g (the default);
//   1: one texture() with GL_LINEAR, where the GPU may quantise the weights (8 bits of sub-texel position
//      on NVIDIA hardware): cheaper, less exact (docs/benchmarks.md, "Feature-grid network").

#ifdef GRID_LEVELS
uniform highp sampler3D u_grid[GRID_LEVELS * GRID_CHUNKS];
uniform int u_grid_hardware_filter;
uniform int u_grid_smoothstep;
// This fragment's features, chunk by chunk as u_grid: lanes 0..3 of [level * GRID_CHUNKS + k] are the level's
// features 4k..4k+3 (a last chunk's lanes beyond C hold no feature).
vec4 g_grid_features[GRID_LEVELS * GRID_CHUNKS];

vec4 grid_level_features(highp sampler3D grid, vec3 c) {
    vec3 nodes = vec3(textureSize(grid, 0));
    vec3 p = (clamp(c, -1.0, 1.0) + 1.0) * (0.5 * (nodes - 1.0));
    if (u_grid_smoothstep != 0) {
        vec3 cell = clamp(floor(p), vec3(0.0), nodes - 2.0);
        vec3 t = p - cell;
        p = cell + t * t * (3.0 - 2.0 * t);
    }
    if (u_grid_hardware_filter != 0) {
        return texture(grid, (p + 0.5) / nodes);
    }
    vec3 lower = clamp(floor(p), vec3(0.0), nodes - 2.0);  // the last cell includes its far end
    vec3 f = p - lower;
    vec3 g = 1.0 - f;
    ivec3 i = ivec3(lower);
    vec4 sum = (g.z * g.y * g.x) * texelFetch(grid, i, 0);
    sum += (g.z * g.y * f.x) * texelFetch(grid, i + ivec3(1, 0, 0), 0);
    sum += (g.z * f.y * g.x) * texelFetch(grid, i + ivec3(0, 1, 0), 0);
    sum += (g.z * f.y * f.x) * texelFetch(grid, i + ivec3(1, 1, 0), 0);
    sum += (f.z * g.y * g.x) * texelFetch(grid, i + ivec3(0, 0, 1), 0);
    sum += (f.z * g.y * f.x) * texelFetch(grid, i + ivec3(1, 0, 1), 0);
    sum += (f.z * f.y * g.x) * texelFetch(grid, i + ivec3(0, 1, 1), 0);
    sum += (f.z * f.y * f.x) * texelFetch(grid, i + ivec3(1, 1, 1), 0);
    return sum;
}

// Fetch every level's features at the network coordinates of the key set by encoding_set_key. Each chunk
// redoes its level's cell arithmetic (a few flops beside its eight fetches): one texture per level, as
// before chunks, is then the same code. u_grid is indexed by constants only, one line per texture: GLSL ES 3.00
// (WebGL2, gratnet export --format web) allows no other sampler-array index. The chain covers 32 textures: the
// runtime takes at most the per-stage samplers minus 4 others (viewer/renderer.py check_grid_texture_units; 28 on
// llvmpipe's and NVIDIA's 32), and the shipped models use at most 12 (MAX_FEATURES 16 = 4 chunks a level).
#if GRID_LEVELS * GRID_CHUNKS > 32
#error featuregrid.glsl: more than 32 grid textures (GRID_LEVELS * GRID_CHUNKS); extend grid_set_key()
#endif
void grid_set_key() {
    g_grid_features[0] = grid_level_features(u_grid[0], g_coordinates);
#if GRID_LEVELS * GRID_CHUNKS > 1
    g_grid_features[1] = grid_level_features(u_grid[1], g_coordinates);
#endif
#if GRID_LEVELS * GRID_CHUNKS > 2
    g_grid_features[2] = grid_level_features(u_grid[2], g_coordinates);
#endif
#if GRID_LEVELS * GRID_CHUNKS > 3
    g_grid_features[3] = grid_level_features(u_grid[3], g_coordinates);
#endif
#if GRID_LEVELS * GRID_CHUNKS > 4
    g_grid_features[4] = grid_level_features(u_grid[4], g_coordinates);
#endif
#if GRID_LEVELS * GRID_CHUNKS > 5
    g_grid_features[5] = grid_level_features(u_grid[5], g_coordinates);
#endif
#if GRID_LEVELS * GRID_CHUNKS > 6
    g_grid_features[6] = grid_level_features(u_grid[6], g_coordinates);
#endif
#if GRID_LEVELS * GRID_CHUNKS > 7
    g_grid_features[7] = grid_level_features(u_grid[7], g_coordinates);
#endif
#if GRID_LEVELS * GRID_CHUNKS > 8
    g_grid_features[8] = grid_level_features(u_grid[8], g_coordinates);
#endif
#if GRID_LEVELS * GRID_CHUNKS > 9
    g_grid_features[9] = grid_level_features(u_grid[9], g_coordinates);
#endif
#if GRID_LEVELS * GRID_CHUNKS > 10
    g_grid_features[10] = grid_level_features(u_grid[10], g_coordinates);
#endif
#if GRID_LEVELS * GRID_CHUNKS > 11
    g_grid_features[11] = grid_level_features(u_grid[11], g_coordinates);
#endif
#if GRID_LEVELS * GRID_CHUNKS > 12
    g_grid_features[12] = grid_level_features(u_grid[12], g_coordinates);
#endif
#if GRID_LEVELS * GRID_CHUNKS > 13
    g_grid_features[13] = grid_level_features(u_grid[13], g_coordinates);
#endif
#if GRID_LEVELS * GRID_CHUNKS > 14
    g_grid_features[14] = grid_level_features(u_grid[14], g_coordinates);
#endif
#if GRID_LEVELS * GRID_CHUNKS > 15
    g_grid_features[15] = grid_level_features(u_grid[15], g_coordinates);
#endif
#if GRID_LEVELS * GRID_CHUNKS > 16
    g_grid_features[16] = grid_level_features(u_grid[16], g_coordinates);
#endif
#if GRID_LEVELS * GRID_CHUNKS > 17
    g_grid_features[17] = grid_level_features(u_grid[17], g_coordinates);
#endif
#if GRID_LEVELS * GRID_CHUNKS > 18
    g_grid_features[18] = grid_level_features(u_grid[18], g_coordinates);
#endif
#if GRID_LEVELS * GRID_CHUNKS > 19
    g_grid_features[19] = grid_level_features(u_grid[19], g_coordinates);
#endif
#if GRID_LEVELS * GRID_CHUNKS > 20
    g_grid_features[20] = grid_level_features(u_grid[20], g_coordinates);
#endif
#if GRID_LEVELS * GRID_CHUNKS > 21
    g_grid_features[21] = grid_level_features(u_grid[21], g_coordinates);
#endif
#if GRID_LEVELS * GRID_CHUNKS > 22
    g_grid_features[22] = grid_level_features(u_grid[22], g_coordinates);
#endif
#if GRID_LEVELS * GRID_CHUNKS > 23
    g_grid_features[23] = grid_level_features(u_grid[23], g_coordinates);
#endif
#if GRID_LEVELS * GRID_CHUNKS > 24
    g_grid_features[24] = grid_level_features(u_grid[24], g_coordinates);
#endif
#if GRID_LEVELS * GRID_CHUNKS > 25
    g_grid_features[25] = grid_level_features(u_grid[25], g_coordinates);
#endif
#if GRID_LEVELS * GRID_CHUNKS > 26
    g_grid_features[26] = grid_level_features(u_grid[26], g_coordinates);
#endif
#if GRID_LEVELS * GRID_CHUNKS > 27
    g_grid_features[27] = grid_level_features(u_grid[27], g_coordinates);
#endif
#if GRID_LEVELS * GRID_CHUNKS > 28
    g_grid_features[28] = grid_level_features(u_grid[28], g_coordinates);
#endif
#if GRID_LEVELS * GRID_CHUNKS > 29
    g_grid_features[29] = grid_level_features(u_grid[29], g_coordinates);
#endif
#if GRID_LEVELS * GRID_CHUNKS > 30
    g_grid_features[30] = grid_level_features(u_grid[30], g_coordinates);
#endif
#if GRID_LEVELS * GRID_CHUNKS > 31
    g_grid_features[31] = grid_level_features(u_grid[31], g_coordinates);
#endif
}

float network_input_feature(int f) {
    if (f < GRID_LEVELS * GRID_FEATURES) {
        int level = f / GRID_FEATURES;
        int within = f - level * GRID_FEATURES;  // the level's feature, in chunk within / 4, lane within % 4
        return g_grid_features[level * GRID_CHUNKS + within / 4][within % 4];
    }
    return encoded_feature(f - GRID_LEVELS * GRID_FEATURES);
}

// Input features 4*block ... 4*block+3 of the MLP: grid features, then the encoding.
vec4 network_input_block(int block) {
    int f = 4 * block;
    return vec4(network_input_feature(f), network_input_feature(f + 1), network_input_feature(f + 2),
                network_input_feature(f + 3));
}
#else
void grid_set_key() {
}

vec4 network_input_block(int block) {
    return encoded_block(block);
}
#endif
