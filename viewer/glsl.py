"""A small GLSL preprocessor and compiler front end: ``#include``, defines and file/line-exact errors.

A program is one file ``shaders/NAME.glsl`` holding both stages, selected with ``#ifdef VERTEX_SHADER``
/ ``#ifdef FRAGMENT_SHADER`` (a compute program, :func:`compile_compute`: one stage, ``#ifdef COMPUTE_SHADER``).
:func:`load_program_source` emits, in this order:

1. ``#version 430 core``;
2. ``#define VERTEX_SHADER``, ``#define FRAGMENT_SHADER`` or ``#define COMPUTE_SHADER``;
3. one ``#define NAME VALUE`` per entry of ``defines`` (ints and floats only — array capacities and
   constants that come from the model file; values are never substituted into the shader text);
4. the program file with every ``#include "x.glsl"`` replaced by that file (resolved relative to the
   including file, recursively; a file is included once, later includes of it are skipped; an include
   cycle or a missing file is an error naming the including file and line). An include whose argument is
   a key of ``overrides`` takes that :class:`GeneratedSource` instead of the file (e.g. the MLP with the
   weights baked in, :mod:`viewer.baked`); its text may not include further files.

``#include "codes.glsl"`` takes no file either: it stands for :func:`gratnet.codes.glsl_source`, the ``#define``s
of the codes Python and the GLSL share (schemes, activations, range kinds, light kinds, counters, bindings). Its
text goes after the defines of step 3, wherever the first include of it stands (inside an ``#if`` too), so that
its names hold everywhere in the program; a define of ``defines`` may not take one of its names.

Every stretch of text taken from a file is preceded by ``#line L FILEID``. Mesa reports the source
number (FILEID) only for preprocessor and syntax errors — its semantic errors always say ``0:`` (measured
with Mesa 22/llvmpipe) — so the line number carries the file too: ``L = FILEID · LINE_STRIDE + line``.
:func:`compile_program` decodes either form and raises :class:`~gratnet.errors.GratNetError` whose
message names the real file and line (``path:line:column: error: …``); a generated source is named by
its :attr:`GeneratedSource.name` (``<baked mlp.glsl: model.npz>:12:5: error: …``).
"""

from __future__ import annotations

import dataclasses
import math
import os
import re
from collections.abc import Mapping
from pathlib import Path

import moderngl

from gratnet.codes import GLSL_INCLUDE, glsl_defines, glsl_source
from gratnet.errors import GratNetError
from shaders import SHADER_ROOT as PACKAGED_SHADER_ROOT
from viewer.pacing import sigint_deferred

__all__ = [
    "CODES_SOURCE",
    "LINE_STRIDE",
    "SHADER_ROOT",
    "GeneratedSource",
    "ProgramSource",
    "compile_compute",
    "compile_program",
    "load_program_source",
    "map_error_log",
    "preprocess",
]

#: The runtime's shader folder: ``shaders/`` at the repository root, installed as a package with its .glsl data.
SHADER_ROOT = PACKAGED_SHADER_ROOT  # shaders/ is a package whose data are the .glsl files
#: Lines per file in the encoded ``#line`` numbers; a shader file may have at most this many lines - 1.
LINE_STRIDE = 100_000
GLSL_VERSION = "#version 430 core"
_STAGES = {"vertex": "VERTEX_SHADER", "fragment": "FRAGMENT_SHADER"}
_ALL_STAGES = {**_STAGES, "compute": "COMPUTE_SHADER"}
_HEADER_NAME = "<generated header>"
_INCLUDE = re.compile(r"^\s*#\s*include\b(.*)$")
_INCLUDE_ARGUMENT = re.compile(r'^\s*"([^"]+)"\s*(//.*)?$')
_VERSION = re.compile(r"^\s*#\s*version\b")
_IDENTIFIER = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")
# Mesa: "0:100012(5): error: …"; NVIDIA and others: "0(100012) : error …".
_MESA_LOCATION = re.compile(r"^(\d+):(\d+)\((\d+)\)")
# NVIDIA: "S(L) : error C0000: …". The " : " after the location is consumed, so that both forms read
# "path:line:" before the message (a caller may look for "file:line:").
_PAREN_LOCATION = re.compile(r"^(\d+)\((\d+)\)(?:\s*:\s*)?")

Defines = Mapping[str, "int | float"]


@dataclasses.dataclass(frozen=True)
class GeneratedSource:
    """GLSL text made by a program, included in place of a file.

    Attributes:
        name: what compile errors call it, e.g. ``<baked mlp.glsl: model.npz>`` (no file by that name exists).
        text: the GLSL; no ``#version`` and no ``#include`` lines.
    """

    name: str
    text: str


#: Include argument (as written after ``#include``, e.g. ``"mlp.glsl"``) → the source that replaces that file.
Overrides = Mapping[str, GeneratedSource]

#: The source of ``#include "codes.glsl"`` (:mod:`gratnet.codes`), put in the program's header.
CODES_SOURCE = GeneratedSource(f"<generated {GLSL_INCLUDE}: gratnet/codes.py>", glsl_source())
_CODE_NAMES = frozenset(glsl_defines())


@dataclasses.dataclass(frozen=True)
class ProgramSource:
    """Preprocessed text of one stage and the files it came from (``files[k - 1]`` has FILEID ``k``).

    A file is its :class:`~pathlib.Path`; a :class:`GeneratedSource` is its ``name`` (a ``str``).
    """

    text: str
    files: tuple[Path | str, ...]


def _program_path(name: str, shader_root: Path) -> Path:
    file_name = name if name.endswith(".glsl") else f"{name}.glsl"
    return shader_root / file_name


def _define_lines(defines: Defines) -> list[str]:
    lines = []
    for name, value in defines.items():
        if not isinstance(name, str) or not _IDENTIFIER.match(name) or name.startswith(("GL_", "__")):
            raise GratNetError(f"invalid GLSL define name {name!r}: use letters, digits and _, not starting GL_ or __")
        if name in _ALL_STAGES.values():
            raise GratNetError(f"define {name} is reserved: the preprocessor sets it from the stage")
        if name in _CODE_NAMES:
            raise GratNetError(f"define {name} is a shared code: gratnet/codes.py defines it ({GLSL_INCLUDE})")
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise GratNetError(f"GLSL define {name} must be an int or a float, got {value!r}")
        if isinstance(value, float):
            if not math.isfinite(value):
                raise GratNetError(f"GLSL define {name} must be finite, got {value!r}")
            text = repr(value)  # shortest round-trip form: '0.01', '1e-05' are valid GLSL float literals
        else:
            text = str(int(value))
        lines.append(f"#define {name} ({text})" if text.startswith("-") else f"#define {name} {text}")
    return lines


class _Preprocessor:
    """Expands includes depth-first, once per file, recording each file's FILEID."""

    def __init__(self, overrides: Overrides | None = None) -> None:
        self.files: list[Path | str] = []
        self.done: set[Path | str] = set()
        self.lines: list[str] = []
        self.header: list[str] = []  # codes.glsl, once included: it goes before the program's text
        self.overrides: dict[str, GeneratedSource] = {}
        for key, source in (overrides or {}).items():
            if not isinstance(source, GeneratedSource):
                raise GratNetError(f"override of {key!r} must be a viewer.glsl.GeneratedSource, got "
                                   f"{type(source).__name__}")
            self.overrides[key] = source

    def _file_id(self, path: Path | str) -> int:
        if path not in self.files:
            self.files.append(path)
        return self.files.index(path) + 1

    def _expand_generated(self, source: GeneratedSource, lines: list[str]) -> None:
        source_lines = source.text.splitlines()
        if len(source_lines) >= LINE_STRIDE:
            raise GratNetError(f"{source.name} has {len(source_lines)} lines; at most {LINE_STRIDE - 1} are supported")
        file_id = self._file_id(source.name)
        self.done.add(source.name)
        lines.append(f"#line {file_id * LINE_STRIDE + 1} {file_id}")
        for number, line in enumerate(source_lines, start=1):
            if _VERSION.match(line) or _INCLUDE.match(line):
                raise GratNetError(f"{source.name}:{number}: a generated source may hold no #version or #include")
            lines.append(line)

    def expand(self, path: Path, stack: tuple[Path, ...]) -> None:
        try:
            text = path.read_text(encoding="utf-8")
        except OSError as error:
            raise GratNetError(f"cannot read shader {path}: {error.strerror or error}") from error
        source_lines = text.splitlines()
        if len(source_lines) >= LINE_STRIDE:
            raise GratNetError(f"shader {path} has {len(source_lines)} lines; at most {LINE_STRIDE - 1} are supported")
        file_id = self._file_id(path)
        self.done.add(path)
        self.lines.append(f"#line {file_id * LINE_STRIDE + 1} {file_id}")
        for number, line in enumerate(source_lines, start=1):
            if _VERSION.match(line):
                raise GratNetError(f"{path}:{number}: remove #version; the preprocessor emits '{GLSL_VERSION}'")
            include = _INCLUDE.match(line)
            if include is None:
                self.lines.append(line)
                continue
            argument = _INCLUDE_ARGUMENT.match(include.group(1))
            if argument is None:
                raise GratNetError(f'{path}:{number}: malformed include, expected #include "file.glsl"')
            generated = self.overrides.get(argument.group(1))
            if generated is None and argument.group(1) == GLSL_INCLUDE:
                if CODES_SOURCE.name not in self.done:  # once, into the header: its names hold in every #if branch
                    self._expand_generated(CODES_SOURCE, self.header)
                self.lines.append(f"#line {file_id * LINE_STRIDE + number + 1} {file_id}")
                continue
            if generated is not None:
                if generated.name not in self.done:  # include-once, as for files
                    self._expand_generated(generated, self.lines)
                self.lines.append(f"#line {file_id * LINE_STRIDE + number + 1} {file_id}")
                continue
            target = (path.parent / argument.group(1)).resolve()
            if target in stack:
                chain = " -> ".join(str(p) for p in (*stack, target))
                raise GratNetError(f"{path}:{number}: include cycle: {chain}")
            if not target.is_file():
                raise GratNetError(
                    f'{path}:{number}: included file "{argument.group(1)}" not found (looked for {target})'
                )
            if target not in self.done:  # include-once: a second include of a file is skipped
                self.expand(target, (*stack, target))
            # Back in this file: the next line keeps its own number.
            self.lines.append(f"#line {file_id * LINE_STRIDE + number + 1} {file_id}")


def preprocess(
    name: str, stage: str, defines: Defines, shader_root: str | os.PathLike[str] | None = None,
    overrides: Overrides | None = None,
) -> ProgramSource:
    """Preprocess program ``name`` for ``stage`` (``"vertex"``, ``"fragment"`` or ``"compute"``); see the module
    docstring.

    ``overrides`` maps an include argument (``"mlp.glsl"``) to the :class:`GeneratedSource` included instead.

    Raises:
        GratNetError: unknown stage, invalid define, missing or unreadable file, include cycle,
            malformed include, a ``#version`` line in a shader file, or a ``#version``/``#include`` line
            in a generated source.
    """
    stage_define = _ALL_STAGES.get(str(stage).lower())
    if stage_define is None:
        raise GratNetError(f"unknown shader stage {stage!r}; choose vertex, fragment or compute")
    root = Path(shader_root) if shader_root is not None else SHADER_ROOT
    path = _program_path(name, root).resolve()
    if not path.is_file():
        raise GratNetError(f"shader program {name!r} not found (looked for {path})")
    preprocessor = _Preprocessor(overrides)
    header = [GLSL_VERSION, f"#define {stage_define}", *_define_lines(defines)]
    preprocessor.expand(path, (path,))
    lines = header + preprocessor.header + preprocessor.lines
    return ProgramSource("\n".join(lines) + "\n", tuple(preprocessor.files))


def load_program_source(
    name: str, stage: str, defines: Defines, shader_root: str | os.PathLike[str] | None = None,
    overrides: Overrides | None = None,
) -> str:
    """The complete GLSL text of one stage of program ``name`` (see :func:`preprocess`)."""
    return preprocess(name, stage, defines, shader_root, overrides).text


def _display_path(path: Path | str) -> str:
    """A path relative to the working directory when it lies inside it (shorter messages), else absolute;
    a generated source's name as it is."""
    if isinstance(path, str):
        return path
    try:
        return str(path.relative_to(Path.cwd()))
    except ValueError:
        return str(path)


def _locate(files: tuple[Path | str, ...], source: int, line: int) -> tuple[str, int]:
    """(file name, line in that file) of an encoded line number (``source`` is ignored when 0)."""
    file_id = source
    if line >= LINE_STRIDE:
        file_id, line = divmod(line, LINE_STRIDE)
    if file_id == 0:
        return _HEADER_NAME, line
    if 1 <= file_id <= len(files):
        return _display_path(files[file_id - 1]), line
    return f"<source {file_id}>", line


def map_error_log(log: str, files: tuple[Path | str, ...]) -> list[str]:
    """Rewrite a driver's compile log so that each location reads ``path:line:column:`` (or ``path:line:``)."""

    def mesa(match: re.Match[str]) -> str:
        where, line = _locate(files, int(match.group(1)), int(match.group(2)))
        return f"{where}:{line}:{match.group(3)}"

    def paren(match: re.Match[str]) -> str:
        where, line = _locate(files, int(match.group(1)), int(match.group(2)))
        return f"{where}:{line}: "

    messages = []
    for raw in log.splitlines():
        text = raw.strip()
        if not text or set(text) <= {"="} or text in ("GLSL Compiler failed", "GLSL Linker failed"):
            continue
        if text in ("vertex_shader", "fragment_shader", "compute_shader", "Program"):
            continue
        text, found = _MESA_LOCATION.subn(mesa, text, count=1)
        if not found:
            text = _PAREN_LOCATION.sub(paren, text, count=1)
        messages.append(text)
    return messages


def compile_program(
    ctx: moderngl.Context, name: str, defines: Defines, shader_root: str | os.PathLike[str] | None = None,
    overrides: Overrides | None = None,
) -> moderngl.Program:
    """Preprocess and link program ``name`` (vertex + fragment stage of ``shaders/NAME.glsl``), with the
    includes named in ``overrides`` replaced by generated sources (see :func:`preprocess`).

    Raises:
        GratNetError: preprocessing failed, or the driver rejected a stage or the link; the message is
            one line naming the stage and, for each error (at most five), the real file and line.
    """
    stages = {stage: preprocess(name, stage, defines, shader_root, overrides) for stage in _STAGES}
    try:
        with sigint_deferred():  # a Ctrl-C inside moderngl's program creation crashed the process
            return ctx.program(vertex_shader=stages["vertex"].text, fragment_shader=stages["fragment"].text)
    except moderngl.Error as error:
        log = str(error)
        failed = "linking"
        for stage in _STAGES:
            if f"{stage}_shader" in log:
                failed = f"the {stage} stage"
        # Both stages come from the same files in the same order, so their FILEIDs agree.
        files = stages["fragment" if "fragment_shader" in log else "vertex"].files
        messages = map_error_log(log, files) or [" ".join(log.split())]
        shown = "; ".join(messages[:5]) + (f"; … ({len(messages) - 5} more)" if len(messages) > 5 else "")
        raise GratNetError(f"cannot compile GLSL program {name!r} ({failed}): {shown}") from error


def compile_compute(
    ctx: moderngl.Context, name: str, defines: Defines, shader_root: str | os.PathLike[str] | None = None,
    overrides: Overrides | None = None,
) -> moderngl.ComputeShader:
    """Preprocess and compile the compute stage of program ``name`` (``#ifdef COMPUTE_SHADER``), as
    :func:`compile_program` does the other two.

    Raises:
        GratNetError: preprocessing failed or the driver rejected the shader (one line, real files and lines).
    """
    source = preprocess(name, "compute", defines, shader_root, overrides)
    try:
        with sigint_deferred():  # as compile_program's
            return ctx.compute_shader(source.text)
    except moderngl.Error as error:
        messages = map_error_log(str(error), source.files) or [" ".join(str(error).split())]
        shown = "; ".join(messages[:5]) + (f"; … ({len(messages) - 5} more)" if len(messages) > 5 else "")
        raise GratNetError(f"cannot compile GLSL compute program {name!r}: {shown}") from error
