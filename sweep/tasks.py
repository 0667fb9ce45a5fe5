"""The work of a sweep as plain functions (no Ray here): each is one task on a worker.

They call the project's own functions, exactly as ``gratnet groundtruth`` and ``gratnet train`` do
(trainer/groundtruth_cli.py, trainer/train_cli.py), and write into the results folder OUT:

    OUT/volumes/NAME.exr (+ NAME.config.json)   one volume per dataset, shared by its runs
    OUT/cache/brdf_*.npy                        ground-truth BRDF slices of the evaluation, shared
    OUT/runs/RUN/                               model.npz, checkpoint.pt, history.json, metrics.json, report.md,
                                                run.json (the run's spec, written first), result.json (its table
                                                row, written last: the run is finished)

Every file is written atomically, so an interrupted sweep leaves whole files or none; a training resumes
from its last checkpoint (trainer.train's own ``resume``).
"""

from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Any

from gratnet.atomic import write_text_atomic
from gratnet.config import config_path_for, save_config
from gratnet.errors import GratNetError
from sweep.spec import DatasetSpec, RunSpec

RESULT_FILE = "result.json"
SPEC_FILE = "run.json"


def volume_path(out: Path, dataset: DatasetSpec) -> Path:
    """Where the dataset's volume lives in the results folder."""
    return out / "volumes" / f"{dataset.name}.exr"


def run_folder(out: Path, run: RunSpec) -> Path:
    """The run's output folder."""
    return out / "runs" / run.name


def _recorded(path: Path, key: str) -> Any:
    """The entry ``key`` of a JSON file, or None when the file is missing or unreadable."""
    try:
        return json.loads(path.read_text(encoding="utf-8")).get(key)
    except (OSError, ValueError, AttributeError):
        return None


def volume_state(out: Path, dataset: DatasetSpec) -> str:
    """"done" (volume and its record present and matching), "todo", or "conflict" (made differently)."""
    path = volume_path(out, dataset)
    recorded = _recorded(config_path_for(path), "dataset")
    if recorded is None:
        return "todo"
    if recorded != json.loads(json.dumps(dataset.to_dict())):
        return "conflict"
    return "done" if path.is_file() else "todo"


def run_state(out: Path, run: RunSpec) -> str:
    """"done" (result.json present), "resume" (a checkpoint), "todo", or "conflict" (another spec's folder)."""
    folder = run_folder(out, run)
    recorded = _recorded(folder / SPEC_FILE, "spec")
    if recorded is None:
        return "todo"
    if recorded != json.loads(json.dumps(run.to_dict())):
        return "conflict"
    if (folder / RESULT_FILE).is_file():
        return "done"
    return "resume" if (folder / "checkpoint.pt").is_file() else "todo"


def load_field(dataset: DatasetSpec) -> Any:
    """The dataset's height field (a file, or the generator with its overrides)."""
    from trainer.loaders import load_heightfield

    return load_heightfield(dataset.heightfield_spec(), dataset.load)


def prepare(dataset: DatasetSpec) -> Any:
    """The prepared surface (resampled, repeated, windowed) that every wavelength block shares."""
    from trainer.fourier import prepare_surface

    return prepare_surface(load_field(dataset), dataset.optics)


def volume_part(dataset: DatasetSpec, surface: Any, block: int, device: str | None = None
                ) -> tuple[Any, int, float]:
    """Block ``block`` of ``dataset.parts``: the float64 XYZ sum over its wavelengths, the node count, and
    the seconds it took. ``device``: as :class:`trainer.fourier.FTerm`'s (None: numpy)."""
    from trainer.groundtruth import compute_volume_part, wavelength_blocks

    started = time.perf_counter()
    wavelengths = wavelength_blocks(dataset.optics, dataset.parts)[block]
    xyz, nodes = compute_volume_part(surface, dataset.volume, dataset.optics, wavelengths, device=device)
    return xyz, nodes, time.perf_counter() - started


def _write_volume(out: Path, dataset: DatasetSpec, volume: Any, seconds: float) -> dict[str, Any]:
    from gratnet.volume import write_volume

    volume.metadata["compute_seconds"] = round(seconds, 3)
    volume.metadata["wavelength_blocks"] = dataset.parts
    path = volume_path(out, dataset)
    write_volume(path, volume)
    save_config(path, dataset=dataset.to_dict(), volume=dataset.volume, optics=dataset.optics, load=dataset.load)
    return dict(volume.metadata)


def assemble_volume(out: Path, dataset: DatasetSpec, surface: Any, *parts: tuple[Any, int, float]
                    ) -> dict[str, Any]:
    """Add the wavelength blocks' sums (in block order) and write the volume; returns its metadata (its
    ``compute_seconds``: the blocks' seconds added, as if computed one after another)."""
    from trainer.groundtruth import volume_from_sum

    total = parts[0][0].copy()
    for xyz, _, _ in parts[1:]:
        total += xyz
    volume = volume_from_sum(load_field(dataset), dataset.volume, dataset.optics, surface, total, parts[0][1])
    return _write_volume(out, dataset, volume, sum(part[2] for part in parts))


def ground_truth(out: Path, dataset: DatasetSpec, device: str | None = None) -> dict[str, Any]:
    """The whole volume in one task (``gratnet groundtruth``'s call); returns its metadata."""
    from trainer.groundtruth import compute_volume

    started = time.perf_counter()
    volume = compute_volume(load_field(dataset), dataset.volume, dataset.optics, progress=False, device=device)
    return _write_volume(out, dataset, volume, time.perf_counter() - started)


def read_volume_metadata(out: Path, dataset: DatasetSpec) -> dict[str, Any]:
    """The metadata of a volume finished by an earlier sweep."""
    from gratnet.volume import read_volume

    return dict(read_volume(volume_path(out, dataset)).metadata)


def evaluation_slice(dataset: DatasetSpec, metadata: dict[str, Any], evaluate: Any, index: int,
                     device: str | None = None) -> None:
    """Fill the evaluation cache with ground-truth BRDF slice ``index`` (trainer.evaluate.STANDARD_SLICES),
    with the optics the evaluation will read back from the volume, so that no run computes it again."""
    from trainer.brdfslice import SliceConfig
    from trainer.evaluate import STANDARD_SLICES, ground_truth_brdf_slice
    from trainer.fourier import OpticsConfig

    theta, phi, exposure = STANDARD_SLICES[index]
    config = SliceConfig(theta, phi, size=evaluate.size, exposure=exposure, ior=evaluate.ior)
    ground_truth_brdf_slice(load_field(dataset), OpticsConfig.from_volume_metadata(metadata), config,
                            evaluate.cache_dir, progress=False, device=device)


def train_run(out: Path, run: RunSpec, threads: int, *dependencies: Any) -> dict[str, Any]:
    """Train (resuming from a checkpoint) and evaluate one run, as ``gratnet train --resume`` does; returns its
    table row. ``dependencies`` are the results of the tasks it waits for (volume, BRDF-slice cache)."""
    import dataclasses

    import torch

    from gratnet.volume import read_volume
    from trainer.evaluate import evaluate_model
    from trainer.fourier import OpticsConfig
    from trainer.train import train

    del dependencies  # only ordering: Ray starts this task once they are done
    torch.set_num_threads(max(1, threads))
    folder = run_folder(out, run)
    write_text_atomic(folder / SPEC_FILE, json.dumps({"spec": run.to_dict()}, indent=1) + "\n")
    started = time.perf_counter()
    path = volume_path(out, run.dataset)
    volume = read_volume(path)
    _, model_file, history = train(volume, run.train, folder, resume=True, progress=False)
    save_config(folder / "model.npz", train=run.train, volume=str(path))
    field = optics = None
    if run.evaluate.brdf_slices:
        field, optics = load_field(run.dataset), OpticsConfig.from_volume_metadata(volume.metadata)
    held_out = ([int(part) for part in run.train.test_slices.split(",") if part.strip()]
                if run.train.split == "slices" else [])
    evaluate_model(model_file, folder, dataclasses.replace(run.evaluate, progress=False), volume=volume, field=field,
                   optics=optics, volume_slices=held_out,
                   extra={"training": {k: v for k, v in history.items() if k != "epochs"}})
    row = result_row(run, folder)
    row["run_seconds"] = round(time.perf_counter() - started, 2)
    write_text_atomic(folder / RESULT_FILE, json.dumps({"spec": run.to_dict(), "row": row}, indent=1) + "\n")
    return row


def result_row(run: RunSpec, folder: Path) -> dict[str, Any]:
    """The run's line of the results table: size, cost and error, read as ``gratnet bench`` reads them."""
    import statistics

    from bench.slices import ModelEntry

    if not (folder / "model.npz").is_file():
        raise GratNetError(f"{folder} has no model.npz")
    entry = ModelEntry.load(folder / "model.npz", run.name)
    history = json.loads((folder / "history.json").read_text(encoding="utf-8"))
    metrics = json.loads((folder / "metrics.json").read_text(encoding="utf-8"))
    epochs = history.get("epochs", [])
    volume_rows = metrics.get("volume_slices", [])
    return {
        "run": run.name, "dataset": run.dataset.name, "preset": run.preset, "variant": run.variant,
        "seed": run.seed, "layer_sizes": list(entry.model.layer_sizes), "parameters": entry.model.parameter_count,
        "macs_per_pixel": entry.model.macs_per_evaluation, "train_samples": history.get("train_samples"),
        "epochs": len(epochs), "train_seconds": history.get("train_seconds"),
        "train_loss": epochs[-1].get("train_loss") if epochs else None,
        "held_out_loss": epochs[-1].get("held_out_loss") if epochs else None,
        "held_out_psnr_db": (statistics.fmean(float(row["psnr_xyz"]) for row in volume_rows)
                             if volume_rows else None),
        "flip_mean": entry.flip_mean, "flip_0_0": entry.flip_normal, "psnr_mean_db": entry.psnr_mean,
        "model": str(folder / "model.npz"),
    }
