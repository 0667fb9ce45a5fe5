"""The ground-truth volume as a look-up table against the network: memory, milliseconds per frame and FLIP on
the exact BRDF slices (analysis.lut_baseline holds the code and says what each figure is).

    python benchmarks/lut_baseline.py paper-cd VOLUME.exr [--strides 1,4] [--frame 1920x1080] [--repeats 3]
        [--cache-dir out/cache] [--json docs/data/lut_baseline_paper-cd.json] [--figure docs/images/lut_baseline.png]
    python benchmarks/lut_baseline.py --plot-only --json ROWS.json [ROWS.json ...] --figure PLOT.png
"""

from __future__ import annotations

from analysis.lut_baseline import main

if __name__ == "__main__":
    raise SystemExit(main())
