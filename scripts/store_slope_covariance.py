"""Record the height field's slope covariance (Smith's shadowing, gratnet.shadowing) in existing model files.

    python scripts/store_slope_covariance.py assets/*/model.npz assets/*/*/model.npz

The ground truth records ``slope_covariance`` in every volume it makes and `gratnet train` copies it into the
model; models trained before that get it here, from the height field their ``metadata["volume"]["source"]``
names (the same computation: trainer.heightfield.HeightField.slope_covariance). Only the JSON header changes:
gratnet.modelfile.rewrite_metadata checks that every array stays bit-identical.
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

from gratnet.modelfile import load_model, rewrite_metadata
from gratnet.shadowing import METADATA_KEY
from trainer.loaders import load_heightfield


def store(path: Path) -> str:
    """Store the covariance in ``path``; returns a one-line report."""
    model = load_model(path)
    volume = model.metadata.get("volume")
    if not isinstance(volume, dict) or not volume.get("source"):
        raise SystemExit(f"{path}: the model names no height field (metadata['volume']['source'])")
    covariance = list(load_heightfield(str(volume["source"])).slope_covariance())
    xx, xy, yy = covariance
    summary = f"rms slopes {math.sqrt(xx):.4f} (x), {math.sqrt(yy):.4f} (y), Σxy {xy:.2e}"
    if volume.get(METADATA_KEY) == covariance:
        return f"{path}: unchanged ({summary})"
    rewrite_metadata(path, {**model.metadata, "volume": {**volume, METADATA_KEY: covariance}})
    return f"{path}: stored {summary} (weights bit-identical)"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("models", nargs="+", type=Path, help="model files (.npz) to update in place")
    for path in parser.parse_args(argv).models:
        print(store(path), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
