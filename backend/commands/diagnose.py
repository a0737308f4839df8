"""``acs-twin diagnose TELEMETRY --dictionary D --scenario S``: name the fault from a telemetry file."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``diagnose`` subcommand."""
    p = sub.add_parser("diagnose", help="detect and name an ACS fault from a packet file or a ground CSV/JSONL file")
    p.add_argument("telemetry", type=Path, help="packet file, or ground file (.csv / .jsonl)")
    p.add_argument("--dictionary", required=True, help="telemetry dictionary (YAML, XTCE or ccsdspy CSV)")
    p.add_argument("--scenario", required=True, help="library scenario name or scenario JSON file the spacecraft flies")
    p.add_argument("--satellite", help="expected satellite name (checked against the dictionary)")
    p.add_argument("--json", dest="json_out", type=Path, help="write the ranked hypotheses as JSON here")
    p.add_argument(
        "--scheduler",
        help="fly the twin replays on this Dask scheduler (tcp://host:port; default "
        "$ACS_TWIN_DASK_SCHEDULER, else on this machine without a cluster)",
    )
    p.set_defaults(handler=run)


def _scenario(name: str):
    from sim_core import scenario_library
    from sim_core.scenario import Scenario

    path = Path(name)
    if path.suffix == ".json" and path.exists():
        return Scenario.model_validate_json(path.read_text())
    return scenario_library.get(name)


def run(args: argparse.Namespace) -> int:
    """Diagnose and print the ranking; exit 2 on bad input."""
    import os

    from backend.jobs import cluster
    from backend.twin.diagnosis import diagnose_file
    from telemetry.dictionary import load_dictionary

    client = None
    try:
        dictionary = load_dictionary(args.dictionary)
        address = args.scheduler or os.environ.get(cluster.SCHEDULER_ENV)
        client = cluster.dask_client(address) if address else None
        flyer = cluster.flyer(client) if client is not None else None
        result = diagnose_file(args.telemetry, dictionary, _scenario(args.scenario), args.satellite, flyer)
    except (ValueError, OSError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    finally:
        if client is not None:
            client.close()
    det = result["detection"]
    if det["detected"]:
        print(
            f"anomaly detected at {det['alarm_utc']} on {det['channel']} "
            f"(false-alarm rate {det['false_alarms_per_day']:.1e}/day)"
        )
    else:
        print(f"no anomaly detected (false-alarm rate {det['false_alarms_per_day']:.1e}/day)")
    for h in result["hypotheses"][:5]:
        wheel = "" if h["wheel"] is None else f" wheel {h['wheel']}"
        onset = "" if h["onset_utc"] is None else f" from {h['onset_utc']}"
        mag = "" if h["magnitude"] is None else f" magnitude {h['magnitude']}"
        print(f"  {h['score']:6.3f}  {h['fault']}{wheel}{onset}{mag}")
    if args.json_out:
        args.json_out.write_text(json.dumps(result, indent=2))
        print(f"wrote {args.json_out}")
    return 0
