"""The error of the tiled kernel's half-precision arithmetic (``tiled-half``, issue 32) against its float32 form
(``tiled``), on the paper's five evaluation slices, one JSON line per model and slice.

    python benchmarks/tiled_half_error.py cd paper-cd paper-scratches --size 256
    python benchmarks/tiled_half_error.py cd --size 64 --as-float   # llvmpipe: the code path only

Per slice (gratnet.brdf.STANDARD_SLICES: light θ, φ and exposure; the view disc of ``--size``²): both kernels
shade the slice's key vectors (``DeferredRenderer.shade_keys``: the list holds exactly the disc's pixels);
reported are the mean LDR-FLIP of the two exposed slices (exposure · A · XYZ, displayed as the evaluation
displays them: trainer/metrics.py), the largest difference in the range-transformed output (eq. 7's y, the
network's own output domain) and the largest relative XYZ difference on pixels at least 1e-3 of the slice's
peak. ``--as-float`` compiles tiled-half's code with float types (``half_as_float``: for drivers without half
arithmetic, such as llvmpipe; it then measures fp16 weight storage only). Runs on whatever EGL gives.
"""

from __future__ import annotations

import argparse
import json
import os
import sys

import numpy as np

from gratnet.brdf import STANDARD_SLICES, a_term, direction, slice_view_directions
from gratnet.display import ldr_flip
from gratnet.encoding import range_forward
from gratnet.errors import GratNetError
from gratnet.modelfile import load_model
from trainer.metrics import to_display_srgb
from viewer.catalog import resolve_material
from viewer.context import create_headless_context
from viewer.deferred import DeferredRenderer
from viewer.renderer import NetworkRenderer


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("materials", nargs="+", help="shipped material names or model-file paths")
    parser.add_argument("--size", type=int, default=256, help="slice side, pixels")
    parser.add_argument("--as-float", action="store_true", help="tiled-half's code in float types (no extension)")
    parser.add_argument("--ior", type=float, default=1.5)
    arguments = parser.parse_args()
    ctx = create_headless_context()
    renderer_name = str(ctx.info.get("GL_RENDERER", "?"))
    views, inside = slice_view_directions(arguments.size)
    try:
        for material in arguments.materials:
            model = load_model(resolve_material(material))
            network = NetworkRenderer(ctx, model, weights_path="texture")
            reference = DeferredRenderer(network, "tiled")
            half = DeferredRenderer(network, "tiled-half", half_as_float=arguments.as_float)
            try:
                for theta, phi, exposure in STANDARD_SLICES:
                    light = direction(theta, phi)
                    keys = -(light + views[inside])
                    xyz = {name: kernel.shade_keys(keys).astype(np.float64)
                           for name, kernel in (("float", reference), ("half", half))}
                    y = {name: range_forward(value, model.range) for name, value in xyz.items()}
                    attenuation = a_term(light, views, ior=arguments.ior)[inside][:, None]
                    images = {}
                    for name, value in xyz.items():
                        image = np.zeros((arguments.size, arguments.size, 3))
                        image[inside] = exposure * attenuation * value
                        images[name] = image
                    flip, _ = ldr_flip(to_display_srgb(images["float"]), to_display_srgb(images["half"]))
                    peak = xyz["float"].max()
                    lit = xyz["float"].max(axis=-1) > 1e-3 * peak
                    relative = (np.abs(xyz["half"] - xyz["float"])[lit]
                                / np.maximum(np.abs(xyz["float"][lit]), 1e-3 * peak))
                    print(json.dumps({
                        "material": material, "slice": [theta, phi, exposure], "size": arguments.size,
                        "half": "as float" if arguments.as_float else "f16", "flip": round(flip, 6),
                        "max_abs_y": float(np.abs(y["half"] - y["float"]).max()),
                        "max_relative_xyz_lit": float(relative.max()) if relative.size else 0.0,
                        "median_relative_xyz_lit": float(np.median(relative)) if relative.size else 0.0,
                        "plan": half.tile_plan.describe(network.layout) if half.tile_plan else None,
                        "renderer": renderer_name, "load_average_1min": round(os.getloadavg()[0], 2),
                    }), flush=True)
            finally:
                half.release()
                reference.release()
                network.release()
    except GratNetError as error:
        print(f"tiled_half_error: {error}", file=sys.stderr)
        return 2
    finally:
        ctx.release()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
