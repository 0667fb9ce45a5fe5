// Program: a BRDF slice of the network (docs/physics.md "BRDF slice"): for a fixed light direction,
// pixel (row i, column j) of a size x size image looks from wo = (x, y, sqrt(1 - x^2 - y^2)) with
// x = -1 + (2j+1)/size, y = 1 - (2i+1)/size (+x right, +y up, pixel centres); outside the unit disc
// the pixel is 0. Output 0: exposure * A(wi, wo) * XYZ(-(wi + wo)) (exposed XYZ, linear, RGBA32F);
// output 1 (when a second attachment is bound): the network's XYZ alone (0 where the MLP was skipped).
// The MLP is skipped where A = 0 and where the bound of skip.glsl says the display would show 0.
// With REFERENCE the ground-truth volume's look-up (reference.glsl) takes the network's place.
// Needs the defines of mlp.glsl and encoding.glsl; the COUNTER_* codes come from codes.glsl (gratnet/codes.py).
#include "codes.glsl"
#include "fullscreen.glsl"

#ifdef FRAGMENT_SHADER
precision highp float;
precision highp int;

#include "encoding.glsl"  // outside the REFERENCE choice: a file is included once, wherever it is first named
#include "counters.glsl"
#ifdef REFERENCE
#include "reference.glsl"  // the ground-truth volume in place of the network
#else
#include "featuregrid.glsl"  // before mlp.glsl: its baked stand-in includes nothing
#include "mlp.glsl"
#include "range.glsl"
#include "skip.glsl"
#endif
#include "brdf.glsl"

uniform int u_size;        // image width = height, pixels
uniform vec3 u_light;      // wi: unit vector towards the light
uniform float u_exposure;
uniform float u_ior;       // <= 0: Fresnel off

layout(location = 0) out vec4 out_exposed;
layout(location = 1) out vec4 out_network;

void main() {
    // gl_FragCoord is the pixel centre; GL rows count from the bottom, so GL row r is image row
    // size-1-r and y = -1 + (2r+1)/size is "up" already (the renderer flips rows on read-back).
    ivec2 pixel = ivec2(gl_FragCoord.xy);
    vec2 p = vec2(2 * pixel + 1) / float(u_size) - 1.0;
    float radius_squared = dot(p, p);
    if (!(radius_squared < 1.0)) {
        out_exposed = vec4(0.0);
        out_network = vec4(0.0);
        count_event(COUNTER_BACKGROUND);
        return;
    }
    count_event(COUNTER_FRAGMENTS);
    out_exposed = vec4(0.0, 0.0, 0.0, 1.0);
    out_network = vec4(0.0, 0.0, 0.0, 1.0);
    vec3 wo = vec3(p, sqrt(max(1.0 - radius_squared, 0.0)));  // clamp before sqrt
    vec3 key = -(u_light + wo);                                 // physics.md "Key vector"
    float a = a_term(u_light, wo, u_ior);  // 0 with the light below the horizon or at |w| <= 1e-6
    if (!(a > 0.0)) {
        count_event(COUNTER_SKIPPED_A_ZERO);
        return;
    }
#ifdef REFERENCE
    count_event(COUNTER_EVALUATIONS);
    vec3 xyz = reference_xyz(key);
#else
    encoding_set_key(key);
    if (skip_by_bound(u_exposure * a)) {
        count_event(COUNTER_SKIPPED_BOUND);
        return;
    }
    count_event(COUNTER_EVALUATIONS);
    vec3 xyz = range_inverse(mlp_evaluate());
#endif
    out_exposed = vec4(u_exposure * a * xyz, 1.0);
    out_network = vec4(xyz, 1.0);
}
#endif
