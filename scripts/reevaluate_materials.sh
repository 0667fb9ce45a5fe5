#!/usr/bin/env bash
# Re-evaluate shipped materials with today's evaluation (region split, training curves; the oracle too when
# out/volumes/NAME.exr exists) without retraining: the model is untouched, the BRDF-slice metrics are
# recomputed (the same numbers for the same model), and metrics.json keeps its "training" block.
# Usage: bash scripts/reevaluate_materials.sh [NAME ...]   (default: every assets/*/model.npz)
set -euo pipefail
cd "$(dirname "$0")/.."
materials=("$@")
if [ ${#materials[@]} -eq 0 ]; then
    for model in assets/*/model.npz; do materials+=("$(basename "$(dirname "$model")")"); done
fi
for name in "${materials[@]}"; do
    report="out/reports/$name"
    volume=()
    [ -f "out/volumes/$name.exr" ] && volume=(--volume "out/volumes/$name.exr" --volume-slices 4,7,10)
    gratnet evaluate "assets/$name/model.npz" "${volume[@]}" --out "$report" --cache-dir out/cache --quiet
    python - "$name" "$report" <<'PY'
import json
import shutil
import sys
from pathlib import Path

from gratnet.atomic import write_text_atomic

name, report = sys.argv[1], Path(sys.argv[2])
shipped_path = Path("assets") / name / "metrics.json"
shipped, fresh = json.loads(shipped_path.read_text()), json.loads((report / "metrics.json").read_text())
for old, new in zip(shipped.get("brdf_slices", []), fresh.get("brdf_slices", []), strict=True):
    if old["slice"] != new["slice"] or old["flip"] != new["flip"]:
        sys.exit(f"{name}: {new['slice']} re-evaluates to FLIP {new['flip']}, shipped {old['flip']}: not merged")
fresh["training"] = shipped.get("training", fresh.get("training"))
write_text_atomic(shipped_path, json.dumps(fresh, indent=2, ensure_ascii=False) + "\n")
for figure in ("report.md", "brdf_slices.png", "brdf_regions.png", "training_curves.png"):
    if (report / figure).exists():
        shutil.copy(report / figure, Path("assets") / name / figure)
print(f"re-evaluated assets/{name}")
PY
done
