"""The sweep's task records: one JSON file per attempt of a task, in OUT/records/KEY/.

Every task of a sweep (sweep/tasks.py) runs inside :func:`attempt`, which writes its record when the attempt
starts (``"outcome": "running"``) and rewrites it when it ends, atomically each time:

- ``"computed"``: the attempt did the work and wrote its output;
- ``"found"``: the output was there already (an earlier attempt or sweep finished it), nothing was computed;
- ``"failed"``: the task raised (``"error"``: its first line);
- ``"running"`` left for good: the attempt was killed (its worker, its node or the whole sweep died).

A record names its task (``key``: ``volume-NAME``, ``volume-NAME-block-K-of-N``, ``slice-NAME-I``,
``run-RUN``; ``label``: as the progress display shows it), where it ran (``node``: the Ray node's id,
``host``, ``pid``), when (``started``, ``seconds``) and, for a training, the epoch it resumed from. Ray
retries a task whose worker or node died (sweep.runner: ``max_retries``) and a rerun of the sweep skips what is
finished, so a finished output is computed once: :func:`computed_more_than_once` is empty.
"""

from __future__ import annotations

import contextlib
import datetime
import json
import os
import socket
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from gratnet.atomic import write_text_atomic

__all__ = ["FOLDER", "NODE_VARIABLE", "attempt", "computed_more_than_once", "read_records"]

#: The records' folder under OUT.
FOLDER = "records"
#: Set by sweep.runner in each Ray worker: the id of the node it runs on.
NODE_VARIABLE = "GRATNET_SWEEP_NODE"


def _write(path: Path, record: dict[str, Any]) -> None:
    write_text_atomic(path, json.dumps(record, indent=1) + "\n")


@contextlib.contextmanager
def attempt(out: Path, key: str, label: str) -> Iterator[dict[str, Any]]:
    """Record one attempt of task ``key``: yields its record, in which the task sets ``outcome`` ("computed" or
    "found") and may add entries; written at the start and again at the end (also when the task raises)."""
    host = socket.gethostname()
    started = time.time_ns()
    path = out / FOLDER / key / f"{started}-{host}-{os.getpid()}.json"
    record: dict[str, Any] = {
        "key": key, "label": label, "node": os.environ.get(NODE_VARIABLE, ""), "host": host, "pid": os.getpid(),
        "started": datetime.datetime.fromtimestamp(started / 1e9, datetime.timezone.utc).isoformat(),
        "outcome": "running",
    }
    _write(path, record)
    clock = time.perf_counter()
    try:
        yield record
    except BaseException as error:
        record.update(outcome="failed", error=(str(error).strip().splitlines() or [type(error).__name__])[0])
        record["seconds"] = round(time.perf_counter() - clock, 3)
        with contextlib.suppress(Exception):  # the task's own error is the one to report
            _write(path, record)
        raise
    if record["outcome"] == "running":
        record["outcome"] = "computed"
    record["seconds"] = round(time.perf_counter() - clock, 3)
    _write(path, record)


def read_records(out: Path) -> list[dict[str, Any]]:
    """Every record under OUT/records (unreadable files skipped: a temporary of a killed write), oldest first."""
    records = []
    for path in sorted((out / FOLDER).glob("*/*.json")):
        if path.name.startswith("."):
            continue
        with contextlib.suppress(OSError, ValueError):
            record = json.loads(path.read_text(encoding="utf-8"))
            if isinstance(record, dict):
                records.append(record)
    return sorted(records, key=lambda record: str(record.get("started", "")))


def computed_more_than_once(records: list[dict[str, Any]]) -> dict[str, int]:
    """Task key → number of attempts that computed it, for the keys computed more than once (should be none)."""
    counts: dict[str, int] = {}
    for record in records:
        if record.get("outcome") == "computed":
            counts[record["key"]] = counts.get(record["key"], 0) + 1
    return {key: count for key, count in counts.items() if count > 1}
