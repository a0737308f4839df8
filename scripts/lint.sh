#!/usr/bin/env bash
# Lint and type step of CI: ruff (lint + format check) and mypy (strict on sim_core and telemetry, checked on
# backend; configuration in pyproject.toml) must all be clean.
# Runs every check, then fails if any failed. Needs the `test` extra (pip install -e '.[test]').
set -uo pipefail
cd "$(dirname "$0")/.."
PY=${PYTHON:-python3}
say() { echo "lint.sh: $*" >&2; }
failed=()
say "ruff check"; "$PY" -m ruff check . || failed+=("ruff check")
say "ruff format --check"; "$PY" -m ruff format --check . || failed+=("ruff format")
say "mypy (strict: sim_core, telemetry; checked: backend)"; "$PY" -m mypy || failed+=("mypy")
if [ ${#failed[@]} -gt 0 ]; then say "failed: ${failed[*]}"; exit 1; fi
say "all clean"
