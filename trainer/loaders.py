"""Height fields by name: a file, a built-in generator (``blazed``; ``generator:NAME(…)``, the source string
every volume and model records) or one of the paper's datasets (``paper-cd``; ``dataset:NAME``).

The file formats are trainer/heightfile.py's, the generators trainer/generators.py's, the datasets
trainer/datasets.py's: this module only decides which one a name means.
"""

from __future__ import annotations

import os
import re
from pathlib import Path
from typing import Any

from gratnet.errors import GratNetError
from trainer.heightfield import HeightField
from trainer.heightfile import SUFFIXES, LoadOptions, read_heightfield_file

__all__ = ["LoadOptions", "generator_from_source", "load_heightfield"]


def load_heightfield(spec: str | os.PathLike[str], options: LoadOptions | None = None) -> HeightField:
    """Load ``spec``: a file (.npy, .npz, .gsf, .png, .exr), a built-in generator name (its defaults) or a
    paper dataset preset (trainer/datasets.py, e.g. ``paper-cd``).

    An existing file wins over a generator of the same name. ``options`` apply to files only.
    """
    from trainer import datasets, generators  # here: they import scipy, which reading a file never needs

    options = options or LoadOptions()
    path = Path(spec)
    if str(spec).startswith("generator:"):
        return generator_from_source(str(spec))
    if str(spec).startswith(datasets.SOURCE_PREFIX):  # a scan-based preset's recorded source
        return datasets.preset(str(spec)).field()
    if not path.exists():
        if str(spec) in generators.GENERATORS:
            return generators.generate(str(spec))
        if datasets.is_preset(str(spec)):
            return datasets.preset(str(spec)).field()
        if path.suffix.lower() in SUFFIXES:
            raise GratNetError(f"no such file: {path}")
        raise GratNetError(f"{str(spec)!r} is neither a file nor a built-in generator "
                           f"({', '.join(generators.GENERATORS)}) nor a paper dataset ({', '.join(datasets.PRESETS)})")
    return read_heightfield_file(path, options)


def generator_from_source(source: str) -> HeightField:
    """Regenerate a built-in field from its recorded source, ``generator:NAME(key=value, …)``.

    Every volume and model records this string, so a generated field can always be rebuilt exactly
    (e.g. to compute ground-truth BRDF slices for a model); anything after the closing parenthesis
    (a note such as ``[repeated …]``) is ignored.
    """
    import ast

    from trainer import generators

    match = re.fullmatch(r"generator:(\w+)\((.*?)\)(\s*\[.*\])?", source.strip())
    if not match:
        raise GratNetError(f"not a generator source string: {source!r} (expected generator:NAME(key=value, ...))")
    try:
        call = ast.parse(f"f({match.group(2)})", mode="eval").body
        if not isinstance(call, ast.Call):  # a ')' inside the parentheses closed the call early
            raise ValueError("not one call")
        overrides: dict[str, Any] = {}
        for keyword in call.keywords:
            if keyword.arg is None:
                raise ValueError("'**' names no parameter")
            overrides[keyword.arg] = ast.literal_eval(keyword.value)
    except (SyntaxError, ValueError) as error:
        raise GratNetError(f"cannot parse the parameters of {source!r}: {error}") from error
    return generators.generate(match.group(1), **overrides)
