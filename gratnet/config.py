"""Typed dataclass configs and their command-line flags.

Every config is a dataclass whose fields carry ``metadata={"help": ...}`` (units in the text) and,
optionally, ``"flag"`` (the public flag name, default ``--field-name``), ``"aliases"`` (more names for the same
flag) and ``"choices"``.
``add_arguments`` turns a config class into argparse flags, ``from_arguments`` builds the resolved
config back, and ``save_config`` writes it as JSON beside an output (``config_text`` gives the JSON for
writers that put an output and its config down together with :func:`gratnet.atomic.atomic_paths`).

A field made by :func:`nested_field` holds a config of its own (``TrainConfig.grid``, a ``GridConfig``), saved as
a dict under the field's name; outside Python its fields keep flat names, the nested field's prefix before
theirs: ``--grid-levels`` on the command line, ``grid_levels`` as a sweep file's key (:func:`flat_fields`). A
class with such a field takes :func:`flat_keywords`, so that ``TrainConfig(grid_levels=2)`` and a config saved
with flat keys, before the nesting, still build it (:func:`nested_dict`, :func:`saved_config_dict`).

Every number given on the command line must fit a float32 shader or an int32 (``parse_float`` /
``parse_int``): NaN, ±inf, magnitudes above 3.4e38 and non-zero magnitudes below 1.2e-38 (they flush to
zero on a GPU) are refused with one line before any work.
"""

from __future__ import annotations

import argparse
import dataclasses
import functools
import json
import math
import os
import typing
from collections.abc import Mapping
from pathlib import Path
from typing import Any, ClassVar, Literal, NamedTuple, Protocol, TypeVar, get_args, get_origin

from gratnet.atomic import write_text_atomic


class _Dataclass(Protocol):
    """A dataclass (the config classes): what ``dataclasses.fields`` takes."""

    __dataclass_fields__: ClassVar[dict[str, dataclasses.Field[Any]]]


ConfigT = TypeVar("ConfigT", bound=_Dataclass)

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


def nested_field(config_class: type, prefix: str) -> Any:
    """A dataclass field holding a ``config_class`` (a frozen dataclass, its defaults by default) whose fields are
    named ``prefix`` + ``_`` + their name outside it: flags ``--PREFIX-NAME``, keywords and sweep keys
    ``PREFIX_NAME``. Saved configs (:func:`config_to_dict`) hold it as a dict under the field's own name."""
    return dataclasses.field(default_factory=config_class, metadata={"nested": prefix, "config": config_class})


def _nested(field: dataclasses.Field) -> tuple[str, type] | None:
    """(prefix, config class) of a :func:`nested_field`, else None."""
    return (field.metadata["nested"], field.metadata["config"]) if "nested" in field.metadata else None


class FlatField(NamedTuple):
    """A leaf field of a config reached by its flat name: the field names from the config down to it, the field
    and its type."""

    path: tuple[str, ...]
    field: dataclasses.Field
    kind: Any


@functools.cache
def flat_fields(config_class: type) -> dict[str, FlatField]:
    """Every init field of ``config_class`` by its flat name, a :func:`nested_field`'s fields in its place under
    theirs (``grid_levels`` → ``("grid", "levels")``): the names of the flags' destinations and of the keywords
    and sweep keys."""
    hints = typing.get_type_hints(config_class)
    found: dict[str, FlatField] = {}
    for field in dataclasses.fields(config_class):
        if not field.init:
            continue
        nested = _nested(field)
        if nested is None:
            found[field.name] = FlatField((field.name,), field, hints[field.name])
            continue
        for name, inner in flat_fields(nested[1]).items():
            found[f"{nested[0]}_{name}"] = FlatField((field.name, *inner.path), inner.field, inner.kind)
    return found


def nested_dict(config_class: type, values: Mapping[str, Any]) -> dict[str, Any]:
    """``values`` (keyed by field names or flat names) laid out as :func:`config_to_dict` lays out a
    ``config_class``: each nested field's flat keys (``grid_levels``) moved into its dict, over the config or dict
    given for it; everything else as it is. A config saved before a nesting (flat keys) reads as one saved after."""
    result = dict(values)
    for field in dataclasses.fields(config_class):
        nested = _nested(field)
        if nested is None:
            continue
        prefix, inner_class = nested[0] + "_", nested[1]
        inner_names = flat_fields(inner_class)
        flat = {key[len(prefix):]: result.pop(key) for key in list(result)
                if key.startswith(prefix) and key[len(prefix):] in inner_names}
        given = result.get(field.name)
        if flat and dataclasses.is_dataclass(given) and not isinstance(given, type):
            given = {inner.name: getattr(given, inner.name) for inner in dataclasses.fields(given) if inner.init}
        if flat or isinstance(given, Mapping):
            result[field.name] = nested_dict(inner_class, {**(given or {}), **flat})
    return result


def nested_values(config_class: type, values: Mapping[str, Any]) -> dict[str, Any]:
    """Keywords of ``config_class`` from ``values`` keyed by field names or flat names (:func:`nested_dict`), each
    nested field's dict made its config."""
    result = nested_dict(config_class, values)
    for field in dataclasses.fields(config_class):
        nested = _nested(field)
        if nested is not None and isinstance(result.get(field.name), Mapping):
            result[field.name] = nested[1](**nested_values(nested[1], result[field.name]))
    return result


def saved_config_dict(config_class: type, saved: Mapping[str, Any]) -> dict[str, Any]:
    """A config's dict as it was saved (by :func:`config_to_dict`, also before a nesting: flat keys) laid out as
    ``config_to_dict(config_class())`` is, the fields added since at their defaults (how it was made)."""
    def over(defaults: dict[str, Any], values: Mapping[str, Any]) -> dict[str, Any]:
        return {**defaults, **{key: over(defaults[key], value) if isinstance(value, Mapping)
                               and isinstance(defaults.get(key), dict) else value for key, value in values.items()}}

    return over(config_to_dict(config_class()), nested_dict(config_class, saved))


def flat_keywords(config_class: type[ConfigT]) -> type[ConfigT]:
    """Class decorator, above ``@dataclasses.dataclass``, for a config with :func:`nested_field` fields: its
    constructor (and so ``dataclasses.replace``) also takes their fields by flat name (``grid_levels=2``) and a
    saved dict for the nested field itself, and reads them back by flat name (``config.grid_levels``), as callers
    and saved configs from before the nesting name them."""
    init = config_class.__init__

    @functools.wraps(init)
    def __init__(self: Any, *args: Any, **values: Any) -> None:
        init(self, *args, **nested_values(config_class, values))

    config_class.__init__ = __init__  # type: ignore[method-assign]  # replaces the dataclass's generated constructor
    for name, flat in flat_fields(config_class).items():
        if len(flat.path) > 1:
            setattr(config_class, name, property(functools.partial(_read_path, path=flat.path),
                                                 doc=f"``{'.'.join(flat.path)}`` by its flat name"))
    return config_class


def _read_path(config: Any, path: tuple[str, ...]) -> Any:
    for name in path:
        config = getattr(config, name)
    return config


def _flag_of(field: dataclasses.Field, prefix: str) -> str:
    return field.metadata.get("flag") or "--" + prefix + field.name.replace("_", "-")


def add_arguments(parser: argparse.ArgumentParser, config_class: type, prefix: str = "") -> dict[str, argparse.Action]:
    """Add one flag per field of ``config_class`` (a dataclass) to ``parser``, a nested field's fields in its place
    (``--grid-levels``); returns the added actions by destination (for a command that words one flag's help its
    own way)."""
    # The group's title is the class docstring's first line (users read --help: no class names there).
    title = (config_class.__doc__ or config_class.__name__).strip().splitlines()[0].replace("``", "").rstrip(".")
    group = parser.add_argument_group(title[:1].lower() + title[1:])
    actions: dict[str, argparse.Action] = {}
    _add_fields(group, config_class, prefix, actions)
    return actions


def _add_fields(group: Any, config_class: type, prefix: str,
                actions: dict[str, argparse.Action]) -> None:
    hints = typing.get_type_hints(config_class)
    for field in dataclasses.fields(config_class):
        if not field.init or field.metadata.get("cli") is False:
            continue
        nested = _nested(field)
        if nested is not None:
            _add_fields(group, nested[1], f"{prefix}{nested[0]}-", actions)
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
        if get_origin(kind) is tuple:  # a repeatable flag: each use adds one value (None when never given)
            actions[destination] = group.add_argument(
                *flags, dest=destination, action="append", type=str, default=None,
                help=f"{help_text} (default: none)",
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


def from_arguments(config_class: type[ConfigT], arguments: argparse.Namespace, prefix: str = "") -> ConfigT:
    """Build a ``config_class`` instance from parsed arguments (fields left out keep their defaults)."""
    values: dict[str, Any] = {}
    for field in dataclasses.fields(config_class):
        nested = _nested(field)
        if nested is not None:
            values[field.name] = from_arguments(nested[1], arguments, f"{prefix}{nested[0]}-")
            continue
        destination = prefix.replace("-", "_") + field.name
        if hasattr(arguments, destination):
            values[field.name] = getattr(arguments, destination)
    return config_class(**values)


def changed_flags(config: Any, prefix: str = "") -> list[str]:
    """The command-line flags that rebuild ``config`` from its class's defaults: one ``--flag value`` (or
    ``--flag`` / ``--no-flag`` for booleans) per CLI field whose value differs from its default, in field order
    (a nested field's in its place)."""
    words: list[str] = []
    for field in dataclasses.fields(config):
        nested = _nested(field)
        if nested is not None and field.init and field.metadata.get("cli") is not False:
            words += changed_flags(getattr(config, field.name), f"{prefix}{nested[0]}-")
            continue
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

    document: dict[str, Any] = {"gratnet_version": __version__, "output": os.fspath(output)}
    document.update({name: config_to_dict(config) for name, config in configs.items()})
    return json.dumps(document, indent=2, sort_keys=False) + "\n"


def save_config(output: str | os.PathLike[str], **configs: Any) -> Path:
    """Save the resolved configs (and the GratNet version) as JSON beside ``output``."""
    path = config_path_for(output)
    write_text_atomic(path, config_text(output, **configs))
    return path
