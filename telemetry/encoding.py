"""Packet encoding: engineering values → fixed-length CCSDS packets (the inverse of telemetry.decoding).

Used by the spacecraft emulator to play the reference satellite and by tests and benchmarks to
build byte-exact inputs. Vectorised over packets; the CRC-16 packet error control is appended
where the dictionary defines it (ECSS-E-ST-70-41C §7.4.1).
"""

from __future__ import annotations

import numpy as np

from telemetry import ccsds
from telemetry.dictionary import PacketDefinition, Parameter

__all__ = ["raw_from_engineering", "encode_packets"]


def raw_from_engineering(values: np.ndarray, p: Parameter) -> np.ndarray:
    """Raw field values of engineering values: inverse of a linear polynomial, range-checked (int64 / float)."""
    v = np.asarray(values)
    if p.polynomial:
        if len(p.polynomial) != 2 or p.polynomial[1] == 0.0:
            raise ValueError(f"{p.name}.polynomial: only linear calibrations c0 + c1*x can be inverted")
        v = np.rint((v.astype(np.float64) - p.polynomial[0]) / p.polynomial[1])
    if p.data_type == "float":
        return v.astype(np.float64)
    if not np.all(np.isfinite(v)):
        raise ValueError(f"{p.name}: NaN or infinite value cannot be encoded as an integer")
    half = 1 << (p.bit_length - 1)
    low, high = (0, 2 * half - 1) if p.data_type == "uint" else (-half, half - 1)
    raw = np.asarray(v).astype(np.int64) if p.bit_length < 64 else np.asarray(v)
    if np.any((raw < low) | (raw > high)):
        raise ValueError(f"{p.name}: value outside the {p.bit_length}-bit {p.data_type} range after calibration")
    return raw


def _field_bits(raw: np.ndarray, p: Parameter) -> np.ndarray:
    """Unsigned bit pattern (uint64) of raw values of one field."""
    if p.data_type == "float":
        pattern = raw.astype(f">f{p.bit_length // 8}").view(f">u{p.bit_length // 8}")
        return pattern.astype(np.uint64)
    return raw.astype(np.int64).view(np.uint64) & np.uint64((1 << p.bit_length) - 1 if p.bit_length < 64 else ~0)


def encode_packets(
    definition: PacketDefinition,
    t_utc_ns: np.ndarray,
    sequence_count: np.ndarray,
    values: dict[str, np.ndarray],
) -> np.ndarray:
    """(n, L) uint8 packets: primary header, secondary-header time code, parameters, CRC (CCSDS 133.0-B-2 §4.1)."""
    t = np.asarray(t_utc_ns, dtype=np.int64).reshape(-1)
    n = t.shape[0]
    if definition.time_code is None:
        raise ValueError(f"{definition.name}.time_code: needed to stamp encoded packets")
    missing = [p.name for p in definition.parameters if p.name not in values]
    if missing:
        raise ValueError(f"values: missing parameters {missing} of {definition.name}")
    out = np.zeros((n, definition.packet_octets), dtype=np.uint8)
    out[:, : ccsds.PRIMARY_HEADER_OCTETS] = ccsds.encode_primary_headers(
        definition.apid, np.asarray(sequence_count).reshape(-1), definition.packet_octets
    )
    t0 = ccsds.PRIMARY_HEADER_OCTETS
    out[:, t0 : t0 + definition.time_code.octets] = ccsds.encode_time(t, definition.time_code)
    for p in definition.parameters:
        raw = np.broadcast_to(raw_from_engineering(values[p.name], p), (n,))
        bits = _field_bits(np.asarray(raw), p)
        first, last = p.bit_offset // 8, (p.bit_offset + p.bit_length - 1) // 8
        shift = 8 * (last + 1) - p.bit_offset - p.bit_length
        word = bits << np.uint64(shift)
        for k in range(last, first - 1, -1):
            out[:, k] |= (word & np.uint64(0xFF)).astype(np.uint8)
            word >>= np.uint64(8)
    if definition.crc:
        crc = np.asarray(ccsds.crc16_ccitt(out[:, :-2]))  # (n,) for the (n, k) rows
        out[:, -2] = (crc >> 8).astype(np.uint8)
        out[:, -1] = (crc & 0xFF).astype(np.uint8)
    return out
