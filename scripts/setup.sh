#!/usr/bin/env bash
# Install GratNet and everything it needs on a fresh Debian machine (idempotent).
# - Debian packages: Mesa's EGL/GL (headless rendering) when running as root with apt-get.
# - Python packages: GratNet in editable mode with the trainer and dev extras; constraints.txt pins
#   torch to the CPU build this machine kind finds locally (a newer torch pulls GBs of CUDA).
set -euo pipefail
cd "$(dirname "$0")/.."

debian_packages=(libegl1 libegl-mesa0 libgbm1 libgl1 libgl1-mesa-dri xvfb)
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

echo "setup: installing Python packages (pip, constraints.txt)"
python3 -m pip install -q --disable-pip-version-check -c constraints.txt -e ".[trainer,dev]"
