// Twin of shaders/brdf.glsl: the A-term of a BRDF (docs/physics.md eq. 5). A_TERM_MIN_W and A_TERM_MAX are
// generated from gratnet.brdf (W_EPSILON, A_MAX).

// R(theta)/R0 of a dielectric with real refractive index `ior`, the (n^2 - 1)^2 of R and R0 cancelled.
fn fresnel_ratio(cos_incidence: f32, ior: f32) -> f32 {
    let cos_i = clamp(cos_incidence, 0.0, 1.0);
    let sin_t_squared = (1.0 - cos_i * cos_i) / ior / ior;  // two divisions: ior^2 under/overflows
    var cos_t_squared = 1.0 - sin_t_squared;
    if (abs(ior - 1.0) < 0.5) {
        // Near n = 1, 1 - sin^2(theta_t) cancels at grazing angles; this is the same with n - 1 exact.
        cos_t_squared = (cos_i * cos_i + (ior - 1.0) * (ior + 1.0)) / (ior * ior);
    }
    if (cos_t_squared <= 0.0) {
        let total = (ior + 1.0) / (ior - 1.0);  // total internal reflection (ior < 1): R = 1
        return total * total;
    }
    let cos_t = sqrt(cos_t_squared);
    let s = (ior + 1.0) / (cos_i + ior * cos_t);
    let p = (ior + 1.0) / (ior * cos_i + cos_t);
    let q = cos_i * cos_i - sin_t_squared;
    let s2 = s * s;
    let qp2 = q * p * p;
    return 0.5 * (s2 * s2 + qp2 * qp2);
}

// eq. 5 for unit directions wi (to the light) and wo (to the viewer) in the surface frame.
fn a_term(wi: vec3<f32>, wo: vec3<f32>, ior: f32) -> f32 {
    let cos_i = wi.z;
    let cos_o = wo.z;
    let w = -(cos_i + cos_o);
    if (!(abs(w) > A_TERM_MIN_W) || !(cos_i > 0.0) || !(cos_o > 0.0)) {
        return 0.0;
    }
    // 1 + wi.wo = |wi + wo|^2 / 2 for unit vectors: no cancellation when the directions are nearly opposite.
    let k = wi + wo;
    let one_plus_cosine = 0.5 * dot(k, k);
    let geometry = one_plus_cosine * one_plus_cosine / (cos_i * cos_o);
    var ratio_squared = 1.0;
    if (ior > 0.0) {
        let cos_half = sqrt(clamp(0.5 * one_plus_cosine, 0.0, 1.0));  // cos(theta_h) = |wi + wo| / 2
        let ratio = fresnel_ratio(cos_half, ior);
        ratio_squared = min(ratio * ratio, A_TERM_MAX);  // inf (ior = 1 at a grazing half-vector) -> cap
    }
    return min(ratio_squared * geometry / (w * w), A_TERM_MAX);
}
