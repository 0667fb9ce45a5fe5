"""A Ray cluster losing a worker node mid-sweep (issue 36), simulated on this machine.

A head (no CPUs: it only schedules) and two worker nodes of one CPU each, started with ``ray start`` as
separate raylets with their own temporary folders; the results folder is shared as it would be on a real
cluster (here: the same disk). ``gratnet sweep --address`` runs a tiny grid on it (one volume in two wavelength
blocks, two trainings of six epochs), and the node running a task is killed with SIGKILL — its raylet, its
workers and its agents, found by an environment variable that only that node's processes carry (``ray stop``
would be a clean stop, not a kill). Twice: once while a training runs (after its first checkpoint), once while
a wavelength block is computed. The sweep must finish; every output equals the one of the same sweep run on
one machine (a local Ray instance); and the task records (OUT/records) show that nothing finished was computed
twice: the killed attempt is left "running", the retry on the other node resumes the training from its
checkpoint, or computes the block that was never finished.

The nodes are removed at the end by killing their processes, not with ``ray stop --force``, which would also
stop every other Ray instance of this user on the machine.
"""

from __future__ import annotations

import json
import os
import secrets
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from tests.helpers import REPO

if str(REPO) not in sys.path:  # scripts/ is a folder of the repository, not an installed package
    sys.path.insert(0, str(REPO))

from scripts import fault_injection as faults  # noqa: E402
from sweep.records import computed_more_than_once, read_records  # noqa: E402

pytestmark = pytest.mark.faults

#: The environment variable marking each node's processes (every process a node starts inherits it).
NODE_VARIABLE = "GRATNET_TEST_NODE"

SWEEP = """\
presets = ["tiny"]
seeds = [0, 1]

[groundtruth]
resolution = 33
slices = 5
sigma_s_um = 1.5
wavelength_step_nm = 100.0
parts = 2

[train]
epochs = 6
test_slices = "2"
batch_size = 256

[evaluate]
size = 16

[resources]
train_cpus = 1

[[datasets]]
generator = "blazed"
params = { size_um = 5.0 }
"""


def _free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return int(probe.getsockname()[1])


def _ray() -> str:
    return str(Path(sys.executable).with_name("ray"))


class Cluster:
    """A head and worker nodes started with ``ray start`` on this machine, each node's processes marked."""

    def __init__(self, folder: Path) -> None:
        self.folder = folder
        self.marker = secrets.token_hex(4)
        # Short: Ray's socket paths under it must fit in 107 bytes.
        self.temp = Path(tempfile.mkdtemp(prefix="gr", dir="/tmp"))
        self.port = _free_port()
        self.address = f"127.0.0.1:{self.port}"
        self.token = secrets.token_hex(16)  # this cluster's own: Ray ≥ 2.5x asks clients for one
        self.nodes: list[str] = []

    def environment(self, node: str | None = None) -> dict[str, str]:
        """For ``ray start`` (``node``: its name, inherited by its processes) and for the driver."""
        environment = {**os.environ, "RAY_USAGE_STATS_ENABLED": "0", "RAY_AUTH_MODE": "token",
                       "RAY_AUTH_TOKEN": self.token, "SPT_NOENV": "1", "OMP_NUM_THREADS": "1",
                       "PYTHONPATH": os.pathsep.join(filter(None, [str(REPO), os.environ.get("PYTHONPATH")]))}
        if node is not None:
            environment[NODE_VARIABLE] = f"{self.marker}-{node}"
        return environment

    def _start(self, node: str, arguments: list[str]) -> None:
        self.nodes.append(node)
        result = subprocess.run([_ray(), "start", *arguments, "--object-store-memory", str(200 * 2**20),
                                 "--temp-dir", str(self.temp / node), "--disable-usage-stats"], cwd=self.folder,
                                env=self.environment(node), capture_output=True, text=True, timeout=120)
        assert result.returncode == 0, f"ray start ({node}) failed: {result.stdout[-2000:]}{result.stderr[-2000:]}"

    def start_head(self) -> None:
        self._start("head", ["--head", "--port", str(self.port), "--node-ip-address", "127.0.0.1", "--num-cpus",
                             "0", "--include-dashboard=false"])

    def add_worker(self, node: str) -> None:
        self._start(node, ["--address", self.address, "--node-ip-address", "127.0.0.1", "--num-cpus", "1"])

    def processes(self, node: str) -> list[int]:
        """The live processes of ``node``."""
        needle = f"{NODE_VARIABLE}={self.marker}-{node}".encode()
        found = []
        for entry in os.scandir("/proc"):
            if entry.name.isdigit():
                try:
                    with open(f"/proc/{entry.name}/environ", "rb") as handle:
                        if needle in handle.read().split(b"\0"):
                            found.append(int(entry.name))
                except OSError:
                    continue
        return found

    def node_of(self, pid: int) -> str | None:
        """The node a process belongs to (None: gone, or not the cluster's)."""
        try:
            with open(f"/proc/{pid}/environ", "rb") as handle:
                variables = handle.read().split(b"\0")
        except OSError:
            return None
        prefix = f"{NODE_VARIABLE}={self.marker}-".encode()
        return next((item[len(prefix):].decode() for item in variables if item.startswith(prefix)), None)

    def kill(self, node: str) -> list[int]:
        """SIGKILL every process of ``node`` (raylet, workers, agents) until none is left; their PIDs."""
        killed: set[int] = set()
        for _ in range(50):
            alive = self.processes(node)
            if not alive:
                break
            for pid in alive:
                try:
                    os.kill(pid, signal.SIGKILL)
                    killed.add(pid)
                except ProcessLookupError:
                    pass
            time.sleep(0.1)
        assert not self.processes(node), f"processes of {node} survive SIGKILL"
        return sorted(killed)

    def stop(self) -> None:
        for node in self.nodes:
            self.kill(node)
        shutil.rmtree(self.temp, ignore_errors=True)


@pytest.fixture(scope="module")
def setup(tmp_path_factory: pytest.TempPathFactory) -> Iterator[tuple[Cluster, Path, Path]]:
    """The sweep file, the one-machine run's results folder, and the cluster (head + w1 + w2)."""
    pytest.importorskip("ray", reason="the cluster tests need Ray: pip install -e '.[sweep]'")
    if not Path("/proc/self/environ").is_file():
        pytest.skip("finding a node's processes needs /proc (Linux)")
    folder = tmp_path_factory.mktemp("cluster")
    sweep_file = folder / "tiny.toml"
    sweep_file.write_text(SWEEP, encoding="utf-8")
    local = folder / "one-machine"
    status, _ = faults.run_to_end(["sweep", str(sweep_file), "--out", str(local), "--workers", "2", "--quiet"],
                                  folder)
    assert status == 0, (folder.with_name(folder.name + ".log")).read_text()
    cluster = Cluster(folder)
    try:
        cluster.start_head()
        cluster.add_worker("w1")
        cluster.add_worker("w2")
        yield cluster, sweep_file, local
    finally:
        cluster.stop()


def _running(out: Path, prefix: str) -> list[dict[str, Any]]:
    return [record for record in read_records(out) if record["key"].startswith(prefix)
            and record["outcome"] == "running"]


def _sweep_losing_a_node(cluster: Cluster, sweep_file: Path, out: Path, victim: str,
                         when: str) -> tuple[str, dict[str, Any], str]:
    """Run the sweep on the cluster, kill the node that runs the first ``victim`` task (``run-`` or ``volume-``)
    once ``when`` holds ("checkpoint": its run has a checkpoint; "started": at once); returns (the node's name,
    the killed attempt's record, the sweep's output)."""
    process = subprocess.Popen([sys.executable, "-m", "gratnet.cli", "sweep", str(sweep_file), "--out", str(out),
                                "--address", cluster.address, "--quiet"], cwd=cluster.folder,
                               env=cluster.environment(), stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        deadline = time.monotonic() + 180
        target = None
        while target is None and process.poll() is None and time.monotonic() < deadline:
            time.sleep(0.02)
            for record in _running(out, victim):
                ready = when == "started" or (out / "runs" / record["key"][len("run-"):] / "checkpoint.pt").is_file()
                node = cluster.node_of(record["pid"])
                if ready and node is not None and node != "head":
                    target = (node, record)
                    break
        assert target is not None, f"no {victim} task to kill was seen running: {process.poll()}"
        node, record = target
        cluster.kill(node)
        output, _ = process.communicate(timeout=300)
    finally:
        if process.poll() is None:
            process.kill()
            process.communicate()
    assert process.returncode == 0, output
    return node, record, output


def _check(out: Path, local: Path, killed: dict[str, Any]) -> list[dict[str, Any]]:
    """Every output equals the one-machine run's; nothing finished computed twice; the killed attempt was done
    again elsewhere. Returns the records of the killed task."""
    compared, differences = faults.compare(out, local)
    assert compared > 20 and not differences, differences
    records = read_records(out)
    assert computed_more_than_once(records) == {}
    attempts = [record for record in records if record["key"] == killed["key"]]
    assert [record["outcome"] for record in attempts] == ["running", "computed"], attempts
    assert attempts[1]["node"] != attempts[0]["node"]  # retried on the node that is left
    print(f"{killed['key']}: killed on node {attempts[0]['node'][:8]} after {attempts[0]['started']}, computed on "
          f"{attempts[1]['node'][:8]} (resumed from epoch {attempts[1].get('resumed_from_epoch')}); "
          f"{len(records)} records, {compared} outputs equal the one-machine run's")
    rows = json.loads((out / "results.json").read_text())
    assert len(rows) == 2
    return attempts


def test_a_training_on_a_killed_node_resumes_on_another_and_ends_as_on_one_machine(setup):
    cluster, sweep_file, local = setup
    out = cluster.folder / "shared" / "training-killed"
    node, killed, output = _sweep_losing_a_node(cluster, sweep_file, out, "run-", "checkpoint")
    assert "2 of 2 runs finished" in output
    attempts = _check(out, local, killed)
    assert attempts[1].get("resumed_from_epoch", 0) >= 1, attempts  # from the checkpoint, not from scratch
    assert not cluster.processes(node)


def test_a_wavelength_block_on_a_killed_node_is_computed_on_another(setup):
    """After the first test's kill one worker is left; a third joins, so that two again share the work."""
    cluster, sweep_file, local = setup
    cluster.add_worker("w3")
    out = cluster.folder / "shared" / "block-killed"
    node, killed, output = _sweep_losing_a_node(cluster, sweep_file, out, "volume-blazed-block", "started")
    assert "2 of 2 runs finished" in output
    _check(out, local, killed)
    assert not (out / "volumes" / "blazed.parts").exists()  # the blocks, once assembled, are removed


def test_a_killed_driver_leaves_no_task_running_on_the_cluster_and_the_rerun_finishes(setup):
    """``gratnet sweep --address`` killed with SIGKILL while a training runs on a worker node: Ray ends the dead
    driver's tasks (the worker running the training is gone within 10 s: the cluster is not the sweep's, so no
    watchdog of the sweep's is involved), and the same command then finishes the sweep, equal to the one-machine
    run, resuming the training from its checkpoint."""
    cluster, sweep_file, local = setup
    cluster.add_worker("w4")
    out = cluster.folder / "shared" / "driver-killed"
    arguments = ["sweep", str(sweep_file), "--out", str(out), "--address", cluster.address, "--quiet"]
    driver = subprocess.Popen([sys.executable, "-m", "gratnet.cli", *arguments], cwd=cluster.folder,
                              env=cluster.environment(), stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        deadline = time.monotonic() + 180
        running: list[dict[str, Any]] = []
        while not running and driver.poll() is None and time.monotonic() < deadline:
            time.sleep(0.02)
            running = [record for record in _running(out, "run-")
                       if (out / "runs" / record["key"][len("run-"):] / "checkpoint.pt").is_file()]
        assert running, "no training was seen running"
        os.kill(driver.pid, signal.SIGKILL)
        driver.wait()
    finally:
        if driver.poll() is None:
            driver.kill()
            driver.wait()
    workers = {record["pid"] for record in running}
    deadline = time.monotonic() + faults.GRACE_SECONDS
    while any(cluster.node_of(pid) for pid in workers) and time.monotonic() < deadline:
        time.sleep(0.1)
    assert not any(cluster.node_of(pid) for pid in workers), "a task of the killed driver still runs"
    result = subprocess.run([sys.executable, "-m", "gratnet.cli", *arguments], cwd=cluster.folder,
                            env=cluster.environment(), capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stderr
    compared, differences = faults.compare(out, local)
    assert compared > 20 and not differences, differences
    records = read_records(out)
    assert computed_more_than_once(records) == {}
    resumed = [record for record in records if record["key"] == running[0]["key"] and record["outcome"] == "computed"]
    assert len(resumed) == 1 and resumed[0].get("resumed_from_epoch", 0) >= 1, resumed


def test_the_slice_tasks_know_the_evaluation_caches_file(tmp_path):
    """trainer.evaluate.brdf_cache_file names the file trainer.evaluate.ground_truth_brdf_slice writes (else a slice
    task would compute a slice the cache holds, and count it computed)."""
    from trainer.brdfslice import SliceConfig
    from trainer.evaluate import brdf_cache_file, ground_truth_brdf_slice
    from trainer.fourier import OpticsConfig
    from trainer.generators import generate

    field = generate("blazed", size_um=5.0)
    optics = OpticsConfig(sigma_s_um=1.5, wavelength_step_nm=100.0)
    config = SliceConfig(30.0, 135.0, size=8, exposure=5000.0)
    ground_truth_brdf_slice(field, optics, config, tmp_path, progress=False)
    assert [path.name for path in tmp_path.iterdir()] == [brdf_cache_file(field, optics, config, tmp_path).name]
