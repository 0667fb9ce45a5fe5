"""Issue 43 probe: Mitsuba's mean over a sphere's covered pixels as its tessellation grows (the shadow terminator).

    python docs/experiments/probes/mitsuba_terminator_probe.py paper-snake studio [--size 32] [--spp 512] [--seed 1]

Mitsuba 3 (``llvm_ad_rgb``, the ``direct`` integrator, the plugin's sampler) renders the material on spheres of
64 × 32, 256 × 128 and 1024 × 512 facets (camera 0.3 m, azimuth 30°, elevation 20°, 22° field of view) under the
environment; prints each mean linear sRGB and its ratio to the finest. Log:
docs/experiments/2026-11-28-environment-agreement.md.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[3]))


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("material")
    parser.add_argument("environment")
    parser.add_argument("--size", type=int, default=32)
    parser.add_argument("--spp", type=int, default=512)
    parser.add_argument("--seed", type=int, default=1)
    arguments = parser.parse_args()
    from gratnet.environment import load_environment
    from mitsuba_plugin import scene as mitsuba_scene
    from mitsuba_plugin.runtime import set_variant
    from viewer.camera import Camera
    from viewer.catalog import resolve_material
    from viewer.meshes import sphere

    environment = load_environment(arguments.environment, what="--environment")
    mi = set_variant("llvm_ad_rgb")
    means = {}
    for segments in (64, 256, 1024):
        started = time.perf_counter()
        scene = mitsuba_scene.build_scene(
            mi, sphere(segments=segments, rings=segments // 2),
            mitsuba_scene.bsdf_dict(resolve_material(arguments.material), 1.5),
            mitsuba_scene.sensor(mi, Camera(0.3, 30.0, 20.0, fov_deg=22.0), arguments.size, arguments.size,
                                 arguments.spp),
            mitsuba_scene.emitters(None, environment), integrator="direct")
        rgb = mitsuba_scene.render_passes(mi, scene, arguments.spp, seed=arguments.seed).astype(np.float64)
        means[segments] = rgb[np.abs(rgb).sum(axis=-1) > 0.0].mean(axis=0)
        seconds = time.perf_counter() - started
        print(f"{segments} × {segments // 2}: mean {means[segments]}, {seconds:.1f} s", flush=True)
    for segments, mean in means.items():
        print(f"{segments} × {segments // 2} / 1024 × 512: {np.round(mean / means[1024], 4)}")


if __name__ == "__main__":
    main()
