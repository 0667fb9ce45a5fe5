"""``gratnet export``: a material for other engines and the web (docs/export.md; issue 44).

A tool on top of the layers: it reads model files (gratnet/), the runtime's GLSL (shaders/) through the runtime's
preprocessor (viewer/glsl.py), viewer's meshes and default views, and writes files; nothing imports it.

- ``glsl.py``: one GLSL function module per material, made from the runtime's own shaders/*.glsl, and its packed
  weights (and a feature-grid model's grid textures).
- ``hlsl.py``: that module cross-compiled to HLSL (glslangValidator → SPIR-V → spirv-cross).
- ``web.py`` and ``web/``: a WebGL2 page (index.html, gratnet.js) showing pure-MLP materials on the built-in meshes.
- ``cli.py``: the command: checks, then every file written into a temporary folder that is renamed onto ``--out``.
"""
