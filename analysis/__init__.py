"""Analysis of GratNet's runs, models and volumes: the tables, records and figures that the docs, the scripts,
the tests and the experiment probes (docs/experiments/probes/) build on.

A tool on top of the layers (it reads trainer/ checkpoints and volumes, renders through viewer/); nothing below
imports it. A module that people run is also a command, ``python -m analysis.MODULE --help``; for example
``python -m analysis.results_table`` writes docs/results.md. benchmarks/README.md lists the modules and their
commands beside the benchmarks, which import what they share from here.
"""
