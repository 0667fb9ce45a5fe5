// Inverse range transform: network outputs y -> CIE XYZ (docs/physics.md eq. 7, including the
// multiplication by the D65 white of eq. 3); mirrors gratnet.encoding.range_inverse.

#include "codes.glsl"  // RANGE_*

uniform int u_range_kind;     // RANGE_*
uniform float u_range_bits;   // B
uniform float u_range_power;  // n (power-log only)
uniform vec3 u_range_white;   // XYZ of a perfect mirror

// e^z - 1 without the cancellation of exp(z) - 1 near 0 (log1p kind, small y).
float expm1_accurate(float z) {
    if (abs(z) < 0.25) {
        // Taylor series to z^7: truncation < 2e-9 relative for |z| < 0.25.
        return z * (1.0 + z / 2.0 * (1.0 + z / 3.0 * (1.0 + z / 4.0 * (1.0 + z / 5.0 * (1.0 + z / 6.0 * (1.0 + z / 7.0))))));
    }
    return exp2(z * 1.4426950408889634) - 1.0;  // cancellation at most 4.5x here
}

// eq. 7 inverted: power-log x = 2^(B (y^(1/n) - 1)), log x = 2^(B (y - 1)) for y in (0, 1] (y <= 0 -> 0),
// log1p x = 2^y - 1 for y >= 0; then x * XYZ_white.
vec3 range_inverse(vec3 y) {
    vec3 x;
    if (u_range_kind == RANGE_LOG1P) {
        vec3 z = max(y, 0.0) * 0.6931471805599453;  // y ln 2
        x = max(vec3(expm1_accurate(z.x), expm1_accurate(z.y), expm1_accurate(z.z)), 0.0);
    } else {
        vec3 clipped = clamp(y, 0.0, 1.0);  // clamp before pow
        vec3 root = u_range_kind == RANGE_POWER_LOG ? pow(clipped, vec3(1.0 / u_range_power)) : clipped;
        x = exp2(u_range_bits * (root - 1.0));
        x = vec3(clipped.x > 0.0 ? x.x : 0.0, clipped.y > 0.0 ? x.y : 0.0, clipped.z > 0.0 ? x.z : 0.0);
    }
    return x * u_range_white;
}
