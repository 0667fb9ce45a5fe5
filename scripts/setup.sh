#!/usr/bin/env bash
# Install GratNet and everything it needs on a fresh Debian machine (idempotent).
# - Debian packages: Mesa's EGL/GL (headless rendering) and Xvfb when running as root with apt-get.
# - Python packages: a virtual environment (default .venv, or $GRATNET_VENV) holding GratNet in editable
#   mode with the trainer and dev extras; nothing is installed into the system's Python. constraints.txt
#   pins torch to the CPU build this machine kind finds locally (a newer torch pulls GBs of CUDA).
# - GRATNET_FRESH_VENV=1 deletes the environment first, so that a missing install step cannot hide behind
#   a package left over from an earlier run (.ci/run sets it).
set -euo pipefail
cd "$(dirname "$0")/.."

# libllvm19: Dr.Jit (Mitsuba 3's llvm variants) aborts on Debian 12's default LLVM 14/15 ("Cannot select: fmaximum").
# libxtst6: the viewer's latency test moves the real X pointer (XTest).
# glslang-tools, spirv-cross: gratnet export writes HLSL with them, and its tests validate the exported modules.
# chromium: gratnet export --format web's page is tested in it, headless (Playwright drives it; docs/export.md).
debian_packages=(libegl1 libegl-mesa0 libgbm1 libgl1 libgl1-mesa-dri xvfb libxtst6 libllvm19 glslang-tools spirv-cross
                 chromium)
if command -v apt-get >/dev/null 2>&1 && [ "$(id -u)" = 0 ]; then
    missing=()
    for package in "${debian_packages[@]}"; do
        dpkg -s "$package" >/dev/null 2>&1 || missing+=("$package")
    done
    if [ ${#missing[@]} -gt 0 ]; then
        echo "setup: installing Debian packages: ${missing[*]}"
        apt-get update -qq
        DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends "${missing[@]}"
    fi
fi

venv="${GRATNET_VENV:-.venv}"
if [ "${GRATNET_FRESH_VENV:-0}" = 1 ] && [ -e "$venv" ]; then
    echo "setup: removing $venv (fresh environment requested)"
    rm -rf "$venv"
fi
if [ ! -x "$venv/bin/python" ]; then
    echo "setup: creating the virtual environment $venv"
    python3 -m venv "$venv"
fi
echo "setup: installing Python packages into $venv (pip, constraints.txt)"
"$venv/bin/python" -m pip install -q --disable-pip-version-check -c constraints.txt -e ".[trainer,dev,mitsuba,sweep]"
echo "setup: done; activate with: source $venv/bin/activate"
