#!/usr/bin/env bash
# Issue 42: the full recipe (20 epochs) of a screened candidate on paper-cd, resumable (--resume after any stop; a
# finished training, its model.npz, is only re-scored). The shipped recipe less its network, as the screen
# (fast_models_screen.sh) but 20 epochs and a seed; then gratnet evaluate on the same eight views.
# Usage: bash docs/experiments/probes/fast_models_full.sh NAME SEED [gratnet train flags of the network ...]
#   OUT=out/fast (volume, runs/e20/NAME/seed-SEED, slice cache), GRATNET=.venv/bin/gratnet
set -euo pipefail
cd "$(dirname "$0")/../../.."
[ $# -ge 2 ] || { echo "usage: fast_models_full.sh NAME SEED [FLAGS ...]" >&2; exit 2; }
name=$1; seed=$2; shift 2
gratnet=${GRATNET:-.venv/bin/gratnet}
out=${OUT:-out/fast}
volume="$out/volumes/paper-cd.exr"
runs="$out/runs/e20/$name/seed-$seed"
[ -f "$volume" ] || "$gratnet" groundtruth paper-cd --sampling simple-max --out "$volume"
mkdir -p "$runs"
if [ ! -f "$runs/model.npz" ]; then
    resume=()
    [ -f "$runs/checkpoint.pt" ] && resume=(--resume)
    SECONDS=0
    env OMP_NUM_THREADS=1 nice -n 10 "$gratnet" train "$volume" --out "$runs" --epochs 20 --batch-size 2048 \
        --split all --architecture grid --range-power 4 --grid-interpolation smoothstep --device cpu --no-evaluate \
        --seed "$seed" "$@" "${resume[@]}"
    echo "$SECONDS" >> "$runs/train_seconds.txt"
fi
env OMP_NUM_THREADS=1 nice -n 10 "$gratnet" evaluate "$runs/model.npz" --out "$runs" --heightfield paper-cd \
    --volume "$volume" --views "45,60,5000;15,200,3000;60,315,5000" --cache-dir "$out/cache"
