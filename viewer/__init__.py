"""GratNet's runtime: the GL renderer and the interactive viewer (never imports torch).

The renderer, shaders and viewer arrive with the GLSL-runtime milestone; the runtime-side data code
they will use (volume format, A-term, XYZ → display sRGB) already lives in ``gratnet``.
"""
