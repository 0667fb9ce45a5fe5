"""Run time against error: the shader's frame time and MLP throughput beside torch's, for trained models.

(``gratnet bench``'s BRDF-slice part; :mod:`bench.scenes` times mesh scenes. A tool on top of viewer/ and
trainer/: the offline stage does not time the runtime.)

For every model file the benchmark measures, on one BRDF-slice view (docs/physics.md "BRDF slice"):

- the GLSL program's wall time per frame at each requested size (``NetworkRenderer.render_brdf_slice``,
  read-back included, after one warm-up frame that pays for compilation and Mesa's JIT), for each weight
  path (``texture``: RGBA32F mat4 blocks; ``baked``: weights as literals in the shader source) with
  skip-work off, so that every pixel inside the unit disc runs the MLP;
- torch on the same key vectors (CPU, and CUDA where present), as the reference: end to end (encoding +
  MLP + inverse range transform, the shader's per-pixel work) and the MLP alone on pre-encoded inputs
  (the stricter reference: the shader's time always includes its encoding);
- the model's cost (:class:`gratnet.cost.ModelCost`): multiply-adds per pixel (MLP and grid interpolation),
  grid values read per pixel, bytes on disk and on the GPU; and achieved GMAC/s = MACs · evaluated pixels / time,
  for both;
- the model's error from the ``metrics.json`` written beside it by ``gratnet train`` / ``gratnet evaluate``:
  mean FLIP and PSNR (CIE XYZ) over the paper's five BRDF slices, and FLIP at (0°, 0°) 2000 RU.

It writes ``bench.json`` (every measurement), ``bench.md`` (a table) and ``pareto.png`` (error against
shader time per frame, the Pareto front marked) into the output folder. Timings are wall-clock on whatever
GL device the context gets (Mesa llvmpipe on a machine without a GPU); they vary with machine load.
"""

from __future__ import annotations

import dataclasses
import json
import math
import statistics
import time
from pathlib import Path
from typing import Any

import numpy as np

from bench.tables import COST_HEADER, cost_cells, format_cell
from gratnet.atomic import write_text_atomic
from gratnet.brdf import STANDARD_SLICES
from gratnet.codes import RENDER_PATHS
from gratnet.config import config_field
from gratnet.cost import ModelCost
from gratnet.errors import GratNetError
from gratnet.figures import save_figure
from gratnet.modelfile import ModelFile, load_model, network_inputs
from viewer.renderer import BAKED_MAX_MACS

__all__ = ["BenchConfig", "ModelEntry", "pareto_front", "run_bench", "shader_frame_times", "torch_throughput"]


@dataclasses.dataclass
class BenchConfig:
    """What ``gratnet bench`` measures."""

    sizes: str = config_field("512,1001", "BRDF-slice sizes to time, pixels per side, comma-separated")
    weights_paths: str = config_field(
        "texture,baked", "shader weight paths to time, comma-separated: texture, baked, auto")
    light_theta_degrees: float = config_field(30.0, "light polar angle of the timed BRDF slice, degrees")
    light_phi_degrees: float = config_field(0.0, "light azimuth of the timed BRDF slice, degrees")
    exposure: float = config_field(5000.0, "exposure of the timed slice (linear factor on A·XYZ)")
    repeats: int = config_field(3, "timed frames per measurement (the median is reported)")
    max_seconds: float = config_field(
        60.0, "stop repeating a measurement once its frames have taken this long in total, seconds")
    baked_max_macs: int = config_field(
        BAKED_MAX_MACS, "time the baked path only for nets up to this many MACs per pixel (above it Mesa's JIT "
        "takes minutes)")
    torch_devices: str = config_field("auto", "torch devices for the reference: auto (cpu, plus cuda if present)")
    torch_threads: int = config_field(0, "torch CPU threads (0: torch's default, one per core)")
    slices: bool = config_field(True, "time the BRDF-slice program against torch (--no-slices: scenes only)")
    scenes: bool = config_field(True, "time mesh scenes (--scene-mesh as gratnet render sets it up) per weights "
                                "path, render path and samples per pixel (--no-scenes: slices only)")
    scene_mesh: str = config_field("cd", "mesh of the timed scenes: cd, sphere, plane or an .obj file")
    scene_sizes: str = config_field(
        "1920x1080,512x512", "scene image sizes, WxH comma-separated (1920x1080: full HD; 512x512: gratnet view's "
        "default picture)")
    render_paths: str = config_field(
        "all", "scene render paths, comma-separated: forward, deferred, auto, or all (every path this build's "
        "renderer offers)")
    spp: str = config_field("1,4", "scene samples per pixel (anti-aliasing), comma-separated, each 1 … 1024",
                            aliases=("--samples",))
    deferred_weights: str = config_field(
        "auto", "deferred render path only: its network kernels and weight forms to time, comma-separated, as gratnet "
        "render's --deferred-weights (e.g. auto,tiled,tiled-fp16); other render paths take auto")

    def scene_size_list(self) -> list[tuple[int, int]]:
        sizes = []
        for part in (part.strip() for part in self.scene_sizes.split(",") if part.strip()):
            pieces = part.lower().replace("×", "x").split("x")
            if len(pieces) != 2 or not all(piece.strip().isdigit() for piece in pieces):
                raise GratNetError(f"--scene-sizes expects WxH,… such as 1920x1080,512x512; got {self.scene_sizes!r}")
            width, height = (int(piece) for piece in pieces)
            if not (1 <= width <= 16384 and 1 <= height <= 16384):
                raise GratNetError(f"--scene-sizes must lie in 1 … 16384 per side, got {part!r}")
            sizes.append((width, height))
        if not sizes:
            raise GratNetError(f"--scene-sizes expects WxH,… such as 1920x1080,512x512; got {self.scene_sizes!r}")
        return sizes

    def render_path_list(self) -> list[str]:
        from bench.scenes import available_render_paths, check_render_paths

        paths = [part.strip() for part in self.render_paths.split(",") if part.strip()]
        if paths == ["all"]:
            return list(available_render_paths())
        if not paths or any(path not in RENDER_PATHS for path in paths):
            raise GratNetError(f"--render-paths takes forward, deferred, auto or all; got {self.render_paths!r}")
        check_render_paths(paths)
        return paths

    def deferred_weights_list(self) -> list[str]:
        from viewer.scene_config import DEFERRED_WEIGHTS

        forms = [part.strip() for part in self.deferred_weights.split(",") if part.strip()]
        bad = [form for form in forms if form not in DEFERRED_WEIGHTS]
        if not forms or bad:
            raise GratNetError(f"--deferred-weights takes {', '.join(DEFERRED_WEIGHTS)}; got {self.deferred_weights!r}")
        return forms

    def spp_list(self) -> list[int]:
        counts = _int_list(self.spp, "--spp")
        if any(not 1 <= count <= 1024 for count in counts):
            raise GratNetError(f"--spp (samples per pixel) must lie in 1 … 1024, got {self.spp!r}")
        return counts

    def size_list(self) -> list[int]:
        sizes = _int_list(self.sizes, "--sizes")
        if any(not 2 <= size <= 16384 for size in sizes):
            raise GratNetError(f"--sizes must lie in 2 … 16384, got {self.sizes!r}")
        return sizes

    def path_list(self) -> list[str]:
        paths = [part.strip() for part in self.weights_paths.split(",") if part.strip()]
        bad = [path for path in paths if path not in ("texture", "baked", "auto")]
        if not paths or bad:
            raise GratNetError(f"--weights-paths takes texture, baked, auto; got {self.weights_paths!r}")
        return paths

    def __post_init__(self) -> None:
        if self.repeats < 1:
            raise GratNetError(f"--repeats must be ≥ 1, got {self.repeats}")
        if not (math.isfinite(self.exposure) and self.exposure > 0):
            raise GratNetError(f"--exposure must be a positive number, got {self.exposure}")
        if not 0.0 <= self.light_theta_degrees < 90.0:
            raise GratNetError(f"--light-theta-degrees must lie in [0, 90), got {self.light_theta_degrees}")


def _int_list(text: str, flag: str) -> list[int]:
    try:
        values = [int(part) for part in text.split(",") if part.strip()]
    except ValueError:
        values = []
    if not values:
        raise GratNetError(f"{flag} expects comma-separated integers, got {text!r}")
    return values


@dataclasses.dataclass
class ModelEntry:
    """One model to benchmark: its file, a label, its error figures (from metrics.json) and its cost."""

    label: str
    path: Path
    model: ModelFile
    material: str
    flip_mean: float | None
    flip_normal: float | None  # FLIP at (0°, 0°) 2000 RU
    psnr_mean: float | None
    cost: ModelCost

    @classmethod
    def load(cls, path: Path, label: str | None = None) -> ModelEntry:
        model = load_model(path)
        source = str(model.metadata.get("volume", {}).get("source", "unknown"))
        material = source.split("generator:", 1)[-1].split("(", 1)[0] if source.startswith("generator:") else source
        flip_mean = flip_normal = psnr_mean = None
        metrics_path = path.with_name("metrics.json")
        if metrics_path.is_file():
            by_view = {(float(entry["theta"]), float(entry["phi"]), float(entry["exposure"])): entry
                       for entry in json.loads(metrics_path.read_text()).get("brdf_slices", [])}
            if all(view in by_view for view in STANDARD_SLICES):  # further views beside them are not counted
                slices = [by_view[view] for view in STANDARD_SLICES]
                flip_mean = statistics.fmean(float(entry["flip"]) for entry in slices)
                psnr_mean = statistics.fmean(float(entry["psnr_xyz"]) for entry in slices)
                flip_normal = float(slices[0]["flip"])
        return cls(label or path.parent.name, path, model, material, flip_mean, flip_normal, psnr_mean,
                   ModelCost.of(model, path))


def _slice_keys(config: BenchConfig, size: int) -> np.ndarray:
    """Key vectors −(ωi + ωo) of the slice's pixels inside the unit disc, ``(N, 3)`` float32."""
    from trainer.brdfslice import SliceConfig, slice_geometry

    light, views, inside = slice_geometry(SliceConfig(config.light_theta_degrees, config.light_phi_degrees, size,
                                                      config.exposure))
    return (-(light + views[inside])).astype(np.float32)


def torch_throughput(model: ModelFile, keys: np.ndarray, device: str, repeats: int, max_seconds: float,
                     threads: int = 0) -> dict[str, Any]:
    """Median wall times in torch for ``keys`` on ``device``: end to end (encoding + MLP + inverse range
    transform, the work the shader does per pixel) and the MLP alone on pre-encoded inputs."""
    import torch

    from gratnet.encoding import network_coordinates, range_inverse
    from trainer.model import FunnelMLP

    if threads:
        torch.set_num_threads(threads)
    network = FunnelMLP(model.layer_sizes[0], list(model.layer_sizes[1:-1]), model.activation,
                        model.output_activation)
    with torch.no_grad():
        for layer, weight, bias in zip(network.linear_layers(), model.weights, model.biases, strict=True):
            layer.weight.copy_(torch.from_numpy(weight))
            layer.bias.copy_(torch.from_numpy(bias))
    network = network.to(device).eval()
    # a feature-grid model's grids, widened to float32 as the shader's textures are read (eq. 6g)
    grids = [torch.from_numpy(np.asarray(grid, np.float32)).to(device) for grid in model.grids]
    key_tensor = torch.from_numpy(keys).to(device)
    batch = 1 << 17  # bounds the encoded batch at ~85 MB (163 float32 features)

    def synchronize() -> None:
        if device.startswith("cuda"):
            torch.cuda.synchronize()

    def encoded(chunk: torch.Tensor) -> torch.Tensor:
        return network_inputs(model, network_coordinates(chunk[:, 0], chunk[:, 1], chunk[:, 2], model.scheme),
                              grids)

    def end_to_end() -> None:
        for start in range(0, key_tensor.shape[0], batch):
            range_inverse(network.predict(encoded(key_tensor[start:start + batch])), model.range)
        synchronize()

    with torch.inference_mode():
        inputs = torch.cat([encoded(key_tensor[start:start + batch])
                            for start in range(0, key_tensor.shape[0], batch)])

        def mlp_only() -> None:
            for start in range(0, inputs.shape[0], batch):
                network.predict(inputs[start:start + batch])
            synchronize()

        end_to_end()  # warm-up: allocations, kernels
        mlp_only()
        times = _timed(end_to_end, repeats, max_seconds)
        mlp_times = _timed(mlp_only, repeats, max_seconds)
    return {"device": device, "threads": torch.get_num_threads() if device == "cpu" else None,
            "times_s": times, "seconds": statistics.median(times),
            "mlp_times_s": mlp_times, "mlp_seconds": statistics.median(mlp_times)}


def _timed(function: Any, repeats: int, max_seconds: float) -> list[float]:
    times: list[float] = []
    while len(times) < repeats and sum(times) < max_seconds:
        start = time.perf_counter()
        function()
        times.append(time.perf_counter() - start)
    return times


def shader_frame_times(ctx: Any, entry: ModelEntry, path: str, config: BenchConfig, sizes: list[int],
                       ) -> list[dict[str, Any]]:
    """Frame times of the brdf_slice program for each size, on weight path ``path``, skip-work off."""
    from viewer.renderer import NetworkRenderer

    rows: list[dict[str, Any]] = []
    start = time.perf_counter()
    renderer = NetworkRenderer(ctx, entry.model, weights_path=path)
    try:
        view = (config.light_theta_degrees, config.light_phi_degrees)

        def frame(size: int) -> None:
            renderer.render_brdf_slice(*view, size, config.exposure, skip_threshold=0.0)

        frame(8)  # compile, link and first draw (Mesa JITs on first use)
        setup_seconds = time.perf_counter() - start
        for size in sizes:
            frame(size)  # warm-up at this size
            times = _timed(lambda size=size: frame(size), config.repeats, config.max_seconds)
            rows.append({"size": size, "weights_path": renderer.weights_path, "setup_s": setup_seconds,
                         "times_s": times, "seconds": statistics.median(times)})
    finally:
        renderer.release()
    return rows


def pareto_front(points: list[tuple[float, float]]) -> list[int]:
    """Indices of the points (cost, error) that no other point beats in both (lower is better), by cost."""
    order = sorted(range(len(points)), key=lambda index: (points[index][0], points[index][1]))
    front: list[int] = []
    best_error = math.inf
    for index in order:
        if points[index][1] < best_error:
            front.append(index)
            best_error = points[index][1]
    return front


def _torch_devices(config: BenchConfig) -> list[str]:
    import torch

    if config.torch_devices == "auto":
        return ["cpu", *(["cuda"] if torch.cuda.is_available() else [])]
    devices = [part.strip() for part in config.torch_devices.split(",") if part.strip()]
    if not devices:
        raise GratNetError(f"--torch-devices expects auto or a list such as cpu,cuda; got {config.torch_devices!r}")
    return devices


def run_bench(ctx: Any, entries: list[ModelEntry], config: BenchConfig, progress: bool = True,
              ) -> list[dict[str, Any]]:
    """Measure every entry (see the module docstring); one result dict per (model, size, weight path)."""
    from tqdm import tqdm

    sizes = config.size_list()
    paths = config.path_list()
    devices = _torch_devices(config)
    gl_device = str(ctx.info.get("GL_RENDERER", "unknown"))
    keys = {size: _slice_keys(config, size) for size in sizes}  # the same view for every model
    results: list[dict[str, Any]] = []
    for entry in tqdm(entries, desc="bench", unit="model", disable=not progress):
        macs = entry.cost.macs_per_pixel  # what a pixel costs: the MLP's and a grid's interpolation multiply-adds
        torch_rows = {}
        for size in sizes:
            for device in devices:
                torch_rows[size, device] = torch_throughput(entry.model, keys[size], device, config.repeats,
                                                            config.max_seconds, config.torch_threads)
        for path in paths:
            if path == "baked" and entry.cost.mlp_macs > config.baked_max_macs:  # the limit is on the baked MLP
                continue
            for row in shader_frame_times(ctx, entry, path, config, sizes):
                size = row["size"]
                pixels = int(keys[size].shape[0])
                gmacs = macs * pixels / row["seconds"] / 1e9
                result = {
                    "model": entry.label, "material": entry.material, "path": str(entry.path),
                    "parameters": entry.model.parameter_count, **entry.cost.to_dict(),
                    "layer_sizes": list(entry.model.layer_sizes),
                    "flip_mean": entry.flip_mean, "flip_0_0": entry.flip_normal, "psnr_mean_db": entry.psnr_mean,
                    "gl_renderer": gl_device, "requested_weights_path": path, **row,
                    "evaluated_pixels": pixels, "shader_gmac_per_s": gmacs,
                }
                for device in devices:
                    reference = torch_rows[size, device]
                    torch_gmacs = macs * pixels / reference["seconds"] / 1e9
                    mlp_gmacs = macs * pixels / reference["mlp_seconds"] / 1e9
                    result[f"torch_{device}_seconds"] = reference["seconds"]
                    result[f"torch_{device}_gmac_per_s"] = torch_gmacs
                    result[f"shader_over_torch_{device}"] = gmacs / torch_gmacs
                    result[f"torch_{device}_mlp_seconds"] = reference["mlp_seconds"]
                    result[f"torch_{device}_mlp_gmac_per_s"] = mlp_gmacs
                    result[f"shader_over_torch_{device}_mlp"] = gmacs / mlp_gmacs
                results.append(result)
                if progress:
                    tqdm.write(json.dumps({key: result[key] for key in (
                        "model", "size", "weights_path", "seconds", "shader_gmac_per_s",
                        "torch_cpu_gmac_per_s", "shader_over_torch_cpu", "shader_over_torch_cpu_mlp")
                        if key in result}))
    return results


def markdown_table(results: list[dict[str, Any]]) -> str:
    """One row per (model, size, weight path)."""
    header = (f"| model | material | parameters | {COST_HEADER} | size | weights | frame (ms) | shader GMAC/s "
              "| torch-CPU GMAC/s, end to end | shader / torch | torch-CPU GMAC/s, MLP only | shader / torch MLP "
              "| mean FLIP (5 slices) | FLIP (0°,0°) | mean PSNR (dB) |")
    lines = [header, "|" + "---|" * (header.count("|") - 1)]
    for row in results:
        lines.append("| " + " | ".join(format_cell(value) for value in (
            row["model"], row["material"], row["parameters"], *cost_cells(row), f"{row['size']}²", row["weights_path"],
            row["seconds"] * 1e3, row["shader_gmac_per_s"], row.get("torch_cpu_gmac_per_s"),
            row.get("shader_over_torch_cpu"), row.get("torch_cpu_mlp_gmac_per_s"), row.get("shader_over_torch_cpu_mlp"),
            row["flip_mean"], row["flip_0_0"], row["psnr_mean_db"])) + " |")
    return "\n".join(lines) + "\n"


def paper_size_comparison(results: list[dict[str, Any]], paper_hidden: tuple[int, ...]) -> list[str]:
    """Per material with a paper-default-size model: the cheapest model whose mean FLIP is at most the paper
    size's, and its multiply-adds as a fraction of the paper size's (the issue's target: ≤ 1/4)."""
    lines = []
    models = {row["model"]: row for row in results if row["flip_mean"] is not None}
    for paper in [row for row in models.values() if tuple(row["layer_sizes"][1:-1]) == paper_hidden]:
        same = [row for row in models.values() if row["material"] == paper["material"]]
        matching = sorted((row for row in same if row["flip_mean"] <= paper["flip_mean"]),
                          key=lambda row: row["macs_per_pixel"])
        best = matching[0]
        lines.append(
            f"- {paper['material']}: the paper-default size ({paper['model']}, {paper['macs_per_pixel']:,} MACs/pixel) "
            f"has mean FLIP {paper['flip_mean']:.4f}; the cheapest model at or below that error is {best['model']} "
            f"({best['macs_per_pixel']:,} MACs/pixel, {best['macs_per_pixel'] / paper['macs_per_pixel']:.1%} of it, "
            f"mean FLIP {best['flip_mean']:.4f}).")
    return lines


def plot_pareto(results: list[dict[str, Any]], output: Path) -> None:
    """Mean FLIP against shader time per frame, one panel per size, the front of each marked; atomic PNG."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    sizes = sorted({row["size"] for row in results})
    figure, axes = plt.subplots(1, len(sizes), figsize=(6.2 * len(sizes), 4.8), squeeze=False)
    for axis, size in zip(axes[0], sizes, strict=True):
        rows = [row for row in results if row["size"] == size and row["flip_mean"] is not None]
        for path, marker in (("texture", "o"), ("baked", "s")):
            chosen = [row for row in rows if row["weights_path"] == path]
            axis.scatter([row["seconds"] * 1e3 for row in chosen], [row["flip_mean"] for row in chosen],
                         marker=marker, label=f"GLSL, {path} weights", zorder=3)
            for row in chosen:
                axis.annotate(f"{row['model']} ({row['macs_per_pixel'] / 1e3:.1f}k MAC)",
                              (row["seconds"] * 1e3, row["flip_mean"]), fontsize=7, xytext=(4, 3),
                              textcoords="offset points")
        # Errors of different materials are not comparable: one front per material with several models.
        for material in sorted({row["material"] for row in rows}):
            same = [row for row in rows if row["material"] == material]
            if len(same) < 2:
                continue
            front = [same[index] for index in pareto_front([(row["seconds"], row["flip_mean"]) for row in same])]
            axis.step([row["seconds"] * 1e3 for row in front], [row["flip_mean"] for row in front], where="post",
                      linestyle="--", label=f"Pareto front, {material}", zorder=2)
        if rows:
            axis.set_xscale("log")
            axis.set_yscale("log")
        else:
            axis.text(0.5, 0.5, "no model has a metrics.json (error) beside it", ha="center", va="center",
                      transform=axis.transAxes)
        axis.set_xlabel(f"shader time per {size}² BRDF-slice frame (ms, log)")
        axis.set_ylabel("mean FLIP over the five evaluation slices (log)")
        axis.set_title(f"error against run time, {size}²  [{rows[0]['gl_renderer'] if rows else ''}]", fontsize=9)
        axis.grid(True, which="both", alpha=0.3)
        if rows:
            axis.legend(fontsize=7)
    figure.tight_layout()
    save_figure(figure, output, dpi=120)
    plt.close(figure)


def write_outputs(results: list[dict[str, Any]], out_dir: Path) -> None:
    """bench.json, bench.md and pareto.png in ``out_dir`` (each written atomically)."""
    out_dir.mkdir(parents=True, exist_ok=True)
    from gratnet.jsontext import strict_json

    write_text_atomic(out_dir / "bench.json", json.dumps(json.loads(strict_json(results, "bench results")), indent=1)
                      + "\n")
    from trainer.model import funnel_sizes

    summary = paper_size_comparison(results, tuple(funnel_sizes(464)))
    write_text_atomic(out_dir / "bench.md", markdown_table(results) + ("\n" + "\n".join(summary) + "\n" if summary
                                                                      else ""))
    plot_pareto(results, out_dir / "pareto.png")
