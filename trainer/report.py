"""Evaluation reports: side-by-side comparison figures, a markdown metrics table, metrics.json."""

from __future__ import annotations

import json
import math
import numbers
import os
from pathlib import Path
from typing import Any
from urllib.parse import quote

import numpy as np

from gratnet.atomic import write_text_atomic
from gratnet.errors import GratNetError
from gratnet.figures import save_figure
from trainer.metrics import show_pair

#: Width of one image panel in the comparison figure, inches.
_PANEL_INCHES = 3.0
#: Resolution of the comparison figure.
FIGURE_DPI = 120


def comparison_figure(
    path: str | os.PathLike[str], rows: list[tuple[str, np.ndarray, np.ndarray]], title: str = ""
) -> None:
    """Write a PNG with one row per ``(label, reference_xyz, test_xyz)``.

    Columns: "ground truth" | "network" (display sRGB of the exposed XYZ images) | "FLIP error"
    (the LDR-FLIP map, 'magma' colormap, colour bar 0…1). Each row is labelled with its mean FLIP
    and its PSNR (XYZ clipped to [0, 1], whole image). The figure is (3 panels + colour bar) wide
    and one panel per row high, panel height following the widest aspect ratio among the rows.
    """
    if not rows:
        raise GratNetError("comparison_figure needs at least one (label, reference, test) row")
    prepared = []
    aspect = 0.0
    for label, reference_xyz, test_xyz in rows:
        shown = show_pair(reference_xyz, test_xyz)
        prepared.append((str(label), shown.reference_srgb, shown.test_srgb, shown.flip_map, shown.mean_flip,
                         shown.psnr_db))
        aspect = max(aspect, shown.reference_srgb.shape[0] / shown.reference_srgb.shape[1])

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    count = len(prepared)
    title_inches = 0.4 if title else 0.0
    header_inches = 0.3
    width = 3 * _PANEL_INCHES + 0.9  # three panels and the colour bar
    height = count * _PANEL_INCHES * aspect + header_inches + title_inches
    figure, axes = plt.subplots(count, 3, figsize=(width, height), dpi=FIGURE_DPI, squeeze=False, layout="constrained")
    try:
        for index, (label, reference_srgb, test_srgb, error_map, mean_flip, psnr) in enumerate(prepared):
            row = axes[index]
            row[0].imshow(reference_srgb, interpolation="nearest")
            row[1].imshow(test_srgb, interpolation="nearest")
            image = row[2].imshow(error_map, cmap="magma", vmin=0.0, vmax=1.0, interpolation="nearest")
            figure.colorbar(image, ax=row[2], fraction=0.046, pad=0.04)
            for axis in row:
                axis.set_xticks([])
                axis.set_yticks([])
            psnr_text = "∞" if math.isinf(psnr) else f"{psnr:.2f}"
            row[0].set_ylabel(f"{label}\nFLIP {mean_flip:.4f}  PSNR {psnr_text} dB", fontsize=8)
            if index == 0:
                for axis, name in zip(row, ("ground truth", "network", "FLIP error"), strict=True):
                    axis.set_title(name, fontsize=9)
        if title:
            figure.suptitle(title, fontsize=10)
        save_figure(figure, path, dpi=FIGURE_DPI)
    finally:
        plt.close(figure)


def _format_cell(value: Any) -> str:
    if value is None:
        return "—"
    if isinstance(value, (bool, np.bool_)):
        return str(bool(value))
    if isinstance(value, numbers.Integral):
        return str(int(value))
    if isinstance(value, numbers.Real):
        number = float(value)
        if math.isnan(number):
            return "NaN"
        if math.isinf(number):
            return "∞" if number > 0 else "−∞"
        return f"{number:.4g}"
    return str(value).replace("|", "\\|").replace("\n", " ")


def metrics_table_markdown(rows: list[dict[str, Any]], columns: list[str]) -> str:
    """A GitHub-flavoured markdown table: header ``columns``, one line per row dict.

    Floats use 4 significant digits (``inf`` → "∞"), integers and strings are written as they are,
    and a missing key or ``None`` shows as "—". Pipes in text are escaped.
    """
    if not columns:
        raise GratNetError("metrics_table_markdown needs at least one column")
    lines = [
        "| " + " | ".join(_format_cell(column) for column in columns) + " |",
        "|" + "|".join(" --- " for _ in columns) + "|",
    ]
    for row in rows:
        lines.append("| " + " | ".join(_format_cell(row.get(column)) for column in columns) + " |")
    return "\n".join(lines) + "\n"


def _json_ready(value: Any) -> Any:
    """Make ``value`` strict-JSON serialisable: numpy → Python, non-finite floats → strings."""
    if isinstance(value, dict):
        return {str(key): _json_ready(item) for key, item in value.items()}
    if isinstance(value, (list, tuple)):
        return [_json_ready(item) for item in value]
    if isinstance(value, np.ndarray):
        return _json_ready(value.tolist())
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    if isinstance(value, numbers.Integral):
        return int(value)
    if isinstance(value, numbers.Real):
        number = float(value)
        if math.isnan(number):
            return "nan"
        if math.isinf(number):
            return "inf" if number > 0 else "-inf"
        return number
    if isinstance(value, os.PathLike):
        return os.fspath(value)
    if value is None or isinstance(value, str):
        return value
    raise GratNetError(f"cannot write a {type(value).__name__} to metrics.json")


def frame_time_text(frame: dict[str, Any]) -> str:
    """One line for a measured frame (trainer.evaluate.measure_frame_time's record), or why there is none."""
    if "error" in frame:
        return f"not measured: {frame['error']}"
    gpu = "" if frame.get("gpu_ms") is None else f", GPU timer {frame['gpu_ms']:.4g} ms"
    load = ", ".join(f"{value:g}" for value in frame.get("load_average_before", []))
    return (f"{frame['ms']:.4g} ms (median wall time of {len(frame.get('times_ms', []))} frames{gpu}; "
            f"{frame['render_path']} path, {frame['weights_path']} weights) on {frame['gl_renderer']}, "
            f"{frame['date']}, load average {load or '?'} before; `{frame['command']}`")


def model_section(model: dict[str, Any], cost: dict[str, Any]) -> str:
    """report.md's "Model" section: the network's shape and its cost (metrics.json's "model" and "cost")."""
    lines = ["## Model\n",
             f"- network: {'-'.join(map(str, model['layer_sizes']))}, {model['parameters']:,} parameters"
             + (f", grid levels {' '.join('×'.join(map(str, shape)) for shape in model['grid_levels'])}"
                if model.get("grid_levels") else ""),
             f"- cost (gratnet.cost; MB = 10⁶ bytes): {cost['summary']}"]
    if "frame_time_1080p" in cost:
        frame = cost["frame_time_1080p"]
        size = f"{frame['width']}×{frame['height']}" if "width" in frame else "1080p"
        lines.append(f"- {size} CD frame on this machine: {frame_time_text(frame)}")
    return "\n".join(lines) + "\n"


def write_report(
    folder: str | os.PathLike[str],
    metrics: dict[str, Any],
    table_rows: list[dict[str, Any]],
    table_columns: list[str],
    title: str,
    sections: list[str] | None = None,
    intro: list[str] | None = None,
) -> None:
    """Write ``folder/metrics.json`` and ``folder/report.md``.

    metrics.json is strict JSON (indent 2): numpy values become Python numbers and non-finite
    floats become the strings "inf", "-inf", "nan". report.md holds the title, ``intro`` (markdown text, e.g.
    :func:`model_section`), the metrics table and links to the PNG files already in ``folder`` (write the
    figures first); ``sections`` (markdown text) follow the table.
    """
    folder = Path(folder)
    text = json.dumps(_json_ready(metrics), indent=2, allow_nan=False, ensure_ascii=False) + "\n"
    write_text_atomic(folder / "metrics.json", text)

    heading = ["## Metrics\n"] if intro else []  # the table must not read as part of the intro's last section
    parts = [f"# {title}\n", *(intro or []), *heading, metrics_table_markdown(table_rows, table_columns),
             *(sections or [])]
    figures = sorted(p.name for p in folder.glob("*.png") if p.is_file() and not p.name.startswith("."))
    if figures:
        parts.append("## Figures\n")
        parts.append("\n".join(f"![{name}]({quote(name)})" for name in figures) + "\n")
    write_text_atomic(folder / "report.md", "\n".join(parts))
