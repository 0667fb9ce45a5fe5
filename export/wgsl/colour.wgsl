// Twin of shaders/colour.glsl: CIE XYZ -> linear sRGB -> exposure -> clip -> display sRGB (docs/physics.md
// "Colour spaces"). u_xyz_to_linear_srgb is colour-science's matrix, generated (column-major, as mat3x3).

fn xyz_to_linear_srgb(xyz: vec3<f32>) -> vec3<f32> {
    return u_xyz_to_linear_srgb * xyz;
}

// The sRGB transfer function (IEC 61966-2-1) of a linear value in [0, 1].
fn srgb_encode(linear: f32) -> f32 {
    let c = clamp(linear, 0.0, 1.0);  // clamp before pow
    return select(1.055 * pow(c, 1.0 / 2.4) - 0.055, 12.92 * c, c <= 0.0031308);
}

// Display sRGB in [0, 1] of an XYZ value: exposure, clip to [0, 1], transfer function.
fn xyz_to_display_srgb(xyz: vec3<f32>, exposure: f32) -> vec3<f32> {
    let linear = clamp(xyz_to_linear_srgb(xyz) * exposure, vec3<f32>(0.0), vec3<f32>(1.0));
    return vec3<f32>(srgb_encode(linear.r), srgb_encode(linear.g), srgb_encode(linear.b));
}
