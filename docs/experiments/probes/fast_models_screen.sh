#!/usr/bin/env bash
# Issue 42 screening: cheaper grid + funnel models on paper-cd at a short budget, each against today's shipped
# recipe (candidate "base") trained for the same epochs. One core (OMP_NUM_THREADS=1, nice), one run after
# another; a run cut off is resumed (--resume) and a finished one (its metrics.json) skipped, so calling again
# goes on where the last call stopped. Each run is then scored with the paper's five BRDF slices and
# docs/results.md's three further views at 256² (gratnet evaluate), and the table is printed by
# fast_models_table.py.
# Usage: bash docs/experiments/probes/fast_models_screen.sh [CANDIDATE ...]   (default: every candidate below)
#   OUT=out/fast (volume, runs, slice cache), EPOCHS=3, GRATNET=.venv/bin/gratnet
# The band (--first-frequency), line (--grid-lines) and polar (--grid-polar) candidates need fast_models_screen.patch, which is not
# part of GratNet: `git checkout 54c7d34 && git apply docs/experiments/probes/fast_models_screen.patch`, then
# run this script from that tree (docs/experiments/2026-11-27-fast-models-screen.md). The branch candidates
# (--first-layer-branches) need fast_models_branches.patch the same way, on 1898f87.
set -euo pipefail
cd "$(dirname "$0")/../../.."
gratnet=${GRATNET:-.venv/bin/gratnet}
out=${OUT:-out/fast}
epochs=${EPOCHS:-3}
views="45,60,5000;15,200,3000;60,315,5000"
volume="$out/volumes/paper-cd.exr"
# The shipped paper-cd recipe less its network (assets/paper-cd/train_command.json).
common=(--batch-size 2048 --split all --architecture grid --range-power 4 --grid-interpolation smoothstep
        --device cpu --no-evaluate --epochs "$epochs")
declare -A candidates=(
    # name: grid (levels × features @ finest, t nodes), encoding (L, L_t), hidden widths. MACs in the log.
    [base]="--preset small --grid-levels 3 --grid-resolution 251 --grid-t-resolution 6 --grid-features 4"
    [g8-L8-h44]="--hidden 44,24,12 --grid-levels 3 --grid-resolution 251 --grid-t-resolution 5 --grid-features 8 --frequencies 8 --t-frequencies 2"
    [g8-L4-h56]="--hidden 56,32,16 --grid-levels 3 --grid-resolution 251 --grid-t-resolution 5 --grid-features 8 --frequencies 4 --t-frequencies 2"
    [g4x4-501-L4-h56]="--hidden 56,32,16 --grid-levels 4 --grid-resolution 501 --grid-level-t 4,4,4,2 --grid-features 4 --frequencies 4 --t-frequencies 2"
    [g8-L2-h40]="--hidden 40,24 --grid-levels 3 --grid-resolution 251 --grid-t-resolution 5 --grid-features 8 --frequencies 2 --t-frequencies 1"
    [g4-L19-h24]="--hidden 24,16 --grid-levels 3 --grid-resolution 251 --grid-t-resolution 6 --grid-features 4"
    # Band encodings: only the spatial terms j₀…18 that the 251² grid cannot carry (--first-frequency j₀).
    [g4-b12-h48]="--hidden 48,24,12 --grid-levels 3 --grid-resolution 251 --grid-t-resolution 6 --grid-features 4 --first-frequency 12"
    [g8-b12-h40]="--hidden 40,24,12 --grid-levels 3 --grid-resolution 251 --grid-t-resolution 5 --grid-features 8 --first-frequency 12 --t-frequencies 2"
    [g4-b14-h32]="--hidden 32,16 --grid-levels 3 --grid-resolution 251 --grid-t-resolution 6 --grid-features 4 --first-frequency 14"
    # Line levels (--grid-lines N): a u*-line (T, 2, N, C) and a v*-line (T, N, 2, C) at the volume's full
    # resolution beside the square levels, so that the grid, not the encoding, carries the narrow orders.
    [g4-L4-h56]="--hidden 56,32,16 --grid-levels 3 --grid-resolution 251 --grid-t-resolution 6 --grid-features 4 --frequencies 4 --t-frequencies 2"
    [ln4-L4-h56]="--hidden 56,32,16 --grid-levels 3 --grid-resolution 251 --grid-t-resolution 6 --grid-features 4 --frequencies 4 --t-frequencies 2 --grid-lines 1001"
    [ln4-L8-h40]="--hidden 40,24,12 --grid-levels 3 --grid-resolution 251 --grid-t-resolution 6 --grid-features 4 --frequencies 8 --t-frequencies 2 --grid-lines 1001"
    [ln4-L2-h48]="--hidden 48,24 --grid-levels 3 --grid-resolution 251 --grid-t-resolution 6 --grid-features 4 --frequencies 2 --t-frequencies 1 --grid-lines 1001"
    # Lines and a band together.
    [ln4-b12-h48]="--hidden 48,24,12 --grid-levels 3 --grid-resolution 251 --grid-t-resolution 6 --grid-features 4 --first-frequency 12 --grid-lines 1001"
    # Narrower funnels on fewer frequencies, the grid as shipped.
    [g4-L19-h28]="--hidden 28,16 --grid-levels 3 --grid-resolution 251 --grid-t-resolution 6 --grid-features 4"
    [g4-L12-h40]="--hidden 40,24 --grid-levels 3 --grid-resolution 251 --grid-t-resolution 6 --grid-features 4 --frequencies 12"
    # A polar level over (c_u, c_v) (--grid-polar A,R: A angle × R radius nodes, periodic in angle) beside the
    # square levels: the streaks of a patch's edges and tracks run through the mirror direction, radially.
    [p4-L8-h44]="--hidden 44,24,12 --grid-levels 3 --grid-resolution 251 --grid-t-resolution 6 --grid-features 4 --frequencies 8 --t-frequencies 2 --grid-polar 1024,64"
    [p4a-L8-h44]="--hidden 44,24,12 --grid-levels 3 --grid-resolution 251 --grid-t-resolution 6 --grid-features 4 --frequencies 8 --t-frequencies 2 --grid-polar 2048,32"
    # g8-L8-h44 with the display-weighted loss (paper-blazed's recipe): visible CIE Y weighted 4×.
    [g8-L8-h44-vis]="--hidden 44,24,12 --grid-levels 3 --grid-resolution 251 --grid-t-resolution 5 --grid-features 8 --frequencies 8 --t-frequencies 2 --loss-visible-y 6e-8,5e-4 --loss-visible-weight 4"
    # g8-L8-h44's neighbours: a finer finest level with fewer t nodes (351² × 3 t), a shallower and wider funnel.
    [g8r351t3-L8-h44]="--hidden 44,24,12 --grid-levels 3 --grid-resolution 351 --grid-t-resolution 3 --grid-features 8 --frequencies 8 --t-frequencies 2"
    [g8t6-L8-h44]="--hidden 44,24,12 --grid-levels 3 --grid-resolution 251 --grid-t-resolution 6 --grid-features 8 --frequencies 8 --t-frequencies 2"
    [g8-L8-h52]="--hidden 52,16 --grid-levels 3 --grid-resolution 251 --grid-t-resolution 5 --grid-features 8 --frequencies 8 --t-frequencies 2"
    # g8-L8 with the two lines (the CD's brightest orders are a narrow stripe along v*: g8-L8-h44's error sits there).
    [ln8-L8-h38]="--hidden 38,24,12 --grid-levels 3 --grid-resolution 251 --grid-t-resolution 5 --grid-features 8 --frequencies 8 --t-frequencies 2 --grid-lines 1001"
    [ln8-L4-h48]="--hidden 48,32,16 --grid-levels 3 --grid-resolution 251 --grid-t-resolution 5 --grid-features 8 --frequencies 4 --t-frequencies 2 --grid-lines 1001"
    # More features per grid node at the file limit (10 × 3 levels, ~7.8 MB), the funnel narrowed to stay under 5,940 MACs.
    [g10-L8-h40]="--hidden 40,24,12 --grid-levels 3 --grid-resolution 251 --grid-t-resolution 5 --grid-features 10 --frequencies 8 --t-frequencies 2"
    # The front beyond a fifth (session 4): the g8 grid with wider funnels and more frequencies, at about 0.3, 0.37
    # and 0.49 of base's work, to find the work at which the error comes within 1.25x of base's.
    [g8-L8-h64]="--hidden 64,32,16 --grid-levels 3 --grid-resolution 251 --grid-t-resolution 5 --grid-features 8 --frequencies 8 --t-frequencies 2"
    [g8-L12-h64]="--hidden 64,32,16 --grid-levels 3 --grid-resolution 251 --grid-t-resolution 5 --grid-features 8 --frequencies 12 --t-frequencies 2"
    [g8-L19-h64]="--hidden 64,32,16 --grid-levels 3 --grid-resolution 251 --grid-t-resolution 5 --grid-features 8 --t-frequencies 2"
    # Depth at a fifth (session 4): base has four hidden layers, every candidate above three or two.
    [g8-L8-d4]="--hidden 36,28,20,12 --grid-levels 3 --grid-resolution 251 --grid-t-resolution 5 --grid-features 8 --frequencies 8 --t-frequencies 2"
    [g4-L12-d4]="--hidden 36,24,16,12 --grid-levels 3 --grid-resolution 251 --grid-t-resolution 6 --grid-features 4 --frequencies 12"
    # The full ladder on the axes alone (session 5, --no-diagonal-frequencies, eq. 6a): the first layer's inputs
    # 183 → 107, so a fifth of base's work keeps 40 units there. h64 is the control against g8-L19-h64.
    [g8-L19a-h40]="--hidden 40,24,12 --grid-levels 3 --grid-resolution 251 --grid-t-resolution 5 --grid-features 8 --t-frequencies 2 --no-diagonal-frequencies"
    [g8-L19a-h64]="--hidden 64,32,16 --grid-levels 3 --grid-resolution 251 --grid-t-resolution 5 --grid-features 8 --t-frequencies 2 --no-diagonal-frequencies"
    # A first layer of separate branches (session 5; needs fast_models_branches.patch): one per spatial group (its
    # sin/cos block, its coordinates, c_t and the t terms), one for the grid features; they meet in the second layer.
    # A unit reads ~44 inputs, not 107 or 183, so the first layer is 80-88 wide at a fifth of base's work.
    [g8-L19a-br]="--hidden 80,24 --first-layer-branches 32,32,16 --grid-levels 3 --grid-resolution 251 --grid-t-resolution 5 --grid-features 8 --t-frequencies 2 --no-diagonal-frequencies"
    [g8-L19-br]="--hidden 88,16 --first-layer-branches 20,20,16,16,16 --grid-levels 3 --grid-resolution 251 --grid-t-resolution 5 --grid-features 8 --t-frequencies 2"
    # The top frequencies' sines vanish at every sample (their phase is a whole multiple of π on the lattice), so
    # their random initial weights draw stripes and rings between the samples unseen by the loss
    # (--zero-unseen-features, session 5): the same runs with them silenced, and base too.
    [g8-L19a-h40z]="--hidden 40,24,12 --grid-levels 3 --grid-resolution 251 --grid-t-resolution 5 --grid-features 8 --t-frequencies 2 --no-diagonal-frequencies --zero-unseen-features"
    [g8-L19a-h64z]="--hidden 64,32,16 --grid-levels 3 --grid-resolution 251 --grid-t-resolution 5 --grid-features 8 --t-frequencies 2 --no-diagonal-frequencies --zero-unseen-features"
    [base-z]="--preset small --grid-levels 3 --grid-resolution 251 --grid-t-resolution 6 --grid-features 4 --zero-unseen-features"
)
order=(base g4-b12-h48 g8-b12-h40 ln4-L4-h56 g4-L4-h56 ln4-b12-h48 g4-L19-h28 g4-L12-h40 g8-L8-h44 ln4-L8-h40 g4-L19-h24 ln4-L2-h48
       ln8-L4-h48 g4-b14-h32 g8-L4-h56 g4x4-501-L4-h56 g8-L2-h40 p4-L8-h44 p4a-L8-h44 g8-L8-h44-vis
       g8r351t3-L8-h44 g8-L8-h52 ln8-L8-h38 g8t6-L8-h44 g10-L8-h40 g8-L8-h64 g8-L12-h64 g8-L19-h64 g8-L8-d4 g4-L12-d4 g8-L19a-h40 g8-L19a-h64 g8-L19a-br g8-L19-br
       g8-L19a-h64z g8-L19a-h40z base-z)
names=("$@")
[ ${#names[@]} -gt 0 ] || names=("${order[@]}")
for name in "${names[@]}"; do
    [ -n "${candidates[$name]:-}" ] || { echo "fast_models_screen: unknown candidate $name" >&2; exit 2; }
done
run() { echo "+ $*"; "$@"; }
if [ ! -f "$volume" ]; then
    run "$gratnet" groundtruth paper-cd --sampling simple-max --out "$volume"
fi
for name in "${names[@]}"; do
    runs="$out/runs/e$epochs/$name"
    if [ -f "$runs/metrics.json" ]; then echo "= $runs: finished"; continue; fi
    if [ ! -f "$runs/model.npz" ]; then
        resume=()
        [ -f "$runs/checkpoint.pt" ] && resume=(--resume)
        read -r -a flags <<< "${candidates[$name]}"
        SECONDS=0
        run env OMP_NUM_THREADS=1 nice -n 10 "$gratnet" train "$volume" --out "$runs" "${common[@]}" "${flags[@]}" \
            "${resume[@]}"
        echo "$SECONDS" > "$runs/train_seconds.txt"
    fi
    run env OMP_NUM_THREADS=1 nice -n 10 "$gratnet" evaluate "$runs/model.npz" --out "$runs" --heightfield paper-cd \
        --volume "$volume" --views "$views" --cache-dir "$out/cache"
done
