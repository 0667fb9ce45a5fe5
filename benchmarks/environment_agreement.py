"""GL against Mitsuba 3 under an environment: the same scene from ``gratnet render`` and ``gratnet mitsuba-render``.

    python benchmarks/environment_agreement.py                    # paper-cd on the CD under the sky, 64², 1024 spp
    python benchmarks/environment_agreement.py --material paper-snake --mesh sphere --environment studio

Both commands render the material's default view (camera of viewer.defaults) under ``--environment`` with the light
off, at ``--spp`` samples per pixel (GL: passes of its MIS estimator; Mitsuba: the ``direct`` integrator with its
envmap emitter and the plugin's table sampler) and the same exposure (the GL picture's, gratnet.showcase's rule).
Their linear sRGB EXRs are scored by LDR-FLIP at that exposure (gratnet.display.ldr_flip), over the whole frame and
over the pixels both cover; each command's wall time is recorded. Writes a JSON record and a figure (GL | Mitsuba |
FLIP), together, and prints the figures. docs/physics.md eq. 9 is the integral both estimate.
"""

from __future__ import annotations

import argparse
import json
import os
import shlex
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

from viewer.scene_config import read_render_exr

REPO = Path(__file__).resolve().parents[1]
DEFAULT_JSON = REPO / "docs" / "data" / "environment_agreement.json"
DEFAULT_FIGURE = REPO / "docs" / "images" / "environment_agreement.png"


def _timed(argv: list[str]) -> float:
    from gratnet.cli import main

    started = time.perf_counter()
    status = main(argv)
    if status != 0:
        raise SystemExit(f"environment_agreement: gratnet {' '.join(argv)} exited {status}")
    return time.perf_counter() - started


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--material", default="paper-cd")
    parser.add_argument("--mesh", default="cd")
    parser.add_argument("--environment", default="sky")
    parser.add_argument("--environment-rotation", default="0", metavar="DEGREES",
                        help="as gratnet render's (default 0: the map as it is; the record of docs/benchmarks.md)")
    parser.add_argument("--size", type=int, default=64)
    parser.add_argument("--spp", type=int, default=1024)
    parser.add_argument("--out", type=Path, default=DEFAULT_JSON)
    parser.add_argument("--figure", type=Path, default=DEFAULT_FIGURE)
    arguments = parser.parse_args(argv)

    from gratnet.atomic import atomic_paths
    from gratnet.display import ldr_flip

    common = ["--material", arguments.material, "--mesh", arguments.mesh, "--environment", arguments.environment,
              "--environment-rotation", arguments.environment_rotation,
              "--size", f"{arguments.size},{arguments.size}", "--spp", str(arguments.spp), "--quiet"]
    load_before = os.getloadavg()[0]
    with tempfile.TemporaryDirectory() as folder:
        gl_path, mitsuba_path = Path(folder) / "gl.exr", Path(folder) / "mitsuba.exr"
        gl_seconds = _timed(["render", *common, "--out", str(gl_path)])
        exposure = json.loads(gl_path.with_suffix(".config.json").read_text())["render"]["exposure"]
        mitsuba_seconds = _timed(["mitsuba-render", *common, "--integrator", "direct", "--exposure", repr(exposure),
                                  "--out", str(mitsuba_path)])
        gl, mitsuba = read_render_exr(gl_path), read_render_exr(mitsuba_path)  # linear sRGB, exposure applied

    def display(linear: np.ndarray) -> np.ndarray:
        from gratnet.display import xyz_to_display_srgb8
        from mitsuba_plugin.shading import xyz_to_linear_srgb_matrix

        xyz = linear @ np.linalg.inv(xyz_to_linear_srgb_matrix())  # the EXRs already hold the exposure
        return xyz_to_display_srgb8(xyz, 1.0).astype(np.float32) / 255.0

    flip, error_map = ldr_flip(display(gl), display(mitsuba))
    covered = (np.abs(gl).sum(axis=-1) > 0.0) & (np.abs(mitsuba).sum(axis=-1) > 0.0)
    record: dict[str, Any] = {
        "date": time.strftime("%Y-%m-%d"), "command": shlex.join(["python", *sys.argv]),
        "material": arguments.material, "mesh": arguments.mesh, "environment": arguments.environment,
        "size": arguments.size, "spp": arguments.spp, "exposure": exposure, "flip_frame": round(flip, 5),
        "flip_covered": round(float(error_map[covered].mean()), 5) if covered.any() else None,
        "mean_gl": [round(float(v), 6) for v in gl[covered].mean(axis=0)],
        "mean_mitsuba": [round(float(v), 6) for v in mitsuba[covered].mean(axis=0)],
        "seconds": {"gl": round(gl_seconds, 1), "mitsuba": round(mitsuba_seconds, 1)},
        "load_average_before": round(load_before, 2), "load_average_after": round(os.getloadavg()[0], 2)}
    print(json.dumps(record))

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 3, figsize=(9.0, 3.3))
    for axis, image, title in ((axes[0], display(gl), f"GL, {arguments.spp} spp"),
                               (axes[1], display(mitsuba), f"Mitsuba 3, {arguments.spp} spp"),
                               (axes[2], error_map, f"FLIP (mean {flip:.3f})")):
        axis.imshow(image, cmap="magma" if image.ndim == 2 else None, vmin=0.0, vmax=1.0)
        axis.set_title(title, fontsize=9)
        axis.axis("off")
    fig.suptitle(f"{arguments.material} on the {arguments.mesh} under {arguments.environment}", fontsize=9)
    fig.tight_layout()
    for target in (arguments.out, arguments.figure):
        target.parent.mkdir(parents=True, exist_ok=True)
    with atomic_paths(arguments.out, arguments.figure) as (json_temporary, figure_temporary):
        Path(json_temporary).write_text(json.dumps(record, indent=1) + "\n", encoding="utf-8")
        fig.savefig(figure_temporary, format="png", dpi=110)
    plt.close(fig)
    print(f"wrote {arguments.out} and {arguments.figure}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
