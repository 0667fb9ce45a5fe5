"""Issue 43 probe: FLIP of 64 resampled passes at three seeds against one cached long reference, and its FLIP map.

    python docs/experiments/probes/environment_candidates_probe.py paper-cd cd sky [--size 64] [--reference-spp 1024] \
        [--figure out.png]

The network on the material's default view (gratnet render's camera), the map as it is. The reference (seed 1000,
the default sampling) is cached in /tmp/gratnet_candidates_probe, so the same reference scores the code before and
after a change of the sampler (run the probe from each checkout). Prints the mean FLIP and relative RMSE of 64
passes at seeds 0, 1, 2; ``--figure`` also saves reference | 64 passes | FLIP map of seed 0, and prints the share of
the FLIP held by the worst pixels. Log: docs/experiments/2026-11-28-environment-agreement.md.
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
    parser.add_argument("mesh")
    parser.add_argument("environment")
    parser.add_argument("--size", type=int, default=64)
    parser.add_argument("--reference-spp", type=int, default=1024)
    parser.add_argument("--figure", type=Path, default=None)
    arguments = parser.parse_args()
    from gratnet.display import ldr_flip, xyz_to_display_srgb8
    from gratnet.environment import load_environment
    from gratnet.modelfile import load_model
    from gratnet.showcase import suggest_exposure
    from viewer.camera import Camera, Light
    from viewer.catalog import build_mesh, resolve_material
    from viewer.context import create_headless_context
    from viewer.defaults import resolve_defaults
    from viewer.scene import SceneRenderer

    size = (arguments.size, arguments.size)
    environment = load_environment(arguments.environment, what="--environment")
    defaults = resolve_defaults(arguments.material, arguments.mesh)
    camera = Camera(defaults.camera_distance, defaults.camera_azimuth_degrees, defaults.camera_elevation_degrees)
    cache = Path("/tmp/gratnet_candidates_probe")
    cache.mkdir(exist_ok=True)
    reference_path = cache / (f"{arguments.material}_{arguments.mesh}_{arguments.environment}_{arguments.size}_"
                              f"{arguments.reference_spp}.npy")

    def display(xyz: np.ndarray, exposure: float) -> np.ndarray:
        return xyz_to_display_srgb8(xyz, exposure).astype(np.float32) / 255.0

    ctx = create_headless_context()
    with SceneRenderer(ctx, load_model(resolve_material(arguments.material)), render_path="auto") as scene:
        uploaded = scene.upload(build_mesh(arguments.mesh))

        def passes(first: int, count: int, seed: int) -> np.ndarray:
            rgba = scene.render_rgba(uploaded, camera, Light.directional(0.0, 0.0, 0.0), size, 1.0, 1.5,
                                     samples=count, first_sample=first, environment=environment, seed=seed)
            return rgba.astype(np.float64)[..., :3]

        passes(0, 1, 0)  # compiles and builds the importance table
        if reference_path.exists():
            reference = np.load(reference_path)
        else:
            total = np.zeros((*size[::-1], 3))
            for first in range(0, arguments.reference_spp, 64):
                total += passes(first, 64, 1000) * 64
                print(f"reference: {first + 64}/{arguments.reference_spp}", file=sys.stderr, end="\r")
            reference = total / arguments.reference_spp
            np.save(reference_path, reference)
        exposure = suggest_exposure(reference, 1.0) or 1.0
        lit = reference.mean(axis=-1) > 0.0
        scores = []
        maps = []
        for seed in (0, 1, 2):
            started = time.perf_counter()
            mean = passes(0, 64, seed)
            seconds = time.perf_counter() - started
            flip, error_map = ldr_flip(display(reference, exposure), display(mean, exposure))
            rmse = np.sqrt(np.mean((mean - reference)[lit] ** 2)) / np.sqrt(np.mean(reference[lit] ** 2))
            scores.append((flip, rmse, seconds))
            maps.append((mean, error_map))
        values = np.array(scores)
        print(f"{arguments.material} {arguments.mesh} {arguments.environment} {arguments.size}²: FLIP at 64 passes "
              f"{values[:, 0].mean():.4f} ({', '.join(f'{v:.4f}' for v in values[:, 0])}), relative RMSE "
              f"{values[:, 1].mean():.3f}, {values[:, 2].mean():.1f} s per 64 passes")
        if arguments.figure is not None:
            import matplotlib

            matplotlib.use("Agg")
            import matplotlib.pyplot as plt

            mean, error_map = maps[0]
            worst = np.sort(error_map.ravel())[::-1]
            shares = [worst[: max(1, worst.size * p // 100)].sum() / worst.sum() for p in (1, 5, 20)]
            print(f"worst 1 %, 5 %, 20 % of pixels hold {', '.join(f'{100 * s:.0f} %' for s in shares)} of the FLIP; "
                  f"lit pixels {error_map[lit].mean():.4f}, unlit {error_map[~lit].mean():.4f}")
            fig, axes = plt.subplots(1, 3, figsize=(9.0, 3.3))
            for axis, image, title in ((axes[0], display(reference, exposure), f"{arguments.reference_spp} passes"),
                                       (axes[1], display(mean, exposure), "64 passes"),
                                       (axes[2], error_map, f"FLIP {scores[0][0]:.4f}")):
                axis.imshow(image, cmap="magma" if image.ndim == 2 else None, vmin=0.0, vmax=0.5 if image.ndim == 2
                            else 1.0)
                axis.set_title(title, fontsize=9)
                axis.axis("off")
            fig.tight_layout()
            fig.savefig(arguments.figure, dpi=110)
        uploaded.release()
    ctx.release()


if __name__ == "__main__":
    main()
