"""Evaluating a model file against ground truth: held-out volume slices and BRDF slices.

BRDF slices (physics.md, "The A-term and BRDF slices") are rendered twice at the same key vectors:
ground truth from the height field (exact F-term, no volume lookup) and the network through the runtime's
numpy evaluator (gratnet.modelfile.evaluate_keys); both × exposure × A. Metrics (trainer/metrics.py):
PSNR on exposed XYZ clipped to [0, 1], SSIM in display sRGB and YCbCr, mean FLIP. Beside the network:
the interpolation oracle (the volume's own samples interpolated at the same keys) and the error split by
region (specular peak, diffraction orders, speckle floor, dark background): trainer/diagnostics.py.

The model's cost (gratnet.cost: MACs and grid values read per pixel, bytes on disk and on the GPU) goes into
metrics.json's "cost" and report.md's model section; with ``frame_time``, so does its 1080p CD frame time on
this machine, measured by ``gratnet bench`` in a child process (:func:`measure_frame_time`: the offline stage
imports no runtime).
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import math
import os
import shlex
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

from gratnet.atomic import atomic_path, make_folder
from gratnet.brdf import STANDARD_SLICES, slice_view_directions
from gratnet.config import config_field, config_to_dict
from gratnet.cost import ModelCost
from gratnet.encoding import range_forward
from gratnet.errors import GratNetError
from gratnet.modelfile import ModelFile, evaluate_keys
from gratnet.volume import Volume, volume_axes
from trainer.brdfslice import SliceConfig, brdf_slice_xyz, expose_slice, slice_geometry
from trainer.fourier import OpticsConfig, prepare_surface
from trainer.heightfield import HeightField
from trainer.metrics import image_metrics
from trainer.report import comparison_figure, model_section, write_report
from trainer.sampling import grid_to_key, slice_w

#: Largest BRDF-slice size of the evaluation (pixels; each one is a network evaluation and a ground truth).
MAX_EVALUATION_SIZE = 4096


@dataclasses.dataclass(frozen=True)
class EvaluateConfig:
    """What to evaluate and at which resolution."""

    size: int = config_field(256, "BRDF-slice image width and height (pixels)")
    ior: float = config_field(1.5, "refractive index of the Fresnel term (0: off)")
    brdf_slices: bool = config_field(True, "evaluate the paper's five BRDF slices (needs the height field)")
    oracle: bool = config_field(True, "also score the interpolation oracle on the BRDF slices: the volume "
                                "interpolated trilinearly at the exact keys (needs the volume; cheap)")
    cache_dir: str = config_field("out/cache", "where ground-truth BRDF slices are cached (.npy)")
    views: str = config_field(
        "", "further BRDF slices scored beside the paper's five (views no training was tuned on): 'θ,φ,RU' "
        "triples separated by ';' (light polar and azimuth angles in degrees, exposure), e.g. '45,60,5000;15,200,3000'"
    )
    # Off by default: the frame takes a minute or more per model on a CPU rasterizer (compiles, the render-path
    # probe, full-HD frames), and a timing says something only on a machine that does nothing else meanwhile.
    frame_time: bool = config_field(
        False, "also measure the model's 1080p CD frame time on this machine (gratnet bench in a child process: the "
        "CD disc at 1920x1080, 1 sample per pixel, auto weights and render paths, as gratnet render draws it)")
    progress: bool = config_field(True, "progress bars while computing ground-truth slices", cli=False)

    def __post_init__(self) -> None:  # checked when made: before any work
        from gratnet.brdf import check_ior

        if not 2 <= self.size <= MAX_EVALUATION_SIZE:
            raise GratNetError(f"--size must be from 2 to {MAX_EVALUATION_SIZE} pixels (typical: 256), got {self.size}")
        check_ior(self.ior)
        self.extra_views()

    def extra_views(self) -> tuple[tuple[float, float, float], ...]:
        """The ``views`` as (θi degrees, φi degrees, exposure) triples."""
        views = []
        for part in filter(None, (item.strip() for item in self.views.split(";"))):
            try:
                theta, phi, exposure = (float(value) for value in part.split(","))
            except ValueError:
                raise GratNetError(f"--views: each view is 'θ,φ,RU' (three numbers), got {part!r}") from None
            if not (0.0 <= theta < 90.0 and math.isfinite(phi) and exposure > 0 and math.isfinite(exposure)):
                raise GratNetError(f"--views: θ must lie in [0, 90) degrees and RU be a positive number, got {part!r}")
            views.append((theta, phi, exposure))
        return tuple(views)


def network_brdf_slice(model: ModelFile, config: SliceConfig) -> np.ndarray:
    """exposure · A · XYZ_network for every pixel of a BRDF slice, (size, size, 3); 0 outside the disc."""
    light, views, inside = slice_geometry(config)
    key = -(light + views)
    xyz = np.zeros(views.shape)
    xyz[inside] = evaluate_keys(model, key[inside][:, 0], key[inside][:, 1], key[inside][:, 2])
    return expose_slice(config, light, views, inside, xyz)


def brdf_cache_file(field: HeightField, optics: OpticsConfig, config: SliceConfig, cache_dir: str | Path) -> Path:
    """The file :func:`ground_truth_brdf_slice` caches a slice in, named by its key (source, optics, slice config):
    a sweep asks whether a slice is there before computing it."""
    key = json.dumps([field.source, config_to_dict(optics), config_to_dict(config)], sort_keys=True)
    return Path(cache_dir) / f"brdf_{hashlib.sha256(key.encode()).hexdigest()[:20]}.npy"


def ground_truth_brdf_slice(
    field: HeightField,
    optics: OpticsConfig,
    config: SliceConfig,
    cache_dir: str | Path | None,
    progress: bool = True,
    device: str | None = None,
) -> np.ndarray:
    """Ground-truth slice (exact key vectors), cached by (source, optics, slice config) in
    :func:`brdf_cache_file`; ``device`` as :class:`trainer.fourier.FTerm`'s (None: numpy; the cache holds either)."""
    path = brdf_cache_file(field, optics, config, cache_dir) if cache_dir else None
    if path is not None and path.exists():
        return np.load(path)
    xyz = brdf_slice_xyz(prepare_surface(field, optics), config, optics, progress=progress, device=device)
    if path is not None:  # atomically: workers of a sweep share the cache
        with atomic_path(path, output=False) as temporary:
            np.save(temporary, xyz)
    return xyz


def model_ground_truth_inputs(model: ModelFile, heightfield: str) -> tuple[HeightField, OpticsConfig]:
    """The height field ``heightfield`` (a file, a generator or a paper dataset; default load options) and the
    optics ``model``'s volume was computed with: what `gratnet evaluate MODEL --heightfield …` computes its
    ground-truth slices from (and so shares their cache)."""
    from trainer.heightfile import LoadOptions
    from trainer.loaders import load_heightfield

    return load_heightfield(heightfield, LoadOptions()), OpticsConfig.from_volume_metadata(model.metadata["volume"])


def slice_label(theta: float, phi: float, exposure: float) -> str:
    """A BRDF slice's name in metrics.json and the reports: '(θ°, φ°) E RU', E the exposure."""
    return f"({theta:g}°, {phi:g}°) {exposure:g} RU"


#: The labels of the paper's five slices (gratnet.brdf.STANDARD_SLICES), (0°, 0°) first, as metrics.json names them.
STANDARD_SLICE_LABELS: tuple[str, ...] = tuple(slice_label(*view) for view in STANDARD_SLICES)


def evaluate_brdf_slices(
    model: ModelFile,
    field: HeightField,
    optics: OpticsConfig,
    config: EvaluateConfig,
    out_dir: Path,
    volume: Volume | None = None,
) -> list[dict[str, Any]]:
    """Metrics and a comparison figure for the paper's five BRDF slices and ``config.views`` (rows marked
    ``extra_view``); per-region errors; and, with a
    ``volume`` and ``config.oracle``, the interpolation oracle's metrics (``oracle``) beside the network's."""
    from trainer.diagnostics import VolumeOracle, region_errors, region_figure, region_labels

    rows, figure_rows, region_maps = [], [], []
    oracle_of_volume = VolumeOracle(volume) if volume is not None and config.oracle else None
    for index, (theta, phi, exposure) in enumerate(STANDARD_SLICES + config.extra_views()):
        slice_config = SliceConfig(theta, phi, size=config.size, exposure=exposure, ior=config.ior)
        reference = ground_truth_brdf_slice(field, optics, slice_config, config.cache_dir, config.progress)
        predicted = network_brdf_slice(model, slice_config)
        _, inside = slice_view_directions(config.size)
        metrics = image_metrics(reference, predicted, mask=inside)
        labels = region_labels(reference, slice_config, optics.sigma_s_um)
        region_maps.append((slice_label(theta, phi, exposure), labels))
        row: dict[str, Any] = {
            "slice": slice_label(theta, phi, exposure), "theta": theta, "phi": phi, "exposure": exposure, **metrics,
            "regions": region_errors(reference, predicted, labels),
        }
        if index >= len(STANDARD_SLICES):
            row["extra_view"] = True  # one of --views (even one that repeats a paper slice): not the paper's
        if oracle_of_volume is not None:
            oracle = oracle_of_volume.brdf_slice(slice_config)
            row["oracle"] = {**image_metrics(reference, oracle, mask=inside),
                             "regions": region_errors(reference, oracle, labels)}
            row["oracle_flip"] = row["oracle"]["flip"]
        rows.append(row)
        figure_rows.append((slice_label(theta, phi, exposure), reference, predicted))
    comparison_figure(out_dir / "brdf_slices.png", figure_rows, title="BRDF slices: ground truth | network | FLIP")
    region_figure(out_dir / "brdf_regions.png", region_maps)
    return rows


def region_table(rows: list[dict[str, Any]]) -> str:
    """Markdown: per slice and region, the pixel fraction and the network's (and oracle's) FLIP and relative L1."""
    from trainer.diagnostics import REGIONS
    from trainer.report import metrics_table_markdown

    lines = []
    for row in rows:
        for name in REGIONS:
            network, oracle = row["regions"][name], row.get("oracle", {}).get("regions", {}).get(name, {})
            lines.append({"slice": row["slice"], "region": name, "fraction": network["fraction"],
                          "flip": network["flip"], "relative_l1": network["relative_l1"],
                          "oracle_flip": oracle.get("flip"), "oracle_relative_l1": oracle.get("relative_l1")})
    return ("## Error by region\n\nRegions of the ground-truth slice (trainer/diagnostics.py): specular peak, "
            "diffraction orders (bright), speckle floor (lit), dark background; fraction of the view disc; FLIP "
            "averaged over the region; relative L1 = Σ|pred − ref| / Σ|ref| of exposed XYZ.\n\n"
            + metrics_table_markdown(lines, ["slice", "region", "fraction", "flip", "relative_l1", "oracle_flip",
                                             "oracle_relative_l1"]))


def evaluate_volume_slices(model: ModelFile, volume: Volume, slices: list[int], out_dir: Path) -> list[dict[str, Any]]:
    """Metrics on whole volume slices (e.g. the held-out ones), shown at an exposure that puts the
    slice's 99.9th-percentile Y at 1; also PSNR of the range-transformed values (full dynamic range)."""
    scheme = volume.metadata["scheme"]
    key = grid_to_key(volume_axes(volume.resolution), scheme)
    u_grid, v_grid = np.meshgrid(key, key, indexing="xy")
    reachable = u_grid**2 + v_grid**2 <= 4.0 + 1e-12
    rows, figure_rows = [], []
    for index in slices:
        t = float((volume.metadata.get("slice_t") or np.linspace(0, 1, volume.slices))[index])
        w = slice_w(scheme, t, key, key)
        predicted = np.zeros(volume.xyz.shape[1:])
        predicted[reachable] = evaluate_keys(model, u_grid[reachable], v_grid[reachable], w[reachable])
        reference = volume.xyz[index].astype(np.float64)
        bright = float(np.percentile(reference[reachable][:, 1], 99.9))
        exposure = 1.0 / bright if bright > 0 else 1.0
        metrics = image_metrics(exposure * reference, exposure * predicted, mask=reachable)
        transformed_error = range_forward(reference[reachable], model.range) - range_forward(
            predicted[reachable], model.range
        )
        mse = float(np.mean(np.square(transformed_error)))
        metrics["psnr_transformed"] = float("inf") if mse == 0 else float(10 * np.log10(1.0 / mse))
        rows.append({"slice": f"volume slice {index} (t = {t:.2f})", "exposure": exposure, **metrics})
        figure_rows.append(
            (f"slice {index}, t = {t:.2f}, exposure {exposure:.3g}", exposure * reference, exposure * predicted)
        )
    comparison_figure(out_dir / "volume_slices.png", figure_rows, title="Held-out volume slices")
    return rows


#: The frame of :func:`measure_frame_time`: full HD, one sample per pixel, on the CD disc (gratnet render's view).
FRAME_TIME_SIZE = (1920, 1080)
FRAME_TIME_MESH = "cd"
#: Timed frames (the median is the figure) after bench's warm-up frame.
FRAME_TIME_REPEATS = 3
#: The child's time limit: a pure MLP's baked compile alone takes ~25 s on llvmpipe, a full-HD frame seconds.
FRAME_TIME_TIMEOUT_S = 1800.0


def frame_time_command(model_path: str | Path, out_dir: str | Path, size: tuple[int, int] | None = None,
                       repeats: int | None = None) -> list[str]:
    """The ``gratnet bench`` command line that times one frame size of ``model_path`` on the CD disc as
    ``gratnet render`` draws it (auto weights and render paths, 1 sample per pixel) and writes
    ``out_dir/scenes.jsonl``."""
    width, height = size or FRAME_TIME_SIZE
    return [sys.executable, "-m", "gratnet.cli", "bench", str(model_path), "--no-slices",
            "--scene-mesh", FRAME_TIME_MESH, "--scene-sizes", f"{width}x{height}", "--spp", "1",
            "--weights-paths", "auto", "--render-paths", "auto", "--deferred-weights", "auto",
            "--repeats", str(FRAME_TIME_REPEATS if repeats is None else repeats), "--quiet", "--out", str(out_dir)]


def measure_frame_time(model_path: str | Path, size: tuple[int, int] | None = None, repeats: int | None = None,
                       timeout_s: float | None = None) -> dict[str, Any]:
    """The CD frame time of the model file at ``model_path`` on this machine (default: :data:`FRAME_TIME_SIZE`),
    measured by ``gratnet bench`` in a child process (:func:`frame_time_command`); the trainer imports no runtime.

    Returns the frame in milliseconds (``ms``: median wall time, read-back included; ``gpu_ms``: the GL timer's,
    ``None`` past ~3.9 s), the paths the renderer took, ``GL_RENDERER``, the command, the date and the load
    average before the run. A child that fails or times out is one :class:`GratNetError` with its last words.
    """
    source = Path(model_path)
    if not source.is_file():
        raise GratNetError(f"frame time: model file {source} does not exist or is not a regular file")
    with tempfile.TemporaryDirectory(prefix="gratnet-frame-time-") as folder:
        command = frame_time_command(source, folder, size, repeats)
        load_before = os.getloadavg()
        started = time.time()
        try:
            done = subprocess.run(command, capture_output=True, text=True,
                                  timeout=FRAME_TIME_TIMEOUT_S if timeout_s is None else timeout_s, check=False)
        except subprocess.TimeoutExpired:
            raise GratNetError(f"frame time: gratnet bench took longer than {timeout_s or FRAME_TIME_TIMEOUT_S:g} s "
                               f"on {source}") from None
        if done.returncode != 0:
            last = (done.stderr.strip().splitlines() or ["no message"])[-1]
            raise GratNetError(f"frame time: gratnet bench failed on {source} (exit status {done.returncode}): {last}")
        rows = [json.loads(line) for line in (Path(folder) / "scenes.jsonl").read_text().splitlines() if line]
    if len(rows) != 1:
        raise GratNetError(f"frame time: gratnet bench gave {len(rows)} scene rows for {source}, expected one")
    row = rows[0]
    return {
        "width": row["width"], "height": row["height"], "mesh": row["mesh"], "spp": row["spp"],
        "ms": 1e3 * row["seconds"], "gpu_ms": None if row["gpu_seconds"] is None else 1e3 * row["gpu_seconds"],
        "times_ms": [1e3 * seconds for seconds in row["times_s"]],
        "weights_path": row["weights_path"], "render_path": row["render_path"],
        "deferred_weights": row["deferred_weights"], "gl_renderer": row["gl_renderer"],
        "gl_version": row["gl_version"], "setup_s": row["setup_s"],
        "date": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime(started)),
        "load_average_before": [round(value, 2) for value in load_before],
        "command": shlex.join(["gratnet", *command[3:-2]]),  # as a user types it, without the temporary folder
    }


def _cost_section(model: ModelFile, model_path: str | Path | None, config: EvaluateConfig) -> dict[str, Any]:
    """metrics.json's "cost": gratnet.cost's figures, its summary line and, with ``config.frame_time``, the 1080p
    CD frame (or why there is none: a failure to time it costs the evaluation nothing)."""
    cost = ModelCost.of(model, model_path)
    section: dict[str, Any] = {**cost.to_dict(), "summary": cost.summary()}
    if config.frame_time:
        try:
            if model_path is None:
                raise GratNetError("frame time: the model has no file to time (evaluate_model got no model_path)")
            section["frame_time_1080p"] = measure_frame_time(model_path)
        except GratNetError as error:
            print(f"gratnet evaluate: warning: {error}", file=sys.stderr)
            section["frame_time_1080p"] = {"error": str(error)}
    return section


def evaluate_model(
    model: ModelFile,
    out_dir: str | Path,
    config: EvaluateConfig,
    volume: Volume | None = None,
    field: HeightField | None = None,
    optics: OpticsConfig | None = None,
    volume_slices: list[int] | None = None,
    extra: dict[str, Any] | None = None,
    history: dict[str, Any] | None = None,
    model_path: str | Path | None = None,
) -> dict[str, Any]:
    """Evaluate and write the report folder (metrics.json, report.md, PNG figures; with the training
    ``history``, training_curves.png: loss and per-epoch slice FLIP against the epoch). ``model_path``: the
    model's file, for its size on disk and the frame time (``config.frame_time``)."""
    out_dir = make_folder(out_dir)
    cost = _cost_section(model, model_path, config)
    results: dict[str, Any] = {
        "model": {
            "layer_sizes": model.layer_sizes,
            "parameters": model.parameter_count,
            "macs_per_evaluation": model.macs_per_evaluation,
        },
        "cost": cost,
        **(extra or {}),
    }
    if model.grids:  # a feature-grid network: its grids count in bytes, and its interpolation in MACs (gratnet.cost)
        results["model"].update({"grid_levels": [list(grid.shape) for grid in model.grids],
                                 "grid_bytes": model.grid_bytes,
                                 "grid_interpolation_macs": cost["grid_interpolation_macs_per_pixel"]})
    table: list[dict[str, Any]] = []
    if volume is not None and volume_slices:
        outside = [index for index in volume_slices if not -volume.slices <= index < volume.slices]
        if outside:
            raise GratNetError(f"--volume-slices {','.join(map(str, outside))}: the volume has {volume.slices} slices "
                               f"(0 to {volume.slices - 1})")
        results["volume_slices"] = evaluate_volume_slices(model, volume, volume_slices, out_dir)
        table += results["volume_slices"]
    sections = []
    if field is not None and config.brdf_slices:
        results["brdf_slices"] = evaluate_brdf_slices(model, field, optics or OpticsConfig(), config, out_dir,
                                                      volume=volume)
        table += results["brdf_slices"]
        sections.append(region_table(results["brdf_slices"]))
        if config.oracle and volume is None:
            sections.append("The interpolation oracle needs the volume (--volume): not evaluated.\n")
    if history is not None:
        from trainer.diagnostics import plot_history

        plot_history(history, out_dir / "training_curves.png")
    write_report(
        out_dir,
        results,
        table,
        ["slice", "psnr_xyz", "ssim_ycbcr", "ssim_srgb", "flip", "oracle_flip", "psnr_transformed"],
        title=f"GratNet evaluation: {model.metadata.get('volume', {}).get('source', '?')[:80]}",
        sections=sections,
        intro=[model_section(results["model"], cost)],
    )
    return results
