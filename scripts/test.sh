#!/usr/bin/env bash
# Set up (idempotent) and run the test suite inside the project's virtual environment: lint, then
# pytest on 2 workers. Extra arguments go to pytest.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
venv="${GRATNET_VENV:-.venv}"
echo "test: ruff"
"$venv/bin/python" -m ruff check .
echo "test: pytest"
"$venv/bin/python" -m pytest -n 2 -q "$@"
