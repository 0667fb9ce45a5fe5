"""Running a sweep on Ray: the task graph, its progress, and the results at the end.

Per dataset: one ground-truth task (or, with ``parts`` > 1, one task per wavelength block and an assembling
task that adds them), then one task per evaluation BRDF slice (filling the shared cache); per run: one
training + evaluation task that depends on its dataset's tasks through their object refs, so each volume is
computed once and Ray starts a run as soon as its volume is written. Finished volumes and runs are skipped;
interrupted trainings resume from their checkpoints (sweep/tasks.py).

Faults (docs/robustness.md):

- a worker or a node that dies: Ray runs its task again elsewhere (``max_retries``, :data:`MAX_RETRIES`;
  exceptions raised by a task are not retried). Tasks are idempotent and write atomically, and pass only small
  values to each other (the arrays go through the results folder), so a retry finds what was finished and a
  finished output is not computed again (OUT/records, sweep/records.py);
- the sweep itself: Ctrl-C, SIGTERM and SIGHUP end it within a second (exit 130, or 128 + the signal). A
  local Ray instance has a watchdog (sweep/watchdog.py) that removes every process of it (SIGKILL) when the
  sweep ends, however: after ``ray.shutdown()`` at a normal end; after a stop, once the driver has only
  disconnected (Ray's shutdown of its processes gives each up to 1 s, one after another: 1–3 s); and when the
  sweep itself is killed with SIGKILL. A stopped sweep's instance thus ends as a killed one's does, which
  leaves nothing half-written (atomic writes). The same command then continues: finished volumes, blocks,
  slices and runs are kept, trainings resume from their checkpoints.

Ray is imported here only, when a sweep runs: every other command works without it.
"""

from __future__ import annotations

import contextlib
import dataclasses
import json
import os
import signal
import sys
import threading
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

from gratnet.atomic import make_folder, write_text_atomic
from gratnet.errors import GratNetError
from sweep import tasks, watchdog
from sweep.records import NODE_VARIABLE
from sweep.spec import SweepSpec

MISSING_RAY = "gratnet sweep needs Ray, which is not installed: pip install 'gratnet[sweep]' (or 'ray>=2.9')"
#: Times Ray runs a task again after its worker process or its node died (Ray's own default, said here).
MAX_RETRIES = 3
#: Seconds of each ``ray.wait`` call: Python's SIGINT handler runs between two calls (inside one, Ray checks
#: for signals only once a second), so Ctrl-C is raised within about this.
WAIT_SECONDS = 0.1


class Stopped(KeyboardInterrupt):
    """SIGTERM or SIGHUP received by the sweep, raised as Ctrl-C's KeyboardInterrupt is (the same cleanup)."""

    def __init__(self, signum: int) -> None:
        super().__init__(signal.Signals(signum).name)
        self.signum = signum


@contextlib.contextmanager
def signals_stop_the_sweep() -> Iterator[None]:
    """While the sweep runs, SIGTERM and SIGHUP raise :class:`Stopped` in the main thread."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    received: list[int] = []

    def stop(signum: int, _frame: object) -> None:
        received.append(signum)
        raise Stopped(signum)

    previous = {number: signal.signal(number, stop) for number in (signal.SIGTERM, signal.SIGHUP)}
    try:
        yield
    except KeyboardInterrupt as error:  # ray.wait turns an exception raised in a handler into a plain one
        if received and not isinstance(error, Stopped):
            raise Stopped(received[0]) from None
        raise
    finally:
        for number, handler in previous.items():
            signal.signal(number, handler)


def on_node(function: Callable[..., Any], *arguments: Any) -> Any:
    """A task as Ray runs it: ``function(*arguments)``, with the Ray node's id in the environment for the task's
    record (sweep/records.py)."""
    import ray

    os.environ[NODE_VARIABLE] = ray.get_runtime_context().get_node_id()
    return function(*arguments)


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
    remote = ray.remote(on_node)

    def task(function: Any, label: str, options: dict[str, Any], *arguments: Any) -> Any:
        ref = remote.options(name=label, max_retries=MAX_RETRIES, retry_exceptions=False,
                             **options).remote(function, *arguments)
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
            parts = [task(tasks.volume_block, f"{name}: λ block {block + 1}/{dataset.parts}", gt_options, out,
                          dataset, block, gt_device) for block in range(dataset.parts)]
            metadata = task(tasks.assemble_volume, f"{name}: assemble volume", {"num_cpus": 1}, out, dataset,
                            *parts)
        dependencies[name] = [metadata]
        evaluate = spec.runs[0].evaluate
        if evaluate.brdf_slices and name in needed:
            from trainer.evaluate import STANDARD_SLICES

            dependencies[name] += [task(tasks.evaluation_slice, f"{name}: BRDF slice {index + 1}", gt_options,
                                        out, dataset, metadata, evaluate, index, gt_device)
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


def _init(ray: Any, address: str | None, workers: int | None) -> None:
    """Join the cluster at ``address``, or start a local instance with ``workers`` CPUs (default: all)."""
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


def _wait(ray: Any, labels: dict[Any, str], progress: bool) -> list[str]:
    """Wait for every task, with a progress bar; the failures, one line per distinct cause."""
    from tqdm.auto import tqdm

    failures: list[str] = []
    bar = tqdm(total=len(labels), desc="sweep", unit="task", disable=not progress, dynamic_ncols=True)
    pending = list(labels)
    causes: set[str] = set()
    repeated = 0
    with bar:
        while pending:
            ready, pending = ray.wait(pending, num_returns=1, timeout=WAIT_SECONDS)
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
    return failures


def _detach_node(ray: Any) -> Any:
    """For a stopped sweep's local instance: take its node from the driver, so that the ``ray.shutdown()`` that
    follows only disconnects (0.3 s) and the watchdog then kills every process of the instance at once (0.2 s),
    as after a kill -9 of the sweep. Ray's own shutdown of the node gives each process up to 1 s to exit, one
    after another (1–3 s measured); killing the instance under a connected driver instead makes the driver print
    Ray's errors (task_manager.cc: "Failed to push error to driver", "(raylet) A worker died …"). Returns the
    node, or None (stopped inside ray.init, or a Ray other than the one measured, 2.60: its own shutdown then)."""
    worker: Any = getattr(getattr(ray, "_private", None), "worker", None)  # Ray's private module, or None
    node = getattr(worker, "_global_node", None)
    if node is not None:
        worker._global_node = None
    return node


def run_sweep(spec: SweepSpec, address: str | None = None, workers: int | None = None, progress: bool = True,
              ) -> tuple[list[dict[str, Any]], list[str]]:
    """Run what is left of ``spec`` on Ray; write the results table and plot. Returns (rows, failures).

    ``address`` joins a running cluster (``ray start --head`` prints it; "auto" finds a local one); without it a
    local Ray instance with ``workers`` CPUs (default: all) is started and shut down afterwards.
    """
    ray = import_ray()
    plan = plan_sweep(spec)
    out = make_folder(spec.out).resolve()
    write_text_atomic(out / "sweep.config.json", json.dumps(spec.to_dict(), indent=1) + "\n")
    if progress:
        print(f"gratnet sweep: {plan.summary()}", file=sys.stderr)
    nothing_left = all(state == "done" for state in plan.runs.values())
    owned = not ray.is_initialized() and not nothing_left
    failures: list[str] = []
    guard = watchdog.start() if owned and not address else None  # before Ray starts any process
    stopped = False
    try:
        if owned:
            _init(ray, address, workers)
        with signals_stop_the_sweep():  # after ray.init, whose own SIGTERM handler would end the process at once
            labels = {} if nothing_left else _submit(ray, spec, plan, out)
            failures = _wait(ray, labels, progress)
    except KeyboardInterrupt:  # Ctrl-C, or Stopped (SIGTERM, SIGHUP)
        stopped = True
        raise
    finally:
        detached = _detach_node(ray) if stopped and guard is not None else None
        try:
            if owned:
                ray.shutdown()
        finally:
            if guard is not None:
                guard.close()
        if detached is not None:
            # Those Ray started are the driver's children: reap them (all dead by now: nothing waits or is signalled).
            detached.kill_all_processes(check_alive=False, allow_graceful=False)
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
