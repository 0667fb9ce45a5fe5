// Compute programs of the deferred render path (viewer/deferred.py, issue 12), one kernel per define:
//
//   COMPACT  over every texel of the G-buffer (surface.glsl compiled with GBUFFER: (key, factor) per
//            covered texel, factor = exposure * irradiance * A, cleared to (0, 0, 0, -1) = background):
//            texels that need the network (factor > 0 and not excluded by skip.glsl's bound) are appended
//            to the list; every other texel is finished here: (0, 0, 0, coverage).
//   SHADE    one invocation per list entry: encoding -> MLP -> inverse range (the same encoding.glsl,
//            mlp.glsl and range.glsl as the forward path's surface.glsl) and the texel becomes
//            (factor * XYZ, 1): exposed CIE XYZ and coverage, as the forward path writes.
//   SHADE_TILED  SHADE as a tiled matrix product (mlp_tiled.glsl, issue 32): one work group per TILED_PIXELS
//            list entries, each layer's weights staged in shared memory once per tile, the activations kept
//            there between layers; the same texels written. With TILED_HALF, half-precision arithmetic
//            (GL_NV_gpu_shader5 or GL_AMD_gpu_shader_half_float, enabled here: TILED_HALF_NV / TILED_HALF_AMD).
//   TINT     under sampled light (surface.glsl's GBUFFER with ENVIRONMENT), after SHADE / SHADE_TILED: every
//            texel's exposed XYZ under its pass's linear sRGB tint (a second texture stacked as the G-buffer, 0
//            where the pixel is not lit), by the forward path's environment_tint (tint.glsl), plus the pass's
//            control-variate term (a third texture, exposed linear sRGB).
//   RESOLVE  per pixel: the mean of its u_samples texels (sample k at row y + k * u_height) times u_scale,
//            added to the output when u_accumulate is set (samples in several chunks).
//
// COMPACT, TINT and RESOLVE run in bands of rows from u_first_row (a multiple of DEFERRED_TILE: no texel twice),
// SHADE in pieces of the list (viewer/deferred.py binds it from an entry on): no dispatch runs long (issue 36).
//
// So background, A = 0 and bound-dark pixels never reach the MLP: the skip rules of the forward path
// become the list's length. Needs the defines of mlp.glsl and encoding.glsl (SHADE), skip.glsl's (COMPACT),
// and SHADE_GROUP (SHADE_TILED: mlp_tiled.glsl's TILED_* instead of SHADE_GROUP); the bindings come from codes.glsl.

#ifdef COMPUTE_SHADER
// An #extension must come before any declaration.
#if defined(TILED_HALF_NV)
#extension GL_NV_gpu_shader5 : require
#elif defined(TILED_HALF_AMD)
#extension GL_AMD_gpu_shader_half_float : require
#endif
precision highp float;
precision highp int;

#include "codes.glsl"  // the bindings, image units, DEFERRED_TILE and COUNTER_* (gratnet/codes.py)

// The list: a 16-byte header, then one packed texel coordinate (x | y << 16) per entry. The header's first
// three words are not read by any kernel (viewer/deferred.py writes them); the fourth is the entry count,
// which viewer/deferred.py reads back at byte 12 and sets for each SHADE piece.
layout(std430, binding = DEFERRED_LIST_BINDING) buffer DeferredList {
    uint dispatch_x;
    uint dispatch_y;
    uint dispatch_z;
    uint entry_count;
    uint entries[];
};

// The preprocessor includes each file once, whatever the #ifdefs around it: a file two kernels need is
// included here, outside them.
#include "encoding.glsl"

#ifdef COMPACT
#include "skip.glsl"

layout(local_size_x = DEFERRED_TILE, local_size_y = DEFERRED_TILE) in;
layout(rgba32f, binding = GBUFFER_IMAGE_BINDING) uniform restrict image2D u_gbuffer;
uniform int u_first_row;  // the first texel row (bands of rows; a multiple of DEFERRED_TILE but for the last)

void main() {
    ivec2 texel = ivec2(gl_GlobalInvocationID.xy) + ivec2(0, u_first_row);
    if (any(greaterThanEqual(texel, imageSize(u_gbuffer)))) {
        return;
    }
    vec4 value = imageLoad(u_gbuffer, texel);
    float factor = value.w;
    if (factor < 0.0) {
        imageStore(u_gbuffer, texel, vec4(0.0));  // background: no coverage
        return;
    }
    count_event(COUNTER_FRAGMENTS);
    if (!(factor > 0.0)) {
        count_event(COUNTER_SKIPPED_A_ZERO);  // back face, below a horizon, no irradiance
        imageStore(u_gbuffer, texel, vec4(0.0, 0.0, 0.0, 1.0));
        return;
    }
    encoding_set_key(value.xyz);
    if (skip_by_bound(factor)) {
        count_event(COUNTER_SKIPPED_BOUND);  // the display would show 0 whatever the network says
        imageStore(u_gbuffer, texel, vec4(0.0, 0.0, 0.0, 1.0));
        return;
    }
    count_event(COUNTER_EVALUATIONS);
    uint index = atomicAdd(entry_count, 1u);
    entries[index] = uint(texel.x) | (uint(texel.y) << 16);
}
#endif

#if defined(SHADE) || defined(SHADE_TILED)
// Both shading kernels' includes, once (see above): the work group's size first (mlp.glsl's shared-memory copy
// reads gl_WorkGroupSize), featuregrid.glsl before mlp.glsl (its baked stand-in includes nothing),
// mlp_tiled.glsl compiles to nothing without its TILED_* defines.
#ifdef SHADE
layout(local_size_x = SHADE_GROUP) in;
#else
layout(local_size_x = TILED_GROUP) in;
#endif
layout(rgba32f, binding = GBUFFER_IMAGE_BINDING) uniform restrict image2D u_gbuffer;
#include "featuregrid.glsl"
#include "mlp.glsl"
#include "mlp_tiled.glsl"
#include "range.glsl"
#endif

#ifdef SHADE
void main() {
#ifdef WEIGHTS_SHARED
    mlp_load_shared_weights();  // the whole group, before any invocation leaves
#endif
    uint index = (gl_WorkGroupID.y * gl_NumWorkGroups.x + gl_WorkGroupID.x) * uint(SHADE_GROUP)
                 + gl_LocalInvocationIndex;
    if (index >= entry_count) {
        return;
    }
    uint entry = entries[index];
    ivec2 texel = ivec2(int(entry & 0xffffu), int(entry >> 16));
    vec4 value = imageLoad(u_gbuffer, texel);
    encoding_set_key(value.xyz);
    vec3 xyz = range_inverse(mlp_evaluate());
    imageStore(u_gbuffer, texel, vec4(value.w * xyz, 1.0));  // value.w: exposure * irradiance * A
}
#endif

#ifdef SHADE_TILED
uint g_tile_first;  // the tile's first list entry

void tiled_store(int pixel, vec3 outputs) {
    uint entry = g_tile_first + uint(pixel);
    if (entry < entry_count) {
        uint position = entries[entry];
        ivec2 texel = ivec2(int(position & 0xffffu), int(position >> 16));
        float factor = imageLoad(u_gbuffer, texel).w;  // exposure * irradiance * A, as SHADE
        imageStore(u_gbuffer, texel, vec4(factor * range_inverse(outputs), 1.0));
    }
}

void main() {
    g_tile_first = (gl_WorkGroupID.y * gl_NumWorkGroups.x + gl_WorkGroupID.x) * uint(TILED_PIXELS);
    // The whole group alike (uniform control flow around the barriers; no return before them, which some
    // compilers refuse).
    if (g_tile_first < entry_count) {
        tiled_encode(g_tile_first, entry_count);
        tiled_layers();
    }
}
#endif

#ifdef TINT
layout(local_size_x = DEFERRED_TILE, local_size_y = DEFERRED_TILE) in;
layout(rgba32f, binding = GBUFFER_IMAGE_BINDING) uniform restrict image2D u_gbuffer;
layout(rgba32f, binding = RESOLVED_IMAGE_BINDING) uniform restrict readonly image2D u_tint;  // unit free till RESOLVE
layout(rgba32f, binding = OFFSET_IMAGE_BINDING) uniform restrict readonly image2D u_offset;  // control variate's
uniform int u_first_row;    // as COMPACT's
#include "tint.glsl"  // environment_tint: the forward path's colour product

void main() {
    ivec2 texel = ivec2(gl_GlobalInvocationID.xy) + ivec2(0, u_first_row);
    if (any(greaterThanEqual(texel, imageSize(u_gbuffer)))) {
        return;
    }
    vec4 value = imageLoad(u_gbuffer, texel);
    vec3 tint = imageLoad(u_tint, texel).rgb;
    vec3 offset = u_rgb_to_xyz * imageLoad(u_offset, texel).rgb;  // 0 on the background (cleared) and unlit passes
    imageStore(u_gbuffer, texel, vec4(environment_tint(value.xyz, tint) + offset, value.w));
}
#endif

#ifdef RESOLVE
layout(local_size_x = DEFERRED_TILE, local_size_y = DEFERRED_TILE) in;
layout(rgba32f, binding = GBUFFER_IMAGE_BINDING) uniform restrict readonly image2D u_gbuffer;
layout(rgba32f, binding = RESOLVED_IMAGE_BINDING) uniform restrict image2D u_output;
uniform int u_samples;     // samples in this chunk of the G-buffer
uniform int u_height;      // image rows per sample
uniform float u_scale;     // 1 / (all samples of the pixel)
uniform bool u_accumulate; // add to the output (a later chunk) instead of replacing it
uniform int u_first_row;   // the dispatch's first pixel row (bands of rows, as COMPACT)

void main() {
    ivec2 pixel = ivec2(gl_GlobalInvocationID.xy) + ivec2(0, u_first_row);
    if (any(greaterThanEqual(pixel, imageSize(u_output)))) {
        return;
    }
    vec4 sum = vec4(0.0);
    for (int k = 0; k < u_samples; ++k) {
        sum += imageLoad(u_gbuffer, ivec2(pixel.x, pixel.y + k * u_height));
    }
    vec4 mean = sum * u_scale;
    imageStore(u_output, pixel, u_accumulate ? imageLoad(u_output, pixel) + mean : mean);
}
#endif
#endif
