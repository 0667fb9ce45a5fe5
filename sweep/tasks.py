"""The work of a sweep as plain functions (no Ray here): each is one task on a worker.

They call the project's own functions, exactly as ``gratnet groundtruth`` and ``gratnet train`` do
(trainer/groundtruth_cli.py, trainer/train_cli.py), and write into the results folder OUT:

    OUT/volumes/NAME.exr (+ NAME.config.json)   one volume per dataset, shared by its runs
    OUT/volumes/NAME.parts/block-K.{npy,json}   a split volume's wavelength blocks (float64 sums), until the
                                                volume is assembled
    OUT/cache/brdf_*.npy                        ground-truth BRDF slices of the evaluation, shared
    OUT/runs/RUN/                               model.npz, checkpoint.pt, history.json, metrics.json, report.md,
                                                run.json (the run's spec, written first), result.json (its table
                                                row, written last: the run is finished)
    OUT/records/KEY/*.json                      one record per attempt of each task (sweep/records.py)

Every task is idempotent: it first looks for its output, and when it is there (finished by an earlier attempt
or sweep) returns it without computing (its record says "found"). Every file is written atomically, so a task
killed at any moment leaves whole files or none, and Ray can run it again (a retry after its worker or node
died) or a rerun of the sweep can: a training resumes from its last checkpoint (trainer.train's own
``resume``), a split volume keeps its finished blocks. Tasks return small values only (metadata, a block's
node count, a table row): the large arrays go through the results folder, so no task's result lives only in
the memory of a node that may die.
"""

from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Any

from gratnet.atomic import atomic_path, atomic_paths, write_text_atomic
from gratnet.config import config_path_for, config_text, nested_dict, save_config
from gratnet.errors import GratNetError
from sweep.records import attempt
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
    if isinstance(recorded, dict) and isinstance(recorded.get("train"), dict):
        from trainer.train_config import TrainConfig

        # Recorded before the grid options were nested (flat grid_* keys): the same run.
        recorded = {**recorded, "train": nested_dict(TrainConfig, recorded["train"])}
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
    """The prepared surface (resampled, repeated, windowed) that every wavelength block shares (deterministic:
    each block's task and the assembling task prepare it alike)."""
    from trainer.fourier import prepare_surface

    return prepare_surface(load_field(dataset), dataset.optics)


def parts_folder(out: Path, dataset: DatasetSpec) -> Path:
    """Where a split volume's finished wavelength blocks wait for the assembling task."""
    return out / "volumes" / f"{dataset.name}.parts"


def _block_files(out: Path, dataset: DatasetSpec, block: int) -> tuple[Path, Path]:
    folder = parts_folder(out, dataset)
    return folder / f"block-{block}.npy", folder / f"block-{block}.json"


def _block_record(dataset: DatasetSpec, block: int) -> dict[str, Any]:
    return json.loads(json.dumps({"dataset": dataset.to_dict(), "block": block, "parts": dataset.parts}))


def _finished_block(out: Path, dataset: DatasetSpec, block: int) -> dict[str, Any] | None:
    """The record of block ``block`` when its sum is on disk for this very dataset and split, else None."""
    array, record = _block_files(out, dataset, block)
    try:
        written = json.loads(record.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    if not isinstance(written, dict) or written.get("block") != _block_record(dataset, block) or not array.is_file():
        return None
    return written


def volume_part(dataset: DatasetSpec, surface: Any, block: int, device: str | None = None
                ) -> tuple[Any, int, float]:
    """Block ``block`` of ``dataset.parts``: the float64 XYZ sum over its wavelengths, the node count, and
    the seconds it took. ``device``: as :class:`trainer.fourier.FTerm`'s (None: numpy)."""
    from trainer.groundtruth import compute_volume_part, wavelength_blocks

    started = time.perf_counter()
    wavelengths = wavelength_blocks(dataset.optics, dataset.parts)[block]
    xyz, nodes = compute_volume_part(surface, dataset.volume, dataset.optics, wavelengths, device=device)
    return xyz, nodes, time.perf_counter() - started


def volume_block(out: Path, dataset: DatasetSpec, block: int, device: str | None = None) -> dict[str, Any]:
    """The task of block ``block``: :func:`volume_part` written to OUT/volumes/NAME.parts/block-K.npy with its
    record (node count, seconds) beside it, which is returned. A block already on disk, or a volume already
    assembled, is not computed again."""
    import numpy as np

    label = f"{dataset.name}: λ block {block + 1}/{dataset.parts}"
    with attempt(out, f"volume-{dataset.name}-block-{block + 1}-of-{dataset.parts}", label) as record:
        if volume_state(out, dataset) == "done":
            record["outcome"] = "found"
            return {"block": block, "assembled": True}
        finished = _finished_block(out, dataset, block)
        if finished is not None:
            record["outcome"] = "found"
            return finished
        xyz, nodes, seconds = volume_part(dataset, prepare(dataset), block, device)
        array, record_file = _block_files(out, dataset, block)
        with atomic_path(array) as temporary:
            np.save(temporary, xyz)
        written = {"block": _block_record(dataset, block), "nodes": int(nodes), "seconds": round(seconds, 3)}
        write_text_atomic(record_file, json.dumps(written, indent=1) + "\n")  # last: the block is finished
        return written


def _write_volume(out: Path, dataset: DatasetSpec, volume: Any, seconds: float) -> dict[str, Any]:
    """The volume and its config, landing together (the config says the volume is this dataset's)."""
    from gratnet.volume import write_volume

    volume.metadata["compute_seconds"] = round(seconds, 3)
    volume.metadata["wavelength_blocks"] = dataset.parts
    path = volume_path(out, dataset)
    config = config_text(path, dataset=dataset.to_dict(), volume=dataset.volume, optics=dataset.optics,
                         load=dataset.load)
    with atomic_paths(path, config_path_for(path)) as (volume_file, config_file):
        write_volume(volume_file, volume)
        config_file.write_text(config, encoding="utf-8")
    return dict(volume.metadata)


def assemble_volume(out: Path, dataset: DatasetSpec, *parts: dict[str, Any]) -> dict[str, Any]:
    """Add the wavelength blocks' sums (read from OUT/volumes/NAME.parts, in block order), write the volume and
    remove the blocks; returns its metadata (its ``compute_seconds``: the blocks' seconds added, as if computed
    one after another). ``parts``: the blocks' tasks' results (only ordering: Ray starts this task after them)."""
    import shutil

    import numpy as np

    from trainer.groundtruth import volume_from_sum

    del parts
    with attempt(out, f"volume-{dataset.name}", f"{dataset.name}: assemble volume") as record:
        if volume_state(out, dataset) == "done":  # (blocks left by a kill after the volume was written: removed)
            record["outcome"] = "found"
            shutil.rmtree(parts_folder(out, dataset), ignore_errors=True)
            return read_volume_metadata(out, dataset)
        found = [_finished_block(out, dataset, block) for block in range(dataset.parts)]
        blocks = [block for block in found if block is not None]
        if len(blocks) < dataset.parts:
            missing = [index + 1 for index, block in enumerate(found) if block is None]
            raise GratNetError(f"{parts_folder(out, dataset)} lacks wavelength blocks {missing} of {dataset.parts}")
        total = np.load(_block_files(out, dataset, 0)[0])
        for block in range(1, dataset.parts):
            total += np.load(_block_files(out, dataset, block)[0])
        volume = volume_from_sum(load_field(dataset), dataset.volume, dataset.optics, prepare(dataset), total,
                                 blocks[0]["nodes"])
        metadata = _write_volume(out, dataset, volume, sum(block["seconds"] for block in blocks))
        shutil.rmtree(parts_folder(out, dataset), ignore_errors=True)
        return metadata


def ground_truth(out: Path, dataset: DatasetSpec, device: str | None = None) -> dict[str, Any]:
    """The whole volume in one task (``gratnet groundtruth``'s call); returns its metadata (a volume already
    written is read, not computed again)."""
    from trainer.groundtruth import compute_volume

    with attempt(out, f"volume-{dataset.name}", f"{dataset.name}: ground truth") as record:
        if volume_state(out, dataset) == "done":
            record["outcome"] = "found"
            return read_volume_metadata(out, dataset)
        started = time.perf_counter()
        volume = compute_volume(load_field(dataset), dataset.volume, dataset.optics, progress=False, device=device)
        return _write_volume(out, dataset, volume, time.perf_counter() - started)


def read_volume_metadata(out: Path, dataset: DatasetSpec) -> dict[str, Any]:
    """The metadata of a finished volume."""
    from gratnet.volume import read_volume

    return dict(read_volume(volume_path(out, dataset)).metadata)


def _slice_config(metadata: dict[str, Any], evaluate: Any, index: int) -> tuple[Any, Any]:
    from trainer.brdfslice import SliceConfig
    from trainer.evaluate import STANDARD_SLICES
    from trainer.fourier import OpticsConfig

    theta, phi, exposure = STANDARD_SLICES[index]
    return (SliceConfig(theta, phi, size=evaluate.size, exposure=exposure, ior=evaluate.ior),
            OpticsConfig.from_volume_metadata(metadata))


def evaluation_slice(out: Path, dataset: DatasetSpec, metadata: dict[str, Any], evaluate: Any, index: int,
                     device: str | None = None) -> None:
    """Fill the evaluation cache with ground-truth BRDF slice ``index`` (trainer.evaluate.STANDARD_SLICES),
    with the optics the evaluation will read back from the volume, so that no run computes it again."""
    from trainer.evaluate import brdf_cache_file, ground_truth_brdf_slice

    with attempt(out, f"slice-{dataset.name}-{index + 1}", f"{dataset.name}: BRDF slice {index + 1}") as record:
        config, optics = _slice_config(metadata, evaluate, index)
        field = load_field(dataset)
        if brdf_cache_file(field, optics, config, evaluate.cache_dir).is_file():
            record["outcome"] = "found"
            return
        ground_truth_brdf_slice(field, optics, config, evaluate.cache_dir, progress=False, device=device)


def train_run(out: Path, run: RunSpec, threads: int, *dependencies: Any) -> dict[str, Any]:
    """Train (resuming from a checkpoint) and evaluate one run, as ``gratnet train --resume`` does; returns its
    table row (a run already finished: its recorded row). ``dependencies`` are the results of the tasks it
    waits for (volume, BRDF-slice cache)."""
    import dataclasses

    import torch

    from gratnet.volume import read_volume
    from trainer.evaluate import evaluate_model
    from trainer.fourier import OpticsConfig
    from trainer.train import read_checkpoint, train

    del dependencies  # only ordering: Ray starts this task once they are done
    folder = run_folder(out, run)
    with attempt(out, f"run-{run.name}", f"run {run.name}") as record:
        if run_state(out, run) == "done":
            record["outcome"] = "found"
            return json.loads((folder / RESULT_FILE).read_text(encoding="utf-8"))["row"]
        torch.set_num_threads(max(1, threads))
        write_text_atomic(folder / SPEC_FILE, json.dumps({"spec": run.to_dict()}, indent=1) + "\n")
        if (folder / "checkpoint.pt").is_file():
            record["resumed_from_epoch"] = int(read_checkpoint(folder / "checkpoint.pt")["epoch"])
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
        evaluate_model(model_file, folder, dataclasses.replace(run.evaluate, progress=False), volume=volume,
                       field=field, optics=optics, volume_slices=held_out, model_path=folder / "model.npz",
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
