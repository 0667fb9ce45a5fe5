// The reference look-up: CIE XYZ of the ground-truth volume at a key vector, in place of the network
// (docs/physics.md "The reference look-up"; gratnet/reference.py is its numpy twin).
//
// The key vector -> network coordinates (c_u, c_v, c_t) of encoding.glsl (the volume's own scheme, u_scheme),
// then trilinear interpolation of the volume's samples, eq. 6g with s(f) = f: sample (s, i, j) is the node
// at c = -1 + 2 * index / (N - 1) on each axis. Eight texelFetches and float32 weights, not the GPU's filter:
// a texture unit's linear filter weighs with as few as 8 fractional bits (NVIDIA), which would not be exact
// between samples. u_reference holds XYZ * u_reference_scale (float16 storage: 2^15, see gratnet/reference.py;
// float32: 1) as (R_u, R_v, S) texels; the look-up divides the scale out.
// Needs #define MAX_FREQUENCIES (>= 1) for encoding.glsl, whose frequencies it does not use.

#include "encoding.glsl"
#include "counters.glsl"

uniform highp sampler3D u_reference;  // RGB16F or RGB32F, texel (j, i, s) = XYZ * scale of sample (s, i, j)
uniform float u_reference_scale;

vec3 reference_xyz(vec3 key) {
    encoding_set_key(key);  // g_coordinates = (c_u, c_v, c_t), eq. 6
    ivec3 nodes = textureSize(u_reference, 0);  // (R_u, R_v, S)
    vec3 position = (clamp(g_coordinates, -1.0, 1.0) + 1.0) * 0.5 * vec3(nodes - ivec3(1));
    ivec3 lower = clamp(ivec3(floor(position)), ivec3(0), max(nodes - ivec3(2), ivec3(0)));
    vec3 f = position - vec3(lower);  // the last cell includes its far end
    ivec3 upper = min(lower + ivec3(1), nodes - ivec3(1));  // a one-slice volume: both corners are slice 0
    vec3 c000 = texelFetch(u_reference, ivec3(lower.x, lower.y, lower.z), 0).rgb;
    vec3 c100 = texelFetch(u_reference, ivec3(upper.x, lower.y, lower.z), 0).rgb;
    vec3 c010 = texelFetch(u_reference, ivec3(lower.x, upper.y, lower.z), 0).rgb;
    vec3 c110 = texelFetch(u_reference, ivec3(upper.x, upper.y, lower.z), 0).rgb;
    vec3 c001 = texelFetch(u_reference, ivec3(lower.x, lower.y, upper.z), 0).rgb;
    vec3 c101 = texelFetch(u_reference, ivec3(upper.x, lower.y, upper.z), 0).rgb;
    vec3 c011 = texelFetch(u_reference, ivec3(lower.x, upper.y, upper.z), 0).rgb;
    vec3 c111 = texelFetch(u_reference, ivec3(upper.x, upper.y, upper.z), 0).rgb;
    vec3 near = mix(mix(c000, c100, f.x), mix(c010, c110, f.x), f.y);
    vec3 far = mix(mix(c001, c101, f.x), mix(c011, c111, f.x), f.y);
    return mix(near, far, f.z) / u_reference_scale;
}
