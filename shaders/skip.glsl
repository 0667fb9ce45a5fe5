// Skipping the MLP where it cannot change the displayed pixel, (issue 5); the work counters are counters.glsl.
//
// Bound: u_skip_bound holds, per coarse cell of network coordinates (c_u, c_v, c_t) (docs/physics.md
// eq. 6), an upper bound of the network's CIE XYZ (gratnet/bounds.py: sampled on a grid twice as fine
// as the training grid, dilated by a cell, with safety margins; validated by measurement, not a proof).
// A pixel whose exposed linear sRGB scale * (M+ . bound) is below u_skip_threshold in every channel
// (M+: the positive part of the CIE XYZ -> linear sRGB matrix, so M . xyz <= M+ . bound for 0 <= xyz <=
// bound) shows display sRGB 0 whatever the network says, so the MLP is skipped and the pixel is 0.
// u_skip_threshold <= 0 never skips (linear/EXR outputs).
//
// Needs encoding.glsl (g_coordinates, set by encoding_set_key).

#include "counters.glsl"

uniform float u_skip_threshold;        // exposed linear sRGB; <= 0: never skip
uniform highp sampler3D u_skip_bound;  // RGBA32F, (Cu, Cv, Ct) texels: .xyz = CIE XYZ bound of the cell
uniform mat3 u_skip_matrix;            // positive part of CIE XYZ -> linear sRGB (GLSL column-major)

// True when `scale` * XYZ(network) (scale = exposure * irradiance * A >= 0) is certainly below the
// display's smallest step in every linear sRGB channel. encoding_set_key must have run for this key.
bool skip_by_bound(float scale) {
    if (!(u_skip_threshold > 0.0)) {
        return false;
    }
    ivec3 cells = textureSize(u_skip_bound, 0);
    vec3 c = clamp(g_coordinates, -1.0, 1.0);
    ivec3 cell = clamp(ivec3(floor((c + 1.0) * 0.5 * vec3(cells))), ivec3(0), cells - ivec3(1));
    vec3 bound = texelFetch(u_skip_bound, cell, 0).xyz;
    vec3 linear = u_skip_matrix * bound;
    float peak = max(linear.r, max(linear.g, linear.b));
    return scale * peak < u_skip_threshold;  // NaN or inf scale: false, i.e. evaluate
}
