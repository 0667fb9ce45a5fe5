#!/usr/bin/env bash
# Build the shipped materials: for each built-in height field, compute its ground-truth volume
# (simple-max, 1001² × 11, 81 λ; skipped when out/volumes/NAME.exr exists), train the network, evaluate
# it on the held-out slices and the paper's BRDF slices, and copy the small results into assets/NAME/:
# model.npz, model.config.json, metrics.json, report.md, history.json and the figures.
# Usage: bash scripts/ship_materials.sh [NAME ...]   (extra train flags via TRAIN_FLAGS="...")
set -euo pipefail
cd "$(dirname "$0")/.."
materials=("$@")
[ ${#materials[@]} -gt 0 ] || materials=(blazed sinusoidal cd snake scratches pits)
for name in "${materials[@]}"; do
    volume="out/volumes/$name.exr"
    if [ ! -f "$volume" ]; then
        gratnet groundtruth "$name" --out "$volume" --sampling simple-max --preview "out/volumes/$name.png" \
            --preview-slice 5
    fi
    run="out/runs/$name"
    rm -f "$run/volume_slices.png"  # the evaluation writes it again only when slices are held out
    # shellcheck disable=SC2086
    gratnet train "$volume" --out "$run" ${TRAIN_FLAGS:-} --cache-dir out/cache
    mkdir -p "assets/$name"
    cp "$run"/{model.npz,model.config.json,metrics.json,report.md,history.json,brdf_slices.png} "assets/$name/"
    # Held-out volume slices exist only when slices were held out (not with --split all).
    # A stale figure from an earlier held-out run must not stay beside a model that had none.
    if [ -f "$run/volume_slices.png" ]; then cp "$run/volume_slices.png" "assets/$name/"
    else rm -f "assets/$name/volume_slices.png"; fi
    echo "shipped assets/$name"
done
