"""``acs-twin warm``: compile the kernels ``acs-twin serve`` needs into numba's on-disk cache, once per install.

numba compiles on first call; cold, the demo satellite's flight and its live twin spend minutes compiling on a
loaded 2-core machine, on the start-up's critical path. ``scripts/run.sh`` runs this after installing (and again
whenever a source file of ``sim_core`` or ``telemetry`` changed, since sim_core.compiled_cache then drops the
cache of the modules that see the change): it flies what ``serve`` flies with the same types — the emulator's
flight with the demo's hidden fault, the decoding of its packets, the live twin synchronising on them —
so that ``serve`` only loads machine code. With ``--recorded`` a second process compiles, beside the flight, every
signature recorded in :mod:`backend.jobs.kernel_signatures` (those the test suite calls beyond the flight's:
scripts/test.sh passes it, so that the pytest workers load the kernels instead of each compiling them); both save
to numba's cache under a lock (:func:`backend.jobs.kernel_signatures.serialise_cache_saves`).
"""

from __future__ import annotations

import argparse
import multiprocessing
import time
from concurrent.futures import ProcessPoolExecutor

WARM_FLIGHT_S = 90.0  # enough telemetry for the live twin to synchronise and fly one segment
WARM_START_UTC = "2026-03-20T00:00:00Z"


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``warm`` subcommand."""
    p = sub.add_parser("warm", help="compile the server's kernels into numba's cache (run.sh does it at install)")
    p.add_argument("--scenario", default="somov-ge4-scan", help="scenario the demo satellite flies (as serve)")
    p.add_argument(
        "--recorded",
        action="store_true",
        help="also compile every kernel signature recorded from a test-suite run (scripts/test.sh passes it)",
    )
    p.set_defaults(handler=run)


def warm_kernels(scenario: str) -> dict[str, float]:
    """Fly the demo emulator, decode its packets and synchronise a live twin on them; seconds per step."""
    from backend.commands.serve import HIDDEN_FAULTS
    from backend.twin.live import LiveTwin
    from sim_core import scenario_library
    from sim_core.faults import parse_fault
    from telemetry.attitude_mapping import shipped_mapping
    from telemetry.decoding import decode_stream
    from telemetry.dictionary import load_dictionary
    from telemetry.emulator import REFERENCE_DICTIONARY, emulate

    steps: dict[str, float] = {}
    t = time.perf_counter()
    stream = emulate(scenario, [parse_fault(f) for f in HIDDEN_FAULTS], WARM_FLIGHT_S, WARM_START_UTC)[2]
    steps["emulator flight"] = time.perf_counter() - t
    t = time.perf_counter()
    dictionary = load_dictionary(REFERENCE_DICTIONARY)
    batches = decode_stream(stream.data, dictionary, source="warm").batches
    steps["decoding"] = time.perf_counter() - t
    t = time.perf_counter()
    mapping = shipped_mapping(REFERENCE_DICTIONARY)
    if mapping is None:
        raise RuntimeError(f"no attitude mapping shipped beside {REFERENCE_DICTIONARY}")
    twin = LiveTwin("warm", mapping, scenario_library.get(scenario), epoch_from_run=True)
    twin.observe(batches, time.time())
    if twin.state.resyncs == 0:
        raise RuntimeError(f"the live twin did not synchronise on {WARM_FLIGHT_S:.0f} s of telemetry: {twin.state}")
    steps["live twin"] = time.perf_counter() - t
    return steps


def run(args: argparse.Namespace) -> int:
    """Compile (or load) the kernels and say how long each step took."""
    from backend.jobs import kernel_signatures

    t = time.perf_counter()
    kernel_signatures.serialise_cache_saves()
    pool = beside = None
    if args.recorded:  # in a process of its own beside the flight: the record holds what the flight does not
        pool = ProcessPoolExecutor(max_workers=1, mp_context=multiprocessing.get_context("spawn"))
        beside = pool.submit(kernel_signatures.compile_recorded_beside, kernel_signatures.RECORD)
    try:
        for step, seconds in warm_kernels(args.scenario).items():
            print(f"  {step}: {seconds:.1f} s")
        if beside is not None:
            report = beside.result()
            seconds = time.perf_counter() - t
            name = kernel_signatures.RECORD.name
            print(f"  recorded signatures ({name}, beside the flight): {report.compiled}, all done in {seconds:.1f} s")
            for skipped in report.skipped:
                print(f"    skipped (numba compiles it on first call instead): {skipped}")
    finally:
        if pool is not None:
            pool.shutdown(cancel_futures=True)
    print(f"acs-twin warm: kernels compiled and cached in {time.perf_counter() - t:.1f} s")
    return 0
