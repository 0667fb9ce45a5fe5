// Full-screen triangle for the vertex stage of every 2-D program: three vertices from gl_VertexID,
// no vertex buffer. The triangle (-1,-1), (3,-1), (-1,3) covers the viewport once, so each pixel's
// fragment runs exactly once (a quad's diagonal would not matter here, but one triangle is simplest).
#ifdef VERTEX_SHADER
void main() {
    vec2 corner = vec2(float((gl_VertexID << 1) & 2), float(gl_VertexID & 2));  // (0,0), (2,0), (0,2)
    gl_Position = vec4(2.0 * corner - 1.0, 0.0, 1.0);
}
#endif
