"""``gratnet bench``: timings of the runtime, a tool on top (layers: gratnet/ ← viewer/, trainer/ ← bench/).

- :mod:`bench.slices`: the BRDF-slice program's frame time and MLP throughput against torch's, beside each
  model's error (the Pareto front of run time against error).
- :mod:`bench.scenes`: frame times of mesh scenes (the CD disc as ``gratnet render`` sets it up) per
  weights path, render path and samples per pixel: what a user waits for.
- :mod:`bench.cli`: the subcommand.

It lives outside trainer/ because the offline stage must not time (or depend on) the runtime's renderer.
"""
