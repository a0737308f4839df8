"""``acs-twin ingest PATH --dictionary DEF [--dictionary DEF …] [--db URL]``: decode, validate, archive a file.

PATH is a CCSDS packet file (any suffix, any size: decoded in chunks) or a ground-processed
``.csv`` / ``.jsonl`` file. Dictionaries: our YAML, XTCE (.xml), a ccsdspy CSV (with ``--apid``;
repeat ``--apid`` in the order of several CSVs) or a folder of ccsdspy CSVs, one per APID; several
``--dictionary`` feed one satellite. ``--time-code`` / ``--time-fields`` say where the time of
XTCE/CSV packets is. The JSON report printed (and stored with the upload) joins the decoder's
report (per APID: accepted, duplicates, gaps, packet lengths against the definition; quarantined
with reasons and byte offsets; undefined APIDs kept raw) with the archive's (packets newly stored,
duplicates already archived per APID, alarm events). ``acs-twin ingest --redecode --dictionary DEF
--satellite S`` decodes the packets of S kept raw for want of a definition, now that DEF defines them.
"""

from __future__ import annotations

import argparse
import getpass
import hashlib
import json
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from telemetry.dictionary import Dictionary

GROUND_SUFFIXES = (".csv", ".jsonl", ".ndjson")


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``ingest`` subcommand."""
    p = sub.add_parser("ingest", help="decode, validate and archive a CCSDS packet file or a ground CSV/JSONL file")
    p.add_argument(
        "path",
        type=Path,
        nargs="?",
        help="packet file, or .csv / .jsonl of ground values (none with --redecode)",
    )
    p.add_argument(
        "--dictionary",
        required=True,
        action="append",
        help="dictionary: .yaml (ours), .xml (XTCE), .csv (ccsdspy) or a folder of ccsdspy CSVs "
        "(APID in each file name); repeat to combine; a bare name means a shipped one",
    )
    p.add_argument("--db", help="SQLAlchemy URL of the archive (default: SQLite in the data directory)")
    p.add_argument("--satellite", help="satellite name in the archive (default: the dictionary's 'satellite')")
    p.add_argument(
        "--apid",
        type=int,
        action="append",
        help="APID of the packets of a ccsdspy CSV dictionary (repeat, in order, for several CSVs)",
    )
    p.add_argument("--time-code", help="secondary-header time code of XTCE/CSV dictionaries: CDS, CDS-ms, CUC-4-2")
    p.add_argument(
        "--time-fields",
        help="time from packet fields: year=F,doy=F,hour=F,minute=F,second=F,microsecond=F (or month=, "
        "day=, millisecond=) or coarse=F,fine=F,fine_bits=N,epoch=ISO[,time_scale=TAI]; "
        "field names may use * wildcards (year=*_HDR_YEAR)",
    )
    p.add_argument(
        "--packet-prefix",
        type=int,
        default=0,
        metavar="OCTETS",
        help="fixed-size header before every packet (frame or ground-station header), stripped",
    )
    p.add_argument(
        "--packet-suffix", type=int, default=0, metavar="OCTETS", help="fixed-size trailer after every packet, stripped"
    )
    p.add_argument("--user", default=None, help="who uploads (default: the login name)")
    p.add_argument("--dry-run", action="store_true", help="decode and validate only; store nothing")
    p.add_argument(
        "--redecode",
        action="store_true",
        help="instead of a file: decode the satellite's packets kept raw for want of a definition whose APIDs the "
        "dictionaries define, archived as one upload (packets they quarantine stay kept)",
    )
    p.set_defaults(handler=run)


def load_dictionaries(
    paths: list[str], apids: list[int] | None, time_code: str | None, time_fields: str | None
) -> Dictionary:
    """One satellite's dictionary from every --dictionary (the n-th .csv takes the n-th --apid)."""
    from telemetry.dictionary import load_dictionary, merge_dictionaries

    queue = list(apids or [])
    parts = []
    for path in paths:
        apid = queue.pop(0) if path.lower().endswith(".csv") and queue else None
        parts.append(load_dictionary(path, apid=apid, time_code=time_code, time_fields=time_fields))
    if queue:
        raise ValueError(f"apid: {len(queue)} --apid more than .csv dictionaries")
    return merge_dictionaries(parts)


def _ground_file(args: argparse.Namespace, dictionary: Dictionary):
    """Decode a ground-processed file with the reader its suffix calls for."""
    from telemetry.ground_files import read_ground_csv, read_ground_jsonl

    data = args.path.read_bytes()
    reader = read_ground_csv if args.path.suffix.lower() == ".csv" else read_ground_jsonl
    return reader(data, dictionary, source=str(args.path)), hashlib.sha256(data).hexdigest()


def run(args: argparse.Namespace) -> int:
    """Decode, validate, store (unless --dry-run) and print the JSON report; 2 on bad input."""
    from telemetry.limits import dictionary_limits

    try:
        if args.redecode and (args.path is not None or args.dry_run):
            raise ValueError("path: --redecode takes no PATH and no --dry-run")
        if not args.redecode and (args.path is None or not args.path.is_file()):
            raise ValueError(f"path: no file {args.path}" if args.path else "path: give a packet file (or --redecode)")
        dictionary = load_dictionaries(args.dictionary, args.apid, args.time_code, args.time_fields)
        if args.packet_prefix or args.packet_suffix:
            dictionary = replace(
                dictionary, packet_prefix_octets=args.packet_prefix, packet_suffix_octets=args.packet_suffix
            )
        archive = None
        if not args.dry_run:
            from telemetry.archive import Archive

            url = args.db
            if url is None:  # pydantic settings: ~6 MB of the ingest process, only when needed
                from backend.core.settings import Settings

                url = Settings().resolved_database_url()
            archive = Archive(url)
        try:
            report = _ingest(args, dictionary, archive, dictionary_limits(dictionary))
        finally:
            if archive is not None:
                archive.close()
    except ValueError as exc:
        print(json.dumps({"error": str(exc)}))
        return 2
    if dictionary.notes:
        report["notes"] = list(dictionary.notes)
    print(json.dumps(report, indent=2))
    return 0


def _ingest(args: argparse.Namespace, dictionary: Dictionary, archive, limits) -> dict:
    """Decode (and archive unless dry run) the file; the report as a JSON-ready mapping."""
    satellite = args.satellite or dictionary.satellite_name
    user = args.user or getpass.getuser()
    if args.redecode:
        from backend.ingest.upload_decoder import RedecodeJob, redecode_kept

        job = RedecodeJob(satellite, ", ".join(args.dictionary), (), user)
        outcome = redecode_kept(archive, job, dictionary)
        archived = None if outcome.result is None else outcome.result.as_report()
        return {"apids": list(outcome.apids), "decode": outcome.report.to_dict(), "archive": archived}
    if args.path.suffix.lower() in GROUND_SUFFIXES:
        decoded, sha256 = _ground_file(args, dictionary)
        report = {"decode": decoded.report.to_dict()}
        if archive is not None:
            stored = archive.ingest_decoded(satellite, decoded, uploaded_by=user, sha256=sha256, limits=limits)
            report["archive"] = stored.as_report()
        return report
    from telemetry.packet_files import ingest_packet_file

    decode_report, stored = ingest_packet_file(
        archive, args.path, dictionary, satellite=satellite, uploaded_by=user, limits=limits
    )
    report = {"decode": decode_report.to_dict()}
    if stored is not None:
        report["archive"] = stored.as_report()
    return report
