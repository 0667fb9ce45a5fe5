"""``gratnet brdfslice HEIGHTFIELD --light θ,φ --out SLICE.png``: a ground-truth BRDF slice image."""

from __future__ import annotations

import argparse
import dataclasses

from gratnet.config import add_arguments, from_arguments, save_config


def parse_angles(text: str) -> tuple[float, float]:
    """'θ,φ' in degrees → (θ, φ)."""
    try:
        theta, phi = (float(part) for part in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected θ,φ in degrees such as 30,0; got {text!r}") from None
    return theta, phi


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``brdfslice`` subcommand."""
    from trainer.brdfslice import SliceConfig
    from trainer.cli_support import add_heightfield_input

    parser = subparsers.add_parser(
        "brdfslice", help="render a ground-truth BRDF slice (fixed light, every view direction) as PNG",
        description="Fix the light direction and show exposure · A · XYZ for every view direction, each "
        "pixel an orthographic projection of the view direction onto the base plane (display sRGB).",
    )
    add_heightfield_input(parser)
    parser.add_argument("--light", type=parse_angles, default=(30.0, 0.0), metavar="θ,φ",
                        help="light direction: polar angle and azimuth in degrees (default: 30,0)")
    parser.add_argument("--out", required=True, metavar="SLICE.png", help="output image (PNG, display sRGB)")
    add_arguments(parser, SliceConfig)
    parser.set_defaults(handler=run)


def run(arguments: argparse.Namespace) -> int:
    """Load, prepare, evaluate, write the PNG atomically with its config."""
    from PIL import Image

    from gratnet.atomic import atomic_path
    from gratnet.display import xyz_to_display_srgb8
    from trainer.brdfslice import SliceConfig, brdf_slice_xyz
    from trainer.cli_support import read_heightfield_input, reporter, require_suffix
    from trainer.fourier import prepare_surface

    require_suffix(arguments.out, ".png", "a PNG image")
    config = dataclasses.replace(
        from_arguments(SliceConfig, arguments),
        light_theta_degrees=arguments.light[0], light_phi_degrees=arguments.light[1],
    )
    field, optics, load_options = read_heightfield_input(arguments)
    surface = prepare_surface(field, optics, report=reporter("brdfslice"))
    xyz = brdf_slice_xyz(surface, config, optics, progress=not arguments.quiet)
    with atomic_path(arguments.out) as temporary:
        Image.fromarray(xyz_to_display_srgb8(xyz, 1.0)).save(temporary, format="PNG")
    save_config(arguments.out, slice=config, optics=optics, load=load_options,
                heightfield=arguments.heightfield, source=field.source)
    print(f"wrote {arguments.out}: light θ={config.light_theta_degrees:g}°, φ={config.light_phi_degrees:g}°, "
          f"exposure {config.exposure:g}")
    return 0
