// The A-term of a BRDF (docs/physics.md eq. 5); mirrors gratnet.brdf.a_term.
//   A(wi, wo) = R^2 G / (R0^2 w^2),  G = (1 + wi.wo)^2 / (cos(theta_i) cos(theta_o)),
// 0 for |w| <= 1e-6 or either direction at or below the horizon; R, R0: Fresnel at the half-vector
// angle and at normal incidence; ior <= 0 turns Fresnel off (R/R0 = 1).

const float A_TERM_MIN_W = 1e-6;

// Unpolarised Fresnel reflectance of a dielectric with real refractive index `ior` at cos(theta).
float fresnel_dielectric(float cos_incidence, float ior) {
    float cos_i = clamp(cos_incidence, 0.0, 1.0);
    float sin_t_squared = (1.0 - cos_i * cos_i) / (ior * ior);
    if (sin_t_squared >= 1.0) {
        return 1.0;  // total internal reflection (ior < 1)
    }
    float cos_t = sqrt(max(1.0 - sin_t_squared, 0.0));  // clamp before sqrt
    float perpendicular = (cos_i - ior * cos_t) / max(cos_i + ior * cos_t, 1e-30);
    float parallel = (ior * cos_i - cos_t) / max(ior * cos_i + cos_t, 1e-30);
    return 0.5 * (perpendicular * perpendicular + parallel * parallel);
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
    float fresnel_ratio = 1.0;
    if (ior > 0.0) {
        float cos_half = sqrt(clamp(0.5 * one_plus_cosine, 0.0, 1.0));  // cos(theta_h) = |wi + wo| / 2
        float ratio = fresnel_dielectric(cos_half, ior) / fresnel_dielectric(1.0, ior);
        fresnel_ratio = ratio * ratio;
    }
    return fresnel_ratio * geometry / (w * w);
}
