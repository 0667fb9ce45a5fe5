"""Every third-party import is declared in pyproject.toml, in the extra its layer may use.

A package that happens to be installed on a developer's machine must not hide a missing declaration:
this reads every module's imports (all of them, also those inside functions) with ``ast``, maps each
top-level module to the distribution that installed it, and checks that distribution against
pyproject.toml:

- ``gratnet/`` and ``viewer/`` (the runtime): the core ``dependencies`` only (no torch).
- ``trainer/`` (the offline stage): core + the ``trainer`` extra.
- ``mitsuba_plugin/`` (the Mitsuba 3 BSDF and ``gratnet mitsuba-render``): core + the ``mitsuba`` extra.
- ``sweep/`` (``gratnet sweep`` on Ray, a tool on top of trainer/): core + the ``trainer`` and ``sweep`` extras.
- ``bench/`` (``gratnet bench``, a tool on top of viewer/ and trainer/: it times the runtime and uses torch
  as the reference): core + the ``trainer`` extra.
- ``analysis/`` (tables, records and figures of runs, models and volumes; it reads trainer checkpoints): core +
  the ``trainer`` extra.
- ``tests/`` and ``benchmarks/``: core + every extra.
"""

from __future__ import annotations

import ast
import importlib.metadata
import inspect
import re
import sys
from collections import defaultdict
from pathlib import Path

import pytest

from tests.helpers import REPO

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - Python 3.10
    import tomli as tomllib

PYPROJECT = tomllib.loads((REPO / "pyproject.toml").read_text(encoding="utf-8"))
OWN_PACKAGES = set(PYPROJECT["tool"]["setuptools"]["packages"]) | {"tests", "benchmarks", "scripts"}


def _normalize(name: str) -> str:
    """PEP 503 normalised distribution name."""
    return re.sub(r"[-_.]+", "-", name).lower()


def _requirement_name(requirement: str) -> str:
    match = re.match(r"\s*([A-Za-z0-9][A-Za-z0-9._-]*)", requirement)
    assert match, f"unparsable requirement {requirement!r} in pyproject.toml"
    return _normalize(match.group(1))


CORE = {_requirement_name(item) for item in PYPROJECT["project"]["dependencies"]}
EXTRAS = {extra: {_requirement_name(item) for item in items}
          for extra, items in PYPROJECT["project"].get("optional-dependencies", {}).items()}
ALLOWED = {
    "gratnet": CORE,
    "viewer": CORE,
    "trainer": CORE | EXTRAS.get("trainer", set()),
    "mitsuba_plugin": CORE | EXTRAS.get("mitsuba", set()),
    "sweep": CORE | EXTRAS.get("trainer", set()) | EXTRAS.get("sweep", set()),
    "bench": CORE | EXTRAS.get("trainer", set()),
    "analysis": CORE | EXTRAS.get("trainer", set()),
    "tests": CORE.union(*EXTRAS.values()),
    "benchmarks": CORE.union(*EXTRAS.values()),
}


def _top_level_distributions() -> dict[str, set[str]]:
    """Top-level importable name → the installed distributions providing it.

    Built from each distribution's file list (importlib.metadata.packages_distributions misses
    single-file extension modules such as OpenEXR's ``OpenEXR.cpython-*.so`` on Python 3.11).
    """
    mapping: dict[str, set[str]] = defaultdict(set)
    for distribution in importlib.metadata.distributions():
        name = _normalize(distribution.metadata["Name"] or "")
        for file in distribution.files or ():
            parts = file.parts
            if not parts or parts[0] in ("..", "__pycache__") or parts[0].endswith((".dist-info", ".egg-info")):
                continue
            top = parts[0] if len(parts) > 1 else inspect.getmodulename(parts[0])
            if top:
                mapping[top].add(name)
    return mapping


def _imports(path: Path) -> set[str]:
    """Top-level names of the absolute imports in one file (anywhere in it)."""
    tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
    names = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names.update(alias.name.split(".")[0] for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            names.add(node.module.split(".")[0])
    return names


def _third_party(names: set[str], local: frozenset[str] = frozenset()) -> set[str]:
    """Names that are neither the standard library, the project's packages nor ``local`` sibling modules."""
    return {name for name in names if name not in sys.stdlib_module_names and name not in OWN_PACKAGES
            and name not in local and name != "__future__"}


@pytest.mark.parametrize("layer", sorted(ALLOWED))
def test_every_import_is_declared_for_its_layer(layer: str) -> None:
    providers = _top_level_distributions()
    files = sorted((REPO / layer).rglob("*.py"))
    assert files, f"no Python files under {layer}/"
    problems = []
    for path in files:
        siblings = frozenset(sibling.stem for sibling in path.parent.glob("*.py"))
        for name in sorted(_third_party(_imports(path), siblings)):
            distributions = providers.get(name)
            where = path.relative_to(REPO)
            if not distributions and _normalize(name) in ALLOWED[layer]:
                continue  # declared, but its environment marker leaves it out here (tomli on Python ≥ 3.11)
            if not distributions:
                problems.append(f"{where}: imports {name!r}, which no installed distribution provides")
            elif not distributions & ALLOWED[layer]:
                problems.append(f"{where}: imports {name!r} from {sorted(distributions)}, not declared for {layer}/ "
                                f"in pyproject.toml")
    assert not problems, "\n".join(problems)


def test_the_checker_finds_an_undeclared_import(tmp_path: Path) -> None:
    """The check itself can fail: a module importing an installed but undeclared distribution is caught."""
    providers = _top_level_distributions()
    undeclared = next(name for name, distributions in sorted(providers.items())
                      if name.isidentifier() and name not in sys.stdlib_module_names
                      and not distributions & ALLOWED["tests"])
    module = tmp_path / "module.py"
    module.write_text(f"def f():\n    import {undeclared}.sub as x\n    from os import path\n    return x, path\n")
    names = _third_party(_imports(module))
    assert names == {undeclared}
    assert not providers[undeclared] & CORE


def test_runtime_dependencies_exclude_torch() -> None:
    """The runtime never needs torch: it is the trainer's extra only."""
    assert "torch" not in CORE
    assert "torch" in EXTRAS["trainer"]
