// Program: XYZ image -> display sRGB in [0, 1] (colour.glsl). Pixel (x, y) reads texel (x, y) of
// u_xyz (RGBA32F, .xyz); the output is the sRGB-encoded colour before 8-bit quantisation.
#include "fullscreen.glsl"

#ifdef FRAGMENT_SHADER
precision highp float;
precision highp int;

#include "colour.glsl"

uniform highp sampler2D u_xyz;
uniform float u_exposure;

layout(location = 0) out vec4 out_colour;

void main() {
    vec3 xyz = texelFetch(u_xyz, ivec2(gl_FragCoord.xy), 0).xyz;
    out_colour = vec4(xyz_to_display_srgb(xyz, u_exposure), 1.0);
}
#endif
