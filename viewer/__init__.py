"""GratNet's runtime: the GL renderer, the commands that use it and the interactive viewer (never imports torch).

Layers inside the wing point one way (tests/contract/test_architecture.py checks that no import circles):

Rendering (no glfw, no imgui; ``gratnet render``, ``gratnet bench`` and the tests use it):
- ``context``: the one GL-context factory (headless EGL, or a window's current context).
- ``glsl``, ``baked``: the GLSL preprocessor (#include with file/line-preserving errors); baked-weight MLP source.
- ``shading``: ``ShadingPrograms``, what every material on the GPU shares (programs, counters, BRDF slices).
- ``renderer``: ``NetworkRenderer``, the funnel MLP per pixel from a model file (weights, programs, BRDF slices).
- ``reference``: ``ReferenceRenderer``, the ground-truth volume looked up per pixel in the network's place.
- ``meshes``, ``camera``, ``antialias``: CD disc, sphere, plane, OBJ; orbit camera, lights; sub-pixel samples.
- ``surface``: what both mesh render paths share (``MeshBuffers``, the surface program's camera/light uniforms).
- ``forward``, ``deferred``: the two render paths; ``scene``: ``SceneRenderer`` over both, and
  ``choose_render_path`` (``auto``: timed once per GPU and network shape, cached).
- ``tiled``: the plan of the deferred path's tiled MLP kernel (tile, blocking, shared memory from the limits).

Library for the commands (no GL at import):
- ``catalog``: shipped materials and built-in meshes by name (resolve, build).
- ``scene_config``: ``SceneConfig``/``RenderConfig``, the shared scene flags, their checks, output writing, the
  checked ``--reference`` volume (``load_reference``).
- ``defaults``: the default light, camera and exposure for a material on a mesh (the pure algorithm).

Commands: ``render_cli`` (``gratnet render``), ``view_cli`` (``gratnet view``).

The interactive viewer:
- ``state``: ``ViewerState`` and the panel's sliders; ``scheduling``: resolution policy, cost model, bands.
- ``app``: ``ViewerApp``, the viewer's logic on any GL context (testable without a display).
- ``reference_view``: the ground truth beside the network (network / reference / FLIP heat map).
- ``scene_supply``, ``compile_worker``, ``default_view``: models, meshes and shaders compiled off the
  window's thread; a switch's default view in a worker process.
- ``srgb``: the window's XYZ → display sRGB in numpy (the same bytes as ``gratnet.display``, no colour-science).
- ``window``: ``ViewerWindow``, the glfw/imgui/EGL shell (the only module that imports glfw or imgui).
"""
