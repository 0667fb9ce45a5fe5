"""``gratnet brdfslice HEIGHTFIELD --light θ,φ --out SLICE.png``: a ground-truth BRDF slice image."""

from __future__ import annotations

import argparse
import dataclasses

from gratnet.config import add_arguments, from_arguments, parse_numbers

#: Largest --size (pixels): the slice is computed for every pixel in float64 (4096² ≈ 400 MB per array).
MAX_SLICE_SIZE = 4096


def parse_angles(text: str) -> tuple[float, float]:
    """'θ,φ' in degrees → (θ, φ); negative values parse (``--light -30,0``: gratnet.cli)."""
    from gratnet.errors import GratNetError

    try:
        theta, phi = parse_numbers(text, 2, "--light", "θ,φ in degrees such as 30,0")
    except GratNetError as error:
        raise argparse.ArgumentTypeError(str(error).removeprefix("--light expects ")) from None
    return theta, phi


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``brdfslice`` subcommand."""
    from trainer.brdfslice import SliceConfig
    from trainer.cli_support import add_heightfield_input

    parser = subparsers.add_parser(
        "brdfslice", help="render a ground-truth BRDF slice (fixed light, every view direction) as PNG",
        description="Fix the light direction and show exposure · A · XYZ for every view direction, each "
        "pixel an orthographic projection of the view direction onto the base plane (display sRGB).",
        epilog="typical use:\n  gratnet brdfslice blazed --light 30,0 --size 256 --out slice.png",
    )
    add_heightfield_input(parser)
    parser.add_argument("--light", type=parse_angles, default=(30.0, 0.0), metavar="θ,φ",
                        help="light direction: polar angle (0 to 90) and azimuth in degrees (default: 30,0)")
    parser.add_argument("--out", required=True, metavar="SLICE.png",
                        help="output image (PNG, display sRGB); its settings go to SLICE.config.json")
    add_arguments(parser, SliceConfig)
    parser.set_defaults(handler=run)


def run(arguments: argparse.Namespace) -> int:
    """Load, prepare, evaluate, write the PNG atomically with its config."""
    from PIL import Image

    from gratnet.atomic import atomic_paths, check_output_file
    from gratnet.brdf import check_exposure, check_ior
    from gratnet.config import config_path_for, config_text
    from gratnet.display import xyz_to_display_srgb8
    from gratnet.errors import GratNetError
    from trainer.brdfslice import SliceConfig, brdf_slice_xyz
    from trainer.cli_support import read_heightfield_input, reporter, require_suffix
    from trainer.fourier import prepare_surface

    require_suffix(arguments.out, ".png", "a PNG image")
    check_output_file(arguments.out)
    check_output_file(config_path_for(arguments.out))
    config = dataclasses.replace(
        from_arguments(SliceConfig, arguments),
        light_theta_degrees=arguments.light[0], light_phi_degrees=arguments.light[1],
    )
    if config.size > MAX_SLICE_SIZE:
        raise GratNetError(f"--size must be at most {MAX_SLICE_SIZE} pixels (typical: 256 to 1024), got {config.size}")
    check_exposure(config.exposure)
    check_ior(config.ior)
    field, optics, load_options = read_heightfield_input(arguments)
    surface = prepare_surface(field, optics, report=reporter("brdfslice"))
    xyz = brdf_slice_xyz(surface, config, optics, progress=not arguments.quiet)
    # The image and its config land together or not at all.
    with atomic_paths(arguments.out, config_path_for(arguments.out)) as (image_temporary, config_temporary):
        Image.fromarray(xyz_to_display_srgb8(xyz, 1.0)).save(image_temporary, format="PNG")
        config_temporary.write_text(config_text(arguments.out, slice=config, optics=optics, load=load_options,
                                                heightfield=arguments.heightfield, source=field.source),
                                    encoding="utf-8")
    print(f"wrote {arguments.out}: light θ={config.light_theta_degrees:g}°, φ={config.light_phi_degrees:g}°, "
          f"exposure {config.exposure:g}")
    return 0
