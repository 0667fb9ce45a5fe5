// Sampled light (issue 43; docs/physics.md "Environment light", "Area lights"): a lat-long map of linear sRGB
// radiance and area lights (area_lights.glsl) integrated over the hemisphere by multiple importance sampling, one
// sample per fragment and render pass.
//
// Compiled into surface.glsl with ENVIRONMENT. Each pass k draws one sample per pixel with one of M
// strategies, chosen in turn: strategy (k + o) mod M with o a per-pixel offset, so any M consecutive passes
// use every strategy once at each pixel, and any one pass is an unbiased one-sample estimate:
//   light sampling: a direction from the environment's luminance distribution (gratnet.environment), or
//      towards one area light by its solid angle (area_lights.glsl), one strategy per emitter;
//   material sampling: a key (u, v) from the material's own importance table (gratnet.importance),
//      i.e. a light direction wi.xy = -(u, v) - wo.xy in the tangent frame, with a defensive cosine share;
//   the delta light (with one of intensity > 0): the directional or point light of lights.glsl.
// u_environment_sampling (gratnet.codes.ENVIRONMENT_SAMPLING) chooses both environment strategies weighted by
// the power heuristic (SAMPLING_MIS; Veach 1997, eq. 9.13 with beta = 2) or one alone (weight 1). A pass
// contributes M * w_s * L(wi) / p_s(wi) as the "irradiance" of the fragment's light, so the mean over passes
// is the integral of A * XYZ * L over the light's directions (physics.md eq. 9) plus the delta light.
// Colour: L is linear sRGB; the fragment's XYZ is taken to linear sRGB, multiplied channel by channel and
// taken back (tint.glsl's environment_tint), as Mitsuba's RGB variants multiply the BSDF's value by the emitter's.
//
// Needs lights.glsl (light_incidence); includes sampling.glsl and the generated codes.

#include "codes.glsl"
#include "sampling.glsl"
#include "area_lights.glsl"
#include "tint.glsl"  // environment_tint and its matrices

#define ENVIRONMENT_PI 3.14159265358979

uniform highp sampler2D u_environment;        // RGBA32F (W, H), linear sRGB radiance (scale applied), row 0: zenith
uniform highp sampler2D u_environment_table;  // its luminance distribution (sampling.glsl), W x (H - 1) cells
uniform highp sampler2D u_material_table;     // the material's (u, v) distribution (sampling.glsl)
uniform ivec2 u_environment_cells;            // the distribution's (columns W, rows H - 1)
uniform ivec2 u_material_cells;               // (columns: u, rows: v)
uniform vec2 u_environment_rotation;          // (cos, sin) of the map's rotation about world +z
uniform vec2 u_material_key_range;            // (key_min, key_max): the table's u and v span
uniform float u_defensive_share;              // share of cosine-weighted material samples (gratnet.importance)
uniform int u_sample_index;                   // the render pass (sample) index k
uniform ivec2 u_pixel_origin;                 // this target's place in the whole picture (a band of it: viewer)
uniform uint u_seed;                          // the render's seed
uniform int u_environment_sampling;           // SAMPLING_MIS, SAMPLING_LIGHT, SAMPLING_MATERIAL or SAMPLING_RESAMPLED
uniform bool u_delta_light;                   // the delta light of lights.glsl takes its turn too
uniform bool u_has_environment;               // false: area lights only (the map's textures are placeholders)
uniform int u_candidates;                     // SAMPLING_RESAMPLED: candidates per pass, 1 .. MAX_CANDIDATES
uniform int u_material_candidates;           // SAMPLING_RESAMPLED: how many of them material sampling draws
uniform highp sampler2D u_material_colour;    // the control variate's colour table: linear sRGB over the (u, v) cells,
                                              // u_colour_slices w slices stacked in rows (gratnet.importance)
uniform bool u_control_variate;               // SAMPLING_RESAMPLED: the colour table is the material's own
uniform int u_colour_slices;                  // slice j at t = (j + 0.5) / u_colour_slices
// This pass's control-variate term (linear sRGB, M * (H - h(y) * W): resample_environment), added after the network.
vec3 g_environment_offset = vec3(0.0);

// The map's unit-square point (x: azimuth, y: polar angle / pi) of a world direction (gratnet.environment).
vec2 environment_point(vec3 world) {
    vec2 c = u_environment_rotation;
    vec3 local = vec3(c.x * world.x + c.y * world.y, -c.y * world.x + c.x * world.y, world.z);  // Rz(-rotation)
    float x = atan(local.x, local.y) * (0.5 / ENVIRONMENT_PI);
    return vec2(x - floor(x), acos(clamp(local.z, -1.0, 1.0)) / ENVIRONMENT_PI);
}

// The world direction of a unit-square point of the map, and sin(theta) there.
vec3 environment_direction(vec2 point, out float sin_theta) {
    float theta = ENVIRONMENT_PI * point.y;
    float phi = 2.0 * ENVIRONMENT_PI * point.x;
    sin_theta = sin(theta);
    vec3 local = vec3(sin_theta * sin(phi), sin_theta * cos(phi), cos(theta));
    vec2 c = u_environment_rotation;
    return vec3(c.x * local.x - c.y * local.y, c.y * local.x + c.x * local.y, local.z);  // Rz(rotation)
}

// The radiance towards world direction `world` (linear sRGB), Mitsuba 3's envmap lookup exactly
// (gratnet.environment.Environment.radiance): columns centred at x = (c + 1/2)/W and wrapping, rows at
// y = r/(H - 1) (row 0 at the zenith, row H - 1 at the nadir), bilinear between them.
vec3 environment_radiance(vec3 world) {
    vec2 point = environment_point(world);
    ivec2 size = textureSize(u_environment, 0);  // (W, H)
    float u = point.x - 0.5 / float(size.x);
    float s = (u - floor(u)) * float(size.x);
    int x0 = min(int(floor(s)), size.x - 1);
    float fx = s - float(x0);
    int x1 = x0 + 1 == size.x ? 0 : x0 + 1;
    float t = point.y * float(size.y - 1);
    int y0 = clamp(int(floor(t)), 0, size.y - 2);
    float fy = t - float(y0);
    int y1 = y0 + 1;
    vec3 top = mix(texelFetch(u_environment, ivec2(x0, y0), 0).rgb, texelFetch(u_environment, ivec2(x1, y0), 0).rgb,
                   fx);
    vec3 bottom = mix(texelFetch(u_environment, ivec2(x0, y1), 0).rgb,
                      texelFetch(u_environment, ivec2(x1, y1), 0).rgb, fx);
    return mix(top, bottom, fy);
}

// The solid-angle density of light sampling at world direction `world`.
float environment_pdf(vec3 world) {
    vec2 point = environment_point(world);
    float sin_theta = sin(ENVIRONMENT_PI * point.y);
    if (!(sin_theta > 0.0)) {
        return 0.0;
    }
    return piecewise_density(u_environment_table, u_environment_cells, point)
           / (2.0 * ENVIRONMENT_PI * ENVIRONMENT_PI * sin_theta);
}

// A world direction from the environment's distribution and its solid-angle density (0: none).
vec3 sample_environment(vec2 xi, out float pdf) {
    float density;
    vec2 point = sample_piecewise(u_environment_table, u_environment_cells, xi, density);
    float sin_theta;
    vec3 world = environment_direction(point, sin_theta);
    pdf = sin_theta > 0.0 ? density / (2.0 * ENVIRONMENT_PI * ENVIRONMENT_PI * sin_theta) : 0.0;
    return world;
}

// The solid-angle density of material sampling of light direction wi for view wo (tangent frame).
float material_pdf(vec3 wo, vec3 wi) {
    if (!(wi.z > 0.0)) {
        return 0.0;
    }
    float span = u_material_key_range.y - u_material_key_range.x;
    vec2 point = (-(wi.xy + wo.xy) - u_material_key_range.x) / span;
    float table = piecewise_density(u_material_table, u_material_cells, point) / (span * span);
    return ((1.0 - u_defensive_share) * table + u_defensive_share / ENVIRONMENT_PI) * wi.z;
}

// A light direction (tangent frame) from the material's distribution for view wo; false when the sampled
// key leaves the hemisphere (no light from there). gratnet.importance.MaterialTable.sample.
bool sample_material(vec3 wo, vec3 xi, out vec3 wi) {
    if (xi.x < u_defensive_share) {  // cosine-weighted: radius sqrt(xi.y), azimuth 2 pi xi.z
        float radius = sqrt(xi.y);
        float phi = 2.0 * ENVIRONMENT_PI * xi.z;
        wi = vec3(radius * cos(phi), radius * sin(phi), sqrt(max(1.0 - xi.y, 0.0)));
        return wi.z > 0.0;
    }
    float density;
    vec2 point = sample_piecewise(u_material_table, u_material_cells, xi.yz, density);  // xi.x chose the branch
    vec2 uv = u_material_key_range.x + (u_material_key_range.y - u_material_key_range.x) * point;
    vec2 planar = -uv - wo.xy;
    float planar_squared = dot(planar, planar);
    wi = vec3(planar, sqrt(max(1.0 - planar_squared, 0.0)));
    return planar_squared < 1.0;
}

// The colour table at light direction wi for view wo (tangent frame): the (u, v) cell of the key, linear in
// t = -w / sqrt(4 - u^2 - v^2) between the slices (held at the first and last), linear sRGB.
vec3 material_colour(vec3 wo, vec3 wi) {
    float span = u_material_key_range.y - u_material_key_range.x;
    vec3 key = -(wi + wo);
    vec2 point = (key.xy - u_material_key_range.x) / span;
    ivec2 cell = clamp(ivec2(floor(point * vec2(u_material_cells))), ivec2(0), u_material_cells - ivec2(1));
    float depth = sqrt(max(4.0 - dot(key.xy, key.xy), 1e-12));
    float slice = clamp(-key.z / depth, 0.0, 1.0) * float(u_colour_slices) - 0.5;
    int low = clamp(int(floor(slice)), 0, u_colour_slices - 1);
    int high = min(low + 1, u_colour_slices - 1);
    float f = clamp(slice - float(low), 0.0, 1.0);
    vec3 a = texelFetch(u_material_colour, cell + ivec2(0, low * u_material_cells.y), 0).rgb;
    vec3 b = texelFetch(u_material_colour, cell + ivec2(0, high * u_material_cells.y), 0).rgb;
    return mix(a, b, f);
}

// Resampled importance sampling of the environment (SAMPLING_RESAMPLED; Talbot, Cline & Egbert 2005): u_candidates
// directions, the first u_material_candidates of them drawn by material sampling and the rest by the environment's
// luminance, each weighed by the mixture's density q = (1 - m) p_light + m p_material (m = u_material_candidates /
// u_candidates: the balance heuristic across the two, so the sum of the weights estimates the target's integral),
// one of them kept with probability proportional to target / q, where the target is what the network is expected to
// give there, A * S * T(u, v) * Y(L): the A-term and Smith's shadowing exactly, the material's (u, v) table T for XYZ
// (its floor keeps it > 0 wherever light can come from) and the luminance of the radiance. Returns
// L(y) * (sum of target/q) / (candidates * target(y)) for the kept direction y (world, `wi_world`), so that the
// pass's A * S * XYZ(y) times it is an unbiased estimate of the environment's integral (invalid candidates count in
// the mean as zeros); 0 when every candidate was. Each strategy's candidates take their 2-D numbers from its own
// Sobol sequence under a per-pixel shift (`shift`), points turn * n + j for its n candidates of this pixel's
// `turn`-th pass: stratified within a pass and across passes, each point still uniform.
// Control variate (u_control_variate; docs/physics.md "Environment light"): h = A * S * C(u, v, t) * L with C the
// material's colour table. The candidates estimate its integral, H = sum of h/q over the candidates / candidates, and
// `offset` = H - h(y) * W (W the kept direction's weight above) is added after the network: the pass is then
// H + (f(y) - h(y)) * W, unbiased for any table, and the network's one direction only corrects what C misses.
vec3 resample_environment(vec3 wo, mat3 world_to_tangent, uvec2 pixel, uint turn, uvec3 shift, out vec3 wi_world,
                          out vec3 offset) {
    mat3 tangent_to_world = transpose(world_to_tangent);
    int by_material = u_material_candidates;
    float share = float(by_material) / float(u_candidates);
    uint lights = uint(u_candidates - by_material);
    uvec2 material_shift = pcg3d(shift).yz;
    float total = 0.0;  // sum of target / q over the candidates
    float kept_target = 0.0;
    vec3 kept_radiance = vec3(0.0);
    vec3 proxy_sum = vec3(0.0);
    vec3 kept_proxy = vec3(0.0);
    offset = vec3(0.0);
    wi_world = vec3(0.0, 0.0, 1.0);
    for (int k = 0; k < MAX_CANDIDATES; ++k) {
        if (k >= u_candidates) {
            break;
        }
        uvec3 hashed = pcg3d(uvec3(pixel, (uint(u_sample_index) * 0x9e3779b9u) ^ (uint(k) * 0x85ebca6bu)
                                           ^ (u_seed * 0xc2b2ae35u) ^ 0x27d4eb2fu));
        vec2 hashed_xi = vec2(hashed.xy >> 8u) * (1.0 / 16777216.0);  // x: material's branch, y: the reservoir
        vec3 world;
        vec3 wi;
        if (k < by_material) {
            vec2 xi = stratified2(turn * uint(by_material) + uint(k), material_shift);
            if (!sample_material(wo, vec3(hashed_xi.x, xi), wi)) {
                continue;
            }
            wi = normalize(wi);
            world = tangent_to_world * wi;
        } else {
            float density;
            world = sample_environment(stratified2(turn * lights + uint(k - by_material), shift.yz), density);
            if (!(density > 0.0)) {
                continue;
            }
            wi = world_to_tangent * world;
        }
        if (!(wi.z > 0.0)) {
            continue;  // below this point's horizon: no light from there
        }
        float material = material_pdf(wo, wi);
        float source = (1.0 - share) * environment_pdf(world) + share * material;
        vec3 radiance = environment_radiance(world);
        float shadowed_a = a_term(wi, wo, u_ior) * smith_shadowing(wi, wo, u_slope_covariance);
        float luminance = dot(radiance, vec3(0.2126, 0.7152, 0.0722));  // linear sRGB's
        float target = shadowed_a * (material / wi.z) * luminance;
        float weight = target / source;
        if (!(source > 0.0) || !(weight > 0.0) || isinf(weight)) {
            continue;
        }
        vec3 proxy = vec3(0.0);
        if (u_control_variate) {
            proxy = shadowed_a * material_colour(wo, wi) * radiance;
            proxy_sum += proxy / source;
        }
        total += weight;
        if (hashed_xi.y * total < weight) {  // keep it with probability weight / total (a one-slot reservoir)
            kept_proxy = proxy;
            kept_target = target;
            kept_radiance = radiance;
            wi_world = world;
        }
    }
    if (!(total > 0.0) || !(kept_target > 0.0)) {
        return vec3(0.0);
    }
    float w = total / (float(u_candidates) * kept_target);
    offset = proxy_sum / float(u_candidates) - kept_proxy * w;
    return kept_radiance * w;
}

// The power heuristic's weight of a strategy of density `chosen` beside one of density `other`.
float power_weight(float chosen, float other) {
    if (!(chosen > 0.0)) {
        return 0.0;
    }
    float ratio = other / chosen;
    return 1.0 / (1.0 + ratio * ratio);
}

// This fragment's light for this pass: the world direction towards it, the scalar irradiance and the linear
// sRGB tint that multiply A * XYZ (tint (1, 1, 1) for the delta light). irradiance 0: no light this pass.
// Strategies, in this order: light sampling of each emitter (the environment if any, then each area light),
// material sampling, the delta light. Each emitter's integral is weighed between its own light sampling and
// material sampling (power heuristic), so a material sample adds every emitter it meets, each with its weight.
void environment_incidence(vec3 position, mat3 world_to_tangent, vec3 wo, out vec3 wi_world, out float irradiance,
                           out vec3 tint) {
    bool resampled = u_environment_sampling == SAMPLING_RESAMPLED;  // the environment by resample_environment
    bool mis = u_environment_sampling == SAMPLING_MIS || resampled;  // area lights: MIS as ever
    bool by_light = u_environment_sampling != SAMPLING_MATERIAL;
    bool by_material = u_environment_sampling != SAMPLING_LIGHT && !(resampled && u_area_count == 0);
    int emitters = (u_has_environment ? 1 : 0) + u_area_count;
    uint light_strategies = by_light ? uint(emitters) : 0u;
    uint sampled = light_strategies + (by_material ? 1u : 0u);  // sampling strategies
    uint count = sampled + (u_delta_light ? 1u : 0u);  // M
    tint = vec3(1.0);
    irradiance = 0.0;
    wi_world = vec3(0.0, 0.0, 1.0);
    if (count == 0u) {
        return;
    }
    uvec2 pixel = uvec2(ivec2(gl_FragCoord.xy) + u_pixel_origin);  // the whole picture's pixel: bands agree
    uint offset = pcg3d(uvec3(pixel, u_seed ^ 0x68bc21ebu)).x % count;
    uint strategy = (uint(u_sample_index) + offset) % count;
    float strategies = float(count);
    if (strategy == sampled) {  // the delta light, once in every M passes
        light_incidence(position, wi_world, irradiance);
        irradiance *= strategies;
        return;
    }
    // The strategy's own passes at this pixel draw its directions from one Sobol sequence under a per-pixel,
    // per-strategy random shift (stratified over passes, each pass still uniform); the first number chooses
    // material sampling's branch (table or cosine) and stays independent.
    uint turn = (uint(u_sample_index) + offset) / count;  // this strategy's 0th, 1st, ... pass here
    uvec3 shift = pcg3d(uvec3(pixel, (u_seed * 0x9e3779b9u) ^ ((strategy + 1u) * 0x85ebca6bu)));
    vec3 xi = vec3(uniform3(uvec3(pixel, uint(u_sample_index) ^ (u_seed * 0x9e3779b9u))).x,
                   stratified2(turn, shift.yz));
    mat3 tangent_to_world = transpose(world_to_tangent);
    vec3 light = vec3(0.0);  // sum over emitters of w_e * L_e / p_s
    if (strategy < light_strategies) {  // light sampling of one emitter
        int emitter = int(strategy) - (u_has_environment ? 1 : 0);  // -1: the environment, else an area light
        float chosen;
        vec3 radiance;
        if (emitter < 0 && resampled) {
            vec3 offset;
            tint = resample_environment(wo, world_to_tangent, pixel, turn, shift, wi_world, offset) * strategies;
            g_environment_offset = offset * strategies;
            irradiance = 1.0;
            return;
        }
        if (emitter < 0) {
            wi_world = sample_environment(xi.yz, chosen);
            radiance = environment_radiance(wi_world);
        } else {
            wi_world = sample_area(emitter, position, xi.yz, chosen);
            radiance = u_area_radiance[emitter];
        }
        if (!(chosen > 0.0)) {
            return;
        }
        float weight = 1.0;
        if (mis) {
            weight = power_weight(chosen, material_pdf(wo, world_to_tangent * wi_world));
        }
        light = radiance * (weight / chosen);
    } else {  // material sampling: every emitter the direction meets
        vec3 wi;
        if (!sample_material(wo, xi, wi)) {
            return;
        }
        wi = normalize(wi);
        float chosen = material_pdf(wo, wi);
        if (!(chosen > 0.0)) {
            return;
        }
        wi_world = tangent_to_world * wi;
        if (u_has_environment && !resampled) {  // resampled: the environment's passes hold all of its light
            float weight = mis ? power_weight(chosen, environment_pdf(wi_world)) : 1.0;
            light += environment_radiance(wi_world) * weight;
        }
        for (int i = 0; i < MAX_AREA_LIGHTS; ++i) {
            if (i >= u_area_count) {
                break;
            }
            float density = area_pdf(i, position, wi_world);
            if (density > 0.0) {
                light += u_area_radiance[i] * (mis ? power_weight(chosen, density) : 1.0);
            }
        }
        light /= chosen;
    }
    tint = light * strategies;
    irradiance = 1.0;
}
