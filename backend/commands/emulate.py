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
        "--forever", action="store_true", help="fly and send without end (the live demo; not with --out or --duration)"
    )
    p.add_argument(
        "--segment",
        type=float,
        default=600.0,
        help="when sending, fly this many seconds at a time, the next while the last is sent (default 600)",
    )
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
    p.add_argument(
        "--dictionary",
        help="name the packets' dictionary in the hello line too, as the listener knows it (a mixed fleet: "
        "e.g. reference_satellite.yaml; needs --satellite)",
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
    """Fly, packetise, then write and/or send; exit 2 on bad input, 1 if the listener cannot be reached.

    Sending without ``--out`` flies in segments of ``--segment`` s, each next one while the last is sent (the first
    packets leave after one segment's flight); ``--forever`` never ends."""
    import asyncio

    from sim_core.faults import parse_fault
    from telemetry import emulator
    from telemetry.dictionary import load_dictionary

    try:
        faults = [parse_fault(text) for text in args.fault]
        if not args.rate > 0.0:
            raise ValueError(f"rate: must be > 0 (inf = unpaced), got {args.rate}")
        if args.forever and (args.out or args.duration is not None):
            raise ValueError("forever: a flight without end has no --duration and cannot be written to --out")
        if not args.segment > 0.0:
            raise ValueError(f"segment: must be > 0 s, got {args.segment}")
        start_utc = _start_utc(args.start_utc)
        if args.out:
            traj, _, stream = emulator.emulate(
                _scenario(args.scenario), faults, args.duration, start_utc, seed=args.seed
            )
            duration = traj.simulated_time_s
        else:
            hk_period = emulator.hk_period_s(load_dictionary(emulator.REFERENCE_DICTIONARY))
            s = emulator.satellite_scenario(_scenario(args.scenario), faults, args.duration, start_utc, hk_period)
            satellite = emulator.Satellite(s, seed=args.seed)
            duration = math.inf if args.forever else s.duration_s
    except ValueError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    _warn_late_faults(faults, duration)
    if args.out:
        print(f"emulated {len(stream)} packets ({len(stream.data)} octets) of {args.scenario}")
        args.out.write_bytes(stream.data)
        print(f"wrote {args.out}")
        if args.port is None:
            return 0
    port = DEFAULT_PORT if args.port is None else args.port
    pace = "unpaced" if math.isinf(args.rate) else f"x{args.rate:g}"
    length = "without end" if math.isinf(duration) else f"{duration:g} s"
    print(f"sending {length} of {args.scenario} to {args.host}:{port} ({pace})", flush=True)
    try:
        on_clock = args.start_utc == "now" and args.rate == 1.0
        options = emulator.SendOptions(
            args.host,
            port,
            args.rate,
            attempts=args.attempts,
            on_wall_clock=on_clock,
            satellite=args.satellite,
            dictionary=args.dictionary,
        )
        if args.out:
            sending = emulator.send_stream(stream, options)
        else:
            streams = emulator.flight_streams(satellite, args.segment, None if math.isinf(duration) else duration)
            sending = emulator.send_streams(streams, options)
        report = asyncio.run(sending)
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
