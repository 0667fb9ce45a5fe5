"""Running a sweep on Ray: the task graph, its progress, and the results at the end.

Per dataset: one ground-truth task (or, with ``parts`` > 1, a preparation task, one task per wavelength block
and an assembling task that adds them), then one task per evaluation BRDF slice (filling the shared cache);
per run: one training + evaluation task that depends on its dataset's tasks through their object refs, so
each volume is computed once and Ray starts a run as soon as its volume is written. Finished volumes and
runs are skipped; interrupted trainings resume from their checkpoints (sweep/tasks.py).

Ray is imported here only, when a sweep runs: every other command works without it.
"""

from __future__ import annotations

import dataclasses
import json
import os
import sys
from pathlib import Path
from typing import Any

from gratnet.atomic import make_folder, write_text_atomic
from gratnet.errors import GratNetError
from sweep import tasks
from sweep.spec import SweepSpec

MISSING_RAY = "gratnet sweep needs Ray, which is not installed: pip install 'gratnet[sweep]' (or 'ray>=2.9')"


def import_ray() -> Any:
    """The ``ray`` module, or one GratNetError saying how to install it."""
    try:
        import ray
    except ImportError:
        raise GratNetError(MISSING_RAY) from None
    return ray


@dataclasses.dataclass
class Plan:
    """What a sweep has left to do, from the state of its results folder."""

    volumes: dict[str, str]  # dataset name -> "done" | "todo"
    runs: dict[str, str]  # run name -> "done" | "resume" | "todo"

    def summary(self) -> str:
        def count(states: dict[str, str], state: str) -> int:
            return sum(value == state for value in states.values())

        return (f"{len(self.volumes)} volumes ({count(self.volumes, 'done')} done), {len(self.runs)} runs "
                f"({count(self.runs, 'done')} done, {count(self.runs, 'resume')} to resume, "
                f"{count(self.runs, 'todo')} to start)")


def plan_sweep(spec: SweepSpec) -> Plan:
    """The state of every volume and run; a folder holding another configuration's output is refused."""
    out = spec.out
    volumes = {dataset.name: tasks.volume_state(out, dataset) for dataset in spec.datasets}
    runs = {run.name: tasks.run_state(out, run) for run in spec.runs}
    for kind, states, where in (("volume", volumes, "volumes/NAME.config.json"), ("run", runs, "runs/NAME/run.json")):
        conflicts = [name for name, state in states.items() if state == "conflict"]
        if conflicts:
            raise GratNetError(f"{out} holds a {kind} {conflicts[0]!r} made with a different configuration "
                               f"({where}); use another --out or delete it")
    return Plan(volumes, runs)


def _submit(ray: Any, spec: SweepSpec, plan: Plan, out: Path) -> dict[Any, str]:
    """Submit every task that is left; returns their refs with a label each."""
    resources = spec.resources
    gt_options: dict[str, Any] = {"num_cpus": resources.groundtruth_cpus}
    gt_device = None  # numpy on the task's CPUs, unless the ground truth asks for GPUs: then CUDA (torch)
    if resources.groundtruth_gpus > 0:
        gt_options["num_gpus"] = resources.groundtruth_gpus
        gt_device = "cuda"
    train_options: dict[str, Any] = {"num_cpus": resources.train_cpus, "num_gpus": resources.train_gpus}
    for options, gigabytes in ((gt_options, resources.groundtruth_memory_gb),
                               (train_options, resources.train_memory_gb)):
        if gigabytes > 0:
            options["memory"] = int(gigabytes * 2**30)
    labels: dict[Any, str] = {}
    remote: dict[Any, Any] = {}  # one Ray remote function per task function

    def task(function: Any, label: str, options: dict[str, Any], *arguments: Any) -> Any:
        if function not in remote:
            remote[function] = ray.remote(function)
        ref = remote[function].options(name=label, **options).remote(*arguments)
        labels[ref] = label
        return ref

    pending_runs = [run for run in spec.runs if plan.runs[run.name] != "done"]
    needed = {run.dataset.name for run in pending_runs}
    dependencies: dict[str, list[Any]] = {}
    for dataset in spec.datasets:
        if dataset.name not in needed and plan.volumes[dataset.name] == "done":
            continue
        name = dataset.name
        if plan.volumes[name] == "done":
            metadata = task(tasks.read_volume_metadata, f"{name}: read volume", {"num_cpus": 1}, out, dataset)
        elif dataset.parts == 1:
            metadata = task(tasks.ground_truth, f"{name}: ground truth", gt_options, out, dataset, gt_device)
        else:
            surface = task(tasks.prepare, f"{name}: prepare surface", gt_options, dataset)
            parts = [task(tasks.volume_part, f"{name}: λ block {block + 1}/{dataset.parts}", gt_options, dataset,
                          surface, block, gt_device) for block in range(dataset.parts)]
            metadata = task(tasks.assemble_volume, f"{name}: assemble volume", {"num_cpus": 1}, out, dataset,
                            surface, *parts)
        dependencies[name] = [metadata]
        evaluate = spec.runs[0].evaluate
        if evaluate.brdf_slices and name in needed:
            from trainer.evaluate import STANDARD_SLICES

            dependencies[name] += [task(tasks.evaluation_slice, f"{name}: BRDF slice {index + 1}", gt_options,
                                        dataset, metadata, evaluate, index, gt_device)
                                   for index in range(len(STANDARD_SLICES))]
    threads = max(1, int(resources.train_cpus))
    for run in pending_runs:
        task(tasks.train_run, f"run {run.name}", train_options, out, run, threads, *dependencies[run.dataset.name])
    return labels


def _cause(error: BaseException) -> str:
    """The first line of a task's own error (a GratNetError's message, or the exception's type and text)."""
    cause = getattr(error, "cause", None) or error
    text = str(cause) if isinstance(cause, GratNetError) else f"{type(cause).__name__}: {cause}"
    return text.strip().splitlines()[0] if text.strip() else type(cause).__name__


def run_sweep(spec: SweepSpec, address: str | None = None, workers: int | None = None, progress: bool = True,
              ) -> tuple[list[dict[str, Any]], list[str]]:
    """Run what is left of ``spec`` on Ray; write the results table and plot. Returns (rows, failures).

    ``address`` joins a running cluster (``ray start --head`` prints it; "auto" finds a local one); without it a
    local Ray instance with ``workers`` CPUs (default: all) is started and shut down afterwards.
    """
    from tqdm.auto import tqdm

    ray = import_ray()
    plan = plan_sweep(spec)
    out = make_folder(spec.out).resolve()
    write_text_atomic(out / "sweep.config.json", json.dumps(spec.to_dict(), indent=1) + "\n")
    if progress:
        print(f"gratnet sweep: {plan.summary()}", file=sys.stderr)
    nothing_left = all(state == "done" for state in plan.runs.values())
    owned = not ray.is_initialized() and not nothing_left
    if owned:
        options: dict[str, Any] = {"include_dashboard": False, "log_to_driver": False, "configure_logging": False}
        if address:
            options["address"] = address
        else:
            options["num_cpus"] = workers or os.cpu_count() or 1
            # A private instance reports no usage statistics (and tries no network beyond loopback for them).
            os.environ.setdefault("RAY_USAGE_STATS_ENABLED", "0")
            # Workers of a local instance import gratnet, trainer and sweep from where the driver does.
            root = str(Path(__file__).resolve().parents[1])
            path = os.pathsep.join(filter(None, [root, os.environ.get("PYTHONPATH")]))
            options["runtime_env"] = {"env_vars": {"PYTHONPATH": path}}
        try:
            ray.init(**options)
        except ConnectionError as error:
            raise GratNetError(f"cannot join the Ray cluster at {address}: {error}") from None
    failures: list[str] = []
    try:
        labels = {} if nothing_left else _submit(ray, spec, plan, out)
        bar = tqdm(total=len(labels), desc="sweep", unit="task", disable=not progress, dynamic_ncols=True)
        pending = list(labels)
        causes: set[str] = set()
        repeated = 0
        with bar:
            while pending:
                ready, pending = ray.wait(pending, num_returns=1)
                for ref in ready:
                    try:
                        ray.get(ref)
                    except Exception as error:  # a task's failure; its dependants raise the same error
                        cause = _cause(error)
                        if cause in causes:
                            repeated += 1
                        else:
                            causes.add(cause)
                            failures.append(f"{labels[ref]}: {cause}")
                    bar.update(1)
                    bar.set_postfix_str(labels[ref][:60])
        if repeated:
            failures.append(f"{repeated} more tasks failed with one of these errors (or depended on a failed task)")
    finally:
        if owned:
            ray.shutdown()
    rows = collect_rows(spec)
    if rows:
        from sweep.results import write_results

        write_results(rows, spec.out)
    if spec.bench is not None and rows:
        run_bench(spec, rows, progress)
    return rows, failures


def collect_rows(spec: SweepSpec) -> list[dict[str, Any]]:
    """The table rows of every finished run of ``spec``, in the sweep's order."""
    rows = []
    for run in spec.runs:
        if tasks.run_state(spec.out, run) == "done":
            rows.append(json.loads((tasks.run_folder(spec.out, run) / tasks.RESULT_FILE).read_text())["row"])
    return rows


def run_bench(spec: SweepSpec, rows: list[dict[str, Any]], progress: bool) -> None:
    """``gratnet bench``'s measurement (shader frame time vs error) of every finished model, in OUT/bench."""
    from bench.slices import ModelEntry, write_outputs
    from bench.slices import run_bench as measure
    from viewer.context import create_headless_context

    entries = [ModelEntry.load(Path(row["model"]), row["run"]) for row in rows]
    ctx = create_headless_context()
    try:
        results = measure(ctx, entries, spec.bench, progress=progress)
    finally:
        ctx.release()
    write_outputs(results, spec.out / "bench")
