// Program: evaluate the runtime pipeline at arbitrary inputs, one per pixel, for parity tests and
// tools. Pixel (x, y) reads its input from texel (x, y) of u_inputs (and u_inputs2):
//   MODE_XYZ       key vector (u, v, w) -> CIE XYZ (eq. 6 -> MLP -> eq. 7)
//   MODE_NETWORK   key vector -> the network's outputs (range-transformed XYZ, before eq. 7's inverse)
//   MODE_ENCODING  key vector -> encoded input features 4*u_block ... 4*u_block+3 (eq. 6)
//   MODE_A_TERM    light direction (u_inputs), view direction (u_inputs2) -> A (eq. 5) in .x, Smith's
//                  shadowing for u_slope_covariance in .y
// Needs the defines of mlp.glsl and encoding.glsl; MODE_* come from codes.glsl (gratnet/codes.py).
#include "codes.glsl"
#include "fullscreen.glsl"

#ifdef FRAGMENT_SHADER
precision highp float;
precision highp int;

#include "encoding.glsl"
#include "featuregrid.glsl"  // before mlp.glsl: its baked stand-in includes nothing
#include "mlp.glsl"
#include "range.glsl"
#include "brdf.glsl"

uniform highp sampler2D u_inputs;   // RGBA32F, .xyz per pixel
uniform highp sampler2D u_inputs2;  // RGBA32F, MODE_A_TERM only
uniform int u_mode;
uniform int u_block;                // MODE_ENCODING only
uniform float u_ior;                // MODE_A_TERM only; <= 0: Fresnel off
uniform vec3 u_slope_covariance;    // MODE_A_TERM only: (Sxx, Sxy, Syy)

layout(location = 0) out vec4 out_value;

void main() {
    ivec2 pixel = ivec2(gl_FragCoord.xy);
    vec3 value = texelFetch(u_inputs, pixel, 0).xyz;
    if (u_mode == MODE_A_TERM) {
        vec3 view = texelFetch(u_inputs2, pixel, 0).xyz;
        out_value = vec4(a_term(value, view, u_ior), smith_shadowing(value, view, u_slope_covariance), 0.0, 0.0);
        return;
    }
    encoding_set_key(value);
    if (u_mode == MODE_ENCODING) {
        out_value = encoded_block(u_block);
        return;
    }
    vec3 y = mlp_evaluate();
    out_value = vec4(u_mode == MODE_NETWORK ? y : range_inverse(y), 0.0);
}
#endif
