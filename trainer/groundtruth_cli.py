"""``gratnet groundtruth HEIGHTFIELD --out VOLUME.exr``: the Fourier-optics reflectance volume.

Public flags (keep them): --out, --res, --slices, --sampling, --sigma-s, --preview.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from gratnet.config import add_arguments, from_arguments, parse_float, parse_int
from gratnet.volume import write_volume


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``groundtruth`` subcommand."""
    from trainer.cli_support import add_heightfield_input
    from trainer.groundtruth import ComputeConfig, VolumeConfig

    parser = subparsers.add_parser(
        "groundtruth",
        help="compute the ground-truth reflectance volume (OpenEXR) of a height field",
        description="Compute CIE XYZ(u,v,w) of a height field (a file or a built-in generator's name) "
        "with the windowed Kirchhoff integral, spectrally (D65, CIE 1931 2°), and write it as OpenEXR.",
        epilog="typical use:\n"
        "  gratnet groundtruth blazed --res 101 --slices 11 --out blazed.exr --preview blazed.png  (minutes)\n"
        "  gratnet groundtruth surface.gsf --res 1001 --out surface.exr  (the paper's grid: hours on 2 CPU cores, "
        "about a minute on a GPU)",
    )
    add_heightfield_input(parser)
    parser.add_argument("--out", required=True, metavar="VOLUME.exr",
                        help="output volume (OpenEXR); its settings go to VOLUME.config.json")
    parser.add_argument("--preview", metavar="PNG", help="also write a PNG of one slice (display sRGB)")
    parser.add_argument("--preview-slice", type=parse_int, default=-1,
                        help="slice shown by --preview, 0 to SLICES−1 or negative from the end (default: -1, the last)")
    parser.add_argument("--exposure", type=parse_float, default=None,
                        help="preview exposure, > 0 (default: chosen so the slice's brightest 0.1%% is white)")
    parser.add_argument("--resume", action="store_true",
                        help="continue from VOLUME.exr.partial.npz, the partial sum an interrupted run left (the "
                        "same command and height field; the result is the uninterrupted run's, bit for bit)")
    add_arguments(parser, VolumeConfig)
    add_arguments(parser, ComputeConfig)
    parser.set_defaults(handler=run)


def run(arguments: argparse.Namespace) -> int:
    """Load, compute, write atomically (volume, config, optional preview)."""
    import numpy as np

    from gratnet.atomic import atomic_paths, check_output_file
    from gratnet.config import config_path_for, config_text
    from gratnet.errors import GratNetError
    from trainer.cli_support import check_volume_limits, read_heightfield_input, reporter, require_suffix
    from trainer.groundtruth import (
        ComputeConfig,
        VolumeConfig,
        checkpoint_path_for,
        checkpoint_wavelengths,
        compute_volume,
    )
    from trainer.preview import save_slice_preview

    # Every output is checked before minutes of computation.
    require_suffix(arguments.out, ".exr", "an OpenEXR file")
    outputs = [arguments.out, config_path_for(arguments.out)]
    if arguments.preview:
        if Path(arguments.preview).suffix.lower() != ".png":
            raise GratNetError(f"--preview must name a PNG image (.png), got {arguments.preview}")
        outputs.append(arguments.preview)
    for output in outputs:
        check_output_file(output, "--preview" if output is arguments.preview else "--out")
    volume_config = from_arguments(VolumeConfig, arguments)
    check_volume_limits(volume_config)
    if arguments.preview and not -volume_config.slices <= arguments.preview_slice < volume_config.slices:
        raise GratNetError(f"--preview-slice {arguments.preview_slice} is out of range: the volume will have "
                           f"{volume_config.slices} slices")
    if arguments.exposure is not None and not arguments.exposure > 0:
        raise GratNetError(f"--exposure must be > 0, got {arguments.exposure:g}")
    compute_config = from_arguments(ComputeConfig, arguments)
    checkpoint = checkpoint_path_for(arguments.out)
    if arguments.resume:  # none or unreadable: refused now (computing afresh would silently ignore --resume)
        checkpoint_wavelengths(checkpoint)
    device = compute_config.resolve()
    field, optics, load_options = read_heightfield_input(arguments)
    started = time.perf_counter()
    try:
        volume = compute_volume(field, volume_config, optics, report=reporter("groundtruth"),
                                progress=not arguments.quiet, device=device, checkpoint=checkpoint,
                                resume=arguments.resume, save_every_s=60.0 * compute_config.checkpoint_minutes)
    except KeyboardInterrupt:
        print(f"gratnet groundtruth: interrupted; {interrupted_state(checkpoint)}", file=sys.stderr)
        return 130
    elapsed = time.perf_counter() - started
    volume.metadata["compute_seconds"] = round(elapsed, 3)
    slice_index, exposure = arguments.preview_slice, arguments.exposure
    if arguments.preview and exposure is None:
        luminance = volume.xyz[slice_index % volume.slices, ..., 1]
        bright = float(np.percentile(luminance, 99.9))
        exposure = 1.0 / bright if bright > 0 else 1.0
    # Volume, config and preview land together or not at all.
    with atomic_paths(*outputs) as temporaries:
        write_volume(temporaries[0], volume)
        temporaries[1].write_text(config_text(arguments.out, volume=volume_config, optics=optics, load=load_options,
                                              compute=compute_config,
                                              heightfield=arguments.heightfield, source=field.source),
                                  encoding="utf-8")
        if arguments.preview:
            save_slice_preview(volume, temporaries[2], slice_index, exposure)
    print(f"wrote {arguments.out}: {volume.slices} slices of {volume.resolution}² "
          f"({volume.metadata['scheme']}), {elapsed:.1f} s")
    if arguments.preview:
        print(f"wrote {arguments.preview} (slice {slice_index}, exposure {exposure:.4g})")
    return 0


def interrupted_state(checkpoint: Path) -> str:
    """What an interrupted ground truth leaves, in words: the checkpoint's wavelengths and how to continue."""
    from gratnet.errors import GratNetError
    from trainer.groundtruth import checkpoint_wavelengths

    if not checkpoint.is_file():
        return "no checkpoint was saved yet, so there is nothing to resume from"
    try:
        done = checkpoint_wavelengths(checkpoint)
    except GratNetError:
        return f"{checkpoint} is unreadable; start afresh without --resume"
    return (f"{checkpoint} holds {done} wavelengths: the same command with --resume continues from there, "
            "as the uninterrupted run would have")
