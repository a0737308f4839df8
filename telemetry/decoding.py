"""Bulk decoding of fixed-length CCSDS packets to numpy arrays, and the stream pipeline frame → validate → decode.

Octet-aligned 8/16/32/64-bit fields are read through one numpy structured dtype over the (n, L)
packet matrix (a strided view, no per-packet Python); other bit fields are gathered from their
covering octets and shifted, vectorised over packets. Calibration: polynomial c0 + c1·x + …
(XTCE PolynomialCalibrator semantics) or an enumeration (codes kept, labels in the dictionary).
"""

from __future__ import annotations

import time

import numpy as np

from sim_core import quaternion
from telemetry import ccsds
from telemetry.dictionary import DerivedParameter, Dictionary, PacketDefinition, Parameter
from telemetry.ingest_report import ApidSummary, IngestReport, DecodeResult, QuarantineRecord, SampleBatch
from telemetry.validation import validate_packets

__all__ = [
    "packet_matrix",
    "decode_raw",
    "calibrate",
    "derive",
    "decode_packets",
    "decode_stream",
    "quaternion_of",
    "DEFAULT_FUTURE_MARGIN_NS",
]

DEFAULT_FUTURE_MARGIN_NS = 86_400 * ccsds.NS_PER_S  # packets stamped > 1 day after ingest are out of range
_ALIGNED = {8, 16, 32, 64}


def packet_matrix(buf: np.ndarray, offset: np.ndarray, packet_octets: int) -> np.ndarray:
    """(n, L) uint8 copy of the n packets of length L starting at the given offsets of buf."""
    return buf[np.asarray(offset, dtype=np.int64)[:, None] + np.arange(packet_octets)]


def _numpy_format(p: Parameter) -> str:
    """Big-endian numpy format of an octet-aligned field."""
    kind = {"uint": "u", "int": "i", "float": "f"}[p.data_type]
    return f">{kind}{p.bit_length // 8}"


def _bit_field(packets: np.ndarray, p: Parameter) -> np.ndarray:
    """Unaligned big-endian bit field (unsigned or two's complement) of every packet, as int64/uint64."""
    first, last = p.bit_offset // 8, (p.bit_offset + p.bit_length - 1) // 8
    word = np.zeros(packets.shape[0], dtype=np.uint64)
    for k in range(first, last + 1):
        word = (word << np.uint64(8)) | packets[:, k].astype(np.uint64)
    shift = np.uint64(8 * (last + 1) - p.bit_offset - p.bit_length)
    value = (word >> shift) & np.uint64((1 << p.bit_length) - 1)
    if p.data_type == "float":
        return value.astype(f"u{p.bit_length // 8}").view(f"f{p.bit_length // 8}")
    if p.data_type == "int":
        signed = value.astype(np.int64)
        return np.where(signed >= 1 << (p.bit_length - 1), signed - (1 << p.bit_length), signed)
    return value if p.bit_length == 64 else value.astype(np.int64)


def decode_raw(packets: np.ndarray, definition: PacketDefinition) -> dict[str, np.ndarray]:
    """Raw (uncalibrated) values of every parameter of an (n, L) packet matrix (CCSDS 133.0-B-2 §4.1.4 user data)."""
    if packets.dtype != np.uint8 or packets.ndim != 2 or packets.shape[1] != definition.packet_octets:
        raise ValueError(f"packets: expected (n, {definition.packet_octets}) uint8, got {packets.dtype} {packets.shape}")
    aligned = [p for p in definition.parameters if p.bit_offset % 8 == 0 and p.bit_length in _ALIGNED]
    out: dict[str, np.ndarray] = {}
    if aligned:
        dtype = np.dtype(
            {
                "names": [p.name for p in aligned],
                "formats": [_numpy_format(p) for p in aligned],
                "offsets": [p.bit_offset // 8 for p in aligned],
                "itemsize": definition.packet_octets,
            }
        )
        records = np.ascontiguousarray(packets).view(dtype)[:, 0]
        for p in aligned:
            out[p.name] = records[p.name]
    for p in definition.parameters:
        if p.name not in out:
            out[p.name] = _bit_field(packets, p)
    return {p.name: out[p.name] for p in definition.parameters}


def calibrate(raw: np.ndarray, p: Parameter) -> np.ndarray:
    """Engineering value of a raw field: polynomial Σ c_k x^k (XTCE PolynomialCalibrator), else the native value."""
    if p.polynomial:
        x = raw.astype(np.float64)
        y = np.full(x.shape, p.polynomial[-1])
        for c in p.polynomial[-2::-1]:
            y = y * x + c
        return y
    if p.data_type == "float":
        return raw.astype(np.float64)
    return raw if raw.dtype == np.uint64 else raw.astype(np.int64)


def derive(d: DerivedParameter, values: dict[str, np.ndarray], time_code: ccsds.TimeCode | None) -> np.ndarray:
    """A derived parameter: attitude error angle of E = Λ̃^p ∘ Λ (seed 000 §4), CDS time, or an alias."""
    if d.kind == "alias":
        return values[d.inputs[0]]
    if d.kind == "cds_time":
        epoch = time_code.epoch_utc_ns if time_code and time_code.format == "CDS" else ccsds.CCSDS_EPOCH_UTC_NS
        day, ms, us = (values[name].astype(np.int64) for name in d.inputs)
        return epoch + day * ccsds.NS_PER_DAY + ms * 1_000_000 + us * 1_000
    estimated = np.stack([values[name] for name in d.inputs[:4]], axis=-1)
    program = np.stack([values[name] for name in d.inputs[4:]], axis=-1)
    return quaternion.angle(quaternion.multiply(quaternion.conjugate(program), estimated))


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
        apid = int(((buf[off] & 7) << 8) | buf[off + 1]) if size >= 2 else None
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
    t0 = ccsds.PRIMARY_HEADER_OCTETS
    t = ccsds.decode_time(packets[:, t0 : t0 + definition.time_code.octets], definition.time_code)
    verdict = validate_packets(definition.apid, offset, headers.sequence_count, t,
                               definition.packet_octets, *window)
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
                          sum(max(g.missing, 0) for g in verdict.gaps), verdict.gaps)
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
    now = time.time_ns() if now_utc_ns is None else now_utc_ns
    until = dictionary.valid_until_utc_ns if dictionary.valid_until_utc_ns is not None else now + DEFAULT_FUTURE_MARGIN_NS
    window = (dictionary.valid_from_utc_ns, until)
    batches = [_decode_apid(buf, offset[apid == a], dictionary.packets[int(a)], window, report) for a in np.unique(apid)]
    report.quarantined.sort(key=lambda q: q.offset)
    report.packets_accepted = sum(len(b.t_utc_ns) for b in batches)
    report.samples_accepted = sum(b.n_samples for b in batches)
    return DecodeResult(batches=batches, report=report)
