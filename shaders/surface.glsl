// Program: a mesh lit by one light, shaded by the network (docs/physics.md "Key vector", eq. 5-7).
// Vertex stage: world-space position, normal and tangent (viewer/meshes.py: unit tangent along the
// height field's x, bitangent = cross(normal, tangent)) -> clip space through u_view_projection.
// Fragment stage: tangent frame from the interpolated normal and tangent (re-orthonormalised; a
// degenerate tangent is replaced by one perpendicular to the normal); wi (to the light) and wo (to the
// eye) in that frame; key = -(wi + wo); output 0 (RGBA32F) = exposure * irradiance * A(wi, wo) * XYZ(key)
// (exposed CIE XYZ, linear) with alpha = 1 (coverage; the renderer clears to 0). Back faces, wi or wo
// at or below the tangent plane, or a degenerate frame give XYZ 0 (never NaN). Output 1 (when a second
// attachment is bound; tests and debugging): the key vector and A, 0 for back faces.
// Work skipped (issue 5): the MLP runs only where A > 0 and the bound of skip.glsl says the display could
// show something. Depth pre-pass: the renderer draws once with this program compiled with DEPTH_ONLY (an
// empty fragment stage, no MLP; colour writes masked), then again with depth func LEQUAL, so early fragment
// tests let only the visible surface run the shading code: one MLP per pixel, no overdraw. A separate
// program, not a uniform and an early return: llvmpipe runs straight-line code such as the baked MLP even
// for fragments that have returned, so a uniform-selected depth pass cost a full shading pass.
// Deferred path (issue 12): compiled with GBUFFER, the fragment stage stops before the network and writes
// (key, exposure * irradiance * A) for shaders/deferred.glsl to evaluate; see surface_inputs below. With
// ENVIRONMENT too, output 1 takes the pass's tint (deferred.glsl's TINT applies it after the network).
// Reference renders (gratnet render --reference): compiled with REFERENCE, the ground-truth volume's look-up
// (reference.glsl) takes the network's place; everything else is the same code.
// Needs the defines of mlp.glsl and encoding.glsl; the codes (COUNTER_*, LIGHT_*) come from codes.glsl.

#include "codes.glsl"

#ifdef VERTEX_SHADER
in vec3 in_position;  // metres, world space
in vec3 in_normal;
in vec3 in_tangent;

uniform mat4 u_view_projection;  // world -> clip (viewer/camera.py)

out vec3 v_position;
out vec3 v_normal;
out vec3 v_tangent;

invariant gl_Position;  // both passes of the depth pre-pass must produce bit-identical depths

void main() {
    v_position = in_position;
    v_normal = in_normal;
    v_tangent = in_tangent;
    gl_Position = u_view_projection * vec4(in_position, 1.0);
}
#endif

#if defined(FRAGMENT_SHADER) && defined(DEPTH_ONLY)
// The depth pre-pass: the vertex stage above writes gl_Position (invariant), the fixed-function depth test
// writes the depth; nothing to shade.
void main() {
}
#elif defined(FRAGMENT_SHADER)
precision highp float;
precision highp int;

#include "brdf.glsl"
#ifndef GBUFFER
// Included outside the REFERENCE choice: the preprocessor (viewer/glsl.py) includes a file once, wherever the
// first #include of it stands, #if or not.
#include "encoding.glsl"
#include "counters.glsl"
#ifdef REFERENCE
#include "reference.glsl"  // the ground-truth volume in place of the network
#else
#include "featuregrid.glsl"  // before mlp.glsl: its baked stand-in includes nothing
#include "mlp.glsl"
#include "range.glsl"
#include "skip.glsl"
#endif
#endif

// Depth (and stencil) tests before the shader runs: occluded fragments never evaluate the MLP. The
// shader writes no depth and never discards, so this changes no pixel.
layout(early_fragment_tests) in;

uniform vec3 u_eye;              // camera position, metres
uniform float u_exposure;
uniform float u_ior;             // <= 0: Fresnel off
uniform vec3 u_slope_covariance; // the relief's slopes (Sxx, Sxy, Syy): Smith's shadowing; 0: none

in vec3 v_position;
in vec3 v_normal;
in vec3 v_tangent;

layout(location = 0) out vec4 out_exposed;
layout(location = 1) out vec4 out_key;  // (key, A); GBUFFER with ENVIRONMENT: (tint, 0)
#if defined(GBUFFER) && defined(ENVIRONMENT)
layout(location = 2) out vec4 out_offset;  // the control variate's term, exposed linear sRGB (environment.glsl)
#endif

// A unit tangent perpendicular to unit n (Duff et al. 2017; viewer.meshes.arbitrary_tangents).
vec3 arbitrary_tangent(vec3 n) {
    float s = n.z >= 0.0 ? 1.0 : -1.0;
    float a = -1.0 / (s + n.z);
    return normalize(vec3(1.0 + s * n.x * n.x * a, s * n.x * n.y * a, -s * n.x));
}

// v / |v|, or 0 when |v| is 0 or not finite (normalize would give NaN).
vec3 safe_normalize(vec3 v) {
    float length_squared = dot(v, v);
    return length_squared > 1e-30 && length_squared < 1e30 ? v * inversesqrt(length_squared) : vec3(0.0);
}

#include "lights.glsl"  // the light: u_light_kind, u_light, u_light_intensity -> light_incidence
#ifdef ENVIRONMENT
#include "environment.glsl"  // an environment map, sampled per pass (environment_incidence)
#endif

// The shading inputs of this fragment: the key vector, A(wi, wo), and the factor that multiplies the
// network's XYZ, exposure * irradiance * A (0 when nothing lights the point: back face, either direction
// at or below the horizon, a degenerate frame, no irradiance). Returns false when the factor is 0.
// `tint`: the light's linear sRGB colour on top of the factor (environment_tint; (1, 1, 1) but under an
// environment).
bool surface_inputs(out vec3 key, out float a, out float factor, out vec3 tint) {
    key = vec3(0.0);
    a = 0.0;
    factor = 0.0;
    tint = vec3(1.0);
    vec3 n = safe_normalize(v_normal);
    if (!gl_FrontFacing || n == vec3(0.0)) {
        return false;  // back face or no frame: A = 0
    }
    vec3 t = v_tangent - dot(v_tangent, n) * n;  // Gram-Schmidt: interpolation tilts the tangent
    t = dot(t, t) > 1e-12 ? normalize(t) : arbitrary_tangent(n);
    vec3 b = cross(n, t);
    mat3 world_to_tangent = transpose(mat3(t, b, n));  // rows t, b, n

    vec3 wo_world = safe_normalize(u_eye - v_position);
    vec3 wo = world_to_tangent * wo_world;
    vec3 wi_world;
    float irradiance;
#ifdef ENVIRONMENT
    environment_incidence(v_position, world_to_tangent, wo, wi_world, irradiance, tint);
#else
    light_incidence(v_position, wi_world, irradiance);
#endif
    vec3 wi = world_to_tangent * wi_world;
    key = -(wi + wo);  // physics.md "Key vector"
    // eq. 5 times Smith's shadowing (physics.md "Shadowing and masking"): 0 below either horizon, at |w| <= 1e-6,
    // or for a zero vector
    a = a_term(wi, wo, u_ior) * smith_shadowing(wi, wo, u_slope_covariance);
    if (!(a > 0.0) || !(irradiance > 0.0)) {
        return false;  // nothing to light
    }
    factor = u_exposure * irradiance * a;
    return true;
}

#ifdef GBUFFER
// The deferred path's G-buffer (viewer/deferred.py): (key, factor) per covered pixel; the renderer clears
// to (0, 0, 0, -1), so factor < 0 marks the background. No network here: deferred.glsl evaluates it.
// Under sampled light, output 1 holds the tint where the pixel is lit, else 0 (the forward path tints only
// lit pixels: an unlit one's tint may be anything, even inf, and 0 keeps TINT's product 0).
void main() {
    vec3 key;
    float a;
    float factor;
    vec3 tint;
    bool lit = surface_inputs(key, a, factor, tint);
    out_exposed = vec4(key, factor);
#ifdef ENVIRONMENT
    out_key = vec4(lit ? tint : vec3(0.0), 0.0);
    out_offset = vec4(u_exposure * g_environment_offset, 0.0);  // lit or not, as the forward path adds it
#endif
}
#else
void main() {
    count_event(COUNTER_FRAGMENTS);
    out_exposed = vec4(0.0, 0.0, 0.0, 1.0);  // covered, no light (yet)
    vec3 key;
    float a;
    float factor;
    vec3 tint;
    bool lit = surface_inputs(key, a, factor, tint);
    out_key = vec4(key, a);
#ifdef ENVIRONMENT
    // the control variate's term (environment.glsl), whether or not the kept direction lights the point
    out_exposed = vec4(u_exposure * (u_rgb_to_xyz * g_environment_offset), 1.0);
#endif
    if (!lit) {
        count_event(COUNTER_SKIPPED_A_ZERO);
        return;  // and skip the network: nothing to light
    }
#ifdef REFERENCE
    count_event(COUNTER_EVALUATIONS);
    vec3 xyz = reference_xyz(key);
#else
    encoding_set_key(key);
    if (skip_by_bound(factor)) {  // never under an environment: one pass's sample is not the pixel
        count_event(COUNTER_SKIPPED_BOUND);
        return;  // the display would show 0 whatever the network says
    }
    count_event(COUNTER_EVALUATIONS);
    vec3 xyz = range_inverse(mlp_evaluate());
#endif
#ifdef ENVIRONMENT
    out_exposed.xyz += environment_tint(factor * xyz, tint);
#else
    out_exposed = vec4(factor * xyz, 1.0);
#endif
}
#endif
#endif
