// Random numbers and piecewise-constant 2D distributions (issue 43): gratnet/sampling2d.py in GLSL.
//
// A distribution is one R32F texture (gratnet.sampling2d.PiecewiseConstant2D.packed): rows 0 .. R-1 hold each
// row's CDF over its C columns (C + 1 values), row R the marginal CDF over rows (R + 1 values). Sampling
// inverts both CDFs by binary search and places the point linearly within its cell; a cell's density is the
// difference of the float32 CDF values it was sampled from times R * C, so the density this file reports is
// exactly the density of the points it draws, float32 rounding included.

// A hash of three integers into three uniform 32-bit integers: pcg3d of Jarzynski & Olano, "Hash Functions
// for GPU Rendering", JCGT 9(3), 2020 (a permuted congruential step mixed across the lanes).
uvec3 pcg3d(uvec3 v) {
    v = v * 1664525u + 1013904223u;
    v.x += v.y * v.z;
    v.y += v.z * v.x;
    v.z += v.x * v.y;
    v ^= v >> 16u;
    v.x += v.y * v.z;
    v.y += v.z * v.x;
    v.z += v.x * v.y;
    return v;
}

// Three numbers in [0, 1) (24 bits each, exactly representable in float32) for `v`.
vec3 uniform3(uvec3 v) {
    return vec3(pcg3d(v) >> 8u) * (1.0 / 16777216.0);
}

// x with its 32 bits in reverse order (GLSL ES 3.00 has no bitfieldReverse).
uint reverse_bits(uint x) {
    x = ((x >> 1u) & 0x55555555u) | ((x & 0x55555555u) << 1u);
    x = ((x >> 2u) & 0x33333333u) | ((x & 0x33333333u) << 2u);
    x = ((x >> 4u) & 0x0f0f0f0fu) | ((x & 0x0f0f0f0fu) << 4u);
    x = ((x >> 8u) & 0x00ff00ffu) | ((x & 0x00ff00ffu) << 8u);
    return (x >> 16u) | (x << 16u);
}

// Point `index` of Sobol's sequence in its first two dimensions (van der Corput in base 2 and Sobol's second),
// as 32-bit fractions: every 2^m consecutive points from a multiple of 2^m put one point in each of 2^m equal
// boxes of the unit square (a (0, 2)-sequence), so the first N points stratify the square for every N.
uvec2 sobol2(uint index) {
    uint first = reverse_bits(index);
    uint second = 0u;
    for (uint v = 1u << 31u; index != 0u; index >>= 1u) {
        if ((index & 1u) != 0u) {
            second ^= v;
        }
        v ^= v >> 1u;
    }
    return uvec2(first, second);
}

// Two numbers in [0, 1) (24 bits each): Sobol point `index` shifted by `shift` modulo 1 (Cranley-Patterson
// rotation: with a uniformly random shift each point is uniform, and the points keep their stratification).
vec2 stratified2(uint index, uvec2 shift) {
    return vec2((sobol2(index) + shift) >> 8u) * (1.0 / 16777216.0);
}

// The largest index i in [0, count - 1] of row `row` whose CDF value (texel i) is <= xi; the CDF has
// count + 1 values, the first 0 and the last 1 (gratnet.sampling2d: numpy's searchsorted(..., "right") - 1).
int cdf_search(highp sampler2D table, int row, int count, float xi) {
    int low = 0;
    int high = count;
    while (high - low > 1) {
        int middle = (low + high) / 2;
        if (texelFetch(table, ivec2(middle, row), 0).r <= xi) {
            low = middle;
        } else {
            high = middle;
        }
    }
    return low;
}

// Where xi lies between a cell's CDF values, in [0, 1) (0 for an empty cell).
float cdf_fraction(float xi, float low, float high) {
    return high > low ? clamp((xi - low) / (high - low), 0.0, 0.99999994) : 0.0;
}

// A point of the unit square (x: columns, y: rows) for uniform numbers xi (x: row choice, y: column choice),
// and its density on the unit square. `shape` = (columns C, rows R).
vec2 sample_piecewise(highp sampler2D table, ivec2 shape, vec2 xi, out float density) {
    int row = cdf_search(table, shape.y, shape.y, xi.x);
    float row_low = texelFetch(table, ivec2(row, shape.y), 0).r;
    float row_high = texelFetch(table, ivec2(row + 1, shape.y), 0).r;
    int column = cdf_search(table, row, shape.x, xi.y);
    float column_low = texelFetch(table, ivec2(column, row), 0).r;
    float column_high = texelFetch(table, ivec2(column + 1, row), 0).r;
    density = (row_high - row_low) * (column_high - column_low) * float(shape.x * shape.y);
    return vec2((float(column) + cdf_fraction(xi.y, column_low, column_high)) / float(shape.x),
                (float(row) + cdf_fraction(xi.x, row_low, row_high)) / float(shape.y));
}

// The density on the unit square at `point` (0 outside [0, 1)^2).
float piecewise_density(highp sampler2D table, ivec2 shape, vec2 point) {
    if (!(point.x >= 0.0 && point.x < 1.0 && point.y >= 0.0 && point.y < 1.0)) {
        return 0.0;
    }
    ivec2 cell = min(ivec2(floor(point * vec2(shape))), shape - ivec2(1));
    float row_probability = texelFetch(table, ivec2(cell.y + 1, shape.y), 0).r
                            - texelFetch(table, ivec2(cell.y, shape.y), 0).r;
    float column_probability = texelFetch(table, ivec2(cell.x + 1, cell.y), 0).r
                               - texelFetch(table, cell, 0).r;
    return row_probability * column_probability * float(shape.x * shape.y);
}
