"""The sweep file (TOML): a declarative grid of datasets × presets × seeds × training variants.

Everything is checked here, before Ray starts or any work is done, by the same checks as the subcommands'
flags (the configs' own, and the command line's limits of numbers, volumes and optics): unknown tables and
keys, wrong types, refused values, unknown generators, presets and generator parameters, missing height-field
files each give one GratNetError that starts with the file's path and names the table and key, e.g.
``sweep.toml: [evaluate] size must be from 2 to 4096 pixels (typical: 256), got 0`` (the CLI prints one line
and exits 2). The resolved grid is a list of :class:`DatasetSpec`
(one ground-truth volume each) and :class:`RunSpec` (one training + evaluation each); their
``to_dict()`` is what the results folder records to recognise finished and interrupted work.

    presets = ["tiny", "small"]          # network sizes (trainer/model.py PRESETS)
    seeds = [0, 1]
    out = "out/sweep"                    # results folder, from the current folder (the CLI's --out wins)

    [groundtruth]                        # VolumeConfig + OpticsConfig fields, for every dataset
    resolution = 257
    wavelength_step_nm = 10.0
    parts = 1                            # wavelength blocks per volume, computed as separate tasks

    [train]                              # TrainConfig options as the flags name them (grid_levels for
    epochs = 4                           # --grid-levels; not preset, seed): every run
    [evaluate]                           # EvaluateConfig fields (size, ior, brdf_slices)
    size = 128
    [resources]                          # per task: CPUs, GPUs (fractions share one GPU), memory
    train_gpus = 0.25
    groundtruth_gpus = 0.5               # ground truth on CUDA (seconds per 1001² volume on an H100)
    groundtruth_memory_gb = 3

    [[datasets]]
    generator = "blazed"                 # a built-in generator …
    params = { period_um = 2.5 }         # … with parameter overrides
    [[datasets]]
    name = "scan"
    file = "scans/patch.gsf"             # … or a height-field file (relative to the sweep file's folder)
    load = { dx_um = 0.1 }               # LoadOptions for the file
    groundtruth = { resolution = 513, parts = 4 }   # per-dataset ground-truth overrides

    [[variants]]                         # training-option axis (default: one variant, "base")
    name = "long"
    epochs = 12

    [bench]                              # optional: gratnet bench's frame-time measurement of every model
    sizes = "512"
"""

from __future__ import annotations

import argparse
import dataclasses
import functools
import json
import math
import re
import sys
import types
import typing
from collections.abc import Callable
from pathlib import Path
from typing import Any, Literal, get_args, get_origin

from gratnet.errors import GratNetError

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - Python 3.10
    import tomli as tomllib

_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9_.+-]*")


@dataclasses.dataclass(frozen=True)
class Resources:
    """Ray resources asked for by each task (a fractional GPU lets several small trainings share one)."""

    groundtruth_cpus: float = 1.0  # also the BLAS threads of its products (Ray sets OMP_NUM_THREADS)
    groundtruth_memory_gb: float = 0.0  # memory reserved per ground-truth task (GiB; 0: none)
    groundtruth_gpus: float = 0.0  # > 0: ground-truth tasks ask Ray for GPUs and run on CUDA (groundtruth --device)
    train_cpus: float = 1.0  # also its torch threads
    train_gpus: float = 0.0  # a fraction lets several trainings share one GPU (CUDA then, as device auto picks)
    train_memory_gb: float = 0.0  # memory reserved per training task (GiB; 0: none)

    def __post_init__(self) -> None:
        for field in dataclasses.fields(self):
            value = getattr(self, field.name)
            if not (math.isfinite(value) and value >= 0):
                raise GratNetError(f"[resources] {field.name} must be a number ≥ 0, got {value!r}")
        if self.groundtruth_cpus <= 0 or self.train_cpus <= 0:
            raise GratNetError("[resources] groundtruth_cpus and train_cpus must be > 0")


@dataclasses.dataclass(frozen=True)
class DatasetSpec:
    """One height field and the ground truth computed from it (one volume, shared by its runs)."""

    name: str
    generator: str | None  # a built-in generator name, or None for a file
    params: dict[str, Any]  # generator parameter overrides
    file: str | None  # a height-field file (absolute path) when not a generator
    load: Any  # trainer.heightfile.LoadOptions
    volume: Any  # trainer.groundtruth.VolumeConfig
    optics: Any  # trainer.fourier.OpticsConfig
    parts: int  # wavelength blocks (tasks) the volume is split into

    def heightfield_spec(self) -> str:
        """What trainer.loaders.load_heightfield reads: a file path or ``generator:NAME(k=v, …)``."""
        if self.file is not None:
            return self.file
        arguments = ", ".join(f"{key}={value!r}" for key, value in sorted(self.params.items()))
        return f"generator:{self.generator}({arguments})"

    def to_dict(self) -> dict[str, Any]:
        """The resolved dataset (what makes its volume), JSON-ready."""
        from gratnet.config import config_to_dict

        return {"name": self.name, "heightfield": self.heightfield_spec(), "load": config_to_dict(self.load),
                "volume": config_to_dict(self.volume), "optics": config_to_dict(self.optics)}


@dataclasses.dataclass(frozen=True)
class RunSpec:
    """One training + evaluation: a dataset's volume, a preset, a training variant and a seed."""

    dataset: DatasetSpec
    preset: str
    variant: str
    seed: int
    train: Any  # trainer.train_config.TrainConfig (preset and seed included)
    evaluate: Any  # trainer.evaluate.EvaluateConfig (cache_dir set to the sweep's)

    @property
    def name(self) -> str:
        """The run's folder name under OUT/runs/ (and its label in the table)."""
        return f"{self.dataset.name}-{self.preset}-{self.variant}-s{self.seed}"

    def to_dict(self) -> dict[str, Any]:
        """The resolved run, JSON-ready (the evaluation cache folder left out: moving OUT keeps it valid)."""
        from gratnet.config import config_to_dict

        evaluate = {key: value for key, value in config_to_dict(self.evaluate).items()
                    if key not in ("cache_dir", "progress", "frame_time")}
        return {"name": self.name, "dataset": self.dataset.to_dict(), "preset": self.preset,
                "variant": self.variant, "seed": self.seed, "train": config_to_dict(self.train),
                "evaluate": evaluate}


@dataclasses.dataclass(frozen=True)
class SweepSpec:
    """The resolved sweep: its datasets, runs, resources and results folder."""

    source: str
    out: Path
    datasets: list[DatasetSpec]
    runs: list[RunSpec]
    resources: Resources
    bench: Any  # bench.slices.BenchConfig, or None: no frame-time benchmark at the end
    document: dict[str, Any]  # the TOML as read

    def to_dict(self) -> dict[str, Any]:
        """The resolved config saved beside the outputs (sweep.config.json)."""
        from gratnet.config import config_to_dict

        return {"source": self.source, "out": str(self.out), "resources": config_to_dict(self.resources),
                "bench": config_to_dict(self.bench) if self.bench is not None else None,
                "datasets": [dataset.to_dict() for dataset in self.datasets],
                "runs": [run.to_dict() for run in self.runs], "document": self.document}


@dataclasses.dataclass(frozen=True)
class Table:
    """A table of the sweep file as its reader names it in messages: ``[train]``, ``[[datasets]] #2 groundtruth``
    (an inline table of the second ``[[datasets]]`` entry), or the top level (no header)."""

    header: str = ""
    path: str = ""

    def key(self, name: str) -> str:
        """How the file names key ``name`` of this table: ``[train] epochs``, ``[[datasets]] #2 groundtruth.res``."""
        inner = f"{self.path}.{name}" if self.path else name
        return f"{self.header} {inner}" if self.header else inner

    def inner(self, path: str) -> Table:
        """The inline table ``path`` of this table."""
        return Table(self.header, path)

    def __str__(self) -> str:
        return " ".join(filter(None, (self.header, self.path))) or "the top level"


SHARED_GROUNDTRUTH = Table("[groundtruth]")
TRAIN = Table("[train]")


@functools.cache
def _flag_fields(config_class: type) -> dict[str, str]:
    """Command-line flag → field name of ``config_class``, as ``gratnet.config.add_arguments`` makes the flags."""
    from gratnet.config import add_arguments

    actions = add_arguments(argparse.ArgumentParser(add_help=False), config_class)
    return {flag: field for field, action in actions.items() for flag in action.option_strings}


def in_toml_words(message: str, config_class: type, name_of: Callable[[str], str], table: Table) -> str:
    """A config's own check ``message`` (which names its command-line flags) reworded for the sweep file: each
    flag of ``config_class`` replaced by ``name_of(field)`` (e.g. ``--epochs`` → ``[train] epochs``); a message
    that names no flag is prefixed with ``table``."""
    flags = _flag_fields(config_class)
    named = False

    def reword(match: re.Match[str]) -> str:
        nonlocal named
        field = flags.get(match.group())
        if field is None:
            return match.group()
        named = True
        return name_of(field)

    text = re.sub(r"--[a-z][a-z0-9-]*", reword, message)
    return text if named or text.startswith(str(table)) else f"{table}: {text}"


def checked(config_class: type, name_of: Callable[[str], str], table: Table, check: Callable[[], Any]) -> Any:
    """``check()``'s result; its GratNetError reworded by :func:`in_toml_words`."""
    try:
        return check()
    except GratNetError as error:
        raise GratNetError(in_toml_words(str(error), config_class, name_of, table)) from None


def _check_value(where: str, value: Any, kind: Any) -> Any:
    """``value`` converted to the dataclass field type ``kind``, or one GratNetError naming ``where``. Numbers get
    the command line's own limits (:func:`gratnet.config.parse_int`, :func:`gratnet.config.parse_float`)."""
    from gratnet.config import parse_float, parse_int

    origin = get_origin(kind)
    if origin is Literal:
        if value not in get_args(kind):
            raise GratNetError(f"{where} must be one of {', '.join(map(repr, get_args(kind)))}; got {value!r}")
        return value
    if origin in (typing.Union, types.UnionType):
        options = [arg for arg in get_args(kind) if arg is not type(None)]
        return _check_value(where, value, options[0])
    if kind is bool:
        if not isinstance(value, bool):
            raise GratNetError(f"{where} must be true or false, got {value!r}")
        return value
    if kind in (int, float):
        if isinstance(value, bool) or not isinstance(value, (int, float)) or (kind is int and isinstance(value, float)):
            raise GratNetError(f"{where} must be {'a whole number' if kind is int else 'a number'}, got {value!r}")
        try:
            return parse_int(str(value)) if kind is int else parse_float(repr(float(value)))
        except argparse.ArgumentTypeError as error:
            raise GratNetError(f"{where} must be a {'whole ' if kind is int else ''}number the command line "
                               f"accepts: {error}") from None
    if kind is str:
        if not isinstance(value, str):
            raise GratNetError(f"{where} must be a string, got {value!r}")
        return value
    return value


def _table(document: dict[str, Any], key: str, table: Table) -> dict[str, Any]:
    """The inline table or table ``key`` of ``document`` (empty when absent)."""
    value = document.get(key, {})
    if not isinstance(value, dict):
        raise GratNetError(f"{table.key(key)} must be a table, got {value!r}")
    return value


def build_config(config_class: type, values: dict[str, Any], table: Table, exclude: tuple[str, ...] = (),
                 base: Any = None, name_of: Callable[[str], str] | None = None) -> Any:
    """``config_class`` from the TOML ``values`` of ``table`` (over ``base``, when given), checked by the class
    itself as the command line is: unknown keys, wrong types and every refused value give one GratNetError that
    names the key (``name_of(field)``: where a field's value came from; default: ``table``)."""
    from gratnet.config import flat_fields

    # Keys are the flags' names (a nested config's fields under its prefix: grid_levels for TrainConfig.grid),
    # which the class's constructor takes (gratnet.config.flat_keywords).
    fields = {name: flat for name, flat in flat_fields(config_class).items()
              if name not in exclude and flat.field.metadata.get("cli") is not False}
    unknown = sorted(set(values) - set(fields))
    if unknown:
        raise GratNetError(f"{table}: unknown key {unknown[0]!r}; known keys: {', '.join(sorted(fields))}")
    values = {key: _check_value(table.key(key), value, fields[key].kind) for key, value in values.items()}
    made = (lambda: dataclasses.replace(base, **values)) if base is not None else (lambda: config_class(**values))
    return checked(config_class, name_of or table.key, table, made)


def _name_list(document: dict[str, Any], key: str, default: list[Any], kind: type) -> list[Any]:
    value = document.get(key, default)
    if not isinstance(value, list) or not value:
        raise GratNetError(f"{key} must be a non-empty list, got {value!r}")
    value = [_check_value(f"{key} entry {item!r}", item, kind) for item in value]
    if len(set(value)) != len(value):
        raise GratNetError(f"{key} lists an entry twice: {value!r}")
    return value


def _split_groundtruth(values: dict[str, Any], table: Table) -> tuple[dict[str, Any], dict[str, Any], int | None]:
    """A ground-truth table split into VolumeConfig fields, OpticsConfig fields and ``parts``."""
    from trainer.fourier import OpticsConfig
    from trainer.groundtruth import VolumeConfig

    volume_fields = {field.name for field in dataclasses.fields(VolumeConfig)}
    optics_fields = {field.name for field in dataclasses.fields(OpticsConfig)}
    unknown = sorted(set(values) - volume_fields - optics_fields - {"parts"})
    if unknown:
        known = ", ".join(sorted(volume_fields | optics_fields | {"parts"}))
        raise GratNetError(f"{table}: unknown key {unknown[0]!r}; known keys: {known}")
    parts = values.get("parts")
    if parts is not None:
        _check_value(table.key("parts"), parts, int)
    return ({k: v for k, v in values.items() if k in volume_fields},
            {k: v for k, v in values.items() if k in optics_fields}, parts)


@dataclasses.dataclass(frozen=True)
class GroundTruth:
    """The ground-truth settings of a table (the shared ``[groundtruth]``, or a dataset's over it), checked."""

    volume: Any  # trainer.groundtruth.VolumeConfig
    optics: Any  # trainer.fourier.OpticsConfig
    parts: int


def _ground_truth(values: dict[str, Any], table: Table, shared: GroundTruth | None = None) -> GroundTruth:
    """``values`` of ground-truth ``table`` over ``shared`` (None: over the defaults), with the command line's
    limits of ``gratnet groundtruth``; each error names the table a value came from."""
    from trainer.cli_support import check_optics_limits, check_volume_limits
    from trainer.fourier import OpticsConfig
    from trainer.groundtruth import VolumeConfig, wavelength_blocks

    volume_values, optics_values, parts = _split_groundtruth(values, table)

    def name_of(field: str) -> str:
        return (table if field in values or shared is None else SHARED_GROUNDTRUTH).key(field)

    volume = build_config(VolumeConfig, volume_values, table, base=shared and shared.volume, name_of=name_of)
    optics = build_config(OpticsConfig, optics_values, table, base=shared and shared.optics, name_of=name_of)
    checked(VolumeConfig, name_of, table, lambda: check_volume_limits(volume))
    checked(OpticsConfig, name_of, table, lambda: check_optics_limits(optics))
    parts = parts if parts is not None else (shared.parts if shared is not None else 1)
    try:
        wavelength_blocks(optics, parts)  # a part count the spectrum cannot hold: refused now
    except GratNetError as error:
        raise GratNetError(f"{name_of('parts')}: {error}") from None
    return GroundTruth(volume, optics, parts)


def _dataset(entry: Any, index: int, shared: GroundTruth, base: Path) -> DatasetSpec:
    from trainer.generators import GENERATORS
    from trainer.heightfile import LoadOptions

    table = Table(f"[[datasets]] #{index + 1}")
    if not isinstance(entry, dict):
        raise GratNetError(f"{table} must be a table, got {entry!r}")
    unknown = sorted(set(entry) - {"name", "generator", "params", "file", "load", "groundtruth"})
    if unknown:
        raise GratNetError(f"{table}: unknown key {unknown[0]!r}; known keys: file, generator, groundtruth, load, "
                           f"name, params")
    generator, file = entry.get("generator"), entry.get("file")
    if (generator is None) == (file is None):
        raise GratNetError(f"{table} needs exactly one of generator = \"NAME\" or file = \"PATH\"")
    params = _table(entry, "params", table)
    if generator is not None:
        _check_value(table.key("generator"), generator, str)
        if generator not in GENERATORS:
            raise GratNetError(f"{table.key('generator')}: unknown generator {generator!r}; built-in generators: "
                               f"{', '.join(GENERATORS)}")
        # The generator's own parameter checks, as `gratnet heightfield generate NAME` makes them.
        build_config(GENERATORS[generator][0], params, table.inner("params"))
        if "load" in entry:
            raise GratNetError(f"{table.key('load')}: load options apply to files only")
        default_name = generator
    else:
        given: str = _check_value(table.key("file"), file, str)
        if params:
            raise GratNetError(f"{table.key('params')}: params apply to generators only (a file has no parameters)")
        path = (base / given).resolve()
        if not path.is_file():
            raise GratNetError(f"{table.key('file')}: height-field file {path} does not exist")
        file = str(path)
        default_name = path.stem
    load = build_config(LoadOptions, _table(entry, "load", table), table.inner("load"))
    name: str = _check_value(table.key("name"), entry.get("name", default_name), str)
    if not _NAME.fullmatch(name):
        raise GratNetError(f"{table.key('name')} {name!r} must be letters, digits and . _ + - (it names folders)")
    own = _ground_truth(_table(entry, "groundtruth", table), table.inner("groundtruth"), shared)
    return DatasetSpec(name, generator, dict(params), file, load, own.volume, own.optics, own.parts)


@dataclasses.dataclass(frozen=True)
class Variant:
    """One entry of the ``[[variants]]`` axis: its name, its TrainConfig (over ``[train]``), and where each of
    its values came from (``name_of(field)``: the entry's key, else ``[train]``'s)."""

    name: str
    train: Any  # trainer.train_config.TrainConfig
    name_of: Callable[[str], str]


def _variants(document: dict[str, Any], base_train: Any) -> list[Variant]:
    """The ``[[variants]]`` axis; by default one variant, "base" (``[train]`` as it is)."""
    from trainer.train_config import TrainConfig

    entries = document.get("variants", [{"name": "base"}])
    if not isinstance(entries, list) or not entries:
        raise GratNetError(f"[[variants]] must be a non-empty list of tables, got {entries!r}")
    variants: list[Variant] = []
    for index, entry in enumerate(entries):
        table = Table(f"[[variants]] #{index + 1}")
        if not isinstance(entry, dict):
            raise GratNetError(f"{table} must be a table, got {entry!r}")
        name = entry.get("name", f"v{index}")
        _check_value(table.key("name"), name, str)
        if not _NAME.fullmatch(name):
            raise GratNetError(f"{table.key('name')} {name!r} must be letters, digits and . _ + -")
        options = {key: value for key, value in entry.items() if key != "name"}

        def name_of(field: str, table: Table = table, options: dict[str, Any] = options) -> str:
            return (table if field in options else TRAIN).key(field)

        train = build_config(TrainConfig, options, table, exclude=("preset", "seed"), base=base_train, name_of=name_of)
        variants.append(Variant(name, train, name_of))
    if len({variant.name for variant in variants}) != len(variants):
        raise GratNetError("[[variants]]: two variants share a name")
    return variants


def _check_axes(base_train: Any, presets: list[str], seeds: list[int]) -> None:
    """Each entry of ``presets`` and ``seeds`` checked by TrainConfig, as ``--preset`` and ``--seed`` are."""
    from trainer.train_config import TrainConfig

    for key, field, values in (("presets", "preset", presets), ("seeds", "seed", seeds)):
        for value in values:
            def name_of(name: str, key: str = key, field: str = field) -> str:
                return f"{key} entry" if name == field else TRAIN.key(name)

            checked(TrainConfig, name_of, TRAIN, functools.partial(dataclasses.replace, base_train, **{field: value}))


def _check_held_out(datasets: list[DatasetSpec], variants: list[Variant]) -> None:
    """Held-out slices beyond a dataset's volume: refused now, not after its ground truth."""
    from trainer.train_config import TrainConfig

    for index, dataset in enumerate(datasets):
        for variant in variants:
            if variant.train.split != "slices":
                continue
            try:
                variant.train.held_out_slices(dataset.volume.slices)
            except GratNetError as error:
                message = in_toml_words(str(error), TrainConfig, variant.name_of, TRAIN)
                raise GratNetError(f"{message} ([[datasets]] #{index + 1}, {dataset.name!r}): hold out fewer "
                                   f"slices, or split = \"all\"") from None


def _bench(document: dict[str, Any]) -> Any:
    """The ``[bench]`` table as a BenchConfig, checked as ``gratnet bench`` checks its flags; None when absent."""
    from bench.slices import BenchConfig
    from gratnet.brdf import check_exposure
    from viewer.catalog import check_mesh_spec

    if "bench" not in document:
        return None
    table = Table("[bench]")
    bench = build_config(BenchConfig, _table(document, "bench", Table()), table)
    checks = (bench.size_list, bench.path_list, bench.scene_size_list, bench.render_path_list, bench.spp_list,
              lambda: check_mesh_spec(bench.scene_mesh), lambda: check_exposure(bench.exposure))
    for check in checks:
        checked(BenchConfig, table.key, table, check)
    return bench


def load_sweep(path: str | Path, out: str | Path | None = None) -> SweepSpec:
    """Read and check the sweep file ``path``; ``out`` overrides its ``out`` key (default ``out/sweep``).

    Every value of every table is checked here, by the configs' own checks (those of the subcommands), before any
    work; an error is one GratNetError that starts with the file's path and names the table and key.
    """
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as error:
        raise GratNetError(f"cannot read the sweep file {path}: {getattr(error, 'strerror', None) or error}") from None
    try:
        document = tomllib.loads(text)
    except tomllib.TOMLDecodeError as error:
        raise GratNetError(f"{path} is not valid TOML: {error}") from None
    try:
        return _resolve(path, document, out)
    except GratNetError as error:
        raise GratNetError(f"{path}: {error}") from None


def _resolve(path: Path, document: dict[str, Any], out: str | Path | None) -> SweepSpec:
    """The checked sweep of the TOML ``document`` read from ``path``."""
    from trainer.evaluate import EvaluateConfig
    from trainer.train_config import TrainConfig

    known = {"out", "presets", "seeds", "groundtruth", "train", "evaluate", "resources", "datasets", "variants",
             "bench"}
    unknown = sorted(set(document) - known)
    if unknown:
        raise GratNetError(f"unknown key {unknown[0]!r}; known keys: {', '.join(sorted(known))}")
    out_value = out if out is not None else document.get("out", "out/sweep")
    if not isinstance(out_value, Path):
        _check_value("out", out_value, str)
    presets = _name_list(document, "presets", ["small"], str)
    seeds = _name_list(document, "seeds", [0], int)

    shared = _ground_truth(_table(document, "groundtruth", Table()), SHARED_GROUNDTRUTH)
    base_train = build_config(TrainConfig, _table(document, "train", Table()), TRAIN, exclude=("preset", "seed"))
    variants = _variants(document, base_train)
    _check_axes(base_train, presets, seeds)
    evaluate = build_config(EvaluateConfig, _table(document, "evaluate", Table()), Table("[evaluate]"),
                            exclude=("cache_dir", "frame_time"))  # runs share the machine: no timing
    resources = build_config(Resources, _table(document, "resources", Table()), Table("[resources]"))
    bench = _bench(document)

    entries = document.get("datasets")
    if not isinstance(entries, list) or not entries:
        raise GratNetError("no [[datasets]]: give at least one generator or file")
    base = path.resolve().parent
    datasets = [_dataset(entry, index, shared, base) for index, entry in enumerate(entries)]
    names = [dataset.name for dataset in datasets]
    if len(set(names)) != len(names):
        raise GratNetError(f"two [[datasets]] share the name {next(n for n in names if names.count(n) > 1)!r}; "
                           f"give them distinct name = \"…\"")
    _check_held_out(datasets, variants)

    out_path = Path(out_value)
    # Absolute: the tasks of a cluster's nodes run in other folders than the driver's.
    evaluate = dataclasses.replace(evaluate, cache_dir=str(out_path.resolve() / "cache"), progress=False)
    runs = [
        RunSpec(dataset, preset, variant.name, seed, dataclasses.replace(variant.train, preset=preset, seed=seed),
                evaluate)
        for dataset in datasets for preset in presets for variant in variants for seed in seeds
    ]
    as_json = json.loads(json.dumps(document, default=str))  # TOML dates as text
    return SweepSpec(str(path), out_path, datasets, runs, resources, bench, as_json)
