"""The ``gratnet`` command: one entry point, one subcommand per registered module.

The packages above gratnet/ (trainer/, viewer/, bench/, sweep/, mitsuba_plugin/) register their subcommands
as entry points of the group ``gratnet.commands`` in pyproject.toml (``render = "viewer.render_cli:register"``),
so that this module names none of them. Each ``register(subparsers)`` adds its parser and sets
``handler=function(arguments) -> int``. Only the entry point a command needs is loaded (all of them for
``gratnet --help``), so that ``gratnet --help`` and the runtime subcommands never import torch.
"""

from __future__ import annotations

import argparse
import atexit
import gc
import importlib.metadata
import logging
import re
import sys
import typing
from collections.abc import Sequence
from typing import Any

from gratnet import __version__, interrupts
from gratnet.errors import GratNetError

#: The entry-point group in which packages register subcommands: name = "module:register".
COMMAND_GROUP = "gratnet.commands"

#: The order of ``gratnet --help``'s list, the order of the work (height field → ground truth → training →
#: rendering → tools); the metadata lists entry points alphabetically. A subcommand not named here follows.
HELP_ORDER = ("heightfield", "groundtruth", "brdfslice", "train", "evaluate", "render", "view", "bench",
              "compare", "mitsuba-render", "sweep", "export")

#: Why no subcommand is found, and the fix: the entry points live in the installed package's metadata.
NOT_INSTALLED = (f"no gratnet subcommands are registered (entry points {COMMAND_GROUP!r}): the gratnet package "
                 f"is not installed; run `pip install -e .` in the repository (or see scripts/gpu_bench.sh for "
                 f"a PYTHONPATH-only machine)")


def subcommands() -> dict[str, importlib.metadata.EntryPoint]:
    """Subcommand name → its registered entry point (none loaded), in :data:`HELP_ORDER`.

    Raises:
        GratNetError: none is registered (the package's metadata is not installed).
    """
    found: dict[str, importlib.metadata.EntryPoint] = {}
    for entry_point in importlib.metadata.entry_points(group=COMMAND_GROUP):
        found.setdefault(entry_point.name, entry_point)  # the first on sys.path wins, as for imports
    if not found:
        raise GratNetError(NOT_INSTALLED)
    rank = {name: number for number, name in enumerate(HELP_ORDER)}
    return {name: found[name] for name in sorted(found, key=lambda name: (rank.get(name, len(rank)), name))}


class _HelpFormatter(argparse.HelpFormatter):
    """argparse's formatter, except that an epilog starting "typical use:" keeps its lines (commands)."""

    def _fill_text(self, text: str, width: int, indent: str) -> str:
        if text.startswith("typical use:"):
            return "\n".join(indent + line for line in text.splitlines())
        return super()._fill_text(text, width, indent)


class GratNetParser(argparse.ArgumentParser):
    """argparse with GratNet's rules for bad input: one line on stderr, exit status 2; and values that
    start with a minus sign (``--light -30,0``, ``--exposure -inf``) are values, not unknown options."""

    # argparse takes only '-5' and '-.5' for negative numbers; comma lists, exponents, inf and nan too.
    _NEGATIVE_VALUE = re.compile(r"^-(?:\d|\.\d|inf|nan)[\w.,+-]*$", re.IGNORECASE)

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        kwargs.setdefault("formatter_class", _HelpFormatter)
        super().__init__(*args, **kwargs)
        self._negative_number_matcher = self._NEGATIVE_VALUE

    def error(self, message: str) -> typing.NoReturn:
        """One line, ``gratnet SUBCOMMAND: error: …``, then exit status 2 (no usage dump)."""
        words = self.prog.split()
        command = " ".join(words[:2])
        hint = f" (see {self.prog} --help)"
        print(f"{command}: error: {' '.join(message.split())}{hint}", file=sys.stderr)
        self.exit(2)


class _StderrHandler(logging.Handler):
    """One line per record on the *current* ``sys.stderr`` (tests capture it anew for each command)."""

    def emit(self, record: logging.LogRecord) -> None:
        try:
            print(self.format(record), file=sys.stderr)
        except Exception:  # logging's rule: a failing handler must not raise
            self.handleError(record)


def build_parser(only: str | None = None,
                 commands: dict[str, importlib.metadata.EntryPoint] | None = None) -> argparse.ArgumentParser:
    """The full parser; with ``only``, load and register just that subcommand's entry point. ``commands``:
    :func:`subcommands` when the caller has it already (default: read from the metadata)."""
    commands = subcommands() if commands is None else commands
    parser = GratNetParser(
        prog="gratnet", description="GratNet: neural rendering of diffractive surfaces."
    )
    parser.add_argument("--version", action="version", version=f"gratnet {__version__}")
    subparsers = parser.add_subparsers(dest="command", metavar="SUBCOMMAND")
    wanted = [commands[only]] if only is not None else list(commands.values())
    registered = set()
    for entry_point in wanted:
        if entry_point.value not in registered:  # one register() may add several subcommands (train, evaluate)
            registered.add(entry_point.value)
            entry_point.load()(subparsers)
    for name in commands:
        if name not in subparsers.choices:
            subparsers.add_parser(name, help=f"(see gratnet {name} --help)")
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run the ``gratnet`` command; bad input exits with one clear line and a non-zero status. As the process's
    own command (``argv`` None), it runs under gratnet.interrupts' supervisor: Ctrl-C is answered within a
    second even inside a long C call that holds the GIL (a shader's first compile)."""
    supervised = argv is None
    argv = list(sys.argv[1:] if argv is None else argv)
    command = next((word for word in argv if not word.startswith("-")), None)
    if supervised:
        status = interrupts.supervise("gratnet" + (f" {command}" if command else ""))
        if status is not None:  # the supervisor: the command ran in its child
            return status
        status = _command(argv, command)
        interrupts.done(status)  # a Ctrl-C from here on (the interpreter's teardown) changes nothing
        return status
    return _command(argv, command)


def _command(argv: list[str], command: str | None) -> int:
    """:func:`main`'s work: parse ``argv`` and run the subcommand (``command``, the first word that is no flag)."""
    try:
        commands = subcommands()
    except GratNetError as error:
        print(f"gratnet: error: {error}", file=sys.stderr)
        return error.exit_code
    try:
        parser = build_parser(only=command if command in commands else None, commands=commands)
    except (KeyboardInterrupt, ImportError) as error:  # Ctrl-C while the subcommand's modules load
        if not is_interrupt(error):
            raise
        return _interrupted("gratnet" + (f" {command}" if command in commands else ""))
    try:
        arguments = parser.parse_args(argv)
    except SystemExit as exit_:  # --help, --version, or a one-line argparse error (GratNetParser.error)
        return exit_.code if isinstance(exit_.code, int) else 2
    if not getattr(arguments, "handler", None):
        parser.print_help()
        return 0 if not argv else 2
    # Library modules report slow one-off steps (e.g. a baked shader's first compile) on the "gratnet"
    # logger; the command shows them on stderr, one line each. --quiet keeps warnings and errors only.
    logger = logging.getLogger("gratnet")
    handler = next((h for h in logger.handlers if isinstance(h, _StderrHandler)), None)
    if handler is None:
        handler = _StderrHandler()
        logger.addHandler(handler)
    handler.setFormatter(logging.Formatter(f"gratnet {arguments.command}: %(message)s"))
    logger.setLevel(logging.WARNING if getattr(arguments, "quiet", False) else logging.INFO)
    from gratnet.atomic import WRITTEN

    written_before = len(WRITTEN)
    try:
        return int(arguments.handler(arguments) or 0)
    except GratNetError as error:
        # One line even when a library's message (OpenEXR, Pillow) spans several.
        print(f"gratnet {arguments.command}: error: {' '.join(str(error).split())}", file=sys.stderr)
        return error.exit_code
    except MemoryError:  # a limit we did not foresee: still one line, and the writers left nothing behind
        print(f"gratnet {arguments.command}: error: not enough memory for these settings; use smaller sizes "
              f"or resolutions (see gratnet {arguments.command} --help)", file=sys.stderr)
        return 2
    except (KeyboardInterrupt, ImportError) as error:
        if not is_interrupt(error):
            raise
        return _interrupted(f"gratnet {arguments.command}", WRITTEN[written_before:])


def is_interrupt(error: BaseException) -> bool:
    """Whether ``error`` is Ctrl-C: a KeyboardInterrupt, or the ImportError ("initialization failed") that a C
    extension (OpenEXR) raises when the KeyboardInterrupt comes while it initializes."""
    return isinstance(error, KeyboardInterrupt) or (
        isinstance(error, ImportError) and isinstance(error.__cause__ or error.__context__, KeyboardInterrupt))


def _interrupted(prefix: str, written: Sequence[object] = ()) -> int:
    """Ctrl-C's answer (a subcommand with outputs of its own to report, such as train or render, answers itself):
    one line, exit status 130. The writers are atomic, so nothing half-written is left; ``written``: the outputs
    the command completed before (gratnet.atomic.WRITTEN), which are kept."""
    if written:
        count = len(set(map(str, written)))  # a checkpoint is written once per epoch: one file
        others = f" and {count - 1} other file{'s' if count > 2 else ''}" if count > 1 else ""
        outcome = f"{written[-1]}{others} written before it {'are' if count > 1 else 'is'} kept, nothing is " \
                  f"half-written"
    else:
        outcome = "no output was written"
    print(f"{prefix}: interrupted; {outcome}", file=sys.stderr)
    # The interpreter's teardown would then spend ~0.4 s collecting the objects of big libraries
    # (colour-science; measured on llvmpipe's 2-core machine); frozen at exit, nothing is collected.
    atexit.register(gc.freeze)
    return 130


if __name__ == "__main__":
    sys.exit(main())
