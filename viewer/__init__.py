"""GratNet's runtime: the GL renderer and the interactive viewer (never imports torch).

- ``viewer.context``: the one GL-context factory (headless EGL, or a window's current context).
- ``viewer.glsl``: the GLSL preprocessor (#include with file/line-preserving errors, stage macros).
- ``viewer.renderer``: ``NetworkRenderer``, the funnel MLP per pixel from a model file's packed texture.
- ``viewer.meshes``, ``viewer.camera``: CD disc (tangent along the tracks), sphere, plane, OBJ;
  orbit camera, lights.
- ``viewer.scene``: ``SceneRenderer``, a mesh rendered with the surface program.
- ``viewer.render_cli``: ``gratnet render``.
"""
