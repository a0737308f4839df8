"""``Archive(url)`` to ready on a new database, as every app start and product start on a new database pays it
(issue 17):

    PYTHONPATH=<checkout> .venv/bin/python benchmarks/archive_open.py [--repeats 6] [--postgres postgresql+psycopg://...]

Each repeat is a fresh process (imports not timed): the first ``Archive`` on a new database in it (alembic not
imported yet, as in a server or CLI process), a second on another new database (as in a test worker), and a reopen
of that one at head. SQLite files in a temporary folder; with --postgres, new schemas on that database (dropped
after). Min and median wall seconds (CPU seconds of the process), with the load average before and after. The
processes import the archive of the checkout on PYTHONPATH: to compare two, alternate runs with each."""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
import uuid
from pathlib import Path

PHASES = ("first", "second", "reopen")


def _new_url(postgres: str | None, folder: Path, name: str) -> str:
    """A new SQLite file in ``folder``, or a new schema on ``postgres`` (search_path set to it)."""
    if postgres is None:
        return f"sqlite:///{folder / name}.sqlite"
    from sqlalchemy import create_engine, text

    from tests.telemetry.archive_databases import postgres_schema_url

    schema = f"bench_{uuid.uuid4().hex[:12]}"
    engine = create_engine(postgres)
    with engine.begin() as conn:
        conn.execute(text(f'CREATE SCHEMA "{schema}"'))
    engine.dispose()
    return postgres_schema_url(postgres, schema)


def _drop_schemas(postgres: str, urls: list[str]) -> None:
    from sqlalchemy import create_engine, text
    from sqlalchemy.engine import make_url

    engine = create_engine(postgres)
    with engine.begin() as conn:
        for url in urls:
            schema = str(make_url(url).query["options"]).removeprefix("-csearch_path=")
            conn.execute(text(f'DROP SCHEMA "{schema}" CASCADE'))
    engine.dispose()


def measure_one(postgres: str | None) -> dict[str, tuple[float, float]]:
    """In this process: (wall s, CPU s) of ``Archive(url)`` for each phase."""
    from telemetry.archive import Archive

    folder = Path(tempfile.mkdtemp(prefix="archive_open_"))
    urls = [_new_url(postgres, folder, "first"), _new_url(postgres, folder, "second")]
    figures = {}
    for phase, url in zip(PHASES, [*urls, urls[1]], strict=True):
        t0, c0 = time.perf_counter(), time.process_time()
        Archive(url).close()
        figures[phase] = (time.perf_counter() - t0, time.process_time() - c0)
    if postgres is not None:
        _drop_schemas(postgres, urls)
    return figures


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--repeats", type=int, default=6)
    parser.add_argument("--postgres", help="a PostgreSQL URL: new schemas there instead of SQLite files")
    parser.add_argument("--one", action="store_true", help=argparse.SUPPRESS)  # a repeat's own process
    args = parser.parse_args()
    if args.one:
        print(json.dumps(measure_one(args.postgres)))
        return
    load_before = os.getloadavg()[0]
    command = [sys.executable, str(Path(__file__).resolve()), "--one"]  # telemetry from PYTHONPATH
    command += ["--postgres", args.postgres] if args.postgres else []
    runs = [
        json.loads(subprocess.run(command, check=True, capture_output=True, text=True).stdout)
        for _ in range(args.repeats)
    ]
    print(f"{'postgresql' if args.postgres else 'sqlite'}: {args.repeats} fresh processes")
    for phase in PHASES:
        wall, cpu = [r[phase][0] for r in runs], [r[phase][1] for r in runs]
        print(
            f"  {phase:7s} wall min {min(wall):.3f} median {statistics.median(wall):.3f} s"
            f" (CPU median {statistics.median(cpu):.3f} s)"
        )
    print(f"load average {load_before:.1f} -> {os.getloadavg()[0]:.1f}")


if __name__ == "__main__":
    main()
