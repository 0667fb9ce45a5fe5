"""GratNet: a neural shader for diffractive surfaces.

Packages:
- ``gratnet``: the command line (``gratnet <subcommand>``), configs, errors, file formats shared by the
  offline stage and the runtime (no torch here).
- ``trainer``: the offline stage: height fields, the Fourier-optics ground truth, training.
- ``viewer``: the runtime: GL renderer and interactive viewer (never imports torch).
"""

__version__ = "0.1.0"
