// Area lights (issue 43; gratnet/area_lights.py, docs/physics.md "Area lights"): rectangles and spheres of constant
// linear sRGB radiance, sampled by solid angle. One branch per kind on the generated AREA_* codes; a new kind adds
// its branches here. gratnet.area_lights holds the numpy twins (radiance_towards, solid_angle_pdf).
// Included by environment.glsl; no visibility: a light neither shadows the surface nor hides another light.

#include "codes.glsl"  // the AREA_* codes and MAX_AREA_LIGHTS (gratnet.area_lights)

#define PI_AREA 3.14159265358979

uniform int u_area_count;                          // lights in use, 0 … MAX_AREA_LIGHTS
uniform int u_area_kind[MAX_AREA_LIGHTS];          // AREA_RECT or AREA_SPHERE
uniform vec3 u_area_centre[MAX_AREA_LIGHTS];       // metres, world
uniform vec3 u_area_axis_u[MAX_AREA_LIGHTS];       // rect: half width vector (m); sphere: (radius, 0, 0)
uniform vec3 u_area_axis_v[MAX_AREA_LIGHTS];       // rect: half height vector (m), u x v the emitting normal
uniform vec3 u_area_radiance[MAX_AREA_LIGHTS];     // W m^-2 sr^-1, linear sRGB

// 1 - cos(theta_max) of a sphere seen at sin^2(theta_max) = r^2 / d^2 = s, without cancellation: s / (1 + sqrt(1 - s))
// (a sphere far away subtends s below float32's epsilon).
float sphere_cap(float s) {
    return s / (1.0 + sqrt(max(1.0 - s, 0.0)));
}

// The solid-angle density of sampling light i towards unit direction `dir` from `position` (0: the ray misses
// it, meets a rectangle's back, or starts inside a sphere). Its radiance there is u_area_radiance[i] when > 0.
float area_pdf(int i, vec3 position, vec3 dir) {
    vec3 centre = u_area_centre[i];
    vec3 u = u_area_axis_u[i];
    if (u_area_kind[i] == AREA_SPHERE) {
        float radius = u.x;
        vec3 offset = centre - position;
        float distance_squared = dot(offset, offset);
        vec3 across = cross(offset, dir);  // |.| = the ray's distance from the centre times |offset| / |offset|
        if (!(distance_squared > radius * radius) || dot(offset, dir) <= 0.0 || dot(across, across) > radius * radius) {
            return 0.0;
        }
        return 1.0 / (2.0 * PI_AREA * sphere_cap(radius * radius / distance_squared));
    }
    // AREA_RECT
    vec3 v = u_area_axis_v[i];
    vec3 normal_area = cross(u, v);  // |.| = a quarter of the area
    float quarter_area = length(normal_area);
    vec3 normal = normal_area / quarter_area;
    float facing = -dot(dir, normal);
    if (!(facing > 0.0)) {
        return 0.0;
    }
    float distance = dot(position - centre, normal) / facing;
    if (!(distance > 0.0)) {
        return 0.0;
    }
    vec3 offset = position + distance * dir - centre;
    if (abs(dot(offset, u)) > dot(u, u) || abs(dot(offset, v)) > dot(v, v)) {
        return 0.0;
    }
    return distance * distance / (4.0 * quarter_area * facing);
}

// A unit direction towards light i from `position` and its solid-angle density (pdf 0: no sample).
vec3 sample_area(int i, vec3 position, vec2 xi, out float pdf) {
    vec3 centre = u_area_centre[i];
    vec3 u = u_area_axis_u[i];
    pdf = 0.0;
    if (u_area_kind[i] == AREA_SPHERE) {  // uniform in the subtended cone
        float radius = u.x;
        vec3 offset = centre - position;
        float distance_squared = dot(offset, offset);
        if (!(distance_squared > radius * radius)) {
            return vec3(0.0, 0.0, 1.0);
        }
        float one_minus = sphere_cap(radius * radius / distance_squared);
        float drop = xi.x * one_minus;  // 1 - cos(theta), uniform in the cap
        float cos_theta = 1.0 - drop;
        float sin_theta = sqrt(max(drop * (2.0 - drop), 0.0));
        float phi = 2.0 * PI_AREA * xi.y;
        vec3 axis = offset * inversesqrt(distance_squared);
        vec3 helper = abs(axis.x) > 0.9 ? vec3(0.0, 1.0, 0.0) : vec3(1.0, 0.0, 0.0);
        vec3 t = normalize(cross(helper, axis));
        vec3 b = cross(axis, t);
        pdf = 1.0 / (2.0 * PI_AREA * one_minus);
        return normalize(sin_theta * cos(phi) * t + sin_theta * sin(phi) * b + cos_theta * axis);
    }
    // AREA_RECT: uniform by area, density d^2 / (A cos theta_light)
    vec3 v = u_area_axis_v[i];
    vec3 normal_area = cross(u, v);
    float quarter_area = length(normal_area);
    vec3 target = centre + (2.0 * xi.x - 1.0) * u + (2.0 * xi.y - 1.0) * v;
    vec3 offset = target - position;
    float distance_squared = dot(offset, offset);
    vec3 dir = offset * inversesqrt(distance_squared);
    float facing = -dot(dir, normal_area / quarter_area);
    if (facing > 0.0) {
        pdf = distance_squared / (4.0 * quarter_area * facing);
    }
    return dir;
}
