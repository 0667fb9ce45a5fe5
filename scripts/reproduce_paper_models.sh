#!/usr/bin/env bash
# Rebuild the shipped paper-* materials from nothing, on a machine with a CUDA GPU (minutes per material) or on
# a CPU (hours): the ground truth (`gratnet groundtruth NAME --device auto`, with the w-slices the model was
# trained on), the exact training flags recorded in assets/NAME/train_command.json, and the evaluation with
# the paper's five BRDF slices and docs/results.md's three further views.
# Usage: bash scripts/reproduce_paper_models.sh [NAME ...]   (default: every assets/paper-* and its quality points)
#   NAME is a material (assets/NAME: its accurate point) or a material's point (NAME/fast: assets/NAME/fast, a
#   material's fast model, docs/formats.md "Quality points"); a point's run goes to OUT/runs/NAME/fast and shares
#   the material's volume.
#   OUT=out/paper (volumes, runs, slice cache), GRATNET=.venv/bin/gratnet, DRY_RUN=1 prints the commands only.
#   SEEDS="0 1 2": each dataset's recipe once per seed (`--seed K` appended), into OUT/runs/NAME/seed-K, then
#   OUT/seeds.json and OUT/seeds.md: per dataset the mean and spread of the (0°, 0°) FLIP against the paper's
#   column (python -m analysis.seed_summary). Finished runs (their metrics.json) are skipped, so a second call
#   goes on where the first stopped; TIME_BUDGET_S=N starts no new run after N seconds (a device call's time limit).
#   DEVICE=cuda trains there whatever device the recipe recorded (paper-cd's was trained on the CPU).
# Nothing is copied into assets/: compare OUT/runs/NAME/metrics.json with assets/NAME/metrics.json.
# GPU training is not bit-reproducible: expect figures near, not equal to, the shipped ones. A recorded
# "environment" (the thread count of a CPU training, e.g. paper-cd's OMP_NUM_THREADS=1) is applied too.
set -euo pipefail
cd "$(dirname "$0")/.."
gratnet=${GRATNET:-.venv/bin/gratnet}
python=${PYTHON:-python3}
out=${OUT:-out/paper}
views="45,60,5000;15,200,3000;60,315,5000"
names=("$@")
seeds=(${SEEDS:-})
started=$SECONDS
budget=${TIME_BUDGET_S:-0}
left=0
declare -A made=()
if [ ${#names[@]} -eq 0 ]; then
    source scripts/paper_points.sh
    mapfile -t names < <(paper_points train_command.json)  # each material, then its quality points (NAME/fast)
fi
run() { echo "+ $*"; if [ -z "${DRY_RUN:-}" ]; then "$@"; fi; }
spent() { [ "$budget" -gt 0 ] && [ $((SECONDS - started)) -ge "$budget" ]; }
for name in "${names[@]}"; do  # every name is checked before any work
    [ -f "assets/$name/train_command.json" ] || { echo "reproduce: no assets/$name/train_command.json" >&2; exit 2; }
done
for name in "${names[@]}"; do
    # The recorded `gratnet train VOLUME --out DIR FLAGS…`: the volume's file name (NAME-sS.exr) gives its w-slices.
    parsed=$("$python" - "assets/$name/train_command.json" <<'PY'
import json, re, shlex, sys
record = json.load(open(sys.argv[1]))
words = shlex.split(record["command"])
volume, rest = words[2], words[3:]
out = rest.index("--out")
flags = rest[:out] + rest[out + 2:]
match = re.search(r"-s(\d+)\.exr$", volume)
environment = " ".join(f"{key}={value}" for key, value in record.get("environment", {}).items())
print(match.group(1) if match else 11, environment or "-")
print(shlex.join(flags))
PY
)
    first=${parsed%%$'\n'*}
    slices=${first%% *}
    environment=${first#* }  # the recorded environment (thread count of a CPU training), "-" if none
    read -r -a flags <<< "$(eval "printf '%s ' ${parsed#*$'\n'}")"
    trainer=("$gratnet")
    if [ "$environment" != "-" ]; then read -r -a assignments <<< "$environment"; trainer=(env "${assignments[@]}" "$gratnet"); fi
    dataset=${name%%/*}  # a quality point trains on its material's height field and volume
    volume="$out/volumes/$dataset-s$slices.exr"
    for seed in "${seeds[@]:-}"; do  # one pass with no seed of its own when SEEDS is unset
        runs="$out/runs/$name${seed:+/seed-$seed}"
        if [ -f "$runs/metrics.json" ]; then echo "= $runs: finished"; continue; fi
        if spent; then left=$((left + 1)); continue; fi
        if [ ! -f "$volume" ] && [ -z "${made[$volume]:-}" ]; then  # once per volume (a dry run writes none)
            made[$volume]=1
            run "$gratnet" groundtruth "$dataset" --sampling simple-max --slices "$slices" --device auto --out "$volume"
        fi
        if [ ! -f "$runs/model.npz" ]; then  # model.npz lands at the end of a training: then only evaluate
            resume=()
            if [ -f "$runs/checkpoint.pt" ]; then resume=(--resume); fi  # a training cut off by the last call
            run "${trainer[@]}" train "$volume" --out "$runs" "${flags[@]}" ${seed:+--seed "$seed"} \
                ${DEVICE:+--device "$DEVICE"} "${resume[@]}"
        fi
        run "$gratnet" evaluate "$runs/model.npz" --out "$runs" --heightfield "$dataset" \
            --volume "$volume" --views "$views" --cache-dir "$out/cache"
    done
done
if [ "$left" -gt 0 ]; then echo "reproduce: TIME_BUDGET_S=$budget spent; $left run(s) left: call again to go on"; fi
if [ ${#seeds[@]} -gt 0 ]; then
    run "$python" -m analysis.seed_summary "$out/runs" --json "$out/seeds.json" --markdown "$out/seeds.md"
fi
