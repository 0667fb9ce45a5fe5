"""Issue 43 probe: the noise of 64 passes per sampling strategy against a long MIS reference, and where it sits.

    python docs/experiments/probes/environment_resampling_probe.py paper-cd cd sky VOLUME.exr mis resampled \
        [--candidates 8] [--material-share 0.25] [--size 128]

Shades with the ground-truth volume looked up per pixel (gratnet render --reference: the network's estimator at a
fraction of its cost). The reference (2,048 MIS passes, seed 1000) is cached in /tmp/gratnet_resampling_probe;
then each strategy's 64 passes (seed 0) are scored by relative RMSE and FLIP, and a figure shows the reference and
the per-pixel variance of one pass (log10). ``--candidates`` and ``--material-share`` set
gratnet.importance.RESAMPLING_CANDIDATES and RESAMPLING_MATERIAL_CANDIDATES (the share times the candidates,
rounded; the share itself at 6efff4f, when this log was measured) before the renderer reads them.
Log: docs/experiments/2026-11-28-resampled-environment.md.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[3]))


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("material")
    parser.add_argument("mesh")
    parser.add_argument("environment")
    parser.add_argument("volume")
    parser.add_argument("strategies", nargs="+")
    parser.add_argument("--candidates", type=int, default=None)
    parser.add_argument("--material-share", type=float, default=None)
    parser.add_argument("--size", type=int, default=128)
    arguments = parser.parse_args()
    from gratnet import importance

    if arguments.candidates is not None:
        importance.RESAMPLING_CANDIDATES = arguments.candidates
    if arguments.material_share is not None:
        importance.RESAMPLING_MATERIAL_CANDIDATES = max(1, round(arguments.material_share
                                                                 * importance.RESAMPLING_CANDIDATES))
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from gratnet.display import ldr_flip, xyz_to_display_srgb8
    from gratnet.environment import load_environment
    from gratnet.showcase import suggest_exposure
    from viewer.camera import Camera, Light
    from viewer.catalog import build_mesh
    from viewer.context import create_headless_context
    from viewer.defaults import resolve_defaults
    from viewer.scene import SceneRenderer
    from viewer.scene_config import load_reference

    size = (arguments.size, arguments.size)
    environment = load_environment(arguments.environment, what="--environment")
    defaults = resolve_defaults(arguments.material, arguments.mesh)
    camera = Camera(defaults.camera_distance, defaults.camera_azimuth_degrees, defaults.camera_elevation_degrees)
    no_light = Light.directional(0.0, 0.0, 0.0)
    cache = Path("/tmp/gratnet_resampling_probe")
    cache.mkdir(exist_ok=True)
    reference_path = cache / f"{arguments.material}_{arguments.mesh}_{arguments.environment}_{arguments.size}.npy"
    ctx = create_headless_context()

    def display(xyz: np.ndarray, exposure: float) -> np.ndarray:
        return xyz_to_display_srgb8(xyz, exposure).astype(np.float32) / 255.0

    with SceneRenderer(ctx, load_reference(arguments.volume, "float16", arguments.material),
                       render_path="auto") as scene:
        mesh = scene.upload(build_mesh(arguments.mesh))

        def passes(first: int, count: int, seed: int, sampling: str) -> np.ndarray:
            return scene.render_rgba(mesh, camera, no_light, size, 1.0, 1.5, samples=count, first_sample=first,
                                     environment=environment, seed=seed, sampling=sampling)[..., :3].astype(np.float64)

        if not reference_path.exists():
            np.save(reference_path, np.mean([passes(16 * k, 16, 1000, "mis") for k in range(128)], axis=0))
        reference = np.load(reference_path)
        exposure = suggest_exposure(reference, 1.0) or 1.0
        figure, axes = plt.subplots(1, 1 + len(arguments.strategies), figsize=(4 * (1 + len(arguments.strategies)), 4))
        axes[0].imshow(display(reference, exposure))
        axes[0].set_title("reference, 2,048 MIS passes")
        for axis, sampling in zip(axes[1:], arguments.strategies, strict=True):
            samples = np.array([passes(k, 1, 0, sampling) for k in range(64)])
            mean = samples.mean(axis=0)
            squared = ((mean - reference) ** 2).sum(axis=-1)
            flip, _ = ldr_flip(display(reference, exposure), display(mean, exposure))
            top = np.sort(squared.ravel())[::-1][: squared.size // 100].sum() / squared.sum()
            print(f"{arguments.material} {arguments.mesh} {arguments.environment} {sampling}: K "
                  f"{importance.RESAMPLING_CANDIDATES}, {importance.RESAMPLING_MATERIAL_CANDIDATES} by material: "
                  f"relative RMSE {np.sqrt(squared.sum() / (reference ** 2).sum()):.4f}, FLIP {flip:.4f}, "
                  f"top 1 % of pixels {100 * top:.0f} % of the squared error", flush=True)
            axis.imshow(np.log10(samples.var(axis=0).sum(axis=-1) + 1e-12))
            axis.set_title(f"{sampling}: log10 variance of one pass")
        out = cache / f"variance_{arguments.material}_{arguments.environment}.png"
        figure.savefig(out, dpi=80)
        print(f"wrote {out}")


if __name__ == "__main__":
    main()
