#!/usr/bin/env bash
# Set up (idempotent) and run the test suite inside the project's virtual environment: lint (ruff), type check
# (mypy, configured in pyproject.toml), then the tests marked `timing` (wall-clock targets: the viewer's latency,
# Ctrl-C within a second) alone, since a second worker's GL tests on the same 2 cores would measure the machine,
# not the code; then the rest on 2 workers.
# Extra arguments go to both pytest runs.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
venv="${GRATNET_VENV:-.venv}"
echo "test: ruff"
"$venv/bin/python" -m ruff check .
echo "test: mypy"
"$venv/bin/python" -m mypy
echo "test: pytest, timing tests alone"
set +e
"$venv/bin/python" -m pytest -n 0 -q -m timing "$@"
status=$?
set -e
[ "$status" = 0 ] || [ "$status" = 5 ] || exit "$status"  # 5: the arguments selected no timing test
echo "test: pytest"
"$venv/bin/python" -m pytest -n 2 -q -m "not timing" "$@"
