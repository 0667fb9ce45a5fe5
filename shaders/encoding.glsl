// Network input: key vector -> network coordinates -> sinusoidal encoding.
// docs/physics.md "Network input and output", eq. 6; mirrors gratnet/encoding.py feature for feature.
//
// Needs #define MAX_FREQUENCIES (>= max(L, L_t, 1)), set from the model file.
//
// Precision: the top frequency is pi * s^(L-1) = pi * (R-1)/2 rad per unit c (1571 for R = 1001). A
// plain float32 product s^j * c is off by up to half an ulp of the product, i.e. up to 1e-4 rad there.
// So the coordinates are carried as unevaluated float pairs (hi + lo), the frequencies s^j come from
// the CPU split as a (10 significant bits) + b, and the product a * c_grid (c_grid: c on a 2^-12 grid)
// is exact and reduced modulo 2 half-turns exactly; the remaining small terms round at ~1e-9. The
// result matches a float64 evaluation at the same float32 key to ~2e-7 rad. `precise` stops the
// compiler from reassociating (which would cancel the error terms to zero).

#include "codes.glsl"  // SCHEME_*

const float PI = 3.14159265358979;

uniform int u_scheme;          // SCHEME_* of the source volume (physics.md "Sampling")
uniform int u_frequencies;     // L: frequencies per spatial coordinate
uniform int u_t_frequencies;   // L_t: frequencies of c_t
uniform int u_spatial_groups;  // G: 4 (c_u, c_v, c_u + c_v, c_u - c_v), or 2 (c_u, c_v) without the diagonals (eq. 6a)
// Row j: (a, b) with a + b = s^j (a has 10 significant bits), then (a_t, b_t) for s_t^j; unused rows 0.
uniform vec4 u_frequency[MAX_FREQUENCIES];

// ---- another driver, emulated (tests only; off unless EMULATE_DRIVER is defined) ------------------
// docs/physics.md, "Float32 error budget": a correct float32 driver may see the key off by a few ulps and
// compute sin/cos with an absolute error of ~2^-21. EMULATE_DRIVER moves each key component by up to
// EMULATE_KEY_ERROR and each phase by up to EMULATE_PHASE_ERROR half-turns, by a hash of the values
// themselves (deterministic, uncorrelated between pixels and lanes): tests/contract/test_precision.py checks that
// gratnet.precision's bound covers the difference on the shipped models.
#ifdef EMULATE_DRIVER
float emulation_hash(float x) {  // in [-1, 1]: a PCG step on the float's bits
    uint h = floatBitsToUint(x) * 747796405u + 2891336453u;
    h = ((h >> ((h >> 28u) + 4u)) ^ h) * 277803737u;
    h = (h >> 22u) ^ h;
    return float(h) * (2.0 / 4294967295.0) - 1.0;
}
#define EMULATED_KEY(key) ((key) + EMULATE_KEY_ERROR * vec3(emulation_hash((key).x), emulation_hash((key).y + 0.5), \
                                                          emulation_hash((key).z + 0.25)))
#define EMULATED_PHASE(x) ((x) + EMULATE_PHASE_ERROR * emulation_hash(x))
#define EMULATED_PHASE4(x) ((x) + EMULATE_PHASE_ERROR * vec4(emulation_hash((x).x), emulation_hash((x).y), \
                                                            emulation_hash((x).z), emulation_hash((x).w)))
#else
#define EMULATED_KEY(key) (key)
#define EMULATED_PHASE(x) (x)
#define EMULATED_PHASE4(x) (x)
#endif

// ---- error-free float transforms (Knuth TwoSum, Veltkamp split, Dekker product) -----------------

vec2 two_sum(float a, float b) {  // a + b = s + e exactly
    precise float s = a + b;
    precise float bb = s - a;
    precise float e = (a - (s - bb)) + (b - bb);
    return vec2(s, e);
}

vec2 veltkamp_split(float a) {  // a = hi + lo, each with at most 12 significant bits
    precise float c = 4097.0 * a;
    precise float hi = c - (c - a);
    precise float lo = a - hi;
    return vec2(hi, lo);
}

vec2 two_product(float a, float b) {  // a * b = p + e exactly
    precise float p = a * b;
    vec2 x = veltkamp_split(a);
    vec2 y = veltkamp_split(b);
    precise float e = ((x.x * y.x - p) + x.x * y.y + x.y * y.x) + x.y * y.y;
    return vec2(p, e);
}

vec2 add_pair(vec2 a, vec2 b) {  // (hi, lo) + (hi, lo), not renormalised (only hi + lo is used)
    vec2 s = two_sum(a.x, b.x);
    precise float lo = s.y + (a.y + b.y);
    return vec2(s.x, lo);
}

// ---- key vector -> network coordinates (eq. 6, first half) --------------------------------------

// c = u*/2 for one key component: u for `regular`, sign(u) * 2 * sqrt(|u|/2) for `simple`/`simple-max`.
vec2 grid_coordinate(float key) {
    if (u_scheme == SCHEME_REGULAR) {
        return vec2(0.5 * key, 0.0);  // exact
    }
    float a = abs(key) * 0.5;          // exact; >= 0, so no clamp is needed before sqrt
    float h = sqrt(a);
    float lo = 0.0;
    if (h > 0.0) {
        vec2 square = two_product(h, h);  // one Newton step on the residual a - h^2 (exact)
        precise float residual = (a - square.x) - square.y;
        lo = residual / (2.0 * h);
    }
    return sign(key) * vec2(h, lo);
}

// t in [0, 1]: -w/2, or for simple-max -w / sqrt(4 - u^2 - v^2) (0 where that root is <= 1e-12).
float key_to_t(vec3 key) {
    float t;
    if (u_scheme == SCHEME_SIMPLE_MAX) {
        // 4 - u^2 - v^2 from exact products: near the rim (u^2 + v^2 -> 4) a float32 difference
        // would lose every digit.
        vec2 uu = two_product(key.x, key.x);
        vec2 vv = two_product(key.y, key.y);
        vec2 s1 = two_sum(4.0, -uu.x);
        vec2 s2 = two_sum(s1.x, -vv.x);
        precise float depth_squared = s2.x + (((s1.y + s2.y) - uu.y) - vv.y);
        float depth = sqrt(max(depth_squared, 0.0));  // clamp before sqrt
        t = depth > 1e-12 ? -key.z / depth : 0.0;
    } else {
        t = -0.5 * key.z;
    }
    return clamp(t, 0.0, 1.0);
}

// Per-fragment state set by encoding_set_key and read by encoded_block.
vec3 g_coordinates;  // (c_u, c_v, c_t), rounded to float
vec4 g_group;        // the coordinate of each spatial group: c_u, c_v, c_u + c_v, c_u - c_v (hi part)
vec4 g_group_grid;   // ... rounded down to a multiple of 2^-12 (<= 14 significant bits)
vec4 g_group_rest;   // ... and the rest, (hi - grid) + lo
vec3 g_t;            // c_t: (hi, grid, rest) likewise

void encoding_set_key(vec3 exact_key) {
    vec3 key = EMULATED_KEY(exact_key);
    vec2 cu = grid_coordinate(key.x);
    vec2 cv = grid_coordinate(key.y);
    vec2 ct = two_sum(2.0 * key_to_t(key), -1.0);  // c_t = 2t - 1
    g_coordinates = vec3(cu.x + cu.y, cv.x + cv.y, ct.x + ct.y);
    vec2 sum = add_pair(cu, cv);
    vec2 difference = add_pair(cu, -cv);
    g_group = vec4(cu.x, cv.x, sum.x, difference.x);
    vec4 low = vec4(cu.y, cv.y, sum.y, difference.y);
    g_group_grid = floor(g_group * 4096.0) / 4096.0;  // exact: scaling by powers of two
    g_group_rest = (g_group - g_group_grid) + low;
    float t_grid = floor(ct.x * 4096.0) / 4096.0;
    g_t = vec3(ct.x, t_grid, (ct.x - t_grid) + ct.y);
}

// s^j * c in half-turns, reduced to about [-1, 1] (frequency = (a, b), c = grid + rest, c_hi ~ c).
float reduced_half_turns(vec2 frequency, float grid, float rest, float c_hi) {
    precise float product = frequency.x * grid;                       // exact: 10 x 14 bits
    precise float r = product - 2.0 * floor(0.5 * product + 0.5);     // exact: minus the nearest even integer
    precise float x = r + (frequency.x * rest + frequency.y * c_hi);  // small terms: rounding ~1e-9
    return EMULATED_PHASE(x);
}

// The same for four phases at once (the baked MLP's encoding, viewer/baked.py): lane k is
// reduced_half_turns(vec2(a[k], b[k]), grid[k], rest[k], c_hi[k]).
vec4 reduced_half_turns4(vec4 a, vec4 b, vec4 grid, vec4 rest, vec4 c_hi) {
    precise vec4 product = a * grid;
    precise vec4 r = product - 2.0 * floor(0.5 * product + 0.5);
    precise vec4 x = r + (a * rest + b * c_hi);
    return EMULATED_PHASE4(x);
}

// Frequency j of the four spatial groups (c_u, c_v, c_u + c_v, c_u - c_v) at once: lane g of `sines` is
// feature 3 + 2Lg + j of eq. 6, lane g of `cosines` feature 3 + 2Lg + L + j.
void encoded_spatial_frequency(int j, out vec4 sines, out vec4 cosines) {
    vec4 half_turns = reduced_half_turns4(vec4(u_frequency[j].x), vec4(u_frequency[j].y), g_group_grid,
                                          g_group_rest, g_group);
    sines = sin(PI * half_turns);
    cosines = cos(PI * half_turns);
}

// Four t frequencies at once, (a, b) = s_t^j split per lane (zero lanes give sin 0, cos 1): lane k of
// `sines` is feature 3 + 8L + j_k, of `cosines` feature 3 + 8L + L_t + j_k.
void encoded_t_frequencies(vec4 a, vec4 b, out vec4 sines, out vec4 cosines) {
    vec4 half_turns = reduced_half_turns4(a, b, vec4(g_t.y), vec4(g_t.z), vec4(g_t.x));
    sines = sin(PI * half_turns);
    cosines = cos(PI * half_turns);
}

float sinusoid(bool cosine, float half_turns) {
    return cosine ? cos(PI * half_turns) : sin(PI * half_turns);
}

// Feature f of eq. 6: [c_u, c_v, c_t, sin/cos blocks of c_u, c_v, c_u+c_v, c_u-c_v, then of c_t], else 0.
// Eq. 6a (u_spatial_groups 2) is the same with the first two groups only: the diagonals' blocks are left out.
float encoded_feature(int f) {
    if (f < 3) {
        return g_coordinates[f];
    }
    int g = f - 3;
    int per_group = 2 * u_frequencies;  // L sines then L cosines
    if (g < u_spatial_groups * per_group) {
        int group = g / per_group;
        int r = g - group * per_group;
        bool cosine = r >= u_frequencies;
        int j = cosine ? r - u_frequencies : r;
        return sinusoid(cosine, reduced_half_turns(u_frequency[j].xy, g_group_grid[group], g_group_rest[group],
                                                   g_group[group]));
    }
    g -= u_spatial_groups * per_group;
    if (g < 2 * u_t_frequencies) {
        bool cosine = g >= u_t_frequencies;
        int j = cosine ? g - u_t_frequencies : g;
        return sinusoid(cosine, reduced_half_turns(u_frequency[j].zw, g_t.y, g_t.z, g_t.x));
    }
    return 0.0;  // padding past the last feature
}

// Features 4*block ... 4*block+3 of the key set by encoding_set_key (the MLP's input block `block`).
vec4 encoded_block(int block) {
    int f = 4 * block;
    return vec4(encoded_feature(f), encoded_feature(f + 1), encoded_feature(f + 2), encoded_feature(f + 3));
}
