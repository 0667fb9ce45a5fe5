"""Issue 43 probe: the viewer's environment light on the forward path against the deferred one, on this machine's
rasterizer. For a model (default paper-cd's accurate point), from an empty Mesa shader cache: the seconds to compile
and first-draw the programs a directionally lit deferred render needs (the viewer's ``surface`` group on a CPU),
then the further seconds each path's sampled-light programs need, then the median seconds of an environment pass
(one sample per pixel, the sky, the flat importance table) on the CD disc at a few sizes.

    MESA_SHADER_CACHE_DIR=$(mktemp -d) python docs/experiments/probes/environment_path_probe.py [MODEL]
"""

from __future__ import annotations

import json
import statistics
import sys
import time

from gratnet.environment import load_environment
from gratnet.modelfile import load_model
from viewer.camera import Camera, Light
from viewer.context import create_headless_context
from viewer.meshes import compact_disc
from viewer.scene import SceneRenderer


def main() -> None:
    model = load_model(sys.argv[1] if len(sys.argv) > 1 else "assets/paper-cd/model.npz")
    ctx = create_headless_context()
    sky = load_environment("sky")
    camera, light = Camera(0.18, -90.0, 50.0), Light.directional(0.0, 0.0, 0.0)
    report: dict[str, object] = {"renderer": ctx.info["GL_RENDERER"]}
    scene = SceneRenderer(ctx, model, weights_path="texture", render_path="deferred", measure_render_path=False)
    scene.provisional_importance = True  # the flat table: the probe times programs and passes, not the table
    buffers = scene.upload(compact_disc())
    started = time.perf_counter()
    for size in ((1, 1), (2, 2)):
        scene.render_rgba(buffers, camera, Light.directional(20.0, 90.0), size, 1.0, 1.5)
    ctx.finish()
    report["surface_deferred_s"] = time.perf_counter() - started
    for path in ("deferred", "forward"):
        started = time.perf_counter()
        for size in ((1, 1), (2, 2)):
            scene.render_rgba(buffers, camera, light, size, 1.0, 1.5, environment=sky, render_path=path)
        ctx.finish()
        report[f"environment_{path}_compile_s"] = time.perf_counter() - started
    for side in (64, 128, 256, 512):
        for path in ("deferred", "forward"):
            times = []
            for sample in range(3):
                started = time.perf_counter()
                scene.render_rgba(buffers, camera, light, (side, side), 1.0, 1.5, environment=sky, render_path=path,
                                  first_sample=sample)
                ctx.finish()
                times.append(time.perf_counter() - started)
            report[f"pass_{path}_{side}_s"] = statistics.median(times)
    print(json.dumps(report, indent=1))


if __name__ == "__main__":
    main()
