"""``gratnet sweep``: grids of ground-truth, training and evaluation runs as tasks on Ray.

A tool on top of trainer/ (layers: gratnet/ ← viewer/, trainer/ ← sweep/): it calls the project's own
functions (trainer.groundtruth, trainer.train, trainer.evaluate, bench.slices) and adds only the grid
(sweep.spec), the task graph (sweep.runner, the only module that imports Ray), the table (sweep.results), one
record per task attempt (sweep.records) and the watchdog that ends a killed sweep's local Ray instance
(sweep.watchdog); what survives which fault: docs/robustness.md.
"""
