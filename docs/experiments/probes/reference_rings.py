"""Probe of docs/experiments/2026-11-26-reference-renders.md: the CD disc, ground truth beside network.

Renders with `gratnet render` (each material's default CD view, 384², 4 spp), then lays the pairs out:

    python docs/experiments/probes/reference_rings.py VOLUME_DIR [--out docs/images/reference_rings.png]

VOLUME_DIR holds paper-cd.exr (`gratnet groundtruth paper-cd --sampling simple-max`) and
paper-scratches-501x11.exr (`gratnet groundtruth paper-scratches --sampling simple-max --res 501 --slices 11`).
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from PIL import Image  # noqa: E402

PAIRS = (("paper-cd", "paper-cd.exr", "1001² × 11, its training volume"),
         ("paper-scratches", "paper-scratches-501x11.exr", "501² × 11, coarser than its 1001² × 41"))


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("volumes", type=Path)
    parser.add_argument("--out", type=Path, default=Path("docs/images/reference_rings.png"))
    arguments = parser.parse_args()
    figure, axes = plt.subplots(2, 2, figsize=(7.2, 7.8), layout="constrained")
    with tempfile.TemporaryDirectory() as folder:
        for row, (material, volume, label) in zip(axes, PAIRS, strict=True):
            for column, extra in enumerate((["--reference", str(arguments.volumes / volume)], [])):
                out = Path(folder) / f"{material}-{column}.png"
                subprocess.run([sys.executable, "-m", "gratnet.cli", "render", "--material", material, "--mesh", "cd",
                                "--size", "384,384", "--spp", "4", "--out", str(out), *extra], check=True)
                row[column].imshow(np.asarray(Image.open(out)))
                row[column].set_axis_off()
            row[0].set_title(f"{material}: ground truth\n(volume {label})", fontsize=7)
            row[1].set_title(f"{material}: network", fontsize=7)
    figure.suptitle("The CD disc at each material's default view (gratnet render, 384², 4 spp)", fontsize=8)
    figure.savefig(arguments.out, dpi=100)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
