"""Every code that Python and the GLSL share is defined once (issue 45): gratnet/codes.py's tables and
gratnet/lights.py's light registry. No GL: the generated ``codes.glsl``, the shader sources and the Python sources
are read as text (Python with ``ast``), and the preprocessor is run without a context.

- the generated defines say what the Python tables say (:func:`define_problems`);
- the shaders use the generated names, type no code, binding or work-group size of their own, include
  ``codes.glsl`` where they use one, and compare no code uniform with a number (:func:`shader_problems`);
- no Python module of the runtime outside the two table modules types a table again (two of a code table's
  names in one literal, or a whole list of flag choices), binds a buffer or image at a literal number, defines
  a generated name, or takes a weight form apart with ``startswith``/``endswith`` (:func:`python_problems`);
- the light registry and the weight forms are what their readers use.

Each checker is also run on a deliberately broken copy, so that it is known to be able to fail.
"""

from __future__ import annotations

import argparse
import ast
import dataclasses
import re
import shutil
from pathlib import Path

import numpy as np
import pytest

from gratnet import codes
from gratnet.codes import (
    DEFERRED_WEIGHTS,
    RENDER_PATHS,
    TABLES,
    WEIGHT_FORMS,
    WEIGHTS_PATHS,
    Kernel,
    Precision,
    WeightForm,
    WeightSource,
    glsl_defines,
    glsl_source,
)
from gratnet.errors import GratNetError
from gratnet.lights import DIRECTIONAL, LIGHT_KINDS, POINT, chosen_kind, light_kind
from tests.helpers import REPO

SHADERS = REPO / "shaders"
#: The runtime's Python (what the tables serve). trainer/ and bench/ keep copies of their own for now (issue 45's
#: report names them); the table modules themselves are exempt.
PYTHON_FOLDERS = ("gratnet", "viewer", "mitsuba_plugin")
TABLE_MODULES = ("gratnet/codes.py", "gratnet/lights.py")
_DEFINE = re.compile(r"^\s*#\s*define\s+([A-Za-z_]\w*)\s+\(?(-?\d+)\)?\s*$", re.MULTILINE)
_INCLUDES_CODES = re.compile(r'^\s*#\s*include\s+"codes\.glsl"', re.MULTILINE)
_PREFIXES = "|".join(table.prefix for table in TABLES)
_PREFIXED = re.compile(rf"\b(?:{_PREFIXES})_[A-Z0-9][A-Z0-9_]*\b")
_TYPED = re.compile(rf"^\s*(?:#\s*define|const\s+u?int)\s+((?:{_PREFIXES})_\w+|\w+_BINDING)\b", re.MULTILINE)
_LITERAL_BINDING = re.compile(r"\bbinding\s*=\s*\d")
_LITERAL_GROUP = re.compile(r"\blocal_size_[xyz]\s*=\s*\d")


def _strip_comments(text: str) -> str:
    text = re.sub(r"/\*.*?\*/", " ", text, flags=re.DOTALL)
    return re.sub(r"//[^\n]*", "", text)


def parse_defines(text: str) -> dict[str, int]:
    """``#define NAME integer`` lines of a GLSL text."""
    return {name: int(value) for name, value in _DEFINE.findall(text)}


def define_problems(text: str) -> list[str]:
    """Where the defines of a generated ``codes.glsl`` text disagree with the Python tables."""
    found = parse_defines(text)
    expected = dict(glsl_defines())
    for table in TABLES:
        for name in table.names:
            expected[table.define(name)] = table.code(name)
    problems = [f"{name}: GLSL {found.get(name)}, Python {value}" for name, value in expected.items()
                if found.get(name) != value]
    problems += [f"{name}: defined in GLSL only" for name in found if name not in expected]
    return problems


def shader_problems(folder: Path) -> list[str]:
    """Codes typed in the shaders of ``folder`` instead of taken from codes.glsl (see the module docstring)."""
    generated = glsl_defines()
    uniforms = "|".join(table.uniform for table in TABLES if table.uniform)
    compared = re.compile(rf"\b(?:{uniforms})\s*(?:[=!<>]=|[<>])\s*-?\d|-?\d\s*(?:[=!<>]=|[<>])\s*(?:{uniforms})\b")
    problems = []
    for path in sorted(folder.glob("*.glsl")):
        text = path.read_text(encoding="utf-8")
        code = _strip_comments(text)
        for name in _TYPED.findall(code):
            problems.append(f"{path.name}: types {name} (gratnet/codes.py defines it)")
        for pattern, what in ((_LITERAL_BINDING, "a binding as a number"), (_LITERAL_GROUP, "a work-group size as a "
                              "number"), (compared, "a code uniform compared with a number")):
            problems += [f"{path.name}: {what}: {match.group(0)!r}" for match in pattern.finditer(code)]
        used = set(_PREFIXED.findall(code)) | {name for name in generated if re.search(rf"\b{name}\b", code)}
        problems += [f"{path.name}: {name} is no generated code" for name in sorted(used) if name not in generated]
        if used and not _INCLUDES_CODES.search(text):
            problems.append(f"{path.name}: uses {', '.join(sorted(used))} without #include \"codes.glsl\"")
    return problems


def _strings(node: ast.AST) -> list[str]:
    return [item.value for item in getattr(node, "elts", getattr(node, "keys", [])) or []
            if isinstance(item, ast.Constant) and isinstance(item.value, str)]


def python_problems(root: Path, folders: tuple[str, ...] = PYTHON_FOLDERS,
                    exempt: tuple[str, ...] = TABLE_MODULES) -> list[str]:
    """Tables typed again in the Python of ``folders`` under ``root`` (see the module docstring)."""
    tables = {f"codes.{table.prefix}": (set(table.names), 2) for table in TABLES}  # (names, how many make a copy)
    choices = {"DEFERRED_WEIGHTS": DEFERRED_WEIGHTS, "RENDER_PATHS": RENDER_PATHS, "WEIGHTS_PATHS": WEIGHTS_PATHS}
    tables.update({f"codes.{name}": (set(names), len(names)) for name, names in choices.items()})
    generated = set(glsl_defines())
    uniforms = {table.uniform for table in TABLES if table.uniform}
    pieces = {name[:end] for name in DEFERRED_WEIGHTS for end in range(3, len(name))}
    pieces |= {name[start:] for name in DEFERRED_WEIGHTS for start in range(1, len(name) - 2)}
    problems = []
    for folder in folders:
        for path in sorted((root / folder).rglob("*.py")):
            where = path.relative_to(root).as_posix()
            if where in exempt:
                continue
            for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), filename=where)):
                line = f"{where}:{getattr(node, 'lineno', 0)}"
                if isinstance(node, (ast.Tuple, ast.List, ast.Set, ast.Dict)):
                    strings = set(_strings(node))
                    for table, (names, copy) in tables.items():
                        if len(strings & names) >= copy:
                            problems.append(f"{line}: types {table} again: {sorted(strings & names)}")
                    if isinstance(node, ast.Dict):
                        problems += [f"{line}: defines {key} (gratnet/codes.py does)" for key in strings & generated]
                if not isinstance(node, ast.Call):
                    continue
                method = node.func.attr if isinstance(node.func, ast.Attribute) else ""
                first = node.args[0] if node.args else None
                if method in ("bind_to_storage_buffer", "bind_to_image") and isinstance(first, ast.Constant):
                    problems.append(f"{line}: {method}({first.value!r}): a binding as a number")
                problems += [f"{line}: defines {keyword.arg} (gratnet/codes.py does)" for keyword in node.keywords
                             if keyword.arg in generated]
                if method in ("startswith", "endswith") and first is not None:
                    cut = {value for value in [getattr(first, "value", None), *_strings(first)] if value in pieces}
                    problems += [f"{line}: {method}({value!r}) takes a weight form apart (gratnet.codes.WeightForm)"
                                 for value in sorted(cut)]
                if (method == "set_uniform" or getattr(node.func, "id", "") == "set_uniform") and len(node.args) >= 3:
                    name, value = node.args[1], node.args[2]
                    if isinstance(name, ast.Constant) and name.value in uniforms and isinstance(value, ast.Constant):
                        problems.append(f"{line}: {name.value} set to the number {value.value!r}")
    return problems


# ----------------------------------------------------------------------------------------------
# The checks on this repository


def test_the_generated_defines_are_the_python_tables():
    assert define_problems(glsl_source()) == []
    for table in TABLES:
        assert [table.code(name) for name in table.names] == list(range(len(table.names)))
        assert len({table.define(name) for name in table.names}) == len(table.names)
    assert glsl_defines()["COUNTER_COUNT"] >= len(codes.COUNTER.names)
    from viewer.glsl import CODES_SOURCE

    assert CODES_SOURCE.text == glsl_source()


def test_resampling_fits_the_shader_loop():
    """shaders/environment.glsl's candidate loop stops at MAX_CANDIDATES but divides by u_candidates: more
    candidates than the loop holds would bias every pass."""
    from gratnet.importance import RESAMPLING_CANDIDATES, RESAMPLING_MATERIAL_CANDIDATES

    assert 1 <= RESAMPLING_CANDIDATES <= glsl_defines()["MAX_CANDIDATES"]
    assert 0 < RESAMPLING_MATERIAL_CANDIDATES < RESAMPLING_CANDIDATES  # both strategies draw some


def test_the_shaders_type_no_code_of_their_own():
    assert shader_problems(SHADERS) == []


def test_every_code_uniform_is_declared_and_every_activation_is_what_mlp_glsl_computes():
    sources = {path.name: _strip_comments(path.read_text(encoding="utf-8")) for path in SHADERS.glob("*.glsl")}
    text = "\n".join(sources.values())
    for table in TABLES:
        if table.uniform:
            assert re.search(rf"\buniform\s+int\s+{table.uniform}\s*(\[\w+\])?\s*;", text), table.uniform
    for table in (codes.HIDDEN, codes.OUTPUT):
        for name in table.names:
            assert f"return {table.expression(name)};" in sources["mlp.glsl"], name
    lights = sources["lights.glsl"]
    for kind in LIGHT_KINDS[1:]:  # the default kind is the last branch, the others are compared
        assert re.search(rf"u_light_kind\s*==\s*{codes.LIGHT.define(kind.name)}\b", lights), kind.name


def test_no_runtime_python_types_a_table_again():
    assert python_problems(REPO) == []


def test_every_program_gets_the_codes_once_before_its_own_text():
    from viewer.glsl import CODES_SOURCE, preprocess

    defines = {"MAX_BLOCKS": 4, "MAX_LAYERS": 2, "MAX_FREQUENCIES": 2, "LEAKY_RELU_SLOPE": 0.01}
    for name, stage, extra in (("surface", "fragment", {"GBUFFER": 1}), ("surface", "fragment", {}),
                               ("brdf_slice", "fragment", {}), ("evaluate_keys", "fragment", {}),
                               ("deferred", "compute", {"RESOLVE": 1}), ("deferred", "compute", {"SHADE": 1})):
        text = preprocess(name, stage, {**defines, **extra}).text
        assert text.count(CODES_SOURCE.text.splitlines()[-1]) == 1, name
        first_line_of_the_program = text.index("\n#line 100001 1\n")
        assert text.index("#define SCHEME_REGULAR") < first_line_of_the_program, name
    with pytest.raises(GratNetError, match="WEIGHTS_BINDING is a shared code"):
        preprocess("deferred", "compute", {**defines, "WEIGHTS_BINDING": 6})


# ----------------------------------------------------------------------------------------------
# The light registry


def test_the_light_registry_gives_codes_flags_and_config_fields():
    from viewer.scene_config import SceneConfig

    assert codes.LIGHT.names == tuple(kind.name for kind in LIGHT_KINDS)
    assert [kind.code for kind in LIGHT_KINDS] == [codes.LIGHT.code(kind.name) for kind in LIGHT_KINDS]
    assert LIGHT_KINDS[0] is DIRECTIONAL and DIRECTIONAL.flag is None  # the default kind: --light θ,φ
    fields = {field.name for field in dataclasses.fields(SceneConfig)}
    flags = [kind.flag for kind in LIGHT_KINDS if kind.flag is not None]
    assert all(flag.field in fields for flag in flags)
    assert len({flag.flag for flag in flags}) == len({flag.dest for flag in flags}) == len(flags)
    with pytest.raises(GratNetError, match="light kind must be directional or point, got 'area'"):
        light_kind("area")


def test_lights_come_from_the_registry_in_every_reader():
    from mitsuba_plugin.scene import emitters
    from viewer.camera import Light
    from viewer.scene_config import RenderConfig, add_scene_arguments, scene_fields

    parser = argparse.ArgumentParser()
    add_scene_arguments(parser, lights={POINT.name: "a point light"})
    arguments = parser.parse_args(["--light", "30,0", "--camera", "0.2,-90,45", "--point-light", "0,0.1,0.2"])
    config = dataclasses.replace(RenderConfig(), **scene_fields(arguments))
    assert config.point_light == (0.0, 0.1, 0.2) and chosen_kind(config) is POINT
    light = Light.from_config(config, 2.0)
    assert (light.kind, light.vector, light.intensity) == ("point", (0.0, 0.1, 0.2), 2.0)
    assert POINT.uniforms(light.vector, light.intensity) == {"u_light_kind": 1, "u_light": (0.0, 0.1, 0.2),
                                                             "u_light_intensity": 2.0}
    direction, irradiance = light.towards((0.0, 0.0, 0.0))
    assert np.allclose(direction, np.array([0.0, 0.1, 0.2]) / np.sqrt(0.05)) and irradiance == pytest.approx(40.0)
    assert emitters(light)["light"] == {"type": "point", "position": [0.0, 0.1, 0.2],
                                        "intensity": {"type": "rgb", "value": [2.0] * 3}}
    directional = Light.from_config(dataclasses.replace(config, point_light=None))
    assert directional == Light.directional(30.0, 0.0) and chosen_kind(RenderConfig()) is DIRECTIONAL
    assert emitters(directional)["light"]["type"] == "directional"
    assert DIRECTIONAL.uniforms(directional.vector, 1.0)["u_light_kind"] == 0


# ----------------------------------------------------------------------------------------------
# Weight forms


def test_weight_forms_are_parsed_once_into_typed_fields():
    from viewer import deferred, scene_config

    assert scene_config.DEFERRED_WEIGHTS is DEFERRED_WEIGHTS is deferred.DEFERRED_WEIGHTS
    assert DEFERRED_WEIGHTS == ("auto", "texture", "ssbo", "shared", "baked", "ssbo-fp16", "shared-fp16", "tiled",
                                "tiled-fp16", "tiled-half")  # the flag's and saved configs' strings, unchanged
    assert all(WeightForm.parse(form.name) is form for form in WEIGHT_FORMS)
    half = WeightForm.parse("tiled-half")
    assert (half.kernel, half.source, half.storage, half.arithmetic) == (Kernel.TILED, WeightSource.BUFFER,
                                                                        Precision.FLOAT16, Precision.FLOAT16)
    shared = WeightForm.parse("shared-fp16")
    assert (shared.kernel, shared.source, shared.storage, shared.texel_bytes, shared.buffer) == (
        Kernel.ENTRY, WeightSource.SHARED, Precision.FLOAT16, 8, True)
    assert not WeightForm.parse("baked").buffer and WeightForm.reading(WeightSource.BUFFER).name == "ssbo"
    assert deferred.TILED_WEIGHTS == ("tiled", "tiled-fp16", "tiled-half")
    assert scene_config.RenderConfig(deferred_weights="ssbo-fp16").weight_form is WeightForm.parse("ssbo-fp16")
    with pytest.raises(GratNetError, match="deferred weights must be one of auto, texture.*got 'cache'"):
        WeightForm.parse("cache")


# ----------------------------------------------------------------------------------------------
# The checkers fail on broken copies


def test_a_define_that_disagrees_with_python_is_found():
    broken = glsl_source().replace("#define SCHEME_SIMPLE 1\n", "#define SCHEME_SIMPLE 3\n")
    assert define_problems(broken) == ["SCHEME_SIMPLE: GLSL 3, Python 1"]
    assert define_problems(broken + "#define LIGHT_AREA 2\n")[-1] == "LIGHT_AREA: defined in GLSL only"


def test_the_shader_checker_finds_codes_typed_in_a_broken_copy(tmp_path):
    shutil.copytree(SHADERS, tmp_path / "shaders")
    folder = tmp_path / "shaders"

    def spoil(name: str, old: str, new: str) -> None:
        text = (folder / name).read_text(encoding="utf-8")
        assert old in text
        (folder / name).write_text(text.replace(old, new, 1), encoding="utf-8")

    spoil("encoding.glsl", "const float PI", "const int SCHEME_REGULAR = 0;\nconst float PI")
    spoil("deferred.glsl", "binding = DEFERRED_LIST_BINDING", "binding = 7")
    spoil("range.glsl", '#include "codes.glsl"', "")
    spoil("lights.glsl", "u_light_kind == LIGHT_POINT", "u_light_kind == 1")
    spoil("mlp.glsl", "HIDDEN_LEAKY_RELU", "HIDDEN_LEAKY")
    spoil("counters.glsl", "#ifdef COUNT_EVALUATIONS", "#define COUNTER_EXTRA 5\n#ifdef COUNT_EVALUATIONS")
    problems = "\n".join(shader_problems(folder))
    for expected in ("encoding.glsl: types SCHEME_REGULAR", "deferred.glsl: a binding as a number: 'binding = 7'",
                     'range.glsl: uses RANGE_LOG1P, RANGE_POWER_LOG without #include "codes.glsl"',
                     "lights.glsl: a code uniform compared with a number: 'u_light_kind == 1'",
                     "mlp.glsl: HIDDEN_LEAKY is no generated code", "counters.glsl: types COUNTER_EXTRA"):
        assert expected in problems
    assert len(shader_problems(folder)) == 7  # and counters.glsl's COUNTER_EXTRA is no generated code


def test_the_python_checker_finds_tables_typed_in_a_broken_copy(tmp_path):
    (tmp_path / "viewer").mkdir()
    (tmp_path / "viewer" / "broken.py").write_text(
        '_SCHEMES = {"regular": 0, "simple": 1, "simple-max": 2}\n'
        'KINDS = ("directional", "point")\n'
        'PATHS = ["auto", "forward", "deferred"]\n'
        "def bind(buffer, weights, program, defines):\n"
        "    buffer.bind_to_storage_buffer(5)\n"
        "    defines.update(SKIP_COUNTER_BINDING=5)\n"
        '    defines = {"DEFERRED_LIST_BINDING": 7}\n'
        '    set_uniform(program, "u_scheme", 2)\n'
        '    return weights.endswith("-fp16") or weights.startswith(("shared", ".tmp"))\n', encoding="utf-8")
    problems = python_problems(tmp_path, ("viewer",), ())
    assert problems == [
        "viewer/broken.py:1: types codes.SCHEME again: ['regular', 'simple', 'simple-max']",
        "viewer/broken.py:2: types codes.LIGHT again: ['directional', 'point']",
        "viewer/broken.py:3: types codes.RENDER_PATHS again: ['auto', 'deferred', 'forward']",
        "viewer/broken.py:5: bind_to_storage_buffer(5): a binding as a number",
        "viewer/broken.py:6: defines SKIP_COUNTER_BINDING (gratnet/codes.py does)",
        "viewer/broken.py:7: defines DEFERRED_LIST_BINDING (gratnet/codes.py does)",
        "viewer/broken.py:8: u_scheme set to the number 2",
        "viewer/broken.py:9: endswith('-fp16') takes a weight form apart (gratnet.codes.WeightForm)",
        "viewer/broken.py:9: startswith('shared') takes a weight form apart (gratnet.codes.WeightForm)",
    ]


def test_the_trainers_scheme_literal_and_activation_names_are_the_tables():
    """The typing Literal of trainer.sampling spells the scheme names for type checkers: it must be the table's."""
    import typing

    from gratnet.codes import HIDDEN, OUTPUT, SCHEME
    from trainer.model import ACTIVATIONS, OUTPUT_ACTIVATIONS
    from trainer.sampling import SCHEMES, Scheme

    assert typing.get_args(Scheme) == SCHEME.names == SCHEMES
    assert sorted(ACTIVATIONS) == sorted(HIDDEN.names) and OUTPUT_ACTIVATIONS == OUTPUT.names
