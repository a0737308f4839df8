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
        "$ACS_TWIN_DASK_SCHEDULER, else a LocalCluster of worker processes on this machine)",
    )
    p.add_argument(
        "--workers", type=int, help="worker processes of the LocalCluster (default: one per core, at most 4)"
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
    from backend.jobs import cluster
    from backend.twin.diagnosis import diagnose_file
    from telemetry.dictionary import load_dictionary

    # the cluster starts when the first twin replay is flown: bad input and nominal telemetry never wait for it
    dask = cluster.ServerCluster(args.scheduler, args.workers or cluster.local_workers())
    try:
        dictionary = load_dictionary(args.dictionary)
        scenario = _scenario(args.scenario)
        result = diagnose_file(
            args.telemetry, dictionary, scenario, args.satellite, lambda s: cluster.fly(dask.client(), s)
        )
    except (ValueError, OSError, RuntimeError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    finally:
        dask.close()
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
