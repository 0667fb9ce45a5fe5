"""GratNet's offline stage: height fields, the Fourier-optics ground truth, training (torch only there).

Of the project, trainer/ imports gratnet/ only (tests/contract/test_architecture.py). Inside it the layers below
point one way: a module uses its own layer and those listed before it, never one after. Training and evaluation
stand side by side: neither imports the other (a model file, gratnet/modelfile.py, is what passes between them;
``train_cli`` joins them). One exception: ``groundtruth``'s ``ComputeConfig`` borrows training's ``--device`` rule
(``train.pick_device``), imported lazily and only where torch is installed.

Ground truth (numpy; torch only to run the F-term on CUDA):
- ``heightfield``: ``HeightField``, heights in µm on a regular square grid.
- ``heightfile``: height-field files (.npy/.npz, .gsf, PNG, EXR) read and written; ``LoadOptions``; previews.
- ``generators``: seeded built-in height fields (``GENERATORS``: a parameter dataclass and a function each).
- ``sampling``: the sampling schemes of the key-vector domain (volume grid ↔ key vectors).
- ``spectral``: the D65 × CIE 1931 weights of the spectral integral.
- ``fourier``: the F-term (``OpticsConfig``, ``prepare_surface``, ``FTerm``; numpy or torch on CUDA).
- ``groundtruth``: ``VolumeConfig``/``ComputeConfig`` and ``compute_volume``, the reflectance volume.
- ``brdfslice``: ground-truth BRDF slices at exact key vectors; ``preview``: a volume slice as a PNG.
- ``reference``: the slow float64 F-term (brute force, the paper's Taylor route), for tests and studies.

Data by name:
- ``datasets``: the paper's datasets as presets (a height field and its optics); ``loaders``: a height field by
  name (a file, ``generator:NAME(…)``, ``dataset:NAME``).

Model (torch):
- ``model``: ``FunnelMLP`` and ``GridNetwork``, the presets and hidden widths, their model files.

Training (torch):
- ``train_config``: ``TrainConfig`` with its nested ``GridConfig``, the run's options and their checks
  (torch-free: the CLI lists the flags without torch).
- ``objective``: the loss of a batch (LogCosh, the display weighting) and the cosine schedule, shared by:
- ``train``: ``train`` and its steps (set-up, resume from checkpoint.pt, one epoch, its scores, the
  checkpoint, the model file and history.json); the samples and their split; Adam and its schedule.
- ``cudagraph``: the step replayed as one CUDA graph; ``offlattice``: training points between the volume's
  samples; ``allocator``: freed memory kept in the process during CPU training.

Evaluation (a model file against ground truth):
- ``metrics``: image metrics (PSNR, SSIM, FLIP); ``report``: figures, the markdown table, metrics.json.
- ``diagnostics``: the interpolation oracle, the error by region, training curves.
- ``evaluate``: ``evaluate_model``, held-out volume slices and BRDF slices scored with all of the above.

Commands (``register`` functions, entry points in pyproject.toml):
- ``cli_support``: what the ground-truth commands share (the HEIGHTFIELD argument, optics and load flags).
- ``heightfield_cli`` (``gratnet heightfield``), ``groundtruth_cli`` (``gratnet groundtruth``),
  ``brdfslice_cli`` (``gratnet brdfslice``), ``train_cli`` (``gratnet train``, ``gratnet evaluate``).
"""
