// CIE XYZ -> linear sRGB -> exposure -> clip -> display sRGB (docs/physics.md "Colour spaces");
// mirrors gratnet.display. The matrix is colour-science's sRGB XYZ-to-RGB matrix, passed in at run
// time (column-major, as GLSL's mat3) so that no colorimetric constants are hard-coded here.

uniform mat3 u_xyz_to_linear_srgb;

vec3 xyz_to_linear_srgb(vec3 xyz) {
    return u_xyz_to_linear_srgb * xyz;
}

// The sRGB transfer function (IEC 61966-2-1) of a linear value in [0, 1].
float srgb_encode(float linear) {
    float c = clamp(linear, 0.0, 1.0);  // clamp before pow
    return c <= 0.0031308 ? 12.92 * c : 1.055 * pow(c, 1.0 / 2.4) - 0.055;
}

// Display sRGB in [0, 1] of an XYZ value: exposure, clip to [0, 1], transfer function.
vec3 xyz_to_display_srgb(vec3 xyz, float exposure) {
    vec3 linear = clamp(xyz_to_linear_srgb(xyz) * exposure, 0.0, 1.0);
    return vec3(srgb_encode(linear.r), srgb_encode(linear.g), srgb_encode(linear.b));
}
