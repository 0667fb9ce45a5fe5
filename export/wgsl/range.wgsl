// Twin of shaders/range.glsl: network outputs y -> CIE XYZ (docs/physics.md eq. 7 inverted, times the D65 white).

// e^z - 1 without the cancellation of exp(z) - 1 near 0 (log1p kind, small y).
fn expm1_accurate(z: f32) -> f32 {
    if (abs(z) < 0.25) {
        // Taylor series to z^7: truncation < 2e-9 relative for |z| < 0.25.
        return z * (1.0 + z / 2.0 * (1.0 + z / 3.0 * (1.0 + z / 4.0 * (1.0 + z / 5.0 * (1.0 + z / 6.0 * (1.0 + z / 7.0))))));
    }
    return exp2(z * 1.4426950408889634) - 1.0;  // cancellation at most 4.5x here
}

// eq. 7 inverted: power-log x = 2^(B (y^(1/n) - 1)), log x = 2^(B (y - 1)) for y in (0, 1] (y <= 0 -> 0),
// log1p x = 2^y - 1 for y >= 0; then x * XYZ_white.
fn range_inverse(y: vec3<f32>) -> vec3<f32> {
    var x: vec3<f32>;
    if (u_range_kind == RANGE_LOG1P) {
        let z = max(y, vec3<f32>(0.0)) * 0.6931471805599453;  // y ln 2
        x = max(vec3<f32>(expm1_accurate(z.x), expm1_accurate(z.y), expm1_accurate(z.z)), vec3<f32>(0.0));
    } else {
        let clipped = clamp(y, vec3<f32>(0.0), vec3<f32>(1.0));  // clamp before pow
        var root = clipped;
        if (u_range_kind == RANGE_POWER_LOG) {
            root = pow(clipped, vec3<f32>(1.0 / u_range_power));
        }
        x = exp2(u_range_bits * (root - 1.0));
        x = select(vec3<f32>(0.0), x, clipped > vec3<f32>(0.0));
    }
    return x * u_range_white;
}
