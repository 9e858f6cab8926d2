#!/usr/bin/env bash
# Create (or refresh) the project's virtual environment in .venv and install
# the four packages editable with their dependencies. Idempotent and quick when
# nothing changed. No ROS needed.
set -euo pipefail
cd "$(dirname "$0")/.."
PY=${PYTHON:-python3}
if [ ! -x .venv/bin/python ]; then
  "$PY" -m venv .venv
fi
stamp=.venv/.pneu-installed
want=$(cat requirements.txt requirements-dev.txt src/*/setup.py | sha256sum | cut -d' ' -f1)
if [ ! -f "$stamp" ] || [ "$(cat "$stamp")" != "$want" ]; then
  echo "[bootstrap] installing dependencies into .venv ..."
  .venv/bin/python -m pip install --quiet --upgrade pip
  .venv/bin/python -m pip install --quiet -r requirements-dev.txt
  .venv/bin/python -m pip install --quiet --no-build-isolation --no-deps \
    -e src/pneu_msgs_py -e src/pneu_driver -e src/pneu_sim -e src/pneu_control
  echo "$want" > "$stamp"
  echo "[bootstrap] done"
fi
