#!/usr/bin/env bash
# The test command: set up .venv, lint and format-check with ruff, run pytest.
set -euo pipefail
cd "$(dirname "$0")/.."
bash tools/bootstrap.sh
.venv/bin/ruff check .
.venv/bin/ruff format --check .
.venv/bin/python -m pytest "$@"
