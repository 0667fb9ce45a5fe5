// Twin of shaders/brdf.glsl: the A-term of a BRDF (docs/physics.md eq. 5) and Smith's shadowing-masking
// (physics.md "Shadowing and masking"). A_TERM_MIN_W and A_TERM_MAX are generated from gratnet.brdf (W_EPSILON,
// A_MAX); the erf approximation's constants are brdf.glsl's (gratnet.shadowing's), as brdf.glsl types them
// (tests/tools/test_export_wgsl.py holds the two texts to the same numbers).

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

// Smith's Lambda for a Gaussian (Beckmann) slope distribution of covariance (Sxx, Sxy, Syy) = slope_covariance
// (gratnet.shadowing.smith_lambda): a = cos(theta) / sqrt(2 w_xy^T S w_xy); erf by Abramowitz & Stegun 7.1.26,
// written as exp(-a^2)/2 * (1/(a sqrt(pi)) - t P(t)) so that nothing cancels or overflows. 0 with no slope
// along the direction or at normal incidence; the caller handles the horizon.
fn smith_lambda(w: vec3<f32>, slope_covariance: vec3<f32>) -> f32 {
    let projected = max(w.x * w.x * slope_covariance.x + 2.0 * w.x * w.y * slope_covariance.y
                        + w.y * w.y * slope_covariance.z, 0.0);
    let spread = sqrt(2.0 * projected);
    if (!(spread > 0.0)) {
        return 0.0;
    }
    let a = w.z / spread;
    let t = 1.0 / (1.0 + 0.3275911 * a);
    let polynomial = t * (0.254829592 + t * (-0.284496736 + t * (1.421413741 + t * (-1.453152027
                                                                                  + t * 1.061405429))));
    return max(0.5 * exp(-a * a) * (0.5641895835477563 / a - polynomial), 0.0);
}

// Smith's height-correlated shadowing-masking S = 1 / (1 + Lambda(wi) + Lambda(wo)) (gratnet.shadowing,
// physics.md "Shadowing and masking"); 0 with either direction at or below the horizon; 1 for a zero covariance.
fn smith_shadowing(wi: vec3<f32>, wo: vec3<f32>, slope_covariance: vec3<f32>) -> f32 {
    if (!(wi.z > 0.0) || !(wo.z > 0.0)) {
        return 0.0;
    }
    return 1.0 / (1.0 + smith_lambda(wi, slope_covariance) + smith_lambda(wo, slope_covariance));
}
