// The light of a mesh render: one kind of gratnet/lights.py's registry, set by its uniforms (LightKind.uniforms).
// light_incidence is the registry's `incidence` in GLSL, one branch per kind on the generated LIGHT_* codes; a new
// kind adds its branch here (and its uniforms, if any). Needs safe_normalize (surface.glsl defines it first).

#include "codes.glsl"

uniform int u_light_kind;        // LIGHT_* (gratnet/lights.py)
uniform vec3 u_light;            // directional: unit vector towards the light; point: its position
uniform float u_light_intensity; // directional: irradiance scale; point: at 1 m (falls off as 1/d^2)

// The unit world direction from `position` towards the light and the irradiance there (0: no light reaches it).
void light_incidence(vec3 position, out vec3 wi_world, out float irradiance) {
    if (u_light_kind == LIGHT_POINT) {
        vec3 offset = u_light - position;
        float distance_squared = dot(offset, offset);
        wi_world = safe_normalize(offset);
        irradiance = distance_squared > 0.0 ? u_light_intensity / distance_squared : 0.0;
    } else {  // LIGHT_DIRECTIONAL
        wi_world = u_light;
        irradiance = u_light_intensity;
    }
}
