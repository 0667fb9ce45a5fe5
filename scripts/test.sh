#!/usr/bin/env bash
# Set up (idempotent) and run the test suite: lint, then pytest on 2 workers.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
echo "test: ruff"
python3 -m ruff check .
echo "test: pytest"
python3 -m pytest -n 2 -q "$@"
