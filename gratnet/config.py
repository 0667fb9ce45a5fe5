"""Typed dataclass configs and their command-line flags.

Every config is a dataclass whose fields carry ``metadata={"help": ...}`` (units in the text) and,
optionally, ``"flag"`` (the public flag name, default ``--field-name``), ``"aliases"`` (more names for the same
flag) and ``"choices"``.
``add_arguments`` turns a config class into argparse flags, ``from_arguments`` builds the resolved
config back, and ``save_config`` writes it as JSON beside an output (``config_text`` gives the JSON for
writers that put an output and its config down together with :func:`gratnet.atomic.atomic_paths`).

Every number given on the command line must fit a float32 shader or an int32 (``parse_float`` /
``parse_int``): NaN, ±inf, magnitudes above 3.4e38 and non-zero magnitudes below 1.2e-38 (they flush to
zero on a GPU) are refused with one line before any work.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import os
import typing
from pathlib import Path
from typing import Any, Literal, TypeVar, get_args, get_origin

from gratnet.atomic import write_text_atomic

ConfigT = TypeVar("ConfigT")

#: Largest finite float32 and smallest positive normal float32.
FLOAT32_MAX = 3.4028234663852886e38
FLOAT32_TINY = 1.1754943508222875e-38
INT32_MAX = 2**31 - 1
#: The --quiet flag's one meaning in every subcommand.
QUIET_HELP = "no progress bars or progress messages on stderr (warnings and errors are still shown)"


def float32_problem(value: float) -> str | None:
    """Why a float32 shader cannot hold ``value`` (NaN, ±inf, too large, too small), or None."""
    if math.isnan(value):
        return "not a number"
    if math.isinf(value):
        return "infinite"
    if abs(value) > FLOAT32_MAX:
        return "beyond float32 range (±3.4e38)"
    if 0.0 < abs(value) < FLOAT32_TINY:
        return "too small for float32 (below 1.2e-38 it flushes to 0)"
    return None


def parse_float(text: str) -> float:
    """An argparse ``type``: a real number that float32 holds (one-line error otherwise)."""
    try:
        value = float(str(text).strip())
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    problem = float32_problem(value)
    if problem is not None:
        raise argparse.ArgumentTypeError(f"{text!r} is {problem}")
    return value + 0.0  # -0 → 0


def parse_int(text: str) -> int:
    """An argparse ``type``: an integer within ±(2³¹ − 1) (one-line error otherwise)."""
    try:
        value = int(str(text).strip())
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected an integer, got {text!r}") from None
    if abs(value) > INT32_MAX:
        raise argparse.ArgumentTypeError(f"{text!r} is beyond the integer range ±2147483647")
    return value


def parse_numbers(text: str, count: int | tuple[int, ...], flag: str, form: str) -> list[float]:
    """Comma-separated numbers that float32 holds (``count`` of them), or a one-line GratNetError naming
    ``flag`` and the expected ``form`` (e.g. "θ,φ in degrees such as 45,90")."""
    from gratnet.errors import GratNetError

    counts = (count,) if isinstance(count, int) else count
    parts = [part.strip() for part in str(text).split(",")]
    try:
        values = [float(part) + 0.0 for part in parts]  # + 0.0: -0 → 0
    except ValueError:
        values = []
    if len(values) not in counts:
        raise GratNetError(f"{flag} expects {form}, got {text!r}")
    for part, value in zip(parts, values, strict=True):
        problem = float32_problem(value)
        if problem is not None:
            raise GratNetError(f"{flag} expects {form}; {part!r} is {problem}")
    return values


def add_quiet_flag(parser: argparse.ArgumentParser) -> None:
    """``--quiet``, with the same meaning in every subcommand (the CLI silences the progress logger)."""
    parser.add_argument("--quiet", action="store_true", help=QUIET_HELP)


def config_field(default: Any, help: str, *, flag: str | None = None, **metadata: Any) -> Any:  # noqa: A002
    """A dataclass field with its help text (state units) and an optional public flag name."""
    metadata = {"help": help, **({"flag": flag} if flag else {}), **metadata}
    return dataclasses.field(default=default, metadata=metadata)


def _flag_of(field: dataclasses.Field, prefix: str) -> str:
    return field.metadata.get("flag") or "--" + prefix + field.name.replace("_", "-")


def add_arguments(parser: argparse.ArgumentParser, config_class: type, prefix: str = "") -> dict[str, argparse.Action]:
    """Add one flag per field of ``config_class`` (a dataclass) to ``parser``; returns the added actions by
    destination (for a command that words one flag's help its own way)."""
    hints = typing.get_type_hints(config_class)
    # The group's title is the class docstring's first line (users read --help: no class names there).
    title = (config_class.__doc__ or config_class.__name__).strip().splitlines()[0].replace("``", "").rstrip(".")
    group = parser.add_argument_group(title[:1].lower() + title[1:])
    actions: dict[str, argparse.Action] = {}
    for field in dataclasses.fields(config_class):
        if not field.init or field.metadata.get("cli") is False:
            continue
        kind = hints[field.name]
        flag = _flag_of(field, prefix)
        default = field.default if field.default is not dataclasses.MISSING else None
        help_text = field.metadata.get("help", "")
        destination = prefix.replace("-", "_") + field.name
        flags = (flag, *field.metadata.get("aliases", ()))
        if kind is bool:
            actions[destination] = group.add_argument(
                *flags, dest=destination, action=argparse.BooleanOptionalAction, default=default,
                help=f"{help_text} (default: {default})",
            )
            continue
        choices = field.metadata.get("choices")
        if get_origin(kind) is Literal:
            choices = list(get_args(kind))
            kind = type(choices[0])
        elif get_origin(kind) in (typing.Union, getattr(__import__("types"), "UnionType", None)):
            non_none = [arg for arg in get_args(kind) if arg is not type(None)]
            kind = non_none[0]
        parse = {float: parse_float, int: parse_int}.get(kind, kind)
        actions[destination] = group.add_argument(
            *flags, dest=destination, type=parse, choices=choices, default=default,
            help=f"{help_text} (default: {default})",
        )
    return actions


def from_arguments(config_class: type[ConfigT], arguments: argparse.Namespace, prefix: str = "") -> ConfigT:
    """Build a ``config_class`` instance from parsed arguments (fields left out keep their defaults)."""
    values = {}
    for field in dataclasses.fields(config_class):  # type: ignore[arg-type]
        destination = prefix.replace("-", "_") + field.name
        if hasattr(arguments, destination):
            values[field.name] = getattr(arguments, destination)
    return config_class(**values)


def changed_flags(config: Any, prefix: str = "") -> list[str]:
    """The command-line flags that rebuild ``config`` from its class's defaults: one ``--flag value`` (or
    ``--flag`` / ``--no-flag`` for booleans) per CLI field whose value differs from its default, in field order."""
    words: list[str] = []
    for field in dataclasses.fields(config):
        if not field.init or field.metadata.get("cli") is False or field.default is dataclasses.MISSING:
            continue
        value = getattr(config, field.name)
        if value == field.default:
            continue
        flag = _flag_of(field, prefix)
        if isinstance(value, bool):
            words.append(flag if value else "--no-" + flag[2:])
        else:
            words += [flag, str(value)]
    return words


def config_to_dict(config: Any) -> dict[str, Any]:
    """A JSON-ready dict of a (possibly nested) dataclass config."""
    def convert(value: Any) -> Any:
        if dataclasses.is_dataclass(value) and not isinstance(value, type):
            return {field.name: convert(getattr(value, field.name)) for field in dataclasses.fields(value)}
        if isinstance(value, (list, tuple)):
            return [convert(item) for item in value]
        if isinstance(value, os.PathLike):
            return os.fspath(value)
        if hasattr(value, "item") and callable(value.item):  # numpy scalars
            return value.item()
        return value

    return convert(config)


def config_path_for(output: str | os.PathLike[str]) -> Path:
    """Where the resolved config of ``output`` is saved: ``NAME.config.json`` beside it."""
    output = Path(output)
    return output.with_name(output.stem + ".config.json")


def config_text(output: str | os.PathLike[str], **configs: Any) -> str:
    """The JSON document of the resolved configs (and the GratNet version) of ``output``."""
    from gratnet import __version__

    document = {"gratnet_version": __version__, "output": os.fspath(output)}
    document.update({name: config_to_dict(config) for name, config in configs.items()})
    return json.dumps(document, indent=2, sort_keys=False) + "\n"


def save_config(output: str | os.PathLike[str], **configs: Any) -> Path:
    """Save the resolved configs (and the GratNet version) as JSON beside ``output``."""
    path = config_path_for(output)
    write_text_atomic(path, config_text(output, **configs))
    return path
