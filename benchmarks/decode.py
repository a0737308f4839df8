"""Decode-side benchmark (issue 5): framing, validation and bulk decoding, against ccsdspy; prints the figures.

    .venv/bin/python benchmarks/decode.py [--scales 1,10,100] [--repeats 3]

* reference stream: the reference satellite's mixed downlink (1x = 30 min: ACS_HK at 4 Hz with 48
  values incl. the derived attitude error, GPS_NAV at 1 Hz with 10) through
  ``telemetry.decoding.decode_stream`` (frame + CRC + time + validation + decode + calibration),
  at each scale; best of N runs (the 2 cores are shared).
* phases at the largest scale: framing alone, and per-APID decode of ready packet matrices.
* ccsdspy: the same ACS_HK packets (one APID, as ccsdspy needs) and the real NOAA-20 file decoded
  by ccsdspy 2 (``FixedLength.load``) vs our ``decode_stream``.
End-to-end figures with the database commit are in benchmarks/ingest.py.
"""

from __future__ import annotations

import argparse
import time
from io import BytesIO
from pathlib import Path

import numpy as np

from telemetry import ccsds
from telemetry.decoding import decode_packets, decode_stream, packet_matrix
from telemetry.dictionary import Dictionary, PacketDefinition, load_dictionary
from telemetry.encoding import encode_packets

BASE_SECONDS = 1_800
T0_UTC_NS = 1_750_000_000 * 10**9
NOW_UTC_NS = T0_UTC_NS + 400 * 86_400 * 10**9
NOAA = Path(__file__).resolve().parents[2] / "shared" / "data" / "real" / "noaa20_jpss1_apid11"


def best_of(repeats: int, fn) -> tuple[float, object]:
    """Shortest wall time of ``repeats`` calls, and the last result."""
    best, result = np.inf, None
    for _ in range(repeats):
        t0 = time.perf_counter()
        result = fn()
        best = min(best, time.perf_counter() - t0)
    return best, result


def values_for(packet: PacketDefinition, n: int, rng: np.random.Generator) -> dict[str, np.ndarray]:
    """Random values on each field's calibration grid."""
    out = {}
    for p in packet.parameters:
        if p.data_type == "float":
            out[p.name] = rng.normal(size=n)
        elif p.polynomial:
            out[p.name] = rng.integers(-3000, 3000, n) * p.polynomial[1]
        else:
            out[p.name] = rng.integers(0, 1 << min(p.bit_length, 8), n)
    return out


def reference_stream(dictionary: Dictionary, seconds: int, rng: np.random.Generator) -> tuple[bytes, np.ndarray]:
    """Time-interleaved packets of every APID over ``seconds``, and the ACS_HK matrix alone."""
    rows, times, hk = [], [], None
    for packet in dictionary.packets.values():
        period_ns = int(round((packet.period_s or 1.0) * 1e9))
        n = int(seconds * 1e9 // period_ns)
        t = T0_UTC_NS + np.arange(n, dtype=np.int64) * period_ns
        matrix = encode_packets(packet, t, np.arange(n) % ccsds.SEQUENCE_COUNT_MODULUS, values_for(packet, n, rng))
        hk = matrix if packet.apid == 256 else hk
        rows.append(matrix)
        times.append(t)
    order = np.argsort(np.concatenate(times), kind="stable")
    sizes = np.concatenate([np.full(len(m), m.shape[1]) for m in rows])
    flat = np.concatenate([m.reshape(-1) for m in rows])
    starts = np.concatenate([[0], np.cumsum(sizes)[:-1]])
    stream = np.concatenate([flat[s : s + z] for s, z in zip(starts[order], sizes[order])])
    return stream.tobytes(), hk


def ccsdspy_layout(packet: PacketDefinition):
    """ccsdspy FixedLength of our layout (bit offsets from the first octet of the packet)."""
    import ccsdspy

    return ccsdspy.FixedLength(
        [
            ccsdspy.PacketField(name=p.name, data_type=p.data_type, bit_length=p.bit_length, bit_offset=p.bit_offset)
            for p in packet.parameters
        ]
    )


def main() -> None:
    """Run and print every figure."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scales", default="1,10,100")
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    dictionary = load_dictionary("reference_satellite.yaml")
    rng = np.random.default_rng(0)
    warm, _ = reference_stream(dictionary, 10, rng)
    decode_stream(warm, dictionary, now_utc_ns=NOW_UTC_NS)
    print("decode_stream (frame + CRC + validate + decode + calibrate + derive), reference downlink:")
    print(f"{'scale':>6} {'MB':>8} {'packets':>9} {'samples':>11} {'best s':>8} {'Msamples/s':>11} {'MB/s':>7}")
    stream, hk = b"", None
    for scale in (int(s) for s in args.scales.split(",")):
        stream, hk = reference_stream(dictionary, BASE_SECONDS * scale, rng)
        seconds, result = best_of(args.repeats, lambda: decode_stream(stream, dictionary, now_utc_ns=NOW_UTC_NS))
        r = result.report
        assert not r.quarantined and r.duplicates == 0
        print(
            f"{scale:>5}x {len(stream) / 1e6:8.1f} {r.packets_accepted:9d} {r.samples_accepted:11d} "
            f"{seconds:8.3f} {r.samples_accepted / seconds / 1e6:11.2f} {len(stream) / seconds / 1e6:7.0f}"
        )
    frame_s, _ = best_of(
        args.repeats, lambda: ccsds.frame_stream(stream, dictionary.packet_octets_by_apid(), dictionary.crc_apids())
    )
    packet = dictionary.packets[256]
    buf = np.frombuffer(stream, np.uint8)
    hk_offsets = np.arange(len(hk)) * packet.packet_octets
    gather_s, _ = best_of(args.repeats, lambda: packet_matrix(buf, hk_offsets, packet.packet_octets))
    decode_s, _ = best_of(args.repeats, lambda: decode_packets(hk, packet))
    n_hk = len(hk) * (len(packet.parameters) + len(packet.derived))
    print(
        f"phases at the last scale: framing+CRC {frame_s:.3f} s ({len(stream) / frame_s / 1e6:.0f} MB/s); "
        f"ACS_HK gather {gather_s:.3f} s; ACS_HK decode+calibrate {decode_s:.3f} s "
        f"({n_hk / decode_s / 1e6:.1f} Msamples/s)"
    )
    layout = ccsdspy_layout(packet)
    hk_bytes = hk.tobytes()
    theirs_s, _ = best_of(args.repeats, lambda: layout.load(BytesIO(hk_bytes)))
    ours_s, _ = best_of(args.repeats, lambda: decode_stream(hk_bytes, dictionary, now_utc_ns=NOW_UTC_NS))
    print(
        f"ACS_HK only, {len(hk)} packets x {len(packet.parameters)} fields: ccsdspy {theirs_s:.3f} s, "
        f"ours (full pipeline) {ours_s:.3f} s -> {theirs_s / ours_s:.1f}x"
    )
    if NOAA.is_dir():
        import ccsdspy

        raw = (NOAA / "J01_G011_LZ_2021-04-09T00-00-00Z_V01.DAT1").read_bytes()
        noaa = load_dictionary("noaa20_apid11_ccsdspy.yaml")
        definition = ccsdspy.FixedLength.from_file(str(NOAA / "ccsdspy_jpss1_geolocation.csv"))
        theirs_s, _ = best_of(args.repeats, lambda: definition.load(BytesIO(raw)))
        ours_s, _ = best_of(args.repeats, lambda: decode_stream(raw, noaa))
        print(
            f"NOAA-20 7,200 packets x 20 fields: ccsdspy {theirs_s * 1e3:.1f} ms, ours (full pipeline) "
            f"{ours_s * 1e3:.1f} ms -> {theirs_s / ours_s:.1f}x"
        )


if __name__ == "__main__":
    main()
