#!/usr/bin/env bash
# The README's run command: install into .venv (again whenever pyproject.toml changed), then start
# the product. Afterwards the command line is .venv/bin/acs-twin (or `source .venv/bin/activate`).
set -euo pipefail
cd "$(dirname "$0")/.."
PY=${PYTHON:-python3}
if [ ! -x .venv/bin/acs-twin ] || [ pyproject.toml -nt .venv/.acs-twin-installed ]; then
  echo "run.sh: installing acs-twin into .venv (once per change of pyproject.toml)" >&2
  [ -x .venv/bin/python ] || "$PY" -m venv .venv
  .venv/bin/python -m pip install -q --upgrade pip
  .venv/bin/python -m pip install -q -e .
  touch .venv/.acs-twin-installed
fi
exec .venv/bin/acs-twin serve "$@"
