"""Silence the unseen features of shipped models and re-evaluate them (docs/physics.md "Network", trainer/unseen.py).

    python scripts/silence_shipped_models.py [NAME ...] [--cache-dir out/cache]   (default: every assets/*/)

For each shipped point (assets/NAME/model.npz, and assets/NAME/fast/model.npz where it exists): the first-layer
columns of the encoding's features that vanish at every training sample are set to zero
(trainer.unseen.silence_model_file; the file's metadata records it under ``unseen_features_silenced``), the model is
re-evaluated with `gratnet evaluate --no-oracle` (its recorded views, size 256), and metrics.json takes the new
network figures while keeping what does not depend on the network (the oracle's, the training block). The model,
metrics.json, report.md and the figures land together (staged, then moved). A point already silenced is left
alone. Needs the ground-truth slices (computed on the way, or read from --cache-dir).
"""

from __future__ import annotations

import argparse
import datetime
import json
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

from gratnet.atomic import write_text_atomic
from gratnet.modelfile import load_model, save_model
from gratnet.showcase import DISPLAY_KEY, with_display
from trainer.unseen import silence_model_file

REPO = Path(__file__).resolve().parent.parent
FIGURES = ("report.md", "brdf_slices.png", "brdf_regions.png")


def merged(old: Any, new: Any) -> Any:
    """``new`` over ``old``: dicts key by key, lists of equal length item by item, anything else ``new``."""
    if isinstance(old, dict) and isinstance(new, dict):
        return {**old, **{key: merged(old.get(key), value) for key, value in new.items()}}
    if isinstance(old, list) and isinstance(new, list) and len(old) == len(new):
        return [merged(a, b) for a, b in zip(old, new, strict=True)]
    return new


def recorded_views(folder: Path, shipped: dict[str, Any]) -> str | None:
    """The further views the point was evaluated on (``--views``): its metrics.config.json's, else those of its
    metrics.json's ``extra_view`` entries (θ, φ, exposure), so that every recorded view is scored again."""
    config = folder / "metrics.config.json"
    if config.exists():
        return json.loads(config.read_text(encoding="utf-8"))["evaluate"]["views"]
    extra = [entry for entry in shipped.get("brdf_slices", []) if entry.get("extra_view")]
    return ";".join(f"{entry['theta']:g},{entry['phi']:g},{entry['exposure']:g}" for entry in extra) or None


def silence_point(folder: Path, cache_dir: Path) -> str:
    model_path = folder / "model.npz"
    model = load_model(model_path)
    before = np.array(model.weights[0])
    columns = silence_model_file(model)
    if not columns or not np.any(before[:, columns]):
        return f"{model_path}: nothing to silence"
    model.metadata = {**model.metadata, "unseen_features_silenced": {
        "columns": columns, "date": datetime.date.today().isoformat(), "by": "trainer.unseen.silence_model_file",
        "weight_norms": np.round(np.linalg.norm(before[:, columns], axis=0), 6).tolist()}}
    if DISPLAY_KEY in model.metadata:  # the stored display analysis (default views) follows the network
        model = with_display(model)
    metrics_path = folder / "metrics.json"
    shipped = json.loads(metrics_path.read_text(encoding="utf-8"))
    views = recorded_views(folder, shipped)
    with tempfile.TemporaryDirectory(dir=folder) as staging:
        stage = Path(staging)
        save_model(stage / "model.npz", model)
        command = [sys.executable, "-m", "gratnet.cli", "evaluate", str(stage / "model.npz"), "--out",
                   str(stage / "report"), "--no-oracle", "--cache-dir", str(cache_dir), "--quiet"]
        if views:
            command += ["--views", views]
        subprocess.run(command, check=True, cwd=REPO)
        fresh = json.loads((stage / "report" / "metrics.json").read_text(encoding="utf-8"))
        if len(fresh.get("brdf_slices", [])) != len(shipped.get("brdf_slices", [])):  # never drop a recorded view
            raise SystemExit(f"{model_path}: re-evaluated {len(fresh.get('brdf_slices', []))} views, recorded "
                             f"{len(shipped.get('brdf_slices', []))}; nothing changed")
        combined = merged(shipped, fresh)
        old = [entry["flip"] for entry in shipped.get("brdf_slices", [])]
        new = [entry["flip"] for entry in combined.get("brdf_slices", [])]
        shutil.move(stage / "model.npz", model_path)
        write_text_atomic(metrics_path, json.dumps(combined, indent=2, ensure_ascii=False) + "\n")
        for figure in FIGURES:
            if (stage / "report" / figure).exists():
                shutil.move(stage / "report" / figure, folder / figure)
    return (f"{model_path}: silenced columns {columns}; mean FLIP of {len(new)} slices "
            f"{np.mean(old):.4f} → {np.mean(new):.4f}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("names", nargs="*", help="shipped materials (default: every assets/*/ with a model)")
    parser.add_argument("--cache-dir", default=str(REPO / "out" / "cache"), help="ground-truth slice cache")
    arguments = parser.parse_args()
    names = arguments.names or sorted(path.parent.name for path in (REPO / "assets").glob("*/model.npz"))
    for name in names:
        for folder in (REPO / "assets" / name, REPO / "assets" / name / "fast"):
            if (folder / "model.npz").exists():
                print(silence_point(folder, Path(arguments.cache_dir)), flush=True)


if __name__ == "__main__":
    main()
