"""What the ground-truth subcommands share: the HEIGHTFIELD argument with its optics and load flags."""

from __future__ import annotations

import argparse
from collections.abc import Callable
from pathlib import Path

from gratnet.config import add_arguments, add_quiet_flag, from_arguments
from gratnet.errors import GratNetError
from trainer.fourier import OpticsConfig
from trainer.groundtruth import VolumeConfig
from trainer.heightfield import HeightField
from trainer.heightfile import LoadOptions
from trainer.loaders import load_heightfield


def add_heightfield_input(parser: argparse.ArgumentParser) -> None:
    """HEIGHTFIELD (file or generator name), --quiet, and the OpticsConfig and LoadOptions flags."""
    parser.add_argument("heightfield", metavar="HEIGHTFIELD",
                        help="height-field file (.npz .gsf .npy .png .exr), built-in generator name (such as "
                        "blazed) or paper dataset (such as paper-cd, with its own σs); list: gratnet heightfield list")
    add_quiet_flag(parser)
    optics_flags = add_arguments(parser, OpticsConfig)
    add_arguments(parser, LoadOptions)
    # A paper dataset preset brings its own σs: None here means "the preset's, else OpticsConfig's default".
    optics_flags["sigma_s_um"].help = (f"std σs of the Gaussian coherence window (µm) (default: a paper dataset's "
                                       f"own, else {OpticsConfig.sigma_s_um:g}, i.e. 4σs = 65 µm)")
    parser.set_defaults(sigma_s_um=None)


def require_suffix(path: str, suffix: str, what: str) -> None:
    """Refuse an output path whose extension is not ``suffix`` (before any work is done)."""
    if Path(path).suffix.lower() != suffix:
        raise GratNetError(f"--out must name {what} ({suffix}), got {path}")


#: Command-line limits of the optics (memory and time grow with the grid side squared and the wavelength count).
MIN_WAVELENGTH_STEP_NM = 0.1
GRID_SAMPLES_RANGE = (16, 16384)
#: Largest --res and --slices: R² · S samples, each a spectral integral (2001² · 101 ≈ 4e8 would take days).
MAX_RESOLUTION = 4001
MAX_SLICES = 1001
#: Largest volume held in memory (float32 XYZ): 8 GB.
MAX_VOLUME_BYTES = 8e9


def check_optics_limits(optics: OpticsConfig) -> None:
    """The command-line limits of the optics (``gratnet groundtruth``'s, ``gratnet sweep``'s): one GratNetError."""
    if optics.wavelength_step_nm < MIN_WAVELENGTH_STEP_NM:
        raise GratNetError(f"--wavelength-step-nm must be at least {MIN_WAVELENGTH_STEP_NM} nm (typical: 5), "
                           f"got {optics.wavelength_step_nm:g}")
    low, high = GRID_SAMPLES_RANGE
    if not low <= optics.max_grid_samples <= high:
        raise GratNetError(f"--max-grid-samples must be from {low} to {high} (typical: 4096), "
                           f"got {optics.max_grid_samples}")


def check_volume_limits(config: VolumeConfig) -> None:
    """The command-line limits of a volume's grid (``gratnet groundtruth``'s, ``gratnet sweep``'s)."""
    if config.resolution > MAX_RESOLUTION:
        raise GratNetError(f"--res must be at most {MAX_RESOLUTION} (typical: 101 to 1001), got {config.resolution}")
    if config.slices > MAX_SLICES:
        raise GratNetError(f"--slices must be at most {MAX_SLICES} (typical: 11), got {config.slices}")
    volume_bytes = config.resolution**2 * config.slices * 3 * 4
    if volume_bytes > MAX_VOLUME_BYTES:
        raise GratNetError(f"--res {config.resolution} with --slices {config.slices} makes a "
                           f"{volume_bytes / 1e9:.0f} GB volume (at most {MAX_VOLUME_BYTES / 1e9:.0f} GB)")


def read_heightfield_input(arguments: argparse.Namespace) -> tuple[HeightField, OpticsConfig, LoadOptions]:
    """The loaded height field with the resolved optics and load options (limits checked before loading)."""
    from trainer import datasets

    if arguments.sigma_s_um is None:
        preset = datasets.PRESETS.get(arguments.heightfield) if not Path(arguments.heightfield).exists() else None
        arguments.sigma_s_um = preset.sigma_s_um if preset is not None else OpticsConfig.sigma_s_um
    optics = from_arguments(OpticsConfig, arguments)
    check_optics_limits(optics)
    load_options = from_arguments(LoadOptions, arguments)
    return load_heightfield(arguments.heightfield, load_options), optics, load_options


def reporter(command: str) -> Callable[[str], None]:
    """A callback that reports ``command``'s preparation steps (resampled, repeated) on stderr, one line each,
    through the "gratnet" logger: ``--quiet`` silences them like every other progress message."""
    import logging

    logger = logging.getLogger("gratnet.prepare")  # gratnet.cli prefixes "gratnet COMMAND: "

    def report(message: str) -> None:
        logger.info(message)

    return report
