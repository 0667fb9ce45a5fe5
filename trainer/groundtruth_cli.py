"""``gratnet groundtruth HEIGHTFIELD --out VOLUME.exr``: the Fourier-optics reflectance volume.

Public flags (keep them): --out, --res, --slices, --sampling, --sigma-s, --preview.
"""

from __future__ import annotations

import argparse
import time

from gratnet.config import add_arguments, from_arguments, save_config
from gratnet.volume import write_volume


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``groundtruth`` subcommand."""
    from trainer.cli_support import add_heightfield_input
    from trainer.groundtruth import VolumeConfig

    parser = subparsers.add_parser(
        "groundtruth",
        help="compute the ground-truth reflectance volume (OpenEXR) of a height field",
        description="Compute CIE XYZ(u,v,w) of a height field (a file or a built-in generator's name) "
        "with the windowed Kirchhoff integral, spectrally (D65, CIE 1931 2°), and write it as OpenEXR.",
    )
    add_heightfield_input(parser)
    parser.add_argument("--out", required=True, metavar="VOLUME.exr", help="output volume (OpenEXR)")
    parser.add_argument("--preview", metavar="PNG", help="also write a PNG of one slice (display sRGB)")
    parser.add_argument("--preview-slice", type=int, default=-1, help="slice shown by --preview (default: last)")
    parser.add_argument("--exposure", type=float, default=None,
                        help="preview exposure (default: chosen so the slice's brightest 0.1%% is white)")
    add_arguments(parser, VolumeConfig)
    parser.set_defaults(handler=run)


def run(arguments: argparse.Namespace) -> int:
    """Load, compute, write atomically (volume, config, optional preview)."""
    import numpy as np

    from trainer.cli_support import read_heightfield_input, reporter, require_suffix
    from trainer.groundtruth import VolumeConfig, compute_volume
    from trainer.preview import save_slice_preview

    require_suffix(arguments.out, ".exr", "an OpenEXR file")
    volume_config = from_arguments(VolumeConfig, arguments)
    field, optics, load_options = read_heightfield_input(arguments)
    started = time.perf_counter()
    volume = compute_volume(field, volume_config, optics, report=reporter("groundtruth"),
                            progress=not arguments.quiet)
    elapsed = time.perf_counter() - started
    volume.metadata["compute_seconds"] = round(elapsed, 3)
    write_volume(arguments.out, volume)
    save_config(arguments.out, volume=volume_config, optics=optics, load=load_options,
                heightfield=arguments.heightfield, source=field.source)
    print(f"wrote {arguments.out}: {volume.slices} slices of {volume.resolution}² "
          f"({volume.metadata['scheme']}), {elapsed:.1f} s")
    if arguments.preview:
        slice_index = arguments.preview_slice
        exposure = arguments.exposure
        if exposure is None:
            luminance = volume.xyz[slice_index % volume.slices, ..., 1]
            bright = float(np.percentile(luminance, 99.9))
            exposure = 1.0 / bright if bright > 0 else 1.0
        save_slice_preview(volume, arguments.preview, slice_index, exposure)
        print(f"wrote {arguments.preview} (slice {slice_index}, exposure {exposure:.4g})")
    return 0
