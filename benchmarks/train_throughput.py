"""Trainer throughput: samples per second of `gratnet train`'s own step (trainer.train.train_step).

    python benchmarks/train_throughput.py [--threads 2] [--steps 30] [--device cpu] [--samples 4000000]
                                          [--cuda-graph] [--hidden W,W,...] [--allocator trainer|glibc-default]
                                          [--adam trainer|foreach] [--slices S]

Builds each network of NETWORKS exactly as `gratnet train` does (TrainConfig → build_model, the same
optimiser and schedule), puts a synthetic data set of ``--samples`` random network coordinates and
targets on the device once (the trainer keeps the whole set resident: per-step work is an index into
it, no host gather or copy), runs ``--warmup`` steps, then times ``--steps`` steps of ``--batch-size``
with no host sync inside the timed loop (one synchronisation at its end); with ``--cuda-graph``, the steps
are trainer/cudagraph.py's (warm-up and capture fall inside ``--warmup``, which must be ≥ 4). Prints one JSON line per
network: parameters, grid bytes, MACs per evaluation, samples per second. The data's values do not
change the cost (the coordinates are uniformly random like a shuffled volume).
"""

from __future__ import annotations

import argparse
import json
import resource
import time
from typing import Any

import torch

from gratnet.encoding import EncodingSpec
from trainer.allocator import keep_freed_memory
from trainer.cudagraph import WARMUP_STEPS, GraphedSteps
from trainer.model import GridNetwork
from trainer.train import build_model, make_optimizer, make_scheduler, train_step
from trainer.train_config import TrainConfig

#: (label, TrainConfig overrides): the paper's and today's MLPs and the feature-grid candidates.
NETWORKS: tuple[tuple[str, dict[str, Any]], ...] = (
    ("mlp small", {"preset": "small"}),
    ("mlp funnel-176", {"preset": "funnel-176"}),
    ("mlp paper", {"preset": "paper"}),
    ("grid 3×251² T11 C2, 64-32-16", {"architecture": "grid", "hidden": "64,32,16", "grid_features": 2}),
    ("grid 3×251² T11 C2, small", {"architecture": "grid", "preset": "small", "grid_features": 2}),
    ("grid 3×251² T6 C4, small", {"architecture": "grid", "preset": "small", "grid_features": 4,
                                  "grid_t_resolution": 6}),
    ("grid 251²+501² T5 C2, small", {"architecture": "grid", "preset": "small", "grid_features": 2, "grid_levels": 2,
                                     "grid_resolution": 501, "grid_t_resolution": 5}),
    ("grid 3×251² T11,11,21 C4, 160-96-48-24 (paper-scratches candidate)", {
        "architecture": "grid", "hidden": "160,96,48,24", "grid_features": 4, "grid_level_t": "11,11,21"}),
    ("grid 3×251² T11 C2, 64-32-16, L=8 L_t=2", {"architecture": "grid", "hidden": "64,32,16", "grid_features": 2,
                                                  "frequencies": 8, "t_frequencies": 2}),
    ("grid 3×251² T21 C3, 160-96-48-24 (paper-scratches shipped)", {
        "architecture": "grid", "hidden": "160,96,48,24", "grid_features": 3, "grid_t_resolution": 21,
        "grid_adam_epsilon": 1e-15}),
    ("grid 3×251² T21 C4, 160-96-48-24 (scratches, 41 slices)", {
        "architecture": "grid", "hidden": "160,96,48,24", "grid_features": 4, "grid_t_resolution": 21,
        "grid_adam_epsilon": 1e-15}),
    ("grid 3×251² T41 C3, 160-96-48-24 (scratches, 41 slices)", {
        "architecture": "grid", "hidden": "160,96,48,24", "grid_features": 3, "grid_t_resolution": 41,
        "grid_adam_epsilon": 1e-15}),
    ("grid 3×251² T11 C8, 160-96-48-24 (paper-scratches of session 28, 41 slices)", {
        "architecture": "grid", "hidden": "160,96,48,24", "grid_features": 8, "grid_t_resolution": 11,
        "grid_adam_epsilon": 1e-15}),
)


def main() -> None:
    """Print one JSON line per network."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--threads", type=int, default=2, help="torch intra-op threads (CPU)")
    parser.add_argument("--device", default="cpu")
    parser.add_argument("--steps", type=int, default=30)
    parser.add_argument("--warmup", type=int, default=3)
    parser.add_argument("--batch-size", type=int, default=32768)
    parser.add_argument("--samples", type=int, default=4_000_000)
    parser.add_argument("--only", default="", help="run only networks whose label contains this")
    parser.add_argument("--hidden", default="", help="hidden widths for every network (overrides its own)")
    parser.add_argument("--cuda-graph", action="store_true", help="replay each step as a CUDA graph")
    parser.add_argument("--allocator", choices=("trainer", "glibc-default"), default="trainer",
                        help="trainer: keep freed memory as `gratnet train` does on a CPU (trainer/allocator.py); "
                        "glibc-default: leave malloc's thresholds as they are (to measure what that costs)")
    parser.add_argument("--adam", choices=("trainer", "foreach"), default="trainer",
                        help="trainer: the optimiser `gratnet train` builds (fused on a CPU: "
                        "trainer.train.fused_adam); foreach: torch's default Adam with the same groups and rates "
                        "(to measure what fusing gains)")
    parser.add_argument("--slices", type=int, default=11,
                        help="w-slices of the volume the encoding is scaled for (its top t frequency)")
    arguments = parser.parse_args()
    if arguments.cuda_graph and arguments.warmup <= WARMUP_STEPS:
        parser.error(f"--cuda-graph needs --warmup > {WARMUP_STEPS} (the eager warm-up steps, then the capture)")
    torch.set_num_threads(arguments.threads)
    device = torch.device(arguments.device)
    if arguments.allocator == "trainer" and device.type == "cpu":
        keep_freed_memory()
    generator = torch.Generator().manual_seed(0)
    coordinates = (torch.rand(arguments.samples, 3, generator=generator) * 2 - 1).to(device)
    targets = torch.rand(arguments.samples, 3, generator=generator).to(device)
    for label, overrides in NETWORKS:
        if arguments.only not in label:
            continue
        if arguments.hidden:
            overrides = {**overrides, "hidden": arguments.hidden}
        config = TrainConfig(batch_size=arguments.batch_size, **overrides)
        encoding = EncodingSpec.for_grid(1001, arguments.slices, config.frequencies, config.t_frequencies,
                                            config.diagonal_frequencies)
        torch.manual_seed(0)
        model = build_model(config, encoding).to(device)
        optimizer = make_optimizer(model, config, fused=False if arguments.adam == "foreach" else None)
        scheduler = make_scheduler(optimizer, config, arguments.steps + arguments.warmup,
                                   isinstance(model, GridNetwork))
        order = torch.randperm(arguments.samples, generator=generator).to(device)
        batches = [order[k * config.batch_size:(k + 1) * config.batch_size]
                   for k in range(arguments.samples // config.batch_size)]
        graph = None
        if arguments.cuda_graph:
            graph = GraphedSteps(model, optimizer, [float(group["lr"]) for group in optimizer.param_groups],
                                 arguments.steps + arguments.warmup, config.final_learning_rate_ratio, 0, encoding,
                                 None, coordinates, targets, config.batch_size)

        loss = torch.zeros(())
        for number in range(arguments.warmup + arguments.steps):
            if number == arguments.warmup:  # the timed steps start
                if device.type == "cuda":
                    torch.cuda.synchronize()
                started, faults = time.perf_counter(), resource.getrusage(resource.RUSAGE_SELF).ru_minflt
            batch = batches[number % len(batches)]
            if graph is not None:
                graph.step(batch)
                loss = graph.running
            else:
                loss = train_step(model, optimizer, scheduler, coordinates[batch], targets[batch], encoding)
        float(loss)  # the one sync
        seconds = time.perf_counter() - started
        faults = resource.getrusage(resource.RUSAGE_SELF).ru_minflt - faults
        mlp = model.mlp if isinstance(model, GridNetwork) else model
        macs = sum(a * b for a, b in zip(mlp.sizes[:-1], mlp.sizes[1:], strict=False))
        print(json.dumps({
            "network": label, "layers": mlp.sizes, "parameters": model.parameter_count,
            "grid_bytes": model.grid_bytes if isinstance(model, GridNetwork) else 0, "macs": macs,
            "threads": arguments.threads, "device": str(device), "batch_size": config.batch_size,
            "cuda_graph": arguments.cuda_graph, "allocator": arguments.allocator,
            "adam": "fused" if all(group["fused"] for group in optimizer.param_groups) else "default",
            "page_faults_per_step": round(faults / arguments.steps),
            "steps": arguments.steps, "samples_per_second": round(arguments.steps * config.batch_size / seconds),
        }, ensure_ascii=False), flush=True)


if __name__ == "__main__":
    main()
