#!/usr/bin/env bash
# Build the shipped materials: for each built-in height field, compute its ground-truth volume
# (simple-max, 1001² × 11, 81 λ; skipped when out/volumes/NAME.exr exists), train the network, evaluate
# it on the held-out slices and the paper's BRDF slices, and copy the small results into assets/NAME/:
# model.npz, model.config.json, metrics.json, report.md, history.json and the figures.
# Usage: bash scripts/ship_materials.sh [NAME ...]   (extra train flags via TRAIN_FLAGS="...")
# NAME may also be one of the paper's datasets (gratnet heightfield list), e.g. paper-cd, with its own σs;
# TRAIN_FLAGS="--epoch-flip-size 128" records the (0°, 0°) slice's FLIP per epoch for the training curves.
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
    # The same for the other optional figures (region maps, training curves).
    for figure in volume_slices.png brdf_regions.png training_curves.png; do
        if [ -f "$run/$figure" ]; then cp "$run/$figure" "assets/$name/"
        else rm -f "assets/$name/$figure"; fi
    done
    echo "shipped assets/$name"
done
