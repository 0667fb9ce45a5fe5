#!/usr/bin/env bash
# Train the paper's network sizes on one material at one fixed budget, for `gratnet bench`'s error axis.
# The same grid, with seeds, volume and table, is `gratnet sweep benchmarks/size_sweep.toml` (sweep/, on Ray).
# Every preset sees the same samples, epochs, schedule and seed; only the hidden widths differ.
# Usage: bash benchmarks/size_sweep.sh [VOLUME.exr] [OUT_DIR]   (extra train flags via SWEEP_FLAGS="...",
# e.g. "--seed 1"; a subset of the presets via SWEEP_PRESETS="small paper")
# Defaults: out/volumes/blazed.exr, out/sweep; 3M training samples (of 11M), all slices, 8 epochs.
set -euo pipefail
cd "$(dirname "$0")/.."
volume="${1:-out/volumes/blazed.exr}"
out="${2:-out/sweep}"
for preset in ${SWEEP_PRESETS:-tiny small medium funnel-176 paper}; do
    if [ -f "$out/$preset/metrics.json" ]; then echo "done already: $out/$preset"; continue; fi
    # shellcheck disable=SC2086
    gratnet train "$volume" --out "$out/$preset" --preset "$preset" --split all --epochs 8 \
        --max-train-samples 3000000 --cache-dir out/cache --quiet --resume ${SWEEP_FLAGS:-}
    echo "trained $out/$preset"
done
