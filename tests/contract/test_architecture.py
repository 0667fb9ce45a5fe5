"""The house rules of the code base (issue 31), read from the source with ``ast`` (nothing is imported):

- no import circle among the project's own modules (every import counts, also those inside functions);
- no module uses another module's private name (one leading underscore), imported or reached as an attribute;
- no source file longer than :data:`MAX_LINES` lines;
- layers point one way: each top-level folder imports only the folders :data:`ALLOWED_IMPORTS` gives it
  (gratnet/, the contract, none; viewer/ and trainer/ only gratnet/; the tools on top the layers below);
- no test module imports another: tests/ is grouped by the layer a test exercises (contract/, trainer/, runtime/,
  tools/), and what tests share is in tests/helpers.py and conftest.py's fixtures.

Each checker is also run on a small synthetic tree that breaks its rule, so that it is known to be able to fail.
The subcommands' registration (entry points instead of a table of module names in gratnet/cli.py) is checked
at the end.
"""

from __future__ import annotations

import ast
import dataclasses
import importlib.metadata
import re
import subprocess
import sys
from collections import defaultdict
from collections.abc import Iterable, Mapping
from pathlib import Path

import pytest

from tests.helpers import REPO

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - Python 3.10
    import tomli as tomllib


#: The folders whose .py files are the project's own modules.
FOLDERS = ("gratnet", "viewer", "trainer", "bench", "sweep", "mitsuba_plugin", "analysis", "export", "shaders",
           "benchmarks", "tests", "scripts")

#: The longest a source file may be (lines).
MAX_LINES = 800

#: The modules of tests/ that its test modules may import: the shared helpers, and conftest.py (whose fixtures
#: pytest hands over without an import).
TEST_SHARED = frozenset({"tests.helpers", "tests.conftest"})

#: Top-level folder → the other top-level folders it may import. gratnet/ is the contract between the offline
#: stage and the runtime: it imports nothing above it. viewer/ (the runtime) and trainer/ (the offline stage)
#: stand on it side by side; shaders/ holds the GLSL the viewer loads. The tools stand on top: bench/ times the
#: runtime against the trainer's torch reference; sweep/ runs trainer/ on Ray and bench/'s measurement and tables;
#: mitsuba_plugin/ shares the viewer's scene setup; analysis/ reads runs, models and volumes (trainer/'s checkpoints
#: and slices, viewer/'s renders) into the tables, records and figures the docs, scripts and probes share; export/
#: writes materials for other engines from the model files and the runtime's GLSL (viewer/'s preprocessor).
#: benchmarks/ and scripts/ may use any package, tests/ anything.
PACKAGES = ("gratnet", "viewer", "trainer", "shaders", "bench", "sweep", "mitsuba_plugin", "analysis", "export")
ALLOWED_IMPORTS: dict[str, frozenset[str]] = {
    "gratnet": frozenset(),
    "shaders": frozenset(),
    "viewer": frozenset({"gratnet", "shaders"}),
    "trainer": frozenset({"gratnet"}),
    "bench": frozenset({"gratnet", "viewer", "trainer", "shaders"}),
    "sweep": frozenset({"gratnet", "viewer", "trainer", "shaders", "bench"}),
    "mitsuba_plugin": frozenset({"gratnet", "viewer", "trainer", "shaders"}),
    "analysis": frozenset({"gratnet", "viewer", "trainer", "shaders"}),
    "export": frozenset({"gratnet", "viewer", "shaders"}),
    "benchmarks": frozenset(PACKAGES),
    "scripts": frozenset(PACKAGES),
    "tests": frozenset(FOLDERS),
}


@dataclasses.dataclass(frozen=True)
class Use:
    """One use of an own module: ``source`` (module) at ``where`` (path:line) uses ``target`` (module), and
    ``name`` of it when the use names one (``from target import name``, ``target.name``)."""

    source: str
    target: str
    where: str
    name: str | None = None


@dataclasses.dataclass
class Scan:
    """What the source says: the own modules (dotted name → file) and every use of one by another."""

    modules: dict[str, Path]
    uses: list[Use]

    def graph(self) -> dict[str, set[str]]:
        """Module → the own modules it imports (or reaches as attributes of an imported package)."""
        edges: dict[str, set[str]] = defaultdict(set)
        for use in self.uses:
            edges[use.source].add(use.target)
        return edges


def module_name(root: Path, path: Path) -> str:
    """Dotted module name of ``path`` under ``root`` (a package's ``__init__.py`` is the package)."""
    parts = path.relative_to(root).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def own_modules(root: Path, folders: Iterable[str]) -> dict[str, Path]:
    """Every .py file under ``root``'s ``folders`` by dotted module name."""
    return {module_name(root, path): path for folder in folders for path in sorted((root / folder).rglob("*.py"))}


def _resolve(dotted: str, modules: Mapping[str, Path]) -> str | None:
    """The longest own module that ``dotted`` starts with (``a.b.c`` → ``a.b`` when a/b.py exists)."""
    parts = dotted.split(".")
    for end in range(len(parts), 0, -1):
        candidate = ".".join(parts[:end])
        if candidate in modules:
            return candidate
    return None


def _absolute(name: str, folder: str, modules: Mapping[str, Path], tops: set[str]) -> str:
    """An absolute import's name as a module name: a sibling script of the importing file in ``folder``
    (``from test_shader_parity import``, which works because the folder is on sys.path) is named with its folder."""
    first = name.split(".")[0]
    if first not in tops and f"{folder}.{first}" in modules:
        return f"{folder}.{name}"
    return name


def _dotted(node: ast.expr) -> str | None:
    """``a.b.c`` of an attribute chain on a plain name, else None."""
    names = []
    while isinstance(node, ast.Attribute):
        names.append(node.attr)
        node = node.value
    if not isinstance(node, ast.Name):
        return None
    return ".".join([node.id, *reversed(names)])


def _is_private(name: str) -> bool:
    return name.startswith("_") and not name.startswith("__")


def scan(root: Path, folders: Iterable[str]) -> Scan:
    """Read every file of ``folders`` under ``root``: its imports anywhere in it, and the attributes it reads of
    the own modules it imported."""
    modules = own_modules(root, folders)
    tops = {name.split(".")[0] for name in modules}
    uses: list[Use] = []
    for module, path in modules.items():
        tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
        package = module if path.name == "__init__.py" else module.rpartition(".")[0]
        bound: dict[str, str] = {}  # a local name → the own module it stands for
        found: list[tuple[str | None, int, str | None]] = []  # (module used, line, name used of it)
        use = found.append
        for node in ast.walk(tree):
            if isinstance(node, ast.Import):
                for alias in node.names:
                    dotted = _absolute(alias.name, package, modules, tops)
                    target = _resolve(dotted, modules)
                    use((target, node.lineno, None))
                    if alias.asname and target == dotted:  # import a.b as m: m is a.b
                        bound[alias.asname] = target
                    elif not alias.asname and target is not None:  # import a.b: a, through which a.b is reached
                        folders = len(dotted.split(".")) - len(alias.name.split("."))  # a sibling's: 1
                        bound[alias.name.split(".")[0]] = ".".join(dotted.split(".")[: folders + 1])
            elif (isinstance(node, ast.Call) and node.args and isinstance(node.args[0], ast.Constant)
                  and isinstance(node.args[0].value, str)
                  and (_dotted(node.func) or "").split(".")[-1] in ("import_module", "__import__")):
                # importlib.import_module("pkg.module"): an import by name (gratnet/cli.py's old table)
                use((_resolve(node.args[0].value, modules), node.lineno, None))
            elif isinstance(node, ast.ImportFrom):
                if node.level:
                    base = package.split(".")[: len(package.split(".")) - (node.level - 1)]
                    source = ".".join(base + ([node.module] if node.module else []))
                else:
                    source = _absolute(node.module or "", package, modules, tops)
                for alias in node.names:
                    submodule = f"{source}.{alias.name}"
                    if submodule in modules:  # from package import module
                        use((submodule, node.lineno, None))
                        bound[alias.asname or alias.name] = submodule
                    else:
                        use((_resolve(source, modules), node.lineno, alias.name))
        for node in ast.walk(tree):  # module.name where module is an own module imported above
            if isinstance(node, ast.Attribute):
                dotted = _dotted(node)
                if dotted is None or dotted.split(".")[0] not in bound:
                    continue
                head, _, rest = dotted.partition(".")
                full = bound[head] + ("." + rest if rest else "")
                target = _resolve(full, modules)
                remainder = full[len(target) + 1:] if target else ""
                if target and remainder and _is_private(remainder.split(".")[0]):
                    use((target, node.lineno, remainder.split(".")[0]))
        relative = path.relative_to(root)
        uses += [Use(module, target, f"{relative}:{line}", name) for target, line, name in found
                 if target is not None and target != module]
    return Scan(modules, uses)


def cycles(graph: Mapping[str, Iterable[str]]) -> list[list[str]]:
    """The groups of modules that import one another in a circle (strongly connected, more than one module),
    each sorted (Tarjan's algorithm, iterative: the graph has hundreds of modules)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    groups: list[list[str]] = []
    for start in sorted(graph):
        if start in index:
            continue
        work = [(start, iter(sorted(graph.get(start, ()))))]
        index[start] = low[start] = len(index)
        stack.append(start)
        on_stack.add(start)
        while work:
            node, children = work[-1]
            child = next(children, None)
            if child is not None:
                if child not in index:
                    index[child] = low[child] = len(index)
                    stack.append(child)
                    on_stack.add(child)
                    work.append((child, iter(sorted(graph.get(child, ())))))
                elif child in on_stack:
                    low[node] = min(low[node], index[child])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[node])
            if low[node] == index[node]:
                group = []
                while True:
                    member = stack.pop()
                    on_stack.discard(member)
                    group.append(member)
                    if member == node:
                        break
                if len(group) > 1:
                    groups.append(sorted(group))
    return sorted(groups)


def _circle(group: list[str], graph: Mapping[str, Iterable[str]]) -> list[str]:
    """A shortest path from the group's first module back to it, through the group (breadth first)."""
    members, first = set(group), group[0]
    previous: dict[str, str] = {}
    frontier = [first]
    while frontier:
        following = []
        for node in frontier:
            for child in sorted(graph.get(node, ())):
                if child == first:
                    route = [node]
                    while route[-1] != first:
                        route.append(previous[route[-1]])
                    return [*reversed(route), first]
                if child in members and child not in previous:
                    previous[child] = node
                    following.append(child)
        frontier = following
    return group  # not reached: a strongly connected group has a circle through each member


def circle_problems(found: Scan) -> list[str]:
    """One line per circle: its modules, and one path around it."""
    graph = found.graph()
    return [f"{', '.join(group)}: {' → '.join(_circle(group, graph))}" for group in cycles(graph)]


def private_problems(found: Scan) -> list[str]:
    return sorted({f"{use.where}: {use.source} uses {use.target}.{use.name}" for use in found.uses
                   if use.name is not None and _is_private(use.name)})


def long_files(root: Path, folders: Iterable[str], limit: int = MAX_LINES) -> list[str]:
    problems = []
    for path in own_modules(root, folders).values():
        lines = len(path.read_text(encoding="utf-8").splitlines())
        if lines > limit:
            problems.append(f"{path.relative_to(root)}: {lines} lines (at most {limit})")
    return problems


def layer_problems(found: Scan, allowed: Mapping[str, frozenset[str]]) -> list[str]:
    problems = set()
    for use in found.uses:
        source, target = use.source.split(".")[0], use.target.split(".")[0]
        if source != target and target not in allowed.get(source, frozenset()):
            problems.add(f"{use.where}: {source}/ imports {use.target} ({target}/ is not below {source}/)")
    return sorted(problems)


def imports_between_tests(found: Scan, shared: frozenset[str] = TEST_SHARED) -> list[str]:
    """Imports of a module of tests/ by another that are not of ``shared`` (or of a package's ``__init__``)."""
    return sorted({f"{use.where}: {use.source} imports {use.target}" for use in found.uses
                   if use.source.split(".")[0] == use.target.split(".")[0] == "tests" and use.target not in shared
                   and found.modules[use.target].name != "__init__.py"})


def named_modules_above(root: Path, folder: str, above: Iterable[str]) -> list[str]:
    """Strings (not docstrings) in ``folder``'s code that name a module of the folders ``above`` it, such as
    ``"viewer.render_cli"``: an import by name waiting to happen (gratnet/cli.py's old table of subcommands)."""
    pattern = re.compile(rf"^(?:{'|'.join(map(re.escape, above))})\.[A-Za-z_][\w.]*(?::\w+)?$")
    problems = []
    for path in own_modules(root, [folder]).values():
        tree = ast.parse(path.read_text(encoding="utf-8"))
        docstrings = {id(node.body[0].value) for node in ast.walk(tree)
                      if isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef))
                      and node.body and isinstance(node.body[0], ast.Expr)}
        problems += [f"{path.relative_to(root)}:{node.lineno}: {node.value!r}" for node in ast.walk(tree)
                     if isinstance(node, ast.Constant) and isinstance(node.value, str) and id(node) not in docstrings
                     and pattern.match(node.value)]
    return problems


@pytest.fixture(scope="module")
def repository() -> Scan:
    return scan(REPO, FOLDERS)


def test_every_folder_has_a_layer_rule():
    assert set(ALLOWED_IMPORTS) == set(FOLDERS)
    assert all(rule <= set(FOLDERS) for rule in ALLOWED_IMPORTS.values())


def test_no_import_circles(repository):
    problems = circle_problems(repository)
    assert not problems, "import circles:\n" + "\n".join(problems)


def test_no_module_uses_another_modules_private_names(repository):
    problems = private_problems(repository)
    assert not problems, "private names used across modules:\n" + "\n".join(problems)


def test_no_source_file_is_too_long():
    problems = long_files(REPO, FOLDERS)
    assert not problems, "\n".join(problems)


def test_the_contract_names_no_module_above_it():
    above = [folder for folder in FOLDERS if folder not in ALLOWED_IMPORTS["gratnet"] | {"gratnet"}]
    problems = named_modules_above(REPO, "gratnet", above)
    assert not problems, "gratnet/ names modules above it:\n" + "\n".join(problems)


def test_layers_point_one_way(repository):
    problems = layer_problems(repository, ALLOWED_IMPORTS)
    assert not problems, "imports against the layers:\n" + "\n".join(problems)


def test_no_test_module_imports_another(repository):
    problems = imports_between_tests(repository)
    assert not problems, "test modules importing test modules (share through tests/helpers.py):\n" + "\n".join(
        problems)


# --- each checker can fail ---------------------------------------------------------------------------------


def _tree(root: Path, files: Mapping[str, str]) -> Path:
    for name, text in files.items():
        path = root / name
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text, encoding="utf-8")
    return root


def test_the_circle_check_finds_a_circle_also_through_an_import_in_a_function(tmp_path):
    root = _tree(tmp_path, {
        "low/__init__.py": "",
        "low/a.py": "from low.b import thing\n",
        "low/b.py": "def thing():\n    from . import c\n    return c\n",
        "low/c.py": "import low.a\n",
        "low/d.py": "from low import a\n",  # into the circle, not part of it
    })
    assert circle_problems(scan(root, ["low"])) == ["low.a, low.b, low.c: low.a → low.b → low.c → low.a"]
    (root / "low" / "c.py").write_text("import low.d\n", encoding="utf-8")  # a → b → c → d → a
    assert circle_problems(scan(root, ["low"])) == [
        "low.a, low.b, low.c, low.d: low.a → low.b → low.c → low.d → low.a"]
    (root / "low" / "c.py").write_text("import json\n", encoding="utf-8")
    assert circle_problems(scan(root, ["low"])) == []


def test_the_private_check_finds_imported_and_reached_private_names(tmp_path):
    root = _tree(tmp_path, {
        "pkg/__init__.py": "",
        "pkg/core.py": "_hidden = 1\n__version__ = '1'\n\n\ndef _own():\n    return _hidden\n",
        "pkg/one.py": "from pkg.core import _hidden\n",
        "pkg/two.py": "import pkg.core\n\n\ndef f():\n    return pkg.core._own()\n",
        "pkg/three.py": "from pkg import core as c\nfrom .core import __version__\nVALUE = c._hidden\n",
        "pkg/fine.py": "from pkg.core import __version__\nimport os\nX = os._exit\n",
    })
    assert private_problems(scan(root, ["pkg"])) == [
        "pkg/one.py:1: pkg.one uses pkg.core._hidden",
        "pkg/three.py:3: pkg.three uses pkg.core._hidden",
        "pkg/two.py:5: pkg.two uses pkg.core._own",
    ]


def test_the_length_check_finds_a_long_file(tmp_path):
    root = _tree(tmp_path, {"pkg/short.py": "x = 1\n" * 10, "pkg/long.py": "x = 1\n" * 11})
    assert long_files(root, ["pkg"], limit=10) == ["pkg/long.py: 11 lines (at most 10)"]


def test_the_layer_check_finds_an_import_upwards(tmp_path):
    root = _tree(tmp_path, {
        "base/__init__.py": "",
        "base/contract.py": "def f():\n    from top import tool\n    return tool\n",
        "base/table.py": "import importlib\n\nTOOL = importlib.import_module('top.tool')\n",
        "top/__init__.py": "",
        "top/tool.py": "from base.contract import f\n",
    })
    found = scan(root, ["base", "top"])
    rules = {"base": frozenset(), "top": frozenset({"base"})}
    assert layer_problems(found, rules) == ["base/contract.py:2: base/ imports top.tool (top/ is not below base/)",
                                            "base/table.py:3: base/ imports top.tool (top/ is not below base/)"]
    assert layer_problems(found, {**rules, "base": frozenset({"top"})}) == []


def test_the_naming_check_finds_a_table_of_module_names(tmp_path):
    source = '"""Commands of top.tool."""\nTABLE = {"run": "top.tool", "x": "top.b:f"}\n'
    root = _tree(tmp_path, {"base/cli.py": source})
    assert named_modules_above(root, "base", ["top"]) == ["base/cli.py:2: 'top.tool'", "base/cli.py:2: 'top.b:f'"]


def test_the_test_import_check_finds_a_test_importing_another(tmp_path):
    root = _tree(tmp_path, {
        "tests/__init__.py": "", "tests/one/__init__.py": "", "tests/two/__init__.py": "", "tests/two/test_c.py": "",
        "tests/helpers.py": "REPO = 1\n", "tests/conftest.py": "from tests.helpers import REPO\n",
        "tests/one/test_a.py": ("from tests import helpers\nfrom tests.helpers import REPO\n"
                                "from tests.two.test_b import f\n"),
        "tests/two/test_b.py": "import test_c\n\n\ndef f():\n    from tests import conftest\n    return conftest\n",
    })
    assert imports_between_tests(scan(root, ["tests"])) == [
        "tests/one/test_a.py:3: tests.one.test_a imports tests.two.test_b",
        "tests/two/test_b.py:1: tests.two.test_b imports tests.two.test_c",
    ]


def test_sibling_scripts_resolve_to_their_folder(tmp_path):
    """A test importing a sibling test by its bare name (pytest puts tests/ on sys.path) is an own import."""
    root = _tree(tmp_path, {"tests/test_a.py": "from test_b import _helper\nimport test_c\nX = test_c._other\n",
                            "tests/test_b.py": "_helper = 1\n", "tests/test_c.py": "_other = 2\n"})
    assert private_problems(scan(root, ["tests"])) == ["tests/test_a.py:1: tests.test_a uses tests.test_b._helper",
                                                       "tests/test_a.py:3: tests.test_a uses tests.test_c._other"]


# --- the gratnet command's subcommands: entry points, not module names in gratnet/ ----------------------------


def _declared_commands() -> dict[str, str]:
    pyproject = tomllib.loads((REPO / "pyproject.toml").read_text(encoding="utf-8"))
    return pyproject["project"]["entry-points"]["gratnet.commands"]


def test_every_subcommand_entry_point_names_a_register_function():
    for name, value in _declared_commands().items():
        module, _, function = value.partition(":")
        path = REPO / (module.replace(".", "/") + ".py")
        assert path.is_file(), f"{name}: {value} names no module"
        tree = ast.parse(path.read_text(encoding="utf-8"))
        assert any(isinstance(node, ast.FunctionDef) and node.name == function for node in tree.body), \
            f"{name}: {path.relative_to(REPO)} has no {function}()"


def test_the_installed_entry_points_are_pyprojects():
    """A stale install (entry points from before a pyproject.toml change) shows here: re-run pip install -e ."""
    installed = {point.name: point.value for point in importlib.metadata.entry_points(group="gratnet.commands")}
    assert installed == _declared_commands(), "re-install the package: pip install --no-deps -e ."


def test_without_installed_metadata_the_command_says_how_to_install(monkeypatch, capsys):
    from gratnet import cli

    monkeypatch.setattr(cli.importlib.metadata, "entry_points", lambda **_: [])
    assert cli.main(["render", "--help"]) == 2
    error = capsys.readouterr().err
    assert error.count("\n") == 1 and error.startswith("gratnet: error: ") and "pip install -e ." in error


def test_help_lists_every_subcommand_in_the_works_order_without_torch():
    code = ("import contextlib, io, sys\nfrom gratnet.cli import HELP_ORDER, main\nout = io.StringIO()\n"
            "with contextlib.redirect_stdout(out):\n    assert main(['--help']) == 0\n"
            "assert 'torch' not in sys.modules, 'gratnet --help imported torch'\n"
            "lines = out.getvalue().splitlines()\n"
            "print(' '.join(line.split()[0] for line in lines if line[:4] == '    ' and line[4:5].strip()))\n")
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=REPO)
    assert result.returncode == 0, result.stderr
    from gratnet.cli import HELP_ORDER

    assert result.stdout.split() == [name for name in HELP_ORDER if name in _declared_commands()]


#: The window toolkit: only the viewer's window shell may import it (rendering code never does, so that
#: `gratnet render`, the tests and the tools run headless).
WINDOW_TOOLKIT = frozenset({"glfw", "imgui_bundle", "imgui"})
WINDOW_SHELL = "viewer/window.py"
PRODUCT_FOLDERS = ("gratnet", "viewer", "trainer", "shaders", "mitsuba_plugin", "sweep", "bench", "analysis")


def window_toolkit_imports(root: Path, folders: Iterable[str] = PRODUCT_FOLDERS) -> list[str]:
    """``file:line imports NAME`` for every import of the window toolkit outside :data:`WINDOW_SHELL`."""
    problems = []
    for folder in folders:
        for path in sorted((root / folder).rglob("*.py")):
            relative = path.relative_to(root).as_posix()
            if relative == WINDOW_SHELL:
                continue
            for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), filename=str(path))):
                names = ([alias.name for alias in node.names] if isinstance(node, ast.Import)
                         else [node.module or ""] if isinstance(node, ast.ImportFrom) and not node.level else [])
                problems += [f"{relative}:{node.lineno} imports {name}" for name in names
                             if name.split(".")[0] in WINDOW_TOOLKIT]
    return problems


def test_only_the_window_shell_imports_glfw_or_imgui():
    assert window_toolkit_imports(REPO) == []


def test_the_window_toolkit_check_finds_an_import_in_rendering_code(tmp_path):
    root = _tree(tmp_path, {"viewer/renderer.py": "def f():\n    import glfw\n",
                            "viewer/window.py": "import glfw\nfrom imgui_bundle import imgui\n",
                            "gratnet/a.py": "from imgui_bundle import imgui\n"})
    assert window_toolkit_imports(root, ("gratnet", "viewer")) == ["gratnet/a.py:1 imports imgui_bundle",
                                                                     "viewer/renderer.py:2 imports glfw"]
