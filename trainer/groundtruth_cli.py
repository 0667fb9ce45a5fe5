"""``gratnet groundtruth HEIGHTFIELD --out VOLUME.exr``: the Fourier-optics reflectance volume.

Public flags (keep them): --out, --res, --slices, --sampling, --sigma-s, --preview.
"""

from __future__ import annotations

import argparse
import sys
import time

from gratnet.config import add_arguments, from_arguments, save_config
from gratnet.errors import GratNetError
from gratnet.volume import write_volume


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``groundtruth`` subcommand."""
    from trainer.fourier import OpticsConfig
    from trainer.groundtruth import VolumeConfig
    from trainer.loaders import LoadOptions

    parser = subparsers.add_parser(
        "groundtruth",
        help="compute the ground-truth reflectance volume (OpenEXR) of a height field",
        description="Compute CIE XYZ(u,v,w) of a height field (a file or a built-in generator's name) "
        "with the windowed Kirchhoff integral, spectrally (D65, CIE 1931 2°), and write it as OpenEXR.",
    )
    parser.add_argument("heightfield", metavar="HEIGHTFIELD", help="height-field file or built-in generator name")
    parser.add_argument("--out", required=True, metavar="VOLUME.exr", help="output volume (OpenEXR)")
    parser.add_argument("--preview", metavar="PNG", help="also write a PNG of one slice (display sRGB)")
    parser.add_argument("--preview-slice", type=int, default=-1, help="slice shown by --preview (default: last)")
    parser.add_argument("--exposure", type=float, default=None,
                        help="preview exposure (default: chosen so the slice's brightest 0.1%% is white)")
    parser.add_argument("--quiet", action="store_true", help="no progress bar")
    add_arguments(parser, VolumeConfig)
    add_arguments(parser, OpticsConfig)
    add_arguments(parser, LoadOptions)
    parser.set_defaults(handler=run)


def run(arguments: argparse.Namespace) -> int:
    """Load, compute, write atomically (volume, config, optional preview)."""
    import numpy as np

    from trainer.fourier import OpticsConfig
    from trainer.groundtruth import VolumeConfig, compute_volume
    from trainer.loaders import LoadOptions, load_heightfield
    from trainer.preview import save_slice_preview

    if not str(arguments.out).lower().endswith(".exr"):
        raise GratNetError(f"--out must name an OpenEXR file (.exr), got {arguments.out}")
    volume_config = from_arguments(VolumeConfig, arguments)
    optics = from_arguments(OpticsConfig, arguments)
    load_options = from_arguments(LoadOptions, arguments)
    field = load_heightfield(arguments.heightfield, load_options)

    def report(message: str) -> None:
        print(f"gratnet groundtruth: {message}", file=sys.stderr)

    started = time.perf_counter()
    volume = compute_volume(field, volume_config, optics, report=report, progress=not arguments.quiet)
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
