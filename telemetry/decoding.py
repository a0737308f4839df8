"""Bulk decoding of fixed-length CCSDS packets to numpy arrays, and the stream pipeline frame → validate → decode.

All fields of a packet type are read in one compiled pass over the (n, L) packet matrix (the
covering octets of each field, big-endian, shifted and masked: any bit offset and length ≤ 64,
spanning ≤ 8 octets); the bit patterns are then viewed as IEEE 754 floats or sign-extended
integers, vectorised per field. No per-packet Python. Calibration: polynomial c0 + c1·x + …
(XTCE PolynomialCalibrator semantics) or an enumeration (codes kept, labels in the dictionary).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from sim_core import quaternion
from telemetry import ccsds
from telemetry.dictionary import DerivedParameter, Dictionary, PacketDefinition, Parameter
from telemetry.ingest_report import ApidSummary, DecodeResult, IngestReport, QuarantineRecord, SampleBatch
from telemetry.validation import HEADER_PROBLEMS, INVALID_TIME, header_mismatch, validate_packets

__all__ = [
    "packet_matrix",
    "decode_raw",
    "calibrate",
    "derive",
    "decode_packets",
    "decode_stream",
    "quaternion_of",
]


@njit(cache=True)
def _gather(buf: np.ndarray, offset: np.ndarray, packet_octets: int) -> np.ndarray:
    """Copy the packets starting at offset into rows of an (n, L) matrix (compiled kernel)."""
    out = np.empty((offset.shape[0], packet_octets), dtype=np.uint8)
    for i in range(offset.shape[0]):
        out[i, :] = buf[offset[i] : offset[i] + packet_octets]
    return out


def packet_matrix(buf: np.ndarray, offset: np.ndarray, packet_octets: int) -> np.ndarray:
    """(n, L) uint8 copy of the n packets of length L starting at the given offsets of buf."""
    offset = np.asarray(offset, dtype=np.int64)
    if offset.size and (offset.min() < 0 or offset.max() + packet_octets > buf.shape[0]):
        raise ValueError("offset: a packet would run past the end of the buffer")
    return _gather(buf, offset, packet_octets)


@njit(cache=True)
def _bit_patterns(packets: np.ndarray, first: np.ndarray, last: np.ndarray, shift: np.ndarray,
                  mask: np.ndarray) -> np.ndarray:
    """(F, n) uint64 big-endian bit patterns of F fields in n packets, one pass over each packet (compiled kernel).

    Field f covers octets first[f]..last[f]; its value is that big-endian word >> shift[f] & mask[f].
    """
    n, n_fields = packets.shape[0], first.shape[0]
    out = np.empty((n_fields, n), dtype=np.uint64)
    for i in range(n):
        for f in range(n_fields):
            word = np.uint64(0)
            for k in range(first[f], last[f] + 1):
                word = (word << np.uint64(8)) | np.uint64(packets[i, k])
            out[f, i] = (word >> shift[f]) & mask[f]
    return out


def _raw_value(pattern: np.ndarray, p: Parameter) -> np.ndarray:
    """Raw value of a field's bit patterns: IEEE 754 float, two's-complement int, or unsigned."""
    if p.data_type == "float":
        return pattern.astype(np.uint32).view(np.float32) if p.bit_length == 32 else pattern.view(np.float64)
    if p.data_type == "int":
        signed = pattern.view(np.int64)
        if p.bit_length == 64:
            return signed
        return np.where(signed >= 1 << (p.bit_length - 1), signed - (1 << p.bit_length), signed)
    return pattern if p.bit_length == 64 else pattern.view(np.int64)


def decode_raw(packets: np.ndarray, definition: PacketDefinition) -> dict[str, np.ndarray]:
    """Raw (uncalibrated) values of every parameter of an (n, L) packet matrix (CCSDS 133.0-B-2 §4.1.4 user data)."""
    if packets.dtype != np.uint8 or packets.ndim != 2 or packets.shape[1] != definition.packet_octets:
        expected = f"(n, {definition.packet_octets}) uint8"
        raise ValueError(f"packets: expected {expected}, got {packets.dtype} {packets.shape}")
    offset = np.array([p.bit_offset for p in definition.parameters], dtype=np.int64)
    length = np.array([p.bit_length for p in definition.parameters], dtype=np.int64)
    first, last = offset // 8, (offset + length - 1) // 8
    shift = (8 * (last + 1) - offset - length).astype(np.uint64)
    mask = np.array([(1 << b) - 1 for b in length.tolist()], dtype=np.uint64)
    patterns = _bit_patterns(np.ascontiguousarray(packets), first, last, shift, mask)
    return {p.name: _raw_value(patterns[f], p) for f, p in enumerate(definition.parameters)}


def calibrate(raw: np.ndarray, p: Parameter) -> np.ndarray:
    """Engineering value of a raw field: polynomial Σ c_k x^k (XTCE PolynomialCalibrator), else the native value."""
    if p.polynomial:
        x = raw.astype(np.float64)
        if len(p.polynomial) == 1:
            return np.full(x.shape, p.polynomial[0])
        y = x * p.polynomial[-1]
        y += p.polynomial[-2]
        for c in p.polynomial[-3::-1]:
            y *= x
            y += c
        return y
    if p.data_type == "float":
        return raw.astype(np.float64, copy=False)
    return raw if raw.dtype == np.uint64 else raw.astype(np.int64, copy=False)


def derive(d: DerivedParameter, values: dict[str, np.ndarray], time_code: ccsds.TimeCode | None) -> np.ndarray:
    """A derived parameter: attitude error angle of E = Λ̃^p ∘ Λ (seed 000 §4), CDS time, or an alias."""
    if d.kind == "alias":
        return values[d.inputs[0]]
    if d.kind == "cds_time":
        epoch = time_code.epoch_ns if time_code and time_code.format == "CDS" else ccsds.CCSDS_EPOCH_NS
        day, ms, us = (values[name].astype(np.int64) for name in d.inputs)
        return epoch + day * ccsds.NS_PER_DAY + ms * 1_000_000 + us * 1_000
    estimated = np.stack([values[name] for name in d.inputs[:4]], axis=-1).astype(np.float64)
    program = np.stack([values[name] for name in d.inputs[4:]], axis=-1).astype(np.float64)
    return _error_angle(estimated, program)


@njit(cache=True)
def _error_angle(estimated: np.ndarray, program: np.ndarray) -> np.ndarray:
    """Angle 2·atan2(|e|, |e0|) of E = Λ̃^p ∘ Λ per row (seed 000 §4), via sim_core.quaternion.multiply_1."""
    out = np.empty(estimated.shape[0])
    conj = np.empty(4)
    for i in range(estimated.shape[0]):
        conj[0] = program[i, 0]
        conj[1:] = -program[i, 1:]
        e = quaternion.multiply_1(conj, estimated[i])
        out[i] = 2.0 * np.arctan2(np.sqrt(e[1] * e[1] + e[2] * e[2] + e[3] * e[3]), abs(e[0]))
    return out


def decode_packets(packets: np.ndarray, definition: PacketDefinition) -> dict[str, np.ndarray]:
    """Engineering values of every raw and derived parameter of an (n, L) packet matrix."""
    raw = decode_raw(packets, definition)
    values = {p.name: calibrate(raw[p.name], p) for p in definition.parameters}
    for d in definition.derived:
        values[d.name] = derive(d, values, definition.time_code)
    return values


def quaternion_of(values: dict[str, np.ndarray], prefix: str) -> np.ndarray:
    """(n, 4) scalar-first quaternion from the parameters ``<prefix>_0`` … ``<prefix>_3``."""
    names = [f"{prefix}_{k}" for k in range(4)]
    missing = [n for n in names if n not in values]
    if missing:
        raise ValueError(f"prefix: no parameters {missing}")
    return np.stack([np.asarray(values[n], dtype=np.float64) for n in names], axis=-1)


def _frame_records(buf: np.ndarray, frames: ccsds.Frames) -> list[QuarantineRecord]:
    """Quarantine records of the stretches framing rejected (not packets, not idle packets)."""
    bad = np.flatnonzero((frames.code != ccsds.FrameCode.OK) & (frames.code != ccsds.FrameCode.IDLE))
    records = []
    for i in bad:
        off, size = int(frames.offset[i]), int(frames.length[i])
        headed = size >= ccsds.PRIMARY_HEADER_OCTETS and int(buf[off]) >> 5 == 0
        apid = ((int(buf[off]) & 7) << 8) | int(buf[off + 1]) if headed else None
        records.append(QuarantineRecord(off, size, ccsds.FrameCode.NAMES[frames.code[i]], apid))
    return records


def _decode_apid(
    buf: np.ndarray, offset: np.ndarray, definition: PacketDefinition, window: tuple[int | None, int | None],
    report: IngestReport,
) -> SampleBatch:
    """Validate and decode the framed packets of one APID; tallies go into the report."""
    if definition.time_code is None:
        raise ValueError(f"time_code: packet {definition.name} has no secondary-header time code to stamp samples")
    packets = packet_matrix(buf, offset, definition.packet_octets)
    headers = ccsds.parse_primary_headers(packets)
    mismatch = header_mismatch(headers, secondary_header=True)
    bad = mismatch != 0
    if bad.any():
        report.quarantined.extend(
            QuarantineRecord(int(offset[i]), definition.packet_octets, "bad_header", definition.apid,
                             int(headers.sequence_count[i]), detail=HEADER_PROBLEMS[mismatch[i]])
            for i in np.flatnonzero(bad)
        )
        offset, packets = offset[~bad], packets[~bad]
        headers = ccsds.parse_primary_headers(packets)
    t0 = ccsds.PRIMARY_HEADER_OCTETS
    t_fields = packets[:, t0 : t0 + definition.time_code.octets]
    t = ccsds.decode_time(t_fields, definition.time_code)
    t[~ccsds.time_fields_valid(t_fields, definition.time_code)] = INVALID_TIME  # -> time_out_of_range
    verdict = validate_packets(definition.apid, offset, headers.sequence_count, t,
                               definition.packet_octets, *window, period_s=definition.period_s)
    kept = packets[verdict.accepted]
    batch = SampleBatch(
        packet=definition.name,
        apid=definition.apid,
        t_utc_ns=t[verdict.accepted],
        sequence_count=headers.sequence_count[verdict.accepted],
        values=decode_packets(kept, definition),
        packets=kept,
    )
    report.quarantined.extend(verdict.quarantined)
    report.duplicates += verdict.duplicates
    summary = ApidSummary(definition.apid, definition.name, len(kept), verdict.duplicates,
                          missing=sum(max(g.missing, 0) for g in verdict.gaps), gaps=verdict.gaps)
    if len(kept):
        summary.t_first_utc_ns, summary.t_last_utc_ns = int(batch.t_utc_ns[0]), int(batch.t_utc_ns[-1])
    report.apids[definition.apid] = summary
    return batch


def decode_stream(
    data: bytes | np.ndarray, dictionary: Dictionary, source: str = "", now_utc_ns: int | None = None
) -> DecodeResult:
    """Frame, validate and decode a mixed-APID packet stream (CCSDS 133.0-B-2 §4.1) into time-ordered batches."""
    buf = np.frombuffer(data, dtype=np.uint8) if isinstance(data, (bytes, bytearray, memoryview)) else data
    frames = ccsds.frame_stream(buf, dictionary.packet_octets_by_apid(), dictionary.crc_apids())
    report = IngestReport(source=source, octets=int(buf.shape[0]))
    report.quarantined.extend(_frame_records(buf, frames))
    report.idle_packets = int(np.count_nonzero(frames.code == ccsds.FrameCode.IDLE))
    offset = frames.offset[frames.code == ccsds.FrameCode.OK]
    apid = ((buf[offset].astype(np.int64) & 7) << 8) | buf[offset + 1]
    window = dictionary.time_window(now_utc_ns)
    batches = [
        _decode_apid(buf, offset[apid == a], dictionary.packets[int(a)], window, report) for a in np.unique(apid)
    ]
    report.quarantined.sort(key=lambda q: q.offset)
    for q in report.quarantined:
        if q.apid in report.apids:
            report.apids[q.apid].quarantined += 1
    report.packets_accepted = sum(len(b.t_utc_ns) for b in batches)
    report.samples_accepted = sum(b.n_samples for b in batches)
    return DecodeResult(batches=batches, report=report)
