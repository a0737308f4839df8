#!/usr/bin/env bash
# The README's test command: install everything the tests need from nothing, then run the suite.
# It says what it does on stderr ("test.sh: ..."); PostgreSQL on 127.0.0.1:5432 (database `test`,
# password-less user `postgres`) is used when it answers, else a throw-away cluster is started.
set -euo pipefail
cd "$(dirname "$0")/.."
PY=${PYTHON:-python3}
# Bytecode is written inside the clone (__pycache__, ignored by git): with PYTHONDONTWRITEBYTECODE set (this
# machine's image sets it) every process of the run — each pytest worker (which also re-rewrites every test
# module's asserts), Dask worker, server and CLI subprocess — compiled the project's sources again.
unset PYTHONDONTWRITEBYTECODE
say() { echo "test.sh: $*" >&2; }

# Another apt/dpkg (unattended-upgrades, a second shell) may hold the locks: wait for them, saying so.
wait_for_apt() {
  local waited=0
  while "$PY" - <<'PYEOF'
import fcntl, sys
for lock in ("/var/lib/dpkg/lock-frontend", "/var/lib/dpkg/lock", "/var/lib/apt/lists/lock"):
    try:
        with open(lock, "w") as f:
            fcntl.lockf(f, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except FileNotFoundError:
        continue
    except OSError:
        sys.exit(0)  # held by someone else
sys.exit(1)
PYEOF
  do
    [ $waited = 0 ] && say "waiting for the apt/dpkg lock (held by: $(fuser /var/lib/dpkg/lock-frontend /var/lib/apt/lists/lock 2>/dev/null | xargs || echo another apt))"
    waited=$((waited + 5)); sleep 5
    if [ $waited -ge 900 ]; then say "apt/dpkg lock still held after 15 min: giving up"; return 1; fi
  done
}
apt_install() {
  wait_for_apt
  say "apt-get install $*"
  apt-get -o DPkg::Lock::Timeout=600 update -qq
  DEBIAN_FRONTEND=noninteractive apt-get -o DPkg::Lock::Timeout=600 install -y -qq "$@" >/dev/null
}

# System packages the browser tests need (Debian chromium; never a downloaded browser).
if ! command -v chromium >/dev/null 2>&1; then
  if [ "$(id -u)" = 0 ]; then
    apt_install chromium
  else
    say "chromium missing and not root: browser tests will be skipped"
  fi
fi

# PostgreSQL is the tested production path. Use the one on 127.0.0.1:5432 if it answers (database
# `test`, password-less `postgres`); else start our own cluster in a temporary directory (stopped on exit).
pg_answers() { command -v pg_isready >/dev/null 2>&1 && pg_isready -q -h 127.0.0.1 -p "$1"; }
start_own_postgres() {
  local port
  PG_BIN=$(ls -d /usr/lib/postgresql/*/bin 2>/dev/null | sort -V | tail -1 || true)
  if [ -z "$PG_BIN" ] && [ "$(id -u)" = 0 ]; then
    apt_install postgresql; PG_BIN=$(ls -d /usr/lib/postgresql/*/bin | sort -V | tail -1)
  fi
  if [ -z "$PG_BIN" ]; then say "no PostgreSQL found and not root: PostgreSQL tests will be skipped"; return 0; fi
  PG_AS=()  # initdb refuses root: run the cluster as the postgres user
  if [ "$(id -u)" = 0 ]; then id postgres >/dev/null 2>&1 || useradd -r -M postgres; PG_AS=(runuser -u postgres --); fi
  PG_DIR=$(mktemp -d /tmp/acs-twin-pg.XXXXXX)
  chmod 755 "$PG_DIR"
  if [ ${#PG_AS[@]} -gt 0 ]; then chown postgres "$PG_DIR"; fi
  port=$("$PY" -c 'import socket; s = socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1])')
  say "no PostgreSQL on 127.0.0.1:5432: starting a throw-away cluster ($PG_BIN/pg_ctl, data $PG_DIR, port $port)"
  "${PG_AS[@]}" "$PG_BIN/initdb" -D "$PG_DIR/data" -U postgres --auth=trust -E UTF8 >"$PG_DIR/initdb.log"
  "${PG_AS[@]}" "$PG_BIN/pg_ctl" -D "$PG_DIR/data" -l "$PG_DIR/server.log" -w \
      -o "-c listen_addresses=127.0.0.1 -p $port -k $PG_DIR" start >/dev/null
  trap '"${PG_AS[@]}" "$PG_BIN/pg_ctl" -D "$PG_DIR/data" -m fast stop >/dev/null 2>&1; rm -rf "$PG_DIR"' EXIT
  "$PG_BIN/createdb" -h 127.0.0.1 -p "$port" -U postgres test
  export ACS_TWIN_TEST_POSTGRES_URL=${ACS_TWIN_TEST_POSTGRES_URL:-postgresql+psycopg://postgres@127.0.0.1:$port/test}
}
if [ -n "${ACS_TWIN_TEST_OWN_POSTGRES:-}" ]; then
  start_own_postgres
elif [ -z "${ACS_TWIN_TEST_POSTGRES_URL:-}" ]; then
  if pg_answers 5432; then
    say "using PostgreSQL on 127.0.0.1:5432 (database test, user postgres)"
  elif command -v pg_ctlcluster >/dev/null 2>&1 && [ -d /etc/postgresql ] && [ "$(id -u)" = 0 ] \
      && pg_ctlcluster --skip-systemctl-redirect "$(ls /etc/postgresql | sort -V | tail -1)" main start 2>/dev/null \
      && pg_answers 5432 && psql -h 127.0.0.1 -U postgres -d test -c 'select 1' >/dev/null 2>&1; then
    say "started the system PostgreSQL cluster on 127.0.0.1:5432"
  else
    start_own_postgres
  fi
  export ACS_TWIN_TEST_POSTGRES_URL=${ACS_TWIN_TEST_POSTGRES_URL:-postgresql+psycopg://postgres@127.0.0.1:5432/test}
fi

if [ ! -x .venv/bin/python ]; then
  say "creating .venv"
  "$PY" -m venv .venv
fi
say "installing the project and its test extra into .venv"
.venv/bin/python -m pip install -q --upgrade pip
.venv/bin/python -m pip install -q -e '.[test]'

[ -n "${ACS_TWIN_TEST_SETUP_ONLY:-}" ] && exit 0
# Compile the numba kernels once, before the two test workers start: cold, each worker would compile the
# closed loop itself (minutes of CPU each, past pytest's per-test timeout on a loaded machine) and two
# processes writing one cache entry at once can fail to load it.
# CI (.ci/run) hands its lint and type step here (ACS_TWIN_LINT_BESIDE_WARM=1): it runs beside `acs-twin warm`,
# whose numba compile keeps one core busy and leaves the other idle; its outcome is awaited before pytest starts
# and decides the exit status with pytest's.
lint_pid=
if [ -n "${ACS_TWIN_LINT_BESIDE_WARM:-}" ]; then
  say "lint and type step (scripts/lint.sh) beside the kernel compile"
  PYTHON=.venv/bin/python bash scripts/lint.sh & lint_pid=$!
fi
# --recorded: also the kernel signatures the suite calls beyond the flight's (backend/jobs/kernel_signatures.json),
# compiled by a second process beside the flight, rather than by whichever test process meets each first.
say "compiling the kernels into numba's cache (acs-twin warm --recorded)"
.venv/bin/acs-twin warm --recorded >&2
lint_status=0
if [ -n "$lint_pid" ]; then wait "$lint_pid" || lint_status=$?; fi
say "running pytest (PostgreSQL: $ACS_TWIN_TEST_POSTGRES_URL)"
# Whole files to the two workers, the files holding a `slow` test first (tests/conftest.py orders them; xdist's
# own reorder by test count would start the long one-test files last, one worker left alone on them at the end).
test_status=0
# --durations: the slowest tests of every run printed at its end, the suite's time kept in sight (issue 17).
.venv/bin/python -m pytest -n 2 --dist loadfile --no-loadscope-reorder --durations=25 "$@" || test_status=$?
if [ "$lint_status" != 0 ]; then say "the lint and type step failed (lint.sh above)"; fi
if [ "$test_status" != 0 ]; then exit "$test_status"; fi
exit "$lint_status"
