"""Typed dataclass configs and their command-line flags.

Every config is a dataclass whose fields carry ``metadata={"help": ...}`` (units in the text) and,
optionally, ``"flag"`` (the public flag name, default ``--field-name``) and ``"choices"``.
``add_arguments`` turns a config class into argparse flags, ``from_arguments`` builds the resolved
config back, and ``save_config`` writes it as JSON beside an output.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import typing
from pathlib import Path
from typing import Any, Literal, TypeVar, get_args, get_origin

from gratnet.atomic import write_text_atomic

ConfigT = TypeVar("ConfigT")


def config_field(default: Any, help: str, *, flag: str | None = None, **metadata: Any) -> Any:  # noqa: A002
    """A dataclass field with its help text (state units) and an optional public flag name."""
    metadata = {"help": help, **({"flag": flag} if flag else {}), **metadata}
    return dataclasses.field(default=default, metadata=metadata)


def _flag_of(field: dataclasses.Field, prefix: str) -> str:
    return field.metadata.get("flag") or "--" + prefix + field.name.replace("_", "-")


def add_arguments(parser: argparse.ArgumentParser, config_class: type, prefix: str = "") -> None:
    """Add one flag per field of ``config_class`` (a dataclass) to ``parser``."""
    hints = typing.get_type_hints(config_class)
    group = parser.add_argument_group(config_class.__name__, (config_class.__doc__ or "").strip().splitlines()[0])
    for field in dataclasses.fields(config_class):
        if not field.init or field.metadata.get("cli") is False:
            continue
        kind = hints[field.name]
        flag = _flag_of(field, prefix)
        default = field.default if field.default is not dataclasses.MISSING else None
        help_text = field.metadata.get("help", "")
        destination = prefix.replace("-", "_") + field.name
        if kind is bool:
            group.add_argument(
                flag, dest=destination, action=argparse.BooleanOptionalAction, default=default,
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
        group.add_argument(
            flag, dest=destination, type=kind, choices=choices, default=default,
            help=f"{help_text} (default: {default})",
        )


def from_arguments(config_class: type[ConfigT], arguments: argparse.Namespace, prefix: str = "") -> ConfigT:
    """Build a ``config_class`` instance from parsed arguments (fields left out keep their defaults)."""
    values = {}
    for field in dataclasses.fields(config_class):  # type: ignore[arg-type]
        destination = prefix.replace("-", "_") + field.name
        if hasattr(arguments, destination):
            values[field.name] = getattr(arguments, destination)
    return config_class(**values)


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


def save_config(output: str | os.PathLike[str], **configs: Any) -> Path:
    """Save the resolved configs (and the GratNet version) as JSON beside ``output``."""
    from gratnet import __version__

    document = {"gratnet_version": __version__, "output": os.fspath(output)}
    document.update({name: config_to_dict(config) for name, config in configs.items()})
    path = config_path_for(output)
    write_text_atomic(path, json.dumps(document, indent=2, sort_keys=False) + "\n")
    return path
