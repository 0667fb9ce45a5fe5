#!/usr/bin/env bash
# Set up (idempotent) and run GratNet's main job: render a shipped material headless (EGL) —
# the paper's CD (paper-cd) network on a compact-disc mesh, and the same network's BRDF slice.
# Outputs go to out/ (or the folder given as the first argument), each with its .config.json.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
venv="${GRATNET_VENV:-.venv}"
out="${1:-out}"
# No --light, --camera or --exposure: they are chosen from the material and the mesh so that the diffraction
# shows (viewer/defaults.py); `gratnet view --material paper-cd --mesh cd` opens at the same values.
"$venv/bin/gratnet" render --material paper-cd --mesh cd --size 640,480 --out "$out/cd_render.png"
"$venv/bin/gratnet" render --material paper-cd --slice --size 256,256 --out "$out/cd_brdf_slice.png"
