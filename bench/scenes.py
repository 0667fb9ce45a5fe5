"""Frame times of mesh scenes: what a user of ``gratnet render`` and ``gratnet view`` waits for (issue 12).

For every model, the mesh (the CD disc by default) is set up as ``gratnet render --mesh cd`` sets it up
(light, camera and exposure from :func:`viewer.defaults.resolve_defaults`, Fresnel at n = 1.5) and
rendered with :meth:`viewer.scene.SceneRenderer.render_rgba` at each requested size, per weights path
(``texture``, ``baked``), per render path (``forward``; ``deferred`` and ``auto`` where the installed
SceneRenderer takes a ``render_path``) and per sample count (anti-aliasing: ``samples`` per pixel). A
frame is one ``render_rgba`` call, read-back of the float image included (a window or a file needs it),
after a warm-up frame at the same size that pays for compilation, Mesa's JIT and allocations. Two times
per frame: the wall time (the read-back waits for the GPU, so it includes all GPU work) and the GL timer
query's GPU time of the same commands (none for frames over ~3.9 s: moderngl reads the timer as 32 bits of
nanoseconds). Every row records ``GL_RENDERER``. The deferred path is timed per ``--deferred-weights`` form
(its network kernel and weights: the per-entry SHADE kernel, or the tiled one, issue 32).

Every row states the model's cost (:class:`gratnet.cost.ModelCost`: MACs and grid values read per pixel, bytes on
disk and on the GPU). Throughput: ``MACs/pixel × evaluations / frame time`` in TMAC/s (the MACs of the MLP and a
grid's interpolation; the GPU timer's time where there is one, else the wall time; the whole frame, G-buffer and
compaction included), and its share of the device's peak FP32
multiply-add rate (:mod:`bench.devices`: datasheet figures keyed by ``GL_RENDERER``; blank for llvmpipe and
unknown devices).

Skip-work is off (no ``skip_threshold``): every covered pixel runs the network, as for an EXR file.
"""

from __future__ import annotations

import dataclasses
import json
import statistics
import time
from typing import Any

import numpy as np

from bench.tables import COST_HEADER, cost_cells, format_cell
from gratnet.cost import ModelCost
from gratnet.errors import GratNetError

__all__ = ["SceneView", "available_render_paths", "check_render_paths", "json_lines", "markdown_table",
           "run_scene_bench", "scene_frame_times", "scene_view", "write_scene_outputs"]

def available_render_paths() -> tuple[str, ...]:
    """The render paths a :class:`~viewer.scene.SceneRenderer` takes (:data:`viewer.scene.RENDER_PATHS`)."""
    from viewer.scene import RENDER_PATHS

    return tuple(RENDER_PATHS)


@dataclasses.dataclass(frozen=True)
class SceneView:
    """A mesh, its camera, light and exposure, as ``gratnet render`` chooses them."""

    mesh: str
    camera: Any  # viewer.camera.Camera
    light: Any  # viewer.camera.Light
    exposure: float
    ior: float | None = 1.5


def scene_view(model_path: str, mesh: str) -> SceneView:
    """``gratnet render --material MODEL --mesh MESH``'s view (its defaults for that pair)."""
    from viewer.camera import Camera, Light
    from viewer.defaults import FOV_DEGREES, resolve_defaults

    defaults = resolve_defaults(model_path, mesh)
    camera = Camera(defaults.camera_distance, defaults.camera_azimuth_degrees, defaults.camera_elevation_degrees,
                    fov_deg=FOV_DEGREES)
    light = Light.directional(defaults.light_theta_degrees, defaults.light_phi_degrees)
    return SceneView(mesh, camera, light, defaults.exposure)


#: Warm-up before timing: frames until this many seconds have passed (at least one, at most
#: :data:`_WARMUP_FRAMES`). One frame was not enough on an H100: after seconds of compiling on the CPU the idle
#: GPU's clocks were down, and the first configuration timed ran at half speed (docs/benchmarks.md "GPU bench").
_WARMUP_SECONDS = 0.5
_WARMUP_FRAMES = 20

#: moderngl reads GL_TIME_ELAPSED as a 32-bit count of nanoseconds: frames longer than this (llvmpipe at full HD)
#: have no GPU time (``None``); their wall time stands.
_TIMER_LIMIT_S = (2**32 - 1) * 1e-9


def _timed(frame: Any, ctx: Any, repeats: int, max_seconds: float) -> tuple[list[float], list[float | None]]:
    """Wall and GL-timer seconds of ``frame()`` calls: ``repeats`` of them, fewer once ``max_seconds`` is spent."""
    walls: list[float] = []
    gpus: list[float | None] = []
    query = ctx.query(time=True)  # moderngl 5 frees queries with the context (they have no release())
    while len(walls) < repeats and sum(walls) < max_seconds:
        start = time.perf_counter()
        with query:
            frame()
        ctx.finish()
        walls.append(time.perf_counter() - start)
        elapsed = query.elapsed * 1e-9  # nanoseconds; waits for the result
        gpus.append(elapsed if walls[-1] < 0.9 * _TIMER_LIMIT_S else None)
    return walls, gpus


def _warm_up(frame: Any, ctx: Any) -> Any:
    """Render until :data:`_WARMUP_SECONDS` have passed (1 to :data:`_WARMUP_FRAMES` frames); the last result."""
    started = time.perf_counter()
    for _ in range(_WARMUP_FRAMES):
        result = frame()
        ctx.finish()
        if time.perf_counter() - started >= _WARMUP_SECONDS:
            break
    return result


def scene_frame_times(ctx: Any, model: Any, model_path: str, view: SceneView, weights_path: str,
                      render_path: str, sizes: list[tuple[int, int]], samples: list[int], repeats: int,
                      max_seconds: float, deferred_weights: str = "auto") -> list[dict[str, Any]]:
    """One row per (size, samples) for one model on one weights path, render path and deferred weights form
    (see the module docstring); ``model_path`` only labels the rows."""
    from bench.devices import fp32_tmac_per_s
    from viewer.catalog import build_mesh
    from viewer.scene import SceneRenderer

    start = time.perf_counter()
    peak = fp32_tmac_per_s(str(ctx.info.get("GL_RENDERER", "")))
    macs = ModelCost.of(model).macs_per_pixel  # per evaluation: the MLP's and a grid's interpolation
    renderer = SceneRenderer(ctx, model, weights_path=weights_path, render_path=render_path,
                             deferred_weights=deferred_weights)
    buffers = None
    rows: list[dict[str, Any]] = []
    try:
        network = renderer.network
        assert network is not None  # a model file's scene shades with its network
        buffers = renderer.upload(build_mesh(view.mesh))

        def frame(size: tuple[int, int], count: int) -> np.ndarray:
            return renderer.render_rgba(buffers, view.camera, view.light, size, view.exposure, view.ior,
                                        samples=count)

        frame((8, 8), 1)  # compile, link and first draw (Mesa JITs on first use)
        setup_seconds = time.perf_counter() - start
        for size in sizes:
            for count in samples:
                coverage = _warm_up(lambda size=size, count=count: frame(size, count), ctx)[..., 3]
                walls, gpus = _timed(lambda size=size, count=count: frame(size, count), ctx, repeats, max_seconds)
                seconds = statistics.median(walls)
                timed_gpus = [gpu for gpu in gpus if gpu is not None]
                gpu_seconds = statistics.median(timed_gpus) if len(timed_gpus) == len(gpus) else None
                evaluations = float(np.sum(coverage)) * count  # samples that hit the mesh, each one evaluation
                path = str(getattr(renderer, "render_path", render_path))
                tmacs = macs * evaluations / (gpu_seconds or seconds) / 1e12
                deferred = renderer.deferred if path == "deferred" else None
                plan = deferred.tile_plan if deferred is not None else None  # the tiled kernel's
                rows.append({
                    "kind": "scene", "mesh": view.mesh, "width": size[0], "height": size[1], "spp": count,
                    "requested_weights_path": weights_path, "weights_path": network.weights_path,
                    "requested_render_path": render_path, "render_path": path,
                    "requested_deferred_weights": deferred_weights,
                    "deferred_weights": deferred.weights if deferred is not None else None,
                    "tile_plan": None if plan is None else plan.describe(network.layout),
                    "tile_pixels": None if plan is None else plan.pixels,
                    "tile_group": None if plan is None else plan.group,
                    "tile_shared_bytes": None if plan is None else plan.shared_bytes,
                    "setup_s": setup_seconds, "times_s": walls, "seconds": seconds, "gpu_times_s": gpus,
                    "gpu_seconds": gpu_seconds, "fps": 1.0 / seconds,
                    "covered_pixels": int(np.count_nonzero(coverage)), "evaluations": evaluations,
                    "gmac_per_s": macs * evaluations / seconds / 1e9,
                    "tmac_per_s": tmacs, "fp32_tmac_per_s": peak,
                    "fp32_share": tmacs / peak if peak else None,
                    "model_file": model_path,
                })
    finally:
        if buffers is not None:
            buffers.release()
        renderer.release()
    return rows


def _milliseconds(seconds: float | None) -> str:
    if seconds is None:
        return "—"
    milliseconds = seconds * 1e3
    return f"{milliseconds:.0f}" if milliseconds >= 100 else f"{milliseconds:.3g}"


def markdown_table(rows: list[dict[str, Any]]) -> str:
    """One row per (model, size, weights path, render path, samples per pixel)."""
    header = (f"| model | {COST_HEADER} | mesh | size | weights | render path | deferred weights | spp "
              "| frame (ms, wall) | GPU (ms, timer) | fps | covered pixels | TMAC/s | of FP32 peak | GL_RENDERER |")
    lines = [header, "|" + "---|" * (header.count("|") - 1)]
    for row in rows:
        render_path = row["render_path"]
        if row["requested_render_path"] != render_path:
            render_path = f"{row['requested_render_path']} → {render_path}"
        deferred = row.get("deferred_weights")
        if deferred is not None and row.get("requested_deferred_weights", deferred) != deferred:
            deferred = f"{row['requested_deferred_weights']} → {deferred}"
        if row.get("tile_pixels") is not None:  # the tiled kernel's plan, in short
            deferred = (f"{deferred} ({row['tile_pixels']} px, {row['tile_group']} inv., "
                        f"{row['tile_shared_bytes'] / 1024:g} KiB)")
        share = row.get("fp32_share")
        lines.append("| " + " | ".join(format_cell(value) for value in (
            row["model"], *cost_cells(row), row["mesh"], f"{row['width']}×{row['height']}", row["weights_path"],
            render_path, deferred, row["spp"], _milliseconds(row["seconds"]), _milliseconds(row["gpu_seconds"]),
            row["fps"], row["covered_pixels"], row.get("tmac_per_s"), None if share is None else f"{100 * share:.1f} %",
            row["gl_renderer"])) + " |")
    return "\n".join(lines) + "\n"


def json_lines(rows: list[dict[str, Any]]) -> str:
    """One JSON object per line (strict JSON: no NaN)."""
    from gratnet.jsontext import strict_json

    return "".join(json.dumps(json.loads(strict_json(row, "bench scene row"))) + "\n" for row in rows)


def check_render_paths(requested: list[str]) -> None:
    """Refuse (one line) a render path the installed SceneRenderer does not offer."""
    available = available_render_paths()
    missing = [path for path in requested if path not in available]
    if missing:
        raise GratNetError(f"--render-paths: this build's renderer offers {', '.join(available)}; "
                           f"not {', '.join(missing)}")


def _path_forms(render_paths: list[str], forms: list[str]) -> list[tuple[str, str]]:
    """(render path, deferred weights) pairs: the deferred path once per form, the others with ``auto``."""
    return [(path, form) for path in render_paths for form in (forms if path == "deferred" else ["auto"])]


def run_scene_bench(ctx: Any, entries: list[Any], config: Any, progress: bool = True) -> list[dict[str, Any]]:
    """Every model (``bench.slices.ModelEntry``) × weights path × render path × size × samples per pixel of
    ``config`` (``bench.slices.BenchConfig``); nets above ``baked_max_macs`` skip the baked path."""
    from tqdm import tqdm

    sizes, paths, samples = config.scene_size_list(), config.path_list(), config.spp_list()
    render_paths, forms = config.render_path_list(), config.deferred_weights_list()
    gl_renderer = str(ctx.info.get("GL_RENDERER", "unknown"))
    gl_version = str(ctx.info.get("GL_VERSION", "unknown"))
    rows: list[dict[str, Any]] = []
    for entry in tqdm(entries, desc="bench scenes", unit="model", disable=not progress):
        view = scene_view(str(entry.path), config.scene_mesh)
        for weights_path in paths:
            if weights_path == "baked" and entry.cost.mlp_macs > config.baked_max_macs:  # the limit is on the baked MLP
                continue
            for render_path, deferred_weights in _path_forms(render_paths, forms):
                if deferred_weights == "baked" and weights_path != "baked":
                    continue  # the baked kernel needs the baked weights path (and is auto's choice there)
                for row in scene_frame_times(ctx, entry.model, str(entry.path), view, weights_path, render_path, sizes,
                                             samples, config.repeats, config.max_seconds, deferred_weights):
                    row = {"model": entry.label, "material": entry.material, **entry.cost.to_dict(),
                           "gl_renderer": gl_renderer, "gl_version": gl_version, **row}
                    rows.append(row)
                    if progress:
                        tqdm.write(json.dumps({key: row[key] for key in (
                            "model", "width", "height", "weights_path", "render_path", "deferred_weights", "spp",
                            "seconds", "gpu_seconds", "tmac_per_s")}))
    return rows


def write_scene_outputs(rows: list[dict[str, Any]], out_dir: Any) -> None:
    """``scenes.jsonl`` (one JSON object per row) and ``scenes.md`` (the table) in ``out_dir``, atomically."""
    from gratnet.atomic import write_text_atomic

    out_dir.mkdir(parents=True, exist_ok=True)
    write_text_atomic(out_dir / "scenes.jsonl", json_lines(rows))
    write_text_atomic(out_dir / "scenes.md", markdown_table(rows))
