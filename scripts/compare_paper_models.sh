#!/usr/bin/env bash
# Score every shipped paper-* network against its own ground truth on meshes (issue 33, docs/results.md
# "Error where users look"): the training volume (`gratnet groundtruth NAME --sampling simple-max --slices S`,
# S and the scheme read from the model file), then `gratnet compare NAME --reference VOLUME` (CD disc, sphere,
# plane × three views, LDR-FLIP over covered pixels), then its compare.json and compare.png copied into
# docs/data/compare/NAME.json and docs/images/compare_NAME.png, and the results table regenerated.
# Usage: bash scripts/compare_paper_models.sh [NAME ...]   (default: every assets/paper-* and its quality points)
#   NAME is a material (its accurate point) or a material's point (NAME/fast: `gratnet compare NAME --quality fast`
#   against the material's volume, into docs/data/compare/fast/NAME.json and docs/images/compare_NAME_fast.png).
#   OUT=out/paper (volumes shared with scripts/reproduce_paper_models.sh, compare folders), DEVICE=auto|cpu|cuda
#   for the ground truth, GRATNET=.venv/bin/gratnet, DRY_RUN=1 prints the commands only. A volume or a compare
#   already there is reused, so a second call goes on where the first stopped.
set -euo pipefail
cd "$(dirname "$0")/.."
gratnet=${GRATNET:-.venv/bin/gratnet}
python=${PYTHON:-.venv/bin/python}
out=${OUT:-out/paper}
size=${SIZE:-384}
spp=${SPP:-4}
names=("$@")
if [ ${#names[@]} -eq 0 ]; then
    source scripts/paper_points.sh
    mapfile -t names < <(paper_points model.npz)  # each material, then its quality points (NAME/fast)
fi
run() { echo "+ $*"; if [ -z "${DRY_RUN:-}" ]; then "$@"; fi; }
for name in "${names[@]}"; do  # every name is checked before any work
    [ -f "assets/$name/model.npz" ] || { echo "compare_paper_models: no assets/$name/model.npz" >&2; exit 2; }
done
for name in "${names[@]}"; do
    dataset=${name%%/*}
    point=${name#"$dataset"}; point=${point#/}  # "" for the accurate point
    quality=(); data="docs/data/compare/$dataset.json"; picture="docs/images/compare_$dataset.png"
    if [ -n "$point" ]; then
        quality=(--quality "$point")
        data="docs/data/compare/$point/$dataset.json"; picture="docs/images/compare_${dataset}_$point.png"
    fi
    # The training volume's w-slices and scheme, as the model file records them.
    read -r slices scheme < <("$python" - "assets/$name/model.npz" <<'PY'
import sys
from gratnet.modelfile import load_model
volume = load_model(sys.argv[1]).metadata["volume"]
print(volume["slices"], volume["scheme"])
PY
)
    volume="$out/volumes/$dataset-s$slices.exr"
    compare="$out/compare/$name"
    if [ ! -f "$volume" ]; then
        run "$gratnet" groundtruth "$dataset" --sampling "$scheme" --slices "$slices" --device "${DEVICE:-auto}" \
            --out "$volume"
    fi
    if [ ! -f "$compare/compare.json" ]; then
        run "$gratnet" compare "$dataset" "${quality[@]}" --reference "$volume" --width "$size" --height "$size" --spp "$spp" \
            --out "$compare"
    fi
    run mkdir -p "$(dirname "$data")"
    run cp "$compare/compare.json" "$data"
    run cp "$compare/compare.png" "$picture"
done
run "$python" -m analysis.results_table
