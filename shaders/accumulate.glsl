// Program: adds one sample image to an accumulation target (anti-aliasing, issue 12). Pixel (x, y) reads
// texel (x, y) of u_sample (RGBA32F); the draw runs with additive blending (ONE, ONE) into an RGBA32F
// target, so the target holds the float32 sum of the samples drawn so far (the caller divides by N).
#include "fullscreen.glsl"

#ifdef FRAGMENT_SHADER
precision highp float;
precision highp int;

uniform highp sampler2D u_sample;

layout(location = 0) out vec4 out_sum;

void main() {
    out_sum = texelFetch(u_sample, ivec2(gl_FragCoord.xy), 0);
}
#endif
