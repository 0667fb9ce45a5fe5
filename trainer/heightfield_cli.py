"""``gratnet heightfield``: generate, convert, preview and list height fields.

    gratnet heightfield list
    gratnet heightfield generate NAME [--PARAM VALUE ...] --out F.npz|F.gsf [--preview P.png]
    gratnet heightfield convert IN --out OUT.npz|OUT.gsf [--dx-um ...] [--height-scale-um ...] [--channel ...]
    gratnet heightfield preview IN --out P.png [--dx-um ...] [--height-scale-um ...] [--channel ...]

Each generator is its own sub-command with one flag per parameter (``gratnet heightfield generate
blazed --help`` lists them with units and defaults). The resolved configuration is saved as
``NAME.config.json`` beside every output.
"""

from __future__ import annotations

import argparse
import dataclasses
from pathlib import Path
from typing import Any

from gratnet.atomic import atomic_paths, check_output_file
from gratnet.config import add_arguments, config_path_for, config_text, from_arguments
from gratnet.errors import GratNetError
from trainer import generators
from trainer.heightfield import HeightField
from trainer.heightfile import LoadOptions, preview_png, save_heightfield
from trainer.loaders import load_heightfield

FIELD_SUFFIXES = (".npz", ".gsf")


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``heightfield`` subcommand and its actions to the ``gratnet`` parser."""
    parser = subparsers.add_parser(
        "heightfield", help="generate, convert and preview height fields",
        description="Height fields: heights in µm on a square grid of spacing dx (µm).",
        epilog="typical use:\n"
        "  gratnet heightfield list\n"
        "  gratnet heightfield generate blazed --out blazed.npz --preview blazed.png\n"
        "  gratnet heightfield convert scan.png --dx-um 0.1 --height-scale-um 0.5 --out scan.npz",
    )
    actions = parser.add_subparsers(dest="action", metavar="ACTION", required=True)

    listing = actions.add_parser("list", help="list the built-in generators with their parameters, and the paper's "
                                 "datasets (presets)")
    listing.set_defaults(handler=_list)

    generate = actions.add_parser(
        "generate", help="generate a built-in height field",
        description="Generate a built-in height field; 'gratnet heightfield generate NAME --help' lists "
                    "NAME's parameters.",
    )
    names = generate.add_subparsers(dest="generator", metavar="NAME", required=True)
    for name, (params_class, function) in generators.GENERATORS.items():
        summary = (function.__doc__ or "").strip().splitlines()[0]
        generator = names.add_parser(name, help=summary, description=summary)
        add_arguments(generator, params_class)
        _add_outputs(generator, FIELD_SUFFIXES)
        generator.set_defaults(handler=_generate, params_class=params_class)

    convert = actions.add_parser("convert", help="convert a height-field file (or generator) to .npz or .gsf")
    convert.add_argument("input", metavar="IN", help="file (.npy .npz .gsf .png .exr) or generator name")
    add_arguments(convert, LoadOptions)
    _add_outputs(convert, FIELD_SUFFIXES)
    convert.set_defaults(handler=_convert)

    preview = actions.add_parser("preview", help="write a colour-mapped PNG of a height field (axes in µm)")
    preview.add_argument("input", metavar="IN", help="file (.npy .npz .gsf .png .exr) or generator name")
    add_arguments(preview, LoadOptions)
    preview.add_argument("--out", required=True, type=Path, metavar="PREVIEW.png",
                         help="output preview image (.png); its settings go to PREVIEW.config.json")
    preview.set_defaults(handler=_preview)


def _add_outputs(parser: argparse.ArgumentParser, suffixes: tuple[str, ...]) -> None:
    parser.add_argument("--out", required=True, type=Path, metavar="FIELD" + "|FIELD".join(suffixes),
                        help=f"output height field ({' or '.join(suffixes)}); its settings go to FIELD.config.json")
    parser.add_argument("--preview", type=Path, default=None, metavar="PREVIEW.png",
                        help="also write a preview image (.png)")


def _check_suffix(path: Path, suffixes: tuple[str, ...], what: str) -> None:
    # Checked before any work so that a typo costs nothing.
    if path.suffix.lower() not in suffixes:
        raise GratNetError(f"{path}: {what} must end in {' or '.join(suffixes)}")


def _summary(field: HeightField) -> dict[str, Any]:
    rows, columns = field.shape
    return {"rows": rows, "columns": columns, "dx_um": field.dx_um, "span_um": field.span_um, "source": field.source}


def _describe(field: HeightField) -> str:
    rows, columns = field.shape
    return f"{columns} × {rows} samples, dx = {field.dx_um:.4g} µm, height span {field.span_um:.4g} µm"


def _outputs(arguments: argparse.Namespace, suffixes: tuple[str, ...]) -> list[Path]:
    """--out, its config and the optional --preview, checked before any work (suffixes, writable)."""
    _check_suffix(arguments.out, suffixes, "--out")
    outputs = [arguments.out, config_path_for(arguments.out)]
    if getattr(arguments, "preview", None) is not None:
        _check_suffix(arguments.preview, (".png",), "--preview")
        outputs.append(arguments.preview)
    for output in outputs:
        check_output_file(output, "--preview" if output is getattr(arguments, "preview", None) else "--out")
    return outputs


def _write(field: HeightField, arguments: argparse.Namespace, outputs: list[Path], **configs: Any) -> None:
    """Save the field, the resolved config beside it and the optional preview: all of them or none."""
    # One config, beside the field; it names the preview (which may share the field's stem).
    preview = None if arguments.preview is None else str(arguments.preview)
    with atomic_paths(*outputs) as temporaries:
        save_heightfield(temporaries[0], field)
        temporaries[1].write_text(config_text(arguments.out, **configs, field=_summary(field), preview=preview),
                                  encoding="utf-8")
        if arguments.preview is not None:
            preview_png(field, temporaries[2])
    print(f"wrote {arguments.out}: {_describe(field)}")
    if arguments.preview is not None:
        print(f"wrote {arguments.preview}")


def _list(arguments: argparse.Namespace) -> int:
    for name, (params_class, function) in generators.GENERATORS.items():
        print(f"{name}: {(function.__doc__ or '').strip().splitlines()[0]}")
        for field in dataclasses.fields(params_class):
            flag = "--" + field.name.replace("_", "-")
            print(f"    {flag:26} {field.default!r:>8}  {field.metadata.get('help', '')}")
    from trainer.datasets import listing

    print(listing())
    return 0


def _generate(arguments: argparse.Namespace) -> int:
    outputs = _outputs(arguments, FIELD_SUFFIXES)
    params = from_arguments(arguments.params_class, arguments)
    field = generators.GENERATORS[arguments.generator][1](params)
    _write(field, arguments, outputs, generator=arguments.generator, parameters=params)
    return 0


def _convert(arguments: argparse.Namespace) -> int:
    outputs = _outputs(arguments, FIELD_SUFFIXES)
    options = from_arguments(LoadOptions, arguments)
    field = load_heightfield(arguments.input, options)
    _write(field, arguments, outputs, input=arguments.input, load_options=options)
    return 0


def _preview(arguments: argparse.Namespace) -> int:
    outputs = _outputs(arguments, (".png",))
    options = from_arguments(LoadOptions, arguments)
    field = load_heightfield(arguments.input, options)
    with atomic_paths(*outputs) as (image_temporary, config_temporary):
        preview_png(field, image_temporary)
        config_temporary.write_text(config_text(arguments.out, input=arguments.input, load_options=options,
                                                field=_summary(field)), encoding="utf-8")
    print(f"wrote {arguments.out}: {_describe(field)}")
    return 0
