"""FLIP error maps of several models at one BRDF slice, side by side (to see the pattern of an error, not its mean).

    python docs/experiments/probes/flip_maps.py MODEL.npz [MODEL.npz …] --heightfield paper-scratches --view 72,30,5000
        [--labels 'shipped;4 features, t 11/11/21'] [--cache-dir out/cache] --out maps.png

Each panel is NVIDIA's FLIP error map (flip-evaluator, as `gratnet evaluate` computes it) of one model's slice
against the exact ground truth, titled with its mean FLIP. The models must share the height field and the
optics of the ground truth (the first model's volume metadata is used for all).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from gratnet.errors import GratNetError
from gratnet.modelfile import load_model
from trainer.brdfslice import SliceConfig
from trainer.evaluate import (
    EvaluateConfig,
    ground_truth_brdf_slice,
    model_ground_truth_inputs,
    network_brdf_slice,
    slice_label,
)
from trainer.metrics import flip


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("models", nargs="+", help="model files (.npz)")
    parser.add_argument("--heightfield", required=True, help="height field or paper dataset of the ground truth")
    parser.add_argument("--view", required=True, help="'θ,φ,RU': light polar and azimuth angles (degrees), exposure")
    parser.add_argument("--labels", default="", help="one title per model, separated by ';' (default: file names)")
    parser.add_argument("--size", type=int, default=256, help="slice width and height (pixels)")
    parser.add_argument("--cache-dir", default="out/cache", help="ground-truth slice cache (as gratnet evaluate's)")
    parser.add_argument("--out", required=True, help="PNG to write")
    args = parser.parse_args()
    try:  # gratnet evaluate's own parsing and checks of a view
        views = EvaluateConfig(views=args.view).extra_views()
    except GratNetError as error:
        sys.exit(f"flip_maps: {error}")
    labels = [label.strip() for label in args.labels.split(";")] if args.labels else [Path(p).parent.name
                                                                                       for p in args.models]
    if len(views) != 1 or len(labels) != len(args.models) or args.size < 2:
        sys.exit("flip_maps: give one --view, one label per model (or none) and --size ≥ 2")
    for path in args.models:
        if not Path(path).is_file():
            sys.exit(f"flip_maps: no such file: {path}")

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from gratnet.figures import save_figure

    models = [load_model(path) for path in args.models]
    field, optics = model_ground_truth_inputs(models[0], args.heightfield)
    theta, phi, exposure = views[0]
    config = SliceConfig(theta, phi, size=args.size, exposure=exposure, ior=1.5)
    reference = ground_truth_brdf_slice(field, optics, config, args.cache_dir)
    fig, axes = plt.subplots(1, len(models), figsize=(3.6 * len(models) + 0.6, 3.9), squeeze=False)
    for ax, model, label in zip(axes[0], models, labels, strict=True):
        mean, error_map = flip(reference, network_brdf_slice(model, config))
        image = ax.imshow(error_map, cmap="magma", vmin=0.0, vmax=0.5)
        ax.set_title(f"{label}\nFLIP {mean:.4f}", fontsize=9)
        ax.axis("off")
    fig.colorbar(image, ax=list(axes[0]), shrink=0.8, label="FLIP error")
    fig.suptitle(f"FLIP error maps, {slice_label(theta, phi, exposure)}", fontsize=10)
    save_figure(fig, args.out)
    plt.close(fig)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
