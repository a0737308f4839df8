"""The endless emulator (issue 11): time to the first packets, and each segment's cost against the time it covers.

    .venv/bin/python benchmarks/emulator_stream.py [--segment 600] [--segments 10]

The demo satellite (``acs-twin serve``'s ``emulate --forever``: somov-ge4-scan, its own truth, the hidden wheel
failure at 1,500 s, onboard FDIR) flies in segments of ``--segment`` s (telemetry.emulator.Satellite), each next one
in a worker thread while the last is sent. The first packets leave once the first segment is flown and packetised;
before, the demo flew one whole orbit (5,801 s) up front: the peer. A segment must cost far less than the real time
it covers, or the stream would stall, and must not grow with the time flown. Prints wall and CPU seconds (min
of ``--repeats`` for the start figures) and the load average: on the shared 2-core machine wall figures are upper
bounds.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from collections.abc import Callable
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from backend.commands.serve import HIDDEN_FAULTS  # noqa: E402
from sim_core.faults import parse_fault  # noqa: E402
from telemetry import emulator  # noqa: E402
from telemetry.dictionary import load_dictionary  # noqa: E402

ONE_ORBIT_S = 5801.0  # what the demo flew up front before it flew in segments


def _timed(work: Callable[[], object]) -> tuple[float, float]:
    """(wall s, CPU s of this process) of one call."""
    wall, cpu = time.perf_counter(), time.process_time()
    work()
    return time.perf_counter() - wall, time.process_time() - cpu


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--segment", type=float, default=emulator.SEGMENT_S)
    p.add_argument("--segments", type=int, default=10)
    p.add_argument("--repeats", type=int, default=3)
    args = p.parse_args()
    faults = [parse_fault(f) for f in HIDDEN_FAULTS]
    s = emulator.satellite_scenario(
        faults=faults,
        duration_s=ONE_ORBIT_S,
        start_utc="2026-03-20T00:00:00Z",
        output_dt_s=emulator.hk_period_s(load_dictionary(emulator.REFERENCE_DICTIONARY)),
    )
    emulator.Satellite(s).fly(args.segment)  # compiled and warm before anything is timed
    first = min(_timed(lambda: emulator.Satellite(s).fly(args.segment)) for _ in range(args.repeats))
    orbit = min(_timed(lambda: emulator.Satellite(s).fly(ONE_ORBIT_S)) for _ in range(args.repeats))
    print(f"load average {os.getloadavg()}")
    print(f"first packets after: {first[0]:.2f} s wall, {first[1]:.2f} s CPU ({args.segment:g} s segment)")
    print(f"peer, one orbit up front: {orbit[0]:.2f} s wall, {orbit[1]:.2f} s CPU")
    satellite, costs = emulator.Satellite(s), []
    for _ in range(args.segments):
        costs.append(_timed(lambda: satellite.fly(args.segment)))
    worst = max(costs)
    print(
        f"{args.segments} segments ({args.segments * args.segment:g} s flown): worst {worst[0]:.2f} s wall "
        f"= {worst[0] / args.segment:.2%} of the time it covers; CPU first {costs[0][1]:.2f} s, last "
        f"{costs[-1][1]:.2f} s (each segment computes only its own ephemeris rows)"
    )


if __name__ == "__main__":
    main()
