#!/usr/bin/env bash
# One-command GPU bench of mesh scenes (issue 12): the shipped CD model on the CD disc at 1920×1080, as
# `gratnet render --material cd --mesh cd` sets it up, texture and baked weights, every render path this
# build offers (forward; deferred and auto once the renderer has them), 1 and 4 samples per pixel.
# Writes $OUT/scenes.md (the table), $OUT/scenes.jsonl (every frame time), $OUT/bench.config.json and
# $OUT/log.txt. Every row names the GL_RENDERER it ran on.
#
# On a lent device machine (facts: docs/benchmarks.md "GPU bench", ../shared/notes/opengl-on-a-gpu.md):
#   1. here, once, with the network:   scripts/gpu_bench.sh --prepare
#      (EGL/GL loader .deb files into .gl/, the Python wheels the image lacks into .whl/; both git-ignored
#      through .git/info/exclude)
#   2. there: the device tool's run with command "bash scripts/gpu_bench.sh" and carry [".gl", ".whl"].
# Anywhere else it runs on whatever EGL gives (Mesa llvmpipe on a machine without a GPU: slow; set
# SIZES=512x512 to try it). Settings: OUT (default out/gpu-bench), SIZES, SPP, WEIGHTS, RENDER_PATHS,
# REPEATS, MATERIAL.
#
# --tiled (issue 32: the tiled compute MLP, viewer/tiled.py, against the per-entry kernel), in this order:
#   1. every shipped cd and paper-* model (and every material's fast point) on the CD disc at 1920×1080, 1 and 4 spp, deferred path, deferred
#      weights ssbo, tiled and tiled-fp16 (texture weights path), one bench call per model: $OUT/tiled-MODEL/;
#   2. the shading kernels alone on 699,052 keys (benchmarks/shade_kernels.py: $OUT/tiled-kernels.jsonl, the
#      MLP's TMAC/s without the frame's other passes);
#   3. cd's current best (baked weights, deferred auto): $OUT/tiled-baked/;
#   4. tiled-half (half arithmetic) where the driver has it: $OUT/tiled-half/, and its error against tiled on
#      the five evaluation slices (benchmarks/tiled_half_error.py: $OUT/tiled-half-error.jsonl);
#   5. a few tile plans (GRATNET_TILE_PLAN) on cd and paper-cd at 1 spp: $OUT/tiled-plan-*/.
# Each part writes its results as it finishes (a call cut short still brings back the parts done; about 6
# minutes in all, estimated, not measured); $OUT/tiled.md gathers every table, which states TMAC/s and the
# share of the GPU's FP32 rate. The models fit one call with the wheels only if assets/ and docs/ stay behind
# and assets/ travels without its pictures, as scripts/gpu_check.sh does it:
#   here:   scripts/gpu_check.sh --prepare && scripts/device_tree.sh shed assets docs
#   there:  the device tool's run, command "bash scripts/gpu_bench.sh --tiled", carry [".gl", ".whl", ".gpu_assets"]
#   here:   scripts/device_tree.sh restore
# --lut (issue 33: the look-up-table baseline on this GPU): paper-cd's training volume computed there (CUDA,
#   `gratnet groundtruth paper-cd --sampling simple-max --device cuda`), then benchmarks/lut_baseline.py (the network
#   and the table at u*/v* strides 1 and 4: memory, ms per 1080p frame, FLIP of the exact slices):
#   $OUT/lut_baseline_paper-cd.json and $OUT/lut_baseline.png; same carry as --tiled.
# Settings: OUT, SIZES, SPP, REPEATS as above; TILED_MATERIALS (default: cd and every paper-* model),
# TILED_FORMS (default ssbo,tiled,tiled-fp16), TILED_PLANS (space-separated GRATNET_TILE_PLAN values).
set -euo pipefail
cd "$(dirname "$0")/.."

# setuptools: the build backend that installs the project's metadata there (below), should the image lack it.
WHEELS="moderngl glcontext colour-science pyrr openexr array-api-compat pypng flip-evaluator setuptools"
DEBS="libegl1 libglvnd0 libopengl0 libgl1 libglx0 libgles2"

if [[ "${1:-}" == "--prepare" ]]; then
    python=${PYTHON:-.venv/bin/python}
    [[ -x "$python" ]] || python=python3
    exclude=$(git rev-parse --git-path info/exclude)
    mkdir -p "$(dirname "$exclude")"
    for folder in /.gl/ /.whl/; do grep -qx "$folder" "$exclude" 2>/dev/null || echo "$folder" >>"$exclude"; done
    mkdir -p .gl .whl /tmp/amd64/partial
    apt_options=(-oAPT::Architecture=amd64 -oAPT::Architectures=amd64 -oDir::State::Lists=/tmp/amd64)
    apt-get "${apt_options[@]}" update -qq
    (cd .gl && apt-get "${apt_options[@]}" download $DEBS)
    for name in $WHEELS; do  # the versions installed here, for CPython 3.12 on x86-64 (the image's)
        version=$("$python" -c "import importlib.metadata as m, sys; print(m.version(sys.argv[1]))" "$name")
        "$python" -m pip download -q --no-deps --only-binary=:all: --python-version 3.12 --implementation cp \
            --platform manylinux_2_28_x86_64 --platform manylinux_2_17_x86_64 --platform manylinux2014_x86_64 \
            --platform manylinux1_x86_64 --platform any -d .whl "$name==$version"
    done
    du -sh .gl .whl
    exit 0
fi

OUT=${OUT:-out/gpu-bench}
mkdir -p "$OUT"
if [[ ! -f assets/cd/model.npz && -d .gpu_assets ]]; then  # assets/ stayed behind: the carried copy takes its place
    mkdir -p assets
    cp -a .gpu_assets/. assets/
fi
if compgen -G ".gl/*.deb" >/dev/null; then  # the GL loaders (glvnd) the bare image lacks
    for f in .gl/*.deb; do dpkg -x "$f" /; done
    ldconfig
fi
vendor=/usr/local/nvidia/share/glvnd/egl_vendor.d/10_nvidia.json
if [[ -f $vendor && -z "${__EGL_VENDOR_LIBRARY_FILENAMES:-}" ]]; then
    export __EGL_VENDOR_LIBRARY_FILENAMES=$vendor
fi
if compgen -G ".whl/*.whl" >/dev/null; then
    python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade --target /tmp/gratnet-site \
        .whl/*.whl
fi
# The gratnet command finds its subcommands through the project's entry points (pyproject.toml
# [project.entry-points."gratnet.commands"]), which live in installed metadata; the checkout on PYTHONPATH alone
# has none (gratnet/cli.py then says so and exits 2). So install the project itself, without dependencies,
# without the network and without build isolation (setuptools from the image or .whl/), into /tmp/gratnet-meta.
# The checkout comes first on PYTHONPATH: the code and assets/ resolve from it, the copy there only brings the
# metadata.
rm -rf /tmp/gratnet-meta
PYTHONPATH=/tmp/gratnet-site${PYTHONPATH:+:$PYTHONPATH} python3 -m pip install -q --no-index --no-deps \
    --no-build-isolation --no-compile --target /tmp/gratnet-meta .
export PYTHONPATH=$PWD:/tmp/gratnet-site:/tmp/gratnet-meta${PYTHONPATH:+:$PYTHONPATH}
python=${PYTHON:-python3}
export PYTHONUNBUFFERED=1
if [[ "${1:-}" == "--lut" ]]; then
    {
        nvidia-smi --query-gpu=name,driver_version --format=csv,noheader 2>/dev/null || true
        volume=/tmp/gratnet-lut/paper-cd-s11.exr
        [[ -f $volume ]] || "$python" -m gratnet.cli groundtruth paper-cd --sampling simple-max --slices 11 \
            --device cuda --quiet --out "$volume"
        "$python" benchmarks/lut_baseline.py paper-cd "$volume" --strides 1,4 --cache-dir /tmp/gratnet-lut/cache \
            --json "$OUT/lut_baseline_paper-cd.json" --figure "$OUT/lut_baseline.png"
    } 2>&1 | tee "$OUT/log.txt"
    exit 0
fi
if [[ "${1:-}" == "--tiled" ]]; then
    # Every material's fast point too (assets/NAME/fast/model.npz, docs/formats.md "Quality points"), by its path.
    materials=${TILED_MATERIALS:-"cd $(cd assets && ls -d paper-* | tr '\n' ' ') $(ls assets/*/fast/model.npz 2>/dev/null | tr '\n' ' ')"}
    common=(--no-slices --scene-mesh cd --scene-sizes "${SIZES:-1920x1080}" --spp "${SPP:-1,4}"
            --repeats "${REPEATS:-5}" --max-seconds 20 --quiet)
    part() {  # part NAME SECONDS ARGS…: one bench call into $OUT/tiled-NAME, its table printed; a failure is logged
        local name=$1 seconds=$2
        shift 2
        echo "== $name: gratnet bench $*"
        if timeout "$seconds" "$python" -m gratnet.cli bench "$@" --out "$OUT/tiled-$name"; then
            cat "$OUT/tiled-$name/scenes.md"
        else
            echo "== $name: failed or timed out (exit $?)"
        fi
    }
    {
        nvidia-smi --query-gpu=name,driver_version --format=csv,noheader 2>/dev/null || true
        for material in $materials; do  # one call per model: a call cut short keeps the models done
            label=${material#assets/}; label=${label%/model.npz}  # assets/paper-cd/fast/model.npz: paper-cd-fast
            part "${label//\//-}" 100 "$material" "${common[@]}" --weights-paths texture --render-paths deferred \
                --deferred-weights "${TILED_FORMS:-ssbo,tiled,tiled-fp16}"
        done
        echo "== kernels: benchmarks/shade_kernels.py (the shading dispatches alone, 699,052 keys)"
        timeout 150 "$python" benchmarks/shade_kernels.py cd paper-cd paper-scratches paper-corner-cubes \
            --forms ssbo,tiled,tiled-fp16,tiled-half | tee "$OUT/tiled-kernels.jsonl" || echo "== kernels: failed"
        part baked 90 cd "${common[@]}" --weights-paths baked --render-paths deferred --deferred-weights auto
        part half 75 cd paper-cd paper-scratches "${common[@]}" --weights-paths texture --render-paths deferred \
            --deferred-weights tiled-half
        echo "== half-error: benchmarks/tiled_half_error.py (tiled-half against tiled on the five evaluation slices)"
        timeout 120 "$python" benchmarks/tiled_half_error.py cd paper-cd paper-scratches paper-corner-cubes --size 256 \
            | tee "$OUT/tiled-half-error.jsonl" || echo "== half-error: failed or timed out"
        for plan in ${TILED_PLANS:-"pixels=16" "pixels=32,group=128" "pixels=16,shared=24576" "pixels=8,group=32"}; do
            GRATNET_TILE_PLAN=$plan part "plan-${plan//[=,]/-}" 45 cd paper-cd "${common[@]}" --spp 1 \
                --weights-paths texture --render-paths deferred --deferred-weights tiled
        done
        # Every part's rows in one table (the header once).
        first=1
        for table in "$OUT"/tiled-*/scenes.md; do
            if [[ $first == 1 ]]; then cat "$table"; first=0; else tail -n +3 "$table"; fi
        done >"$OUT/tiled.md"
    } 2>&1 | tee "$OUT/log.txt"
    exit 0
fi
{
    nvidia-smi --query-gpu=name,driver_version --format=csv,noheader 2>/dev/null || true
    "$python" -m gratnet.cli bench "${MATERIAL:-cd}" --no-slices --scene-mesh cd --scene-sizes "${SIZES:-1920x1080}" \
        --weights-paths "${WEIGHTS:-texture,baked}" --render-paths "${RENDER_PATHS:-all}" --spp "${SPP:-1,4}" \
        --repeats "${REPEATS:-5}" --max-seconds 60 --out "$OUT"
    cat "$OUT/scenes.md"
} 2>&1 | tee "$OUT/log.txt"
