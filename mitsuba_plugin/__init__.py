"""GratNet materials in Mitsuba 3 (the optional ``mitsuba`` extra: ``pip install -e '.[mitsuba]'``).

- ``mitsuba_plugin.runtime.set_variant(name)``: set a Mitsuba variant and register the ``gratnet`` BSDF;
  ``with plugin_errors(): mi.load_file(...)`` gives the plugin's one-line errors back out of Mitsuba's wrapping;
- ``mitsuba_plugin.bsdf``: the BSDF plugin (a trained network, evaluated with numpy, as glossy reflection;
  ``filename`` takes a shipped material name or a model file, relative to the scene file or the current
  directory);
- ``mitsuba_plugin.shading``: its numbers in numpy (value, sampling, pdf), importable without Mitsuba;
- ``mitsuba_plugin.scene``: GratNet meshes, cameras and lights as a Mitsuba scene;
- ``mitsuba_plugin.render_cli``: ``gratnet mitsuba-render``.

Nothing imports Mitsuba at import time, so the package (and ``gratnet --help``) loads without the extra.
"""
