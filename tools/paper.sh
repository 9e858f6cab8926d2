#!/usr/bin/env bash
# The main job: set up .venv and reproduce the paper's experiments on the twin.
set -euo pipefail
cd "$(dirname "$0")/.."
bash tools/bootstrap.sh
.venv/bin/pneu paper --overwrite --out "${1:-out/paper}"  # regenerates: replaces its own outputs
.venv/bin/python tools/results_doc.py "${1:-out/paper}/paper_table.md" docs/results.md  # the table, into the docs
