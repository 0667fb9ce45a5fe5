// The A-term of a BRDF (docs/physics.md eq. 5); mirrors gratnet.brdf.a_term.
//   A(wi, wo) = min((R/R0)^2 G / w^2, A_TERM_MAX),  G = (1 + wi.wo)^2 / (cos(theta_i) cos(theta_o)),
// 0 for |w| <= 1e-6 or either direction at or below the horizon; R, R0: Fresnel at the half-vector
// angle and at normal incidence; ior <= 0 turns Fresnel off (R/R0 = 1).

const float A_TERM_MIN_W = 1e-6;
// Cap on A (gratnet.brdf.A_MAX): with exposure <= 1e10, exposure * A * XYZ stays within float32.
const float A_TERM_MAX = 1e26;

// R(theta)/R0 of a dielectric with real refractive index `ior` (gratnet.brdf.fresnel_ratio): the
// (n^2 - 1)^2 common to R and R0 is cancelled analytically, so the ratio stays exact as n -> 1
// (direct R/R0 in float32 was 12-57 % off within 1e-5 of 1) and has a limit at n = 1.
float fresnel_ratio(float cos_incidence, float ior) {
    float cos_i = clamp(cos_incidence, 0.0, 1.0);
    float sin_t_squared = (1.0 - cos_i * cos_i) / ior / ior;  // two divisions: ior^2 under/overflows
    float cos_t_squared = 1.0 - sin_t_squared;
    if (abs(ior - 1.0) < 0.5) {
        // Near n = 1, 1 - sin^2(theta_t) cancels at grazing angles; (cos^2 + (n - 1)(n + 1)) / n^2 is the
        // same quantity with n - 1 exact.
        cos_t_squared = (cos_i * cos_i + (ior - 1.0) * (ior + 1.0)) / (ior * ior);
    }
    if (cos_t_squared <= 0.0) {
        float total = (ior + 1.0) / (ior - 1.0);  // total internal reflection (ior < 1): R = 1
        return total * total;
    }
    float cos_t = sqrt(cos_t_squared);
    float s = (ior + 1.0) / (cos_i + ior * cos_t);
    float p = (ior + 1.0) / (ior * cos_i + cos_t);
    float q = cos_i * cos_i - sin_t_squared;
    float s2 = s * s;
    float qp2 = q * p * p;
    return 0.5 * (s2 * s2 + qp2 * qp2);
}

// eq. 5 for unit directions wi (to the light) and wo (to the viewer) in the surface frame.
float a_term(vec3 wi, vec3 wo, float ior) {
    float cos_i = wi.z;
    float cos_o = wo.z;
    float w = -(cos_i + cos_o);
    if (!(abs(w) > A_TERM_MIN_W) || !(cos_i > 0.0) || !(cos_o > 0.0)) {
        return 0.0;
    }
    // 1 + wi.wo = |wi + wo|^2 / 2 for unit vectors: a sum of squares, no cancellation when the two
    // directions are nearly opposite (grazing), where 1 + dot(wi, wo) would lose every digit.
    vec3 k = wi + wo;
    float one_plus_cosine = 0.5 * dot(k, k);
    float geometry = one_plus_cosine * one_plus_cosine / (cos_i * cos_o);
    float ratio_squared = 1.0;
    if (ior > 0.0) {
        float cos_half = sqrt(clamp(0.5 * one_plus_cosine, 0.0, 1.0));  // cos(theta_h) = |wi + wo| / 2
        float ratio = fresnel_ratio(cos_half, ior);
        ratio_squared = min(ratio * ratio, A_TERM_MAX);  // inf (ior = 1 at a grazing half-vector) -> cap
    }
    return min(ratio_squared * geometry / (w * w), A_TERM_MAX);
}

// Smith's Lambda for a Gaussian (Beckmann) slope distribution of covariance (Sxx, Sxy, Syy) = slope_covariance
// (gratnet.shadowing.smith_lambda): a = cos(theta) / sqrt(2 w_xy^T S w_xy); erf by Abramowitz & Stegun 7.1.26,
// written as exp(-a^2)/2 * (1/(a sqrt(pi)) - t P(t)) so that nothing cancels or overflows. 0 with no slope
// along the direction or at normal incidence; the caller handles the horizon.
float smith_lambda(vec3 w, vec3 slope_covariance) {
    float projected = max(w.x * w.x * slope_covariance.x + 2.0 * w.x * w.y * slope_covariance.y
                          + w.y * w.y * slope_covariance.z, 0.0);
    float spread = sqrt(2.0 * projected);
    if (!(spread > 0.0)) {
        return 0.0;
    }
    float a = w.z / spread;
    float t = 1.0 / (1.0 + 0.3275911 * a);
    float polynomial = t * (0.254829592 + t * (-0.284496736 + t * (1.421413741 + t * (-1.453152027
                                                                                      + t * 1.061405429))));
    return max(0.5 * exp(-a * a) * (0.5641895835477563 / a - polynomial), 0.0);
}

// Smith's height-correlated shadowing-masking S = 1 / (1 + Lambda(wi) + Lambda(wo)) (gratnet.shadowing,
// physics.md "Shadowing and masking"); 0 with either direction at or below the horizon; 1 for a zero covariance.
float smith_shadowing(vec3 wi, vec3 wo, vec3 slope_covariance) {
    if (!(wi.z > 0.0) || !(wo.z > 0.0)) {
        return 0.0;
    }
    return 1.0 / (1.0 + smith_lambda(wi, slope_covariance) + smith_lambda(wo, slope_covariance));
}
