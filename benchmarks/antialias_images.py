"""Anti-aliasing on the CD disc (issue 12): pictures at 1 … N samples per pixel, their error against a
reference, and the cost per sample count. Prints a markdown table; writes the side-by-side PNG.

    python benchmarks/antialias_images.py --out docs/images/antialias_cd.png

The view is ``gratnet render --material cd --mesh cd``'s (its defaults). The reference is the same view at
``--reference-factor`` × the size with ``--reference-spp`` samples, box-filtered down (factor² ×
reference-spp stratified samples per pixel): what N jittered samples per pixel converge to. The error is
mean FLIP (display sRGB, trainer.metrics.flip) and PSNR of CIE XYZ inside the disc. Times are wall
seconds of one ``SceneRenderer.render`` call (read-back included), after a warm-up render.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from bench.scenes import scene_view
from gratnet.modelfile import load_model
from trainer.metrics import flip, psnr_xyz
from viewer.catalog import resolve_material
from viewer.context import create_headless_context
from viewer.scene import SceneRenderer


def _box_down(image: np.ndarray, factor: int) -> np.ndarray:
    height, width = image.shape[0] // factor, image.shape[1] // factor
    return image.reshape(height, factor, width, factor, -1).mean(axis=(1, 3))


def _panel(pixels: np.ndarray, crop: tuple[int, int, int], zoom: int) -> np.ndarray:
    """The picture with the crop's frame drawn, above the crop enlarged ``zoom`` × (nearest neighbour)."""
    row, column, side = crop
    framed = pixels.copy()
    framed[row, column:column + side] = framed[row + side - 1, column:column + side] = 255
    framed[row:row + side, column] = framed[row:row + side, column + side - 1] = 255
    enlarged = np.repeat(np.repeat(pixels[row:row + side, column:column + side], zoom, 0), zoom, 1)
    width = framed.shape[1]
    pad = np.zeros((enlarged.shape[0], width, 3), np.uint8)
    pad[:, :enlarged.shape[1]] = enlarged[:, :width]
    return np.concatenate([framed, np.full((4, width, 3), 255, np.uint8), pad], axis=0)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--material", default="cd")
    parser.add_argument("--size", type=int, default=256, help="picture side, pixels")
    parser.add_argument("--spp", default="1,4,16,64", help="sample counts to render")
    parser.add_argument("--shown", default="1,64", help="the two sample counts side by side in the PNG")
    parser.add_argument("--reference-factor", type=int, default=4)
    parser.add_argument("--reference-spp", type=int, default=16)
    parser.add_argument("--crop", default="70,140,64", help="ROW,COLUMN,SIDE of the enlarged crop")
    parser.add_argument("--out", type=Path, required=True, help="the side-by-side PNG")
    arguments = parser.parse_args()
    counts = [int(part) for part in arguments.spp.split(",")]
    shown = [int(part) for part in arguments.shown.split(",")]
    crop_row, crop_column, crop_side = (int(part) for part in arguments.crop.split(","))
    crop = (crop_row, crop_column, crop_side)
    size = (arguments.size, arguments.size)

    path = resolve_material(arguments.material)
    view = scene_view(str(path), "cd")
    ctx = create_headless_context()
    images: dict[int, np.ndarray] = {}
    seconds: dict[int, float] = {}
    with SceneRenderer(ctx, load_model(path)) as renderer:
        from viewer.catalog import build_mesh

        buffers = renderer.upload(build_mesh("cd"))

        def render(side: tuple[int, int], samples: int) -> np.ndarray:
            return renderer.render(buffers, view.camera, view.light, side, view.exposure, view.ior, samples=samples)

        render(size, 1)  # warm-up: compile (Mesa's cache), JIT, allocations
        for count in counts:
            start = time.perf_counter()
            images[count] = render(size, count)
            seconds[count] = time.perf_counter() - start
        factor = arguments.reference_factor
        start = time.perf_counter()
        reference = _box_down(render((size[0] * factor, size[1] * factor), arguments.reference_spp), factor)
        reference_seconds = time.perf_counter() - start
        coverage = renderer.render_rgba(buffers, view.camera, view.light, size, view.exposure, view.ior,
                                        samples=16)[..., 3]
        buffers.release()
        gl_renderer = ctx.info["GL_RENDERER"]
    ctx.release()

    disc = coverage > 0.999  # pixels wholly on the disc (its edges converge too, but are not the point here)
    print(f"CD disc, {size[0]}×{size[1]}, {arguments.material}, {gl_renderer}; reference: {factor}× the size at "
          f"{arguments.reference_spp} spp, box-filtered ({reference_seconds:.0f} s)")
    print("| spp | render (s, wall) | per sample (s) | mean FLIP vs reference | PSNR XYZ, disc (dB) |")
    print("|---|---|---|---|---|")
    for count in counts:
        mean_flip, _ = flip(reference, images[count])
        print(f"| {count} | {seconds[count]:.2f} | {seconds[count] / count:.3f} | {mean_flip:.4f} | "
              f"{psnr_xyz(reference, images[count], disc):.1f} |")

    from PIL import Image

    from gratnet.atomic import atomic_path

    zoom = max(1, size[0] // crop[2])  # the crop enlarged to the picture's width
    panels = [_panel(SceneRenderer.display_srgb8(images[count]), crop, zoom) for count in shown]
    gap = np.full((panels[0].shape[0], 6, 3), 255, np.uint8)
    picture = np.concatenate([panels[0], gap, panels[1]], axis=1)
    arguments.out.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(arguments.out) as temporary:
        Image.fromarray(picture).save(temporary, format="PNG", optimize=True)
    print(f"wrote {arguments.out} ({' | '.join(f'{count} spp' for count in shown)}; below each: rows "
          f"{crop[0]}–{crop[0] + crop[2]}, columns {crop[1]}–{crop[1] + crop[2]}, enlarged {zoom}×)")


if __name__ == "__main__":
    main()
