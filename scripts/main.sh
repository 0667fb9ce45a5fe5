#!/usr/bin/env bash
# Set up (idempotent) and run GratNet's main job for now: the ground-truth volume of the built-in
# synthetic CD (default grid: 1001² × 11 slices, 81 wavelengths) with a slice preview, and a
# ground-truth BRDF slice PNG. Outputs go to out/ (or the folder given as the first argument).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
out="${1:-out}"
gratnet groundtruth cd --out "$out/cd.exr" --preview "$out/cd_volume_slice.png" --preview-slice 5 --exposure 3000
gratnet brdfslice cd --light 30,0 --size 256 --exposure 5000 --out "$out/cd_brdf_slice_30_0.png"
