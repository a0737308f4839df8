"""Reference-satellite packets for the telemetry tests: deterministic engineering values, encoded."""

from __future__ import annotations

import numpy as np

from telemetry.dictionary import Dictionary, PacketDefinition, load_dictionary
from telemetry.encoding import encode_packets

T0_UTC_NS = 1_750_000_000 * 10**9  # 2025-06-15T15:06:40Z, inside the reference mission window
NOW_UTC_NS = T0_UTC_NS + 86_400 * 10**9  # the ingest clock the tests pretend


def reference() -> Dictionary:
    """The shipped reference-satellite dictionary."""
    return load_dictionary("reference_satellite.yaml")


def engineering_values(packet: PacketDefinition, n: int, seed: int = 0) -> dict[str, np.ndarray]:
    """Random values every field can carry exactly (float32-representable, on the calibration grid)."""
    rng = np.random.default_rng(seed)
    values = {}
    for p in packet.parameters:
        if p.data_type == "float":
            values[p.name] = rng.normal(size=n).astype(np.float32).astype(np.float64)
        elif p.polynomial:
            values[p.name] = rng.integers(-3000, 3000, n) * p.polynomial[1]
        else:
            values[p.name] = rng.integers(0, 1 << min(p.bit_length, 8), n)
    return values


def packets(packet: PacketDefinition, n: int, first_count: int = 0, seed: int = 0) -> np.ndarray:
    """(n, L) packets at the packet's period from T0_UTC_NS with consecutive sequence counts."""
    period_ns = int(round((packet.period_s or 1.0) * 1e9))
    t = T0_UTC_NS + np.arange(n, dtype=np.int64) * period_ns
    return encode_packets(packet, t, first_count + np.arange(n), engineering_values(packet, n, seed))


HK_PER_GPS = 4  # ACS_HK at 4 Hz, GPS_NAV at 1 Hz


def mixed_stream(n_gps: int) -> bytes:
    """ACS_HK and GPS_NAV packets of the reference satellite interleaved in time order (4 HK then 1 GPS): n_gps
    seconds, 4 × 126 + 62 octets each."""
    d = reference()
    hk = packets(d.packets[256], HK_PER_GPS * n_gps).reshape(n_gps, -1)
    gps = packets(d.packets[257], n_gps, seed=1)
    return np.hstack([hk, gps]).tobytes()
