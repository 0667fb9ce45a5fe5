"""Contact sheet: every shipped material (rows) on every built-in mesh (columns) at the shared defaults.

    python benchmarks/defaults_sheet.py --size 192,144 --out docs/images/defaults_sheet.png

Each tile is what ``gratnet render --material M --mesh MESH`` writes with no --light, --camera or
--exposure (viewer.defaults.resolve_defaults), rendered headless with the texture weight path (same
pixels as the baked path to float32 precision; it compiles in about a second instead of ~25 s per model
on llvmpipe). Under each tile: the resolved light θ,φ (degrees), exposure and the fraction of pixels the
display shows black. Also prints one line per tile.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
from PIL import Image, ImageDraw

from gratnet.atomic import atomic_path
from gratnet.modelfile import load_model
from gratnet.showcase import black_fraction
from viewer.camera import Camera, Light
from viewer.catalog import MESHES, build_mesh, resolve_material, shipped_materials
from viewer.context import create_headless_context
from viewer.defaults import FOV_DEGREES, resolve_defaults
from viewer.scene import SceneRenderer
from viewer.scene_config import parse_size

_LABEL_HEIGHT = 26


def render_sheet(size: tuple[int, int]) -> tuple[np.ndarray, list[str]]:
    """The sheet (display sRGB ``uint8``) and one report line per tile."""
    width, height = size
    materials, meshes = shipped_materials(), list(MESHES)
    sheet = Image.new("RGB", (len(meshes) * width + 60, len(materials) * (height + _LABEL_HEIGHT)), (24, 24, 24))
    draw = ImageDraw.Draw(sheet)
    lines = []
    ctx = create_headless_context()
    try:
        for row, material in enumerate(materials):
            top = row * (height + _LABEL_HEIGHT)
            draw.text((4, top + height // 2), material, fill=(230, 230, 230))
            with SceneRenderer(ctx, load_model(resolve_material(material)), weights_path="texture") as renderer:
                for column, mesh in enumerate(meshes):
                    d = resolve_defaults(material, mesh)
                    camera = Camera(d.camera_distance, d.camera_azimuth_degrees, d.camera_elevation_degrees,
                                    fov_deg=FOV_DEGREES)
                    light = Light.directional(d.light_theta_degrees, d.light_phi_degrees)
                    xyz = renderer.render(build_mesh(mesh), camera, light, size, d.exposure, 1.5)
                    black = black_fraction(xyz)
                    left = 60 + column * width
                    sheet.paste(Image.fromarray(SceneRenderer.display_srgb8(xyz)), (left, top))
                    draw.text((left + 3, top + height + 2), f"{mesh}: light {d.light_text}", fill=(200, 200, 200))
                    draw.text((left + 3, top + height + 13), f"exposure {d.exposure:g}, {100 * black:.1f}% black",
                              fill=(200, 200, 200))
                    lines.append(f"{material:11s} {mesh:7s} light {d.light_text:>12s} camera {d.camera_text:>14s} "
                                 f"exposure {d.exposure:<7g} black {100 * black:5.1f} %")
    finally:
        ctx.release()
    return np.asarray(sheet), lines


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", default="192,144", help="tile size W,H in pixels (default: 192,144)")
    parser.add_argument("--out", default="docs/images/defaults_sheet.png", help="output PNG")
    arguments = parser.parse_args(argv)
    sheet, lines = render_sheet(parse_size(arguments.size))
    out = Path(arguments.out)
    with atomic_path(out) as temporary:
        Image.fromarray(sheet).save(temporary, format="PNG")
    print("\n".join(lines))
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
