"""Add (or refresh) the ``metadata["display"]`` analysis in existing GratNet model files, in place.

    python scripts/store_display_analysis.py assets/*/model.npz

The trainer stores it in every model it saves (gratnet.showcase.with_display); files written before it
get it computed at load time instead (about a second). This script stores it once. Only the JSON header
changes: the script re-reads the written file and checks that every weight, bias and the packed texture
are bit-identical to the original's, and restores the original otherwise.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from gratnet.modelfile import load_model, rewrite_metadata
from gratnet.showcase import DISPLAY_KEY, with_display


def store(path: Path) -> str:
    """Store the analysis in ``path``; returns a one-line report."""
    model = load_model(path)
    updated = with_display(model)
    if model.metadata.get(DISPLAY_KEY) == updated.metadata[DISPLAY_KEY]:
        return f"{path}: unchanged"
    rewrite_metadata(path, updated.metadata)  # checks the arrays stay bit-identical
    display = updated.metadata[DISPLAY_KEY]
    return (f"{path}: stored exposure {display['exposure']:g}, peaks {display['peak_keys_uv'][:2]} "
            "(weights bit-identical)")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("models", nargs="+", type=Path, help="model files (.npz) to update in place")
    for path in parser.parse_args(argv).models:
        print(store(path))
    return 0


if __name__ == "__main__":
    sys.exit(main())
