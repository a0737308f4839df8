"""``acs-twin export --db URL --satellite S --parameters P1,P2 [--start ISO --end ISO] [--format csv|parquet]
[--out FILE]``: every archived sample of the parameters, one row per time (telemetry.export), never downsampled.

Columns: ``t_utc`` (ISO 8601 UTC with nanoseconds and ``Z`` in CSV, timestamp[ns, UTC] in Parquet) and
one per parameter, empty where it has no sample at that time. Without --out, CSV goes to stdout.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``export`` subcommand."""
    p = sub.add_parser("export", help="export archived parameters at full resolution as CSV or Parquet")
    p.add_argument("--db", help="SQLAlchemy URL of the archive (default: SQLite in the data directory)")
    p.add_argument("--satellite", required=True, help="satellite name in the archive")
    p.add_argument("--parameters", required=True, help="comma-separated parameter names")
    p.add_argument("--start", help="first time, ISO 8601 UTC (2021-04-09T00:00:00.5Z); default: the beginning")
    p.add_argument("--end", help="last time, ISO 8601 UTC; default: the end")
    p.add_argument("--format", choices=("csv", "parquet"), help="default: from --out's suffix, else csv")
    p.add_argument("--out", type=Path, help="file to write (default: CSV on stdout)")
    p.set_defaults(handler=run)


def _format(args: argparse.Namespace) -> str:
    if args.format:
        return str(args.format)
    return "parquet" if args.out is not None and args.out.suffix.lower() == ".parquet" else "csv"


def run(args: argparse.Namespace) -> int:
    """Write the export; 2 with a JSON error naming the field on bad input."""
    from telemetry.dictionary import parse_utc_ns
    from telemetry.export import export_batches, write_export

    fmt = _format(args)
    names = [n.strip() for n in args.parameters.split(",") if n.strip()]
    try:
        if fmt == "parquet" and args.out is None:
            raise ValueError("out: Parquet needs --out FILE")
        t0 = parse_utc_ns(args.start) if args.start else -(2**62)
        t1 = parse_utc_ns(args.end) if args.end else 2**62
        from backend.core.settings import Settings
        from telemetry.archive import Archive

        with Archive(args.db or Settings().resolved_database_url(), migrate=False) as archive:
            schema, batches = export_batches(archive, args.satellite, names, t0, t1)
            rows = write_export(schema, batches, args.out if args.out is not None else sys.stdout.buffer, fmt)
    except ValueError as exc:
        print(json.dumps({"error": str(exc)}), file=sys.stderr)
        return 2
    if args.out is not None:
        print(json.dumps({"rows": rows, "columns": ["t_utc", *names], "format": fmt, "out": str(args.out)}))
    return 0
