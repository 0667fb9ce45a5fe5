"""The interpolation oracle of every ground-truth volume in a folder: what its training grid supports.

For each VOLUME.exr: the volume interpolated trilinearly at the exact key vectors of the paper's five BRDF
slices (trainer/diagnostics.py VolumeOracle), scored against the exact ground-truth slices with the
project's own metrics (mean FLIP, PSNR of CIE XYZ inside the view disc) and split by region. No network is
involved: this is the floor a network trained on that grid could reach if it interpolated perfectly.

    python -m analysis.oracle_table VOLUME_DIR [--size 256] [--cache-dir out/cache] [--json out.json]
        [--figure docs/images/oracle_slices.png] [--device cpu|cuda] [--uv-stride 1,2]
        [--stride-figure docs/images/oracle_uv_stride.png]

Prints one JSON line per volume and a markdown table (FLIP per slice) on stdout. The ground-truth slices
are cached in --cache-dir (the same cache `gratnet evaluate` uses), so a second run is cheap.

--uv-stride 1,2 also scores each volume with only every 2nd u*/v* sample kept (a 501² lattice from a 1001²
one, the same w-slices): how the oracle's error depends on the lattice spacing, i.e. whether a finer u*/v*
lattice (more samples per slice) or more w-slices would lower it, without computing a finer volume.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
from tqdm import tqdm

from gratnet.atomic import atomic_path, write_text_atomic
from gratnet.volume import Volume, read_volume
from trainer.brdfslice import SliceConfig, slice_view_directions
from trainer.diagnostics import REGIONS, VolumeOracle, region_errors, region_labels
from trainer.evaluate import STANDARD_SLICES, ground_truth_brdf_slice, slice_label
from trainer.fourier import OpticsConfig
from trainer.loaders import LoadOptions, load_heightfield
from trainer.metrics import image_metrics
from trainer.report import comparison_figure


def decimated(volume: Volume, stride: int) -> Volume:
    """The volume with every ``stride``-th u*/v* sample kept (both ends included: (R − 1) must divide by it)."""
    if stride < 1 or (volume.resolution - 1) % stride:
        raise SystemExit(f"oracle_table: --uv-stride {stride} does not divide the {volume.resolution}² lattice's "
                         f"{volume.resolution - 1} intervals")
    return Volume(np.ascontiguousarray(volume.xyz[:, ::stride, ::stride]), dict(volume.metadata))


def oracle_rows(volume_path: Path, size: int, cache_dir: str, progress: bool,
                device: str | None = None, uv_stride: int = 1) -> tuple[dict[str, Any], list]:
    """Oracle metrics of one volume (one dict) and its figure rows (label, reference, oracle); ``uv_stride``:
    keep every such u*/v* sample only (:func:`decimated`)."""
    started = time.perf_counter()
    volume = decimated(read_volume(volume_path), uv_stride)
    metadata = volume.metadata
    source = str(metadata.get("source", ""))
    if not source.startswith(("generator:", "dataset:")):
        raise SystemExit(f"oracle_table: {volume_path} was not made from a built-in generator or dataset "
                         f"(source {source!r}): its ground-truth slices cannot be recomputed")
    field = load_heightfield(source, LoadOptions())
    optics = OpticsConfig.from_volume_metadata(metadata)
    oracle = VolumeOracle(volume)
    _, inside = slice_view_directions(size)
    slices, figure = [], []
    for theta, phi, exposure in STANDARD_SLICES:
        config = SliceConfig(theta, phi, size=size, exposure=exposure)
        reference = ground_truth_brdf_slice(field, optics, config, cache_dir, progress, device)
        predicted = oracle.brdf_slice(config)
        labels = region_labels(reference, config, optics.sigma_s_um)
        label = slice_label(theta, phi, exposure)
        slices.append({"slice": label, **image_metrics(reference, predicted, mask=inside),
                       "regions": region_errors(reference, predicted, labels)})
        figure.append((f"{volume_path.stem} {volume.resolution}² {label}", reference, predicted))
    row = {
        "volume": volume_path.name, "source": source, "resolution": volume.resolution, "uv_stride": uv_stride,
        "slices": volume.slices,
        "scheme": metadata.get("scheme"), "sigma_s_um": optics.sigma_s_um, "size": size,
        "volume_bytes": int(volume.xyz.astype(np.float32).nbytes), "brdf_slices": slices,
        "seconds": round(time.perf_counter() - started, 1),
    }
    return row, figure


def markdown(rows: list[dict[str, Any]]) -> str:
    """FLIP per slice (and PSNR of the (0°, 0°) slice) of every volume's oracle."""
    labels = [slice_["slice"] for slice_ in rows[0]["brdf_slices"]]
    lines = ["| volume | grid | " + " | ".join(labels) + " | PSNR (0°, 0°) dB | lit-region FLIP (0°, 0°) |",
             "|---|---|" + "---|" * (len(labels) + 2)]
    for row in rows:
        flips = " | ".join(f"{slice_['flip']:.4f}" for slice_ in row["brdf_slices"])
        first = row["brdf_slices"][0]
        lit = {name: first["regions"][name]["flip"] for name in REGIONS if name != "dark"
               and first["regions"][name]["fraction"] > 0}
        lit_text = ", ".join(f"{name} {value:.3f}" for name, value in lit.items())
        lines.append(f"| {row['volume']} | {row['resolution']}² × {row['slices']} | {flips} | "
                     f"{first['psnr_xyz']:.1f} | {lit_text} |")
    return "\n".join(lines) + "\n"


def stride_figure(rows: list[dict[str, Any]], path: Path) -> None:
    """One panel per volume: each slice's oracle FLIP against the u*/v* nodes per axis (log-log), and the
    worst slice over the (0°, 0°) slice beside each lattice."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from gratnet.figures import save_figure

    volumes = list(dict.fromkeys(row["volume"] for row in rows))
    figure, axes = plt.subplots(1, len(volumes), figsize=(4.2 * len(volumes), 3.6), squeeze=False)
    for axis, name in zip(axes[0], volumes, strict=True):
        mine = sorted((row for row in rows if row["volume"] == name), key=lambda row: row["resolution"])
        nodes = [row["resolution"] for row in mine]
        for index, label in enumerate(slice_["slice"] for slice_ in mine[0]["brdf_slices"]):
            axis.plot(nodes, [row["brdf_slices"][index]["flip"] for row in mine], "o-", label=label)
        for row in mine:
            flips = [slice_["flip"] for slice_ in row["brdf_slices"]]
            axis.annotate(f"{max(flips[1:]) / flips[0]:.2f}×", (row["resolution"], max(flips)),
                          textcoords="offset points", xytext=(0, 6), ha="center", fontsize=8)
        axis.set_xscale("log")
        axis.set_yscale("log")
        axis.set_xticks(nodes, [f"{n}²" for n in nodes])
        axis.minorticks_off()
        axis.set_xlabel("u*/v* nodes of the lattice")
        axis.set_ylabel("oracle mean FLIP")
        axis.set_title(f"{name} ({mine[0]['slices']} w-slices)", fontsize=9)
        axis.grid(True, which="major", alpha=0.3)
        axis.margins(y=0.2)
    axes[0][0].legend(fontsize=7)
    figure.suptitle("Interpolation oracle against lattice spacing (labels: worst other slice / (0°, 0°))",
                    fontsize=9)
    figure.tight_layout()
    save_figure(figure, path, dpi=100)
    plt.close(figure)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("volumes", type=Path, help="folder of ground-truth volumes (*.exr)")
    parser.add_argument("--size", type=int, default=256, help="BRDF-slice width and height (pixels)")
    parser.add_argument("--cache-dir", default="out/cache", help="ground-truth slice cache (as gratnet evaluate)")
    parser.add_argument("--json", type=Path, help="write all rows as one JSON file")
    parser.add_argument("--figure", type=Path, help="PNG: ground truth | oracle | FLIP for every slice")
    parser.add_argument("--quiet", action="store_true", help="no progress bars")
    parser.add_argument("--device", default="cpu", help="where uncached ground-truth slices are computed: cpu "
                        "(numpy) or cuda (as gratnet groundtruth --device)")
    parser.add_argument("--uv-stride", default="1", help="comma-separated strides: score each volume with every "
                        "N-th u*/v* sample kept, for each N (1: the volume as it is)")
    parser.add_argument("--stride-figure", type=Path, help="PNG: each slice's oracle FLIP against the lattice's "
                        "nodes, one panel per volume (with --uv-stride of two or more strides)")
    arguments = parser.parse_args(argv)
    try:
        strides = [int(text) for text in arguments.uv_stride.split(",")]
    except ValueError:
        parser.error(f"--uv-stride takes comma-separated whole numbers, got {arguments.uv_stride!r}")
    if min(strides) < 1:
        parser.error(f"--uv-stride: every stride must be ≥ 1, got {arguments.uv_stride!r}")
    if arguments.stride_figure and len(set(strides)) < 2:
        parser.error("--stride-figure needs --uv-stride with two or more strides")
    from trainer.groundtruth import ComputeConfig

    device = ComputeConfig(arguments.device).resolve()
    paths = sorted(arguments.volumes.glob("*.exr"))
    if not paths:
        print(f"oracle_table: no *.exr in {arguments.volumes}", file=sys.stderr)
        return 2
    rows, figure_rows = [], []
    for path in tqdm(paths, desc="volumes", disable=arguments.quiet):
        for stride in strides:
            row, figure = oracle_rows(path, arguments.size, arguments.cache_dir, not arguments.quiet, device, stride)
            print(json.dumps(row), flush=True)
            rows.append(row)
            figure_rows.extend(figure)
    if arguments.json:
        write_text_atomic(arguments.json, json.dumps(rows, indent=1) + "\n")
    if arguments.figure:
        with atomic_path(arguments.figure) as temporary:
            comparison_figure(temporary, figure_rows, title="interpolation oracle: ground truth | oracle | FLIP")
    if arguments.stride_figure:
        stride_figure(rows, arguments.stride_figure)
    print(markdown(rows))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
