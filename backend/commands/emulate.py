"""``acs-twin emulate``: play the reference satellite, sending its CCSDS packets over TCP or writing a packet file."""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

DEFAULT_PORT = 10025  # backend.core.settings.Settings.telemetry_port default


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``emulate`` subcommand."""
    p = sub.add_parser("emulate", help="spacecraft emulator: fly a scenario and send its telemetry packets")
    p.add_argument("--scenario", default="somov-ge4-scan", help="library scenario (or scenario JSON file) it flies")
    p.add_argument("--host", default="127.0.0.1", help="live listener host")
    p.add_argument("--port", type=int, help=f"live listener TCP port (default {DEFAULT_PORT} unless only --out)")
    p.add_argument("--rate", type=float, default=1.0, help="time acceleration (1 = real time, inf = unpaced)")
    p.add_argument("--duration", type=float, help="simulated seconds (default: the scenario's)")
    p.add_argument(
        "--fault",
        action="append",
        default=[],
        metavar="TARGET:INDEX:TYPE@ONSET[+DUR][,gain=G|,value=V]",
        help="hidden fault, e.g. wheel:1:failure@600 (0-based sim_core index: wheel 1 = wheel_*_2)",
    )
    p.add_argument(
        "--start-utc", help="epoch of the flight, ISO 8601 or 'now' (at rate 1 packets then leave at their time stamps)"
    )
    p.add_argument("--attempts", type=int, help="connection attempts before giving up (default: keep trying)")
    p.add_argument("--seed", type=int, default=0, help="seed of the emulated sensor noise")
    p.add_argument(
        "--satellite",
        help="name the packets' satellite on each connection (a listener serving a fleet files them under it; "
        "default: the listener's own satellite)",
    )
    p.add_argument("--out", type=Path, help="write the packets to this file (for upload) instead of only sending")
    p.set_defaults(handler=run)


def _start_utc(text: str | None) -> str | None:
    """ISO time of the flight epoch; 'now' is the next whole UTC second."""
    if text != "now":
        return text
    import time

    return time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime(int(time.time()) + 1))


def _scenario(name: str):
    """A library scenario name as is, or the Scenario of a JSON file (as ``acs-twin simulate`` reads it)."""
    path = Path(name)
    if path.suffix != ".json" or not path.exists():
        return name
    from sim_core.scenario import Scenario

    return Scenario.model_validate_json(path.read_text())


def _warn_late_faults(faults: list, duration_s: float) -> None:
    """Say so when a hidden fault begins after the end of the flight (it would never act)."""
    for f in faults:
        if f.onset_s >= duration_s:
            print(
                f"warning: fault {f.target}:{f.index}:{f.type} begins at {f.onset_s:g} s, after the end of the "
                f"flight ({duration_s:g} s); pass --duration",
                file=sys.stderr,
            )


def run(args: argparse.Namespace) -> int:
    """Fly, packetise, then write and/or send; exit 2 on bad input, 1 if the listener cannot be reached."""
    import asyncio

    from sim_core.faults import parse_fault
    from telemetry import emulator

    try:
        faults = [parse_fault(text) for text in args.fault]
        if not args.rate > 0.0:
            raise ValueError(f"rate: must be > 0 (inf = unpaced), got {args.rate}")
        traj, _, stream = emulator.emulate(
            _scenario(args.scenario), faults, args.duration, _start_utc(args.start_utc), seed=args.seed
        )
    except ValueError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    _warn_late_faults(faults, traj.simulated_time_s)
    print(f"emulated {len(stream)} packets ({len(stream.data)} octets) of {args.scenario}")
    if args.out:
        args.out.write_bytes(stream.data)
        print(f"wrote {args.out}")
        if args.port is None:
            return 0
    port = DEFAULT_PORT if args.port is None else args.port
    pace = "unpaced" if math.isinf(args.rate) else f"x{args.rate:g}"
    print(f"sending to {args.host}:{port} ({pace})", flush=True)
    try:
        on_clock = args.start_utc == "now" and args.rate == 1.0
        report = asyncio.run(
            emulator.send_stream(
                stream,
                args.host,
                port,
                args.rate,
                attempts=args.attempts,
                on_wall_clock=on_clock,
                satellite=args.satellite,
            )
        )
    except ValueError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except OSError as exc:
        print(f"error: cannot reach the listener at {args.host}:{port}: {exc}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        return 130
    print(f"sent {report.packets_sent} packets, {report.octets_sent} octets over {report.connections} connection(s)")
    return 0
