#!/usr/bin/env bash
# Session 29's one device call (docs/experiments/2026-11-26-scratches-sixteen-features.md): the 41-slice
# paper-scratches ground truth on the GPU, then four trainings at once on it (the control is the shipped recipe,
# 8 features at t 11; the others move the grid's bytes to 12 or 16 features per node at fewer t nodes, or widen
# the MLP), stopped at DEADLINE seconds from the start; a run stopped before its last epoch is written out from
# its last checkpoint (python -m analysis.checkpoint_model). Writes to $OUT (7 files: a device call returns 8 at most):
# NAME.npz per run, epochs.txt (each run's per-epoch lines: loss, seconds, learning rate, FLIP of (0°, 0°) at
# 128²), job.log and logs.tgz (commands, histories, log tails).
#
# On a lent device machine: the device tool's run, command
#     DEVICE=cuda EPOCHS=8 DEADLINE=480 THREADS=4 bash docs/experiments/probes/gpu_scratches_features.sh
# carry [".whl"] (the wheels of scripts/gpu_bench.sh --prepare, less the GL ones). The tracked tree (62.5 MiB)
# and those wheels (11.8 MB) exceed what a call carries (64 MiB), so for the call leave three paper models
# behind (`scripts/device_tree.sh shed assets/paper-corner-cubes assets/paper-snake assets/paper-pits`) and
# put them back after (`scripts/device_tree.sh restore`).
# A local dry run: NOWHL=1 PYTHON=python RES=41 SLICES=3 EPOCHS=2 DEVICE=cpu THREADS=1 MAXS=20000 bash THIS.
set -uo pipefail
cd "$(dirname "$0")/../../.."
T0=$(date +%s)
OUT=${OUT:-/tmp/gpujob-out}; mkdir -p "$OUT"
RES=${RES:-1001}; SLICES=${SLICES:-41}; EPOCHS=${EPOCHS:-10}; DEADLINE=${DEADLINE:-470}; DEVICE=${DEVICE:-cuda}
THREADS=${THREADS:-4}; MAXS=${MAXS:-0}
W=/tmp/gpujob; mkdir -p $W
if [ -z "${NOWHL:-}" ] && compgen -G ".whl/*.whl" >/dev/null; then
  python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade --target /tmp/site .whl/*.whl || exit 3
  export PYTHONPATH=/tmp/site:$PWD
else
  export PYTHONPATH=$PWD${PYTHONPATH:+:$PYTHONPATH}
fi
export PYTHONUNBUFFERED=1
py=${PYTHON:-python3}
log() { echo "[$(( $(date +%s) - T0 )) s] $*" | tee -a $OUT/job.log; }
nvidia-smi --query-gpu=name,driver_version --format=csv,noheader 2>&1 | tee -a $OUT/job.log
vol=$W/scratches-s$SLICES.exr
log "ground truth res $RES slices $SLICES"
$py -m gratnet.cli groundtruth paper-scratches --sampling simple-max --slices $SLICES --res $RES --device $DEVICE \
  --out $vol > $W/gt.log 2>&1 || { tail -20 $W/gt.log | tee -a $OUT/job.log; exit 4; }
log "ground truth done"
common="--split all --architecture grid --preset small --grid-levels 3 --grid-resolution 251 --range-power 4
  --grid-interpolation smoothstep --device $DEVICE --batch-size 2048 --epochs $EPOCHS --grid-adam-epsilon 1e-15
  --no-evaluate --epoch-flip-size 128 --heightfield paper-scratches --cache-dir $W/cache"
[ "$MAXS" != 0 ] && common="$common --max-train-samples $MAXS"
declare -A runs=(
  [c-f8t11]="--grid-t-resolution 11 --grid-features 8 --hidden 160,96,48,24"
  [f12t7]="--grid-t-resolution 7 --grid-features 12 --hidden 160,96,48,24"
  [f16t5]="--grid-t-resolution 5 --grid-features 16 --hidden 160,96,48,24"
  [f8t11-wide]="--grid-t-resolution 11 --grid-features 8 --hidden 256,128,64,32"
)
# the epoch-FLIP ground-truth slice, computed once before the four start (they share the cache)
mkdir -p $W/cache
for name in "${!runs[@]}"; do
  echo "gratnet train VOLUME --out RUN $common ${runs[$name]}" | tr -s ' \n' ' ' > $W/$name.command; echo >> $W/$name.command
  OMP_NUM_THREADS=$THREADS setsid $py -m gratnet.cli train $vol --out $W/$name $common ${runs[$name]} > $W/$name.log 2>&1 &
  echo $! > $W/$name.pid
  log "started $name"
done
while :; do
  alive=0; for name in "${!runs[@]}"; do kill -0 $(cat $W/$name.pid) 2>/dev/null && alive=1; done
  [ $alive = 0 ] && break
  if (( $(date +%s) - T0 > DEADLINE )); then
    log "deadline: stopping"; for name in "${!runs[@]}"; do kill -TERM -$(cat $W/$name.pid) 2>/dev/null; done; sleep 3; break
  fi
  for name in "${!runs[@]}"; do  # per-epoch records so far (kept even if the call's limit cuts the rest)
    tr '\r' '\n' < $W/$name.log | grep -a -o "epoch [0-9]*: train_loss.*" | sed "s/^/$name /"
  done > $OUT/epochs.txt
  sleep 15
done
for name in "${!runs[@]}"; do
  tr '\r' '\n' < $W/$name.log | grep -a -o "epoch [0-9]*: train_loss.*" | sed "s/^/$name /" | tee -a $OUT/epochs.new \
    | tail -2 | tee -a $OUT/job.log
  if [ ! -f $W/$name/model.npz ] && [ -f $W/$name/checkpoint.pt ]; then
    log "$name: exporting its last checkpoint"
    $py -m analysis.checkpoint_model $W/$name/checkpoint.pt $vol --out $W/$name/model.npz >> $W/$name.log 2>&1 &
  fi
done
wait
mv $OUT/epochs.new $OUT/epochs.txt
for name in "${!runs[@]}"; do
  [ -f $W/$name/model.npz ] && cp $W/$name/model.npz $OUT/$name.npz
  [ -f $W/$name/history.json ] && cp $W/$name/history.json $W/$name.history.json
done
tail -c 4000 $W/gt.log > $W/gt.tail.txt
for name in "${!runs[@]}"; do tr '\r' '\n' < $W/$name.log | grep -av "batch/s" | tail -c 20000 > $W/$name.log.tail.txt; done
(cd $W && tar czf $OUT/logs.tgz *.command *.history.json gt.tail.txt *.log.tail.txt 2>/dev/null)
ls -la $OUT | tee -a $OUT/job.log
log "end"
