"""GratNet materials in Mitsuba 3 (the optional ``mitsuba`` extra: ``pip install -e '.[mitsuba]'``).

- ``mitsuba_plugin.runtime.set_variant(name)``: set a Mitsuba variant and register the ``gratnet`` BSDF;
- ``mitsuba_plugin.bsdf``: the BSDF plugin (a trained network, evaluated with numpy, as glossy reflection);
- ``mitsuba_plugin.shading``: its numbers in numpy (value, sampling, pdf), importable without Mitsuba;
- ``mitsuba_plugin.scene``: GratNet meshes, cameras and lights as a Mitsuba scene;
- ``mitsuba_plugin.render_cli``: ``gratnet mitsuba-render``.

Nothing imports Mitsuba at import time, so the package (and ``gratnet --help``) loads without the extra.
"""
