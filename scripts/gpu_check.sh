#!/usr/bin/env bash
# "The same picture on every driver" (issue 32 item 4; docs/physics.md, "Float32 error budget"): on a lent GPU,
# run the GL test modules and render every shipped material (CD disc and sphere, 640×480, forward and deferred,
# EXR) into $OUT; then, here, scripts/gpu_check_compare.py renders the same on llvmpipe and reports FLIP per image
# (target ≤ 0.001) and the largest relative difference.
#
#   1. here, once, with the network:   scripts/gpu_check.sh --prepare
#      (scripts/gpu_bench.sh --prepare: EGL/GL .debs into .gl/, the runtime's wheels into .whl/; then pytest's
#      wheels into .whl/ and assets/ without its pictures into .gpu_assets/: the tracked tree is over the device
#      tool's 64 MiB, so assets/ and docs/ stay behind (scripts/device_tree.sh shed) and the models travel as
#      .gpu_assets/; all three git-ignored through .git/info/exclude)
#        scripts/device_tree.sh shed assets docs
#   2. the device tool's run: command "bash scripts/gpu_check.sh", carry [".gl", ".whl", ".gpu_assets"], timeout_s
#      600 (a call may run 10 minutes; should the tests and renders not fit in one, run "SKIP_RENDERS=1 bash
#      scripts/gpu_check.sh" and then "SKIP_TESTS=1 bash scripts/gpu_check.sh" while the machine is warm)
#   3. here: scripts/device_tree.sh restore
#            python scripts/gpu_check_compare.py check FILES_AT/gpu-check/renders    (FILES_AT: the run's files_at)
# Writes $OUT/gpu-check/: device.txt, tests.txt (pytest's report), tests.xml (junit), failures/ (golden-image
# failures' actual/expected/diff), renders/ (EXR + config per image, renders.json), log.txt.
# Settings: OUT (default out), TESTS (the modules), WORKERS (pytest -n, default 4), MATERIALS (default: all),
# SIZE (640,480), WEIGHTS (texture), SKIP_TESTS=1, SKIP_RENDERS=1. Anywhere else it runs on whatever EGL gives
# (llvmpipe here: slow; MATERIALS=blazed SIZE=160,120 TESTS=tests/contract/test_precision.py to try it).
set -euo pipefail
cd "$(dirname "$0")/.."

# Not pillow or packaging: the image's matplotlib brings both (and the 64 MiB are tight: about 55 MiB travel).
TEST_WHEELS="pytest pytest-xdist execnet pluggy iniconfig pygments"

if [[ "${1:-}" == "--prepare" ]]; then
    bash scripts/gpu_bench.sh --prepare
    python=${PYTHON:-.venv/bin/python}
    [[ -x "$python" ]] || python=python3
    for name in $TEST_WHEELS; do  # as gpu_bench.sh: this machine's versions, for the image's CPython 3.12
        version=$("$python" -c "import importlib.metadata as m, sys; print(m.version(sys.argv[1]))" "$name")
        "$python" -m pip download -q --no-deps --only-binary=:all: --python-version 3.12 --implementation cp \
            --platform manylinux_2_28_x86_64 --platform manylinux_2_17_x86_64 --platform manylinux2014_x86_64 \
            --platform manylinux1_x86_64 --platform any -d .whl "$name==$version"
    done
    exclude=$(git rev-parse --git-path info/exclude)
    grep -qx "/.gpu_assets/" "$exclude" 2>/dev/null || echo "/.gpu_assets/" >>"$exclude"
    rm -rf .gpu_assets
    # The models and what tests read beside them; not the pictures (brdf_slices.png alone is 25 MB).
    mkdir -p .gpu_assets
    tar -C assets --exclude='*.png' -cf - . | tar -C .gpu_assets -xf -
    du -sh .gl .whl .gpu_assets
    scripts/device_tree.sh size .gl .whl .gpu_assets
    echo "next: scripts/device_tree.sh shed assets docs; then run 'bash scripts/gpu_check.sh' with carry .gl .whl .gpu_assets"
    exit 0
fi

OUT=${OUT:-out}/gpu-check
mkdir -p "$OUT"
if [[ ! -f assets/blazed/model.npz && -d .gpu_assets ]]; then  # assets/ stayed behind: the carried copy takes its place
    mkdir -p assets
    cp -a .gpu_assets/. assets/
fi
# The GPU image's environment, as scripts/gpu_bench.sh sets it up (GL loaders, EGL vendor, wheels, the project's
# entry points), each step only where it is missing: on a machine that has them (a dry run here with
# PYTHON=.venv/bin/python) nothing system-wide is touched.
python=${PYTHON:-python3}
if compgen -G ".gl/*.deb" >/dev/null && ! ldconfig -p | grep -q "libEGL.so.1 "; then
    for f in .gl/*.deb; do dpkg -x "$f" /; done
    ldconfig
fi
vendor=/usr/local/nvidia/share/glvnd/egl_vendor.d/10_nvidia.json
if [[ -f $vendor && -z "${__EGL_VENDOR_LIBRARY_FILENAMES:-}" ]]; then
    export __EGL_VENDOR_LIBRARY_FILENAMES=$vendor
fi
if ! "$python" -c "import moderngl, flip_evaluator, pytest, colour, OpenEXR" 2>/dev/null; then
    python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade --target /tmp/gratnet-site \
        .whl/*.whl
    export PYTHONPATH=/tmp/gratnet-site${PYTHONPATH:+:$PYTHONPATH}
fi
if [[ -z "$("$python" -c "import importlib.metadata as m; print(*m.entry_points(group='gratnet.commands'))" \
            2>/dev/null)" ]]; then
    rm -rf /tmp/gratnet-meta
    "$python" -m pip install -q --no-index --no-deps --no-build-isolation --no-compile --target /tmp/gratnet-meta .
    export PYTHONPATH=/tmp/gratnet-meta${PYTHONPATH:+:$PYTHONPATH}
fi
export PYTHONPATH=$PWD${PYTHONPATH:+:$PYTHONPATH}
export PYTHONUNBUFFERED=1

{
    echo "== device"
    nvidia-smi --query-gpu=name,driver_version --format=csv,noheader 2>/dev/null || true
    "$python" -c "from viewer.context import create_headless_context as c; x = c(); print(x.info['GL_RENDERER'], x.info['GL_VERSION'])"
} 2>&1 | tee "$OUT/device.txt"

status=0
if [[ -z "${SKIP_TESTS:-}" ]]; then
    TESTS=${TESTS:-"tests/contract/test_precision.py tests/runtime/test_deferred.py tests/runtime/test_shader_parity.py tests/contract/test_grid.py tests/runtime/test_grid_shaders.py tests/runtime/test_antialias.py tests/runtime/test_golden.py tests/runtime/test_scene.py"}
    workers=()
    if "$python" -c "import xdist" 2>/dev/null; then workers=(-n "${WORKERS:-4}"); fi
    rm -rf tests/_failures
    # shellcheck disable=SC2086  # TESTS is a list of paths
    "$python" -m pytest $TESTS "${workers[@]}" -q -rfEs -p no:cacheprovider --junitxml="$OUT/tests.xml" 2>&1 \
        | tee "$OUT/tests.txt" || status=1
    [[ -d tests/_failures ]] && cp -r tests/_failures "$OUT/failures"
fi
if [[ -z "${SKIP_RENDERS:-}" ]]; then
    materials=()
    if [[ -n "${MATERIALS:-}" ]]; then materials=(--materials "$MATERIALS"); fi
    "$python" scripts/gpu_check_compare.py render "$OUT/renders" "${materials[@]}" --size "${SIZE:-640,480}" \
        --weights-path "${WEIGHTS:-texture}" 2>&1 | tee "$OUT/log.txt" || status=1
fi
exit $status
