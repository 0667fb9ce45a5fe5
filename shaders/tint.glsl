// The colour of sampled light (issue 43; docs/physics.md "Environment light", "Colour"): exposed CIE XYZ under a
// linear sRGB tint, each sRGB channel scaled, as Mitsuba's RGB variants multiply a BSDF's value by an emitter's.
// Shared by the forward path (environment.glsl, in the fragment stage) and the deferred path's TINT kernel
// (deferred.glsl), so both tint alike; viewer/environment_light.py sets the matrices.

uniform mat3 u_xyz_to_rgb;  // CIE XYZ -> linear sRGB (gratnet.display)
uniform mat3 u_rgb_to_xyz;  // its inverse

// exposed XYZ under a linear sRGB tint (the identity for tint (1, 1, 1)).
vec3 environment_tint(vec3 xyz, vec3 tint) {
    return u_rgb_to_xyz * (tint * (u_xyz_to_rgb * xyz));
}
