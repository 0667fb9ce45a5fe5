"""The sweep file (TOML): a declarative grid of datasets × presets × seeds × training variants.

Everything is checked here, before Ray starts or any work is done: unknown tables and keys, wrong types,
unknown generators, presets and generator parameters, missing height-field files each give one
GratNetError (the CLI prints one line and exits 2). The resolved grid is a list of :class:`DatasetSpec`
(one ground-truth volume each) and :class:`RunSpec` (one training + evaluation each); their
``to_dict()`` is what the results folder records to recognise finished and interrupted work.

    presets = ["tiny", "small"]          # network sizes (trainer/model.py PRESETS)
    seeds = [0, 1]
    out = "out/sweep"                    # results folder, from the current folder (the CLI's --out wins)

    [groundtruth]                        # VolumeConfig + OpticsConfig fields, for every dataset
    resolution = 257
    wavelength_step_nm = 10.0
    parts = 1                            # wavelength blocks per volume, computed as separate tasks

    [train]                              # TrainConfig fields (not preset, seed): every run
    epochs = 4
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

import dataclasses
import json
import math
import re
import sys
import typing
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
                    if key not in ("cache_dir", "progress")}
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


def _check_value(where: str, value: Any, kind: Any) -> Any:
    """``value`` converted to the dataclass field type ``kind``, or one GratNetError naming ``where``."""
    origin = get_origin(kind)
    if origin is Literal:
        if value not in get_args(kind):
            raise GratNetError(f"{where} must be one of {', '.join(map(repr, get_args(kind)))}; got {value!r}")
        return value
    if origin in (typing.Union, getattr(__import__("types"), "UnionType", None)):
        options = [arg for arg in get_args(kind) if arg is not type(None)]
        return _check_value(where, value, options[0])
    if kind is bool:
        if not isinstance(value, bool):
            raise GratNetError(f"{where} must be true or false, got {value!r}")
        return value
    if kind is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise GratNetError(f"{where} must be a whole number, got {value!r}")
        return value
    if kind is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            raise GratNetError(f"{where} must be a finite number, got {value!r}")
        return float(value)
    if kind is str:
        if not isinstance(value, str):
            raise GratNetError(f"{where} must be a string, got {value!r}")
        return value
    return value


def _table(document: dict[str, Any], key: str, where: str) -> dict[str, Any]:
    value = document.get(key, {})
    if not isinstance(value, dict):
        raise GratNetError(f"{where}{key} must be a table, got {value!r}")
    return value


def build_config(config_class: type, values: dict[str, Any], where: str, exclude: tuple[str, ...] = (),
                 base: Any = None) -> Any:
    """``config_class`` from a TOML table: unknown keys and wrong types refused, one line naming ``where``."""
    hints = typing.get_type_hints(config_class)
    fields = {field.name for field in dataclasses.fields(config_class)
              if field.init and field.name not in exclude and field.metadata.get("cli") is not False}
    unknown = sorted(set(values) - fields)
    if unknown:
        raise GratNetError(f"{where}: unknown key {unknown[0]!r}; known keys: {', '.join(sorted(fields))}")
    checked = {key: _check_value(f"{where}.{key}", value, hints[key]) for key, value in values.items()}
    if base is not None:
        return dataclasses.replace(base, **checked)
    return config_class(**checked)


def _name_list(document: dict[str, Any], key: str, default: list[Any], kind: type) -> list[Any]:
    value = document.get(key, default)
    if not isinstance(value, list) or not value:
        raise GratNetError(f"{key} must be a non-empty list, got {value!r}")
    for item in value:
        _check_value(f"{key} entry", item, kind)
    if len(set(value)) != len(value):
        raise GratNetError(f"{key} lists an entry twice: {value!r}")
    return value


def _split_groundtruth(values: dict[str, Any], where: str) -> tuple[dict[str, Any], dict[str, Any], int | None]:
    """A [groundtruth] table split into VolumeConfig fields, OpticsConfig fields and ``parts``."""
    from trainer.fourier import OpticsConfig
    from trainer.groundtruth import VolumeConfig

    volume_fields = {field.name for field in dataclasses.fields(VolumeConfig)}
    optics_fields = {field.name for field in dataclasses.fields(OpticsConfig)}
    unknown = sorted(set(values) - volume_fields - optics_fields - {"parts"})
    if unknown:
        known = ", ".join(sorted(volume_fields | optics_fields | {"parts"}))
        raise GratNetError(f"{where}: unknown key {unknown[0]!r}; known keys: {known}")
    parts = values.get("parts")
    if parts is not None:
        _check_value(f"{where}.parts", parts, int)
    return ({k: v for k, v in values.items() if k in volume_fields},
            {k: v for k, v in values.items() if k in optics_fields}, parts)


def _dataset(entry: Any, index: int, shared: dict[str, Any], base: Path) -> DatasetSpec:
    from trainer.fourier import OpticsConfig
    from trainer.generators import GENERATORS, parameters_for
    from trainer.groundtruth import VolumeConfig, wavelength_blocks
    from trainer.heightfile import LoadOptions

    where = f"datasets[{index}]"
    if not isinstance(entry, dict):
        raise GratNetError(f"{where} must be a table, got {entry!r}")
    unknown = sorted(set(entry) - {"name", "generator", "params", "file", "load", "groundtruth"})
    if unknown:
        raise GratNetError(f"{where}: unknown key {unknown[0]!r}; known keys: file, generator, groundtruth, load, "
                           f"name, params")
    generator, file = entry.get("generator"), entry.get("file")
    if (generator is None) == (file is None):
        raise GratNetError(f"{where} needs exactly one of generator = \"NAME\" or file = \"PATH\"")
    params = _table(entry, "params", f"{where}.")
    if generator is not None:
        _check_value(f"{where}.generator", generator, str)
        if generator not in GENERATORS:
            raise GratNetError(f"{where}: unknown generator {generator!r}; built-in generators: "
                               f"{', '.join(GENERATORS)}")
        parameters_for(generator, **params)  # unknown or out-of-range parameters: refused now
        if "load" in entry:
            raise GratNetError(f"{where}: load options apply to files only")
    else:
        _check_value(f"{where}.file", file, str)
        if params:
            raise GratNetError(f"{where}: params apply to generators only (a file has no parameters)")
        path = (base / file).resolve()
        if not path.is_file():
            raise GratNetError(f"{where}: height-field file {path} does not exist")
        file = str(path)
    load = build_config(LoadOptions, _table(entry, "load", f"{where}."), f"{where}.load")
    name = entry.get("name", generator if generator is not None else Path(file).stem)
    _check_value(f"{where}.name", name, str)
    if not _NAME.fullmatch(name):
        raise GratNetError(f"{where}: name {name!r} must be letters, digits and . _ + - (it names folders)")
    volume_values, optics_values, parts = _split_groundtruth(shared, "[groundtruth]")
    own_volume, own_optics, own_parts = _split_groundtruth(_table(entry, "groundtruth", f"{where}."),
                                                           f"{where}.groundtruth")
    volume = build_config(VolumeConfig, {**volume_values, **own_volume}, f"{where} ground truth")
    optics = build_config(OpticsConfig, {**optics_values, **own_optics}, f"{where} ground truth")
    parts = own_parts if own_parts is not None else (parts if parts is not None else 1)
    wavelength_blocks(optics, parts)  # a part count the spectrum cannot hold: refused now
    return DatasetSpec(name, generator, dict(params), file, load, volume, optics, parts)


def load_sweep(path: str | Path, out: str | Path | None = None) -> SweepSpec:
    """Read and check the sweep file ``path``; ``out`` overrides its ``out`` key (default ``out/sweep``)."""
    from bench.slices import BenchConfig
    from trainer.evaluate import EvaluateConfig
    from trainer.model import PRESETS
    from trainer.train_config import TrainConfig

    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as error:
        raise GratNetError(f"cannot read the sweep file {path}: {getattr(error, 'strerror', None) or error}") from None
    try:
        document = tomllib.loads(text)
    except tomllib.TOMLDecodeError as error:
        raise GratNetError(f"{path} is not valid TOML: {error}") from None
    known = {"out", "presets", "seeds", "groundtruth", "train", "evaluate", "resources", "datasets", "variants",
             "bench"}
    unknown = sorted(set(document) - known)
    if unknown:
        raise GratNetError(f"{path}: unknown key {unknown[0]!r}; known keys: {', '.join(sorted(known))}")
    base = path.resolve().parent
    out_value = out if out is not None else document.get("out", "out/sweep")
    _check_value("out", out_value, str) if not isinstance(out_value, Path) else None

    presets = _name_list(document, "presets", ["small"], str)
    for preset in presets:
        if preset not in PRESETS:
            raise GratNetError(f"unknown preset {preset!r}; choose from {', '.join(PRESETS)}")
    seeds = _name_list(document, "seeds", [0], int)
    if min(seeds) < 0:
        raise GratNetError(f"seeds must be ≥ 0, got {seeds!r}")

    shared_groundtruth = _table(document, "groundtruth", "")
    _split_groundtruth(shared_groundtruth, "[groundtruth]")
    entries = document.get("datasets")
    if not isinstance(entries, list) or not entries:
        raise GratNetError(f"{path}: no [[datasets]]: give at least one generator or file")
    datasets = [_dataset(entry, index, shared_groundtruth, base) for index, entry in enumerate(entries)]
    names = [dataset.name for dataset in datasets]
    if len(set(names)) != len(names):
        raise GratNetError(f"two datasets share the name {next(n for n in names if names.count(n) > 1)!r}; "
                           f"give them distinct name = \"…\"")

    out_path = Path(out_value)
    base_train = build_config(TrainConfig, _table(document, "train", ""), "[train]", exclude=("preset", "seed"))
    evaluate = build_config(EvaluateConfig, _table(document, "evaluate", ""), "[evaluate]", exclude=("cache_dir",))
    evaluate = dataclasses.replace(evaluate, cache_dir=str(out_path / "cache"), progress=False)
    variants_value = document.get("variants", [{"name": "base"}])
    if not isinstance(variants_value, list) or not variants_value:
        raise GratNetError(f"variants must be a non-empty list of tables, got {variants_value!r}")
    variants: list[tuple[str, Any]] = []
    for index, entry in enumerate(variants_value):
        if not isinstance(entry, dict):
            raise GratNetError(f"variants[{index}] must be a table, got {entry!r}")
        name = entry.get("name", f"v{index}")
        _check_value(f"variants[{index}].name", name, str)
        if not _NAME.fullmatch(name):
            raise GratNetError(f"variants[{index}]: name {name!r} must be letters, digits and . _ + -")
        options = {key: value for key, value in entry.items() if key != "name"}
        variants.append((name, build_config(TrainConfig, options, f"variants[{index}]", exclude=("preset", "seed"),
                                            base=base_train)))
    if len({name for name, _ in variants}) != len(variants):
        raise GratNetError("two variants share a name")
    runs = [
        RunSpec(dataset, preset, variant, seed, dataclasses.replace(train, preset=preset, seed=seed), evaluate)
        for dataset in datasets for preset in presets for variant, train in variants for seed in seeds
    ]
    for run in runs:
        if run.train.split == "slices":  # held-out slices beyond the volume: refused now, not after ground truth
            slices = run.dataset.volume.slices
            try:
                held_out = [int(part) for part in run.train.test_slices.split(",") if part.strip()]
            except ValueError:
                raise GratNetError(f"test_slices must be comma-separated integers, got {run.train.test_slices!r}") \
                    from None
            if not held_out or min(held_out) < 0 or max(held_out) >= slices:
                raise GratNetError(f"run {run.name}: test_slices {run.train.test_slices!r} out of range for "
                                   f"{slices} slices (set [train] test_slices or split = \"all\")")
    resources = build_config(Resources, _table(document, "resources", ""), "[resources]")
    bench = None
    if "bench" in document:
        bench = build_config(BenchConfig, _table(document, "bench", ""), "[bench]")
        bench.size_list(), bench.path_list()
    as_json = json.loads(json.dumps(document, default=str))  # TOML dates as text
    return SweepSpec(str(path), out_path, datasets, runs, resources, bench, as_json)
