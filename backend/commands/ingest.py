"""``acs-twin ingest PATH --dictionary DEF [--db URL]``: decode, validate and archive a telemetry file.

PATH is a CCSDS packet file (any suffix) or a ground-processed ``.csv`` / ``.jsonl`` file. The
JSON report printed (and stored with the upload) joins the decoder's report (accepted,
quarantined with reasons and byte offsets, duplicates, sequence gaps per APID) with the archive's
(packets newly stored, duplicates already archived, alarm events).
"""

from __future__ import annotations

import argparse
import getpass
import hashlib
import json
from pathlib import Path


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``ingest`` subcommand."""
    p = sub.add_parser("ingest", help="decode, validate and archive a CCSDS packet file or a ground CSV/JSONL file")
    p.add_argument("path", type=Path, help="packet file, or .csv / .jsonl of ground-processed values")
    p.add_argument("--dictionary", required=True,
                   help="dictionary: .yaml (ours), .xml (XTCE) or .csv (ccsdspy); a bare name means a shipped one")
    p.add_argument("--db", help="SQLAlchemy URL of the archive (default: SQLite in the data directory)")
    p.add_argument("--satellite", help="satellite name in the archive (default: the dictionary's 'satellite')")
    p.add_argument("--apid", type=int, help="APID of the packets of a ccsdspy CSV dictionary")
    p.add_argument("--time-code", help="secondary-header time code of XTCE/CSV dictionaries: CDS, CDS-ms, CUC-4-2")
    p.add_argument("--user", default=None, help="who uploads (default: the login name)")
    p.add_argument("--dry-run", action="store_true", help="decode and validate only; store nothing")
    p.set_defaults(handler=run)


def _decode(args: argparse.Namespace, data: bytes, dictionary):
    """Decode the file with the reader its suffix calls for."""
    from telemetry.decoding import decode_stream
    from telemetry.ground_files import read_ground_csv, read_ground_jsonl

    suffix = args.path.suffix.lower()
    if suffix == ".csv":
        return read_ground_csv(data, dictionary, source=str(args.path))
    if suffix in (".jsonl", ".ndjson"):
        return read_ground_jsonl(data, dictionary, source=str(args.path))
    return decode_stream(data, dictionary, source=str(args.path))


def run(args: argparse.Namespace) -> int:
    """Decode, validate, store (unless --dry-run) and print the JSON report; 2 on bad input."""
    from telemetry.dictionary import load_dictionary
    from telemetry.limits import dictionary_limits

    try:
        if not args.path.is_file():
            raise ValueError(f"path: no file {args.path}")
        dictionary = load_dictionary(args.dictionary, apid=args.apid, time_code=args.time_code)
        data = args.path.read_bytes()
        decoded = _decode(args, data, dictionary)
    except ValueError as exc:
        print(json.dumps({"error": str(exc)}))
        return 2
    report = {"decode": decoded.report.to_dict()}
    if not args.dry_run:
        from backend.core.settings import Settings
        from telemetry.archive import Archive

        url = args.db or Settings().resolved_database_url()
        with Archive(url) as archive:
            stored = archive.ingest_decoded(
                args.satellite or dictionary.satellite_name,
                decoded,
                uploaded_by=args.user or getpass.getuser(),
                sha256=hashlib.sha256(data).hexdigest(),
                limits=dictionary_limits(dictionary),
            )
        report["archive"] = stored.as_report()
    print(json.dumps(report, indent=2))
    return 0
