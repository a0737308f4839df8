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
# numba compiles on first call (minutes on a loaded machine): compile the server's kernels into its on-disk cache
# now, once per change of the sources, so that the server, the demo's live twin and monitors start in seconds.
if [ ! -f .venv/.acs-twin-warm ] || [ -n "$(find sim_core telemetry backend -name '*.py' -newer .venv/.acs-twin-warm -print -quit)" ]; then
  echo "run.sh: compiling the kernels into numba's cache (once per change of the sources)" >&2
  .venv/bin/acs-twin warm >&2
  touch .venv/.acs-twin-warm
fi
exec .venv/bin/acs-twin serve "$@"
