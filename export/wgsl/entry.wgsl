// ---- entry points (gratnet export; the GLSL module's, export/glsl.py) -----------------------------------------

// CIE XYZ of the D65-normalised reflectance (a flat mirror's specular peak has Y = 1) for unit vectors wi
// (towards the light) and wo (towards the viewer) in the tangent frame, z along the normal: the network at the
// key vector -(wi + wo), eq. 7's inverse applied; no A-term.
fn gratnet_reflectance(wi: vec3<f32>, wo: vec3<f32>) -> vec3<f32> {
    gratnet_set_layers();
    encoding_set_key(-(wi + wo));
    return range_inverse(mlp_evaluate());
}

// exposure * A(wi, wo) * S(wi, wo) * gratnet_reflectance(wi, wo): gratnet render's exposed XYZ of a mesh pixel for
// a directional light of irradiance 1, S being Smith's shadowing-masking for the material's slope covariance
// (brdf.wgsl's smith_shadowing, GRATNET_SLOPE_COVARIANCE; docs/physics.md "Shadowing and masking"). ior: the
// refractive index of the Fresnel factor (gratnet render's default 1.5; <= 0: no Fresnel). 0, without evaluating
// the network, where A * S = 0 (either direction at or below the horizon).
fn gratnet_shade(wi: vec3<f32>, wo: vec3<f32>, ior: f32, exposure: f32) -> vec3<f32> {
    let a = a_term(wi, wo, ior) * smith_shadowing(wi, wo, GRATNET_SLOPE_COVARIANCE);
    if (!(a > 0.0)) {
        return vec3<f32>(0.0);
    }
    return exposure * a * gratnet_reflectance(wi, wo);
}

// exposure * A(wi, wo) * gratnet_reflectance(wi, wo), without Smith's shadowing: the value of a BRDF slice
// (shaders/brdf_slice.glsl, gratnet render --slice, the paper's evaluation), which has no S. Same arguments and
// zeros as gratnet_shade.
fn gratnet_shade_unshadowed(wi: vec3<f32>, wo: vec3<f32>, ior: f32, exposure: f32) -> vec3<f32> {
    let a = a_term(wi, wo, ior);
    if (!(a > 0.0)) {
        return vec3<f32>(0.0);
    }
    return exposure * a * gratnet_reflectance(wi, wo);
}
