"""The ``gratnet`` command: one entry point, one subcommand per module.

Each subcommand module exposes ``register(subparsers)``, which adds its parser and sets
``handler=function(arguments) -> int``. Modules are imported lazily so that ``gratnet --help`` and
the runtime subcommands never import torch.
"""

from __future__ import annotations

import argparse
import importlib
import logging
import sys
from collections.abc import Sequence

from gratnet import __version__
from gratnet.errors import GratNetError

# Subcommand name -> module that registers it (imported only when needed).
SUBCOMMAND_MODULES: dict[str, str] = {
    "heightfield": "trainer.heightfield_cli",
    "groundtruth": "trainer.groundtruth_cli",
    "brdfslice": "trainer.brdfslice_cli",
    "train": "trainer.train_cli",
    "evaluate": "trainer.train_cli",
    "render": "viewer.render_cli",
    "view": "viewer.view_cli",
    "bench": "trainer.bench_cli",
    "mitsuba-render": "mitsuba_plugin.render_cli",
    "sweep": "sweep.cli",
}


def build_parser(only: str | None = None) -> argparse.ArgumentParser:
    """The full parser; with ``only``, import and register just that subcommand."""
    parser = argparse.ArgumentParser(
        prog="gratnet", description="GratNet: neural rendering of diffractive surfaces."
    )
    parser.add_argument("--version", action="version", version=f"gratnet {__version__}")
    subparsers = parser.add_subparsers(dest="command", metavar="SUBCOMMAND")
    wanted = [SUBCOMMAND_MODULES[only]] if only is not None else list(SUBCOMMAND_MODULES.values())
    for module_name in dict.fromkeys(wanted):  # a module may register several subcommands
        importlib.import_module(module_name).register(subparsers)
    for name in SUBCOMMAND_MODULES:
        if name not in subparsers.choices:
            subparsers.add_parser(name, help=f"(see gratnet {name} --help)")
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run the ``gratnet`` command; bad input exits with one clear line and a non-zero status."""
    argv = list(sys.argv[1:] if argv is None else argv)
    command = next((word for word in argv if not word.startswith("-")), None)
    parser = build_parser(only=command if command in SUBCOMMAND_MODULES else None)
    arguments = parser.parse_args(argv)
    if not getattr(arguments, "handler", None):
        parser.print_help()
        return 0 if not argv else 2
    # Library modules report slow one-off steps (e.g. a baked shader's first compile) on the "gratnet"
    # logger; the command shows them on stderr, one line each.
    logger = logging.getLogger("gratnet")
    if not logger.handlers:
        handler = logging.StreamHandler(sys.stderr)
        handler.setFormatter(logging.Formatter(f"gratnet {arguments.command}: %(message)s"))
        logger.addHandler(handler)
        logger.setLevel(logging.INFO)
    try:
        return int(arguments.handler(arguments) or 0)
    except GratNetError as error:
        print(f"gratnet {arguments.command}: error: {error}", file=sys.stderr)
        return error.exit_code
    except KeyboardInterrupt:
        print(f"gratnet {arguments.command}: interrupted; no output was written", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
