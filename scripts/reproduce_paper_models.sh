#!/usr/bin/env bash
# Rebuild the shipped paper-* materials from nothing, on a machine with a CUDA GPU (minutes per material) or on
# a CPU (hours): the ground truth (`gratnet groundtruth NAME --device auto`, with the w-slices the model was
# trained on), the exact training flags recorded in assets/NAME/train_command.json, and the evaluation with
# the paper's five BRDF slices and docs/results.md's three further views.
# Usage: bash scripts/reproduce_paper_models.sh [NAME ...]   (default: every assets/paper-*)
#   OUT=out/paper (volumes, runs, slice cache), GRATNET=.venv/bin/gratnet, DRY_RUN=1 prints the commands only.
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
if [ ${#names[@]} -eq 0 ]; then
    for folder in assets/paper-*/; do names+=("$(basename "$folder")"); done
fi
run() { echo "+ $*"; if [ -z "${DRY_RUN:-}" ]; then "$@"; fi; }
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
    volume="$out/volumes/$name-s$slices.exr"
    if [ ! -f "$volume" ]; then
        run "$gratnet" groundtruth "$name" --sampling simple-max --slices "$slices" --device auto --out "$volume"
    fi
    run "${trainer[@]}" train "$volume" --out "$out/runs/$name" "${flags[@]}"
    run "$gratnet" evaluate "$out/runs/$name/model.npz" --out "$out/runs/$name" --heightfield "$name" \
        --volume "$volume" --views "$views" --cache-dir "$out/cache"
done
