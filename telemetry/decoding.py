"""Bulk decoding of fixed-length CCSDS packets to numpy arrays, and the stream pipeline frame → validate → decode.

All fields of a packet layout are read in one compiled pass straight from the stream buffer at the
packets' offsets (no per-packet matrix is built): the covering octets of each field, big-endian,
shifted, masked and sign-extended (any bit offset and length ≤ 64, spanning ≤ 8 octets), into one
(F, n) column matrix whose rows are the parameters' values (int64 rows are handed out as views).
IEEE 754 floats and other byte orders are then converted per field. No per-packet Python.
Calibration: polynomial c0 + c1·x + … (XTCE PolynomialCalibrator semantics) or an enumeration
(codes kept, labels in the dictionary).
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from numba import njit, types
from numba.core import cgutils
from numba.extending import intrinsic

from sim_core import quaternion
from telemetry import ccsds, xtce_bulk
from telemetry.dictionary import DerivedParameter, Dictionary, PacketDefinition, Parameter, XtceSource, xtce_parameter
from telemetry.ingest_report import (
    ApidSummary,
    ColumnMatrices,
    DecodeResult,
    IngestReport,
    QuarantineRecord,
    SampleBatch,
    UndefinedPackets,
)
from telemetry.packet_time import TIME_PROBLEMS, field_times
from telemetry.validation import HEADER_PROBLEMS, INVALID_TIME, SequenceState, header_mismatch, validate_packets

__all__ = [
    "packet_matrix",
    "decode_raw",
    "calibrate",
    "derive",
    "decode_packets",
    "decode_stream",
    "decoded_octets_per_octet",
    "quaternion_of",
]


@intrinsic
def _copy_octets(typingctx: Any, dst: Any, dst_start: Any, src: Any, src_start: Any, count: Any) -> Any:
    """memcpy of ``count`` octets from src[src_start:] to dst[dst_start:] (contiguous uint8 arrays, in bounds: the
    caller's duty). A numba slice assignment copies ~4 GB/s here, memcpy ~15 GB/s (issue 12)."""
    if not all(isinstance(a, types.Array) and a.layout == "C" and a.dtype == types.uint8 for a in (dst, src)):
        return None  # no such function: a strided view would be copied wrong
    sig = types.void(dst, types.intp, src, types.intp, types.intp)

    def codegen(context: Any, builder: Any, signature: Any, args: Any) -> Any:
        to = context.make_array(signature.args[0])(context, builder, args[0])
        of = context.make_array(signature.args[2])(context, builder, args[2])
        to_octet, of_octet = builder.gep(to.data, [args[1]]), builder.gep(of.data, [args[3]])
        cgutils.raw_memcpy(builder, to_octet, of_octet, args[4], 1)  # type: ignore[no-untyped-call]
        return context.get_dummy_value()

    return sig, codegen


@njit(cache=True, nogil=True)
def _gather(buf: np.ndarray, offset: np.ndarray, packet_octets: int) -> np.ndarray:
    """Copy the packets starting at offset (each within buf) into rows of an (n, L) matrix (compiled kernel; a
    memcpy per row: 6-octet rows ~6x faster than a slice assignment)."""
    out = np.empty((offset.shape[0], packet_octets), dtype=np.uint8)
    rows = out.reshape(-1)
    for i in range(offset.shape[0]):
        _copy_octets(rows, i * packet_octets, buf, offset[i], packet_octets)  # type: ignore[call-arg]  # typingctx: numba's
    return out


def packet_matrix(buf: np.ndarray, offset: np.ndarray, packet_octets: int) -> np.ndarray:
    """(n, L) uint8 copy of the n packets of length L starting at the given offsets of buf."""
    offset = np.asarray(offset, dtype=np.int64)
    if offset.size and (offset.min() < 0 or offset.max() + packet_octets > buf.shape[0]):
        raise ValueError("offset: a packet would run past the end of the buffer")
    return _gather(np.ascontiguousarray(buf), offset, packet_octets)


def _reorder_octets(pattern: np.ndarray, p: Parameter) -> np.ndarray:
    """A field's bit pattern with its octets reordered as ccsdspy does (``little`` or digits like ``3412``).

    As ccsdspy (decode.py, packet_types._do_array_byte_reordering): the masked, right-aligned value
    sits in a container of the field's covering octets (3 -> 4, 5..7 -> 8) that is byte-swapped for
    ``little``; a digit order permutes that container's octets (1 = least significant), right-aligned.
    """
    covering = (p.bit_offset + p.bit_length - 1) // 8 - p.bit_offset // 8 + 1
    width = {3: 4, 5: 8, 6: 8, 7: 8}.get(covering, covering)
    shifts = np.arange(8 * (width - 1), -8, -8, dtype=np.uint64)
    octets = (pattern[:, None] >> shifts) & np.uint64(0xFF)  # most significant first
    if p.byte_order == "little":
        octets = octets[:, ::-1]
    else:
        digits = [int(d) for d in p.byte_order]
        chosen = [d - 1 for d in reversed(digits)]
        select = chosen + sorted(set(range(width)) - set(chosen))
        reordered = octets[:, ::-1][:, select]
        padding = width - len(digits)
        octets = np.zeros_like(reordered)
        octets[:, padding:] = reordered[:, : width - padding]
    return np.bitwise_or.reduce(octets << shifts, axis=1) if width else pattern


def _raw_value(pattern: np.ndarray, p: Parameter) -> np.ndarray:
    """Raw value of a field's bit patterns: IEEE 754 float, two's-complement int, or unsigned."""
    if p.byte_order != "big":
        pattern = _reorder_octets(pattern, p)
    if p.data_type == "float":
        return pattern.astype(np.uint32).view(np.float32) if p.bit_length == 32 else pattern.view(np.float64)
    if p.data_type == "int":
        signed = pattern.view(np.int64)
        if p.bit_length == 64:
            return signed
        return np.where(signed >= 1 << (p.bit_length - 1), signed - (1 << p.bit_length), signed)
    return pattern if p.bit_length == 64 else pattern.view(np.int64)


_BLOCK_PACKETS = 64  # packets whose fields are read field after field: their octets stay in the L1 cache
_OCTET = np.uint64(8)
_U1, _U2, _U3, _U8 = np.uint64(1), np.uint64(2), np.uint64(3), np.uint64(8)  # unsigned index steps


@njit(cache=True, nogil=True, inline="always")
def _field_word(buf: np.ndarray, k0: int, k1: int, shift: np.uint64, mask: np.uint64, sign: np.uint64) -> np.uint64:
    """The big-endian word of octets k0..k1-1 of buf >> shift & mask, sign-extended where it has the sign bit."""
    word = np.uint64(0)
    for k in range(k0, k1):
        word = (word << _OCTET) | np.uint64(buf[k])
    value = (word >> shift) & mask
    if value & sign:
        value |= ~mask
    return value


@njit(cache=True, nogil=True)
def _field_columns(
    buf: np.ndarray,
    offset: np.ndarray,
    first: np.ndarray,
    last: np.ndarray,
    shift: np.ndarray,
    mask: np.ndarray,
    sign: np.ndarray,
    slot: np.ndarray,
    row: np.ndarray,
    out1: np.ndarray,
    out2: np.ndarray,
    out4: np.ndarray,
    out8: np.ndarray,
) -> None:
    """The fields of the n packets at offset in buf, read in place into rows of (·, n) matrices of 1, 2, 4 and
    8 octets (compiled kernel): field f goes to row row[f] of out1/out2/out4/out8 by slot[f] = 0/1/2/3.

    Field f covers octets first[f]..last[f] of its packet; its value is that big-endian word
    >> shift[f] & mask[f], sign-extended to 64 bits (two's complement) where sign[f] has its sign bit,
    kept in the slot's width (the low octets: a narrower signed field is its two's complement there).
    Packets are taken _BLOCK_PACKETS at a time, field after field (each output row written contiguously, the
    slot's branch taken once per field); a field covering 1, 2, 3-4 octets in a slot of that width, or an unsigned
    one of 4 or 8 octets in the 8-octet slot, has a loop of its own (CYGNSS: ~70 M fields/s -> ~130 M fields/s,
    2026-12-03; ECM's signed 24-bit fields ~10 -> 4-8 ns each, 2026-12-04). Those loops index with unsigned
    integers: a signed index costs a negative-index wraparound per access (CYGNSS APID 393, 101 fields of
    8,484 packets: 1.66 -> 0.73 ms, 2026-12-05).
    """
    n, n_fields = offset.shape[0], first.shape[0]
    for start in range(0, n, _BLOCK_PACKETS):
        stop = min(start + _BLOCK_PACKETS, n)
        u_start, u_stop = np.uint64(start), np.uint64(stop)
        for f in range(n_fields):
            lo, hi, sh, m, sg, s, r = first[f], last[f] + 1, shift[f], mask[f], sign[f], slot[f], row[f]
            octets = hi - lo
            u_lo, u_r = np.uint64(lo), np.uint64(r)  # unsigned indices: no negative-index wraparound in the loops
            if s == 0 and octets == 1:  # sign-extended in the slot's width: its low octets of the 64-bit rule
                m1, sg1 = np.uint8(m), np.uint8(sg)
                for i in range(u_start, u_stop):
                    value8 = (buf[np.uint64(offset[i]) + u_lo] >> np.uint8(sh)) & m1
                    out1[u_r, i] = value8 | ~m1 if value8 & sg1 else value8
            elif s == 1 and octets == 2:
                m2, sg2 = np.uint16(m), np.uint16(sg)
                for i in range(u_start, u_stop):
                    o = np.uint64(offset[i]) + u_lo
                    word16 = (np.uint16(buf[o]) << np.uint16(8)) | np.uint16(buf[o + _U1])
                    value16 = (word16 >> np.uint16(sh)) & m2
                    out2[u_r, i] = value16 | ~m2 if value16 & sg2 else value16
            elif s == 2 and (octets == 4 or octets == 3):
                m4, sg4 = np.uint32(m), np.uint32(sg)
                for i in range(u_start, u_stop):
                    o = np.uint64(offset[i]) + u_lo
                    word32 = (np.uint32(buf[o]) << np.uint32(16)) | (np.uint32(buf[o + _U1]) << np.uint32(8))
                    word32 |= np.uint32(buf[o + _U2])
                    if octets == 4:
                        word32 = (word32 << np.uint32(8)) | np.uint32(buf[o + _U3])
                    value32 = (word32 >> np.uint32(sh)) & m4
                    out4[u_r, i] = value32 | ~m4 if value32 & sg4 else value32
            elif sg == 0 and s == 3 and octets == 4:  # 32-bit floats, fields of other byte orders
                for i in range(u_start, u_stop):
                    o = np.uint64(offset[i]) + u_lo
                    word = (
                        (np.uint64(buf[o]) << np.uint64(24))
                        | (np.uint64(buf[o + _U1]) << np.uint64(16))
                        | (np.uint64(buf[o + _U2]) << _OCTET)
                        | np.uint64(buf[o + _U3])
                    )
                    out8[u_r, i] = (word >> sh) & m
            elif sg == 0 and s == 3 and octets == 8:
                for i in range(u_start, u_stop):
                    o = np.uint64(offset[i]) + u_lo
                    word = np.uint64(0)
                    for k in range(_U8):
                        word = (word << _OCTET) | np.uint64(buf[o + k])
                    out8[u_r, i] = (word >> sh) & m
            else:
                for i in range(start, stop):
                    value = _field_word(buf, offset[i] + lo, offset[i] + hi, sh, m, sg)
                    if s == 0:
                        out1[r, i] = np.uint8(value & np.uint64(0xFF))
                    elif s == 1:
                        out2[r, i] = np.uint16(value & np.uint64(0xFFFF))
                    elif s == 2:
                        out4[r, i] = np.uint32(value & np.uint64(0xFFFFFFFF))
                    else:
                        out8[r, i] = value


_SLOT_OCTETS = (1, 2, 4, 8)  # octets of the kernel's output rows by slot
_NO_ROWS = tuple(np.empty((0, 0), f"u{w}") for w in _SLOT_OCTETS)  # a slot no field of a layout uses


@dataclass(frozen=True)
class _LayoutPlan:
    """A fixed layout compiled for :func:`_field_columns`: kernel arrays, each field's slot and row, and the
    dtype its bits are read as when they are already its raw value (big-endian integers: _integer_dtype),
    else None (floats, other byte orders: converted from the 64-bit pattern by _raw_value)."""

    parameters: tuple[Parameter, ...]
    first: np.ndarray
    last: np.ndarray
    shift: np.ndarray
    mask: np.ndarray
    sign: np.ndarray
    slot: np.ndarray
    row: np.ndarray
    rows: tuple[int, int, int, int]  # rows of each slot's matrix
    views: tuple[np.dtype | None, ...]
    casts: tuple[np.dtype | None, ...]  # integers of other byte orders: the dtype _raw_value's int64 goes to
    # big-endian integers without calibration (values = raw = a row of their slot's matrix in their dtype): (name,
    # index in plain_views, row), and the (slot, dtype) views they are rows of (a slot may hold several dtypes)
    plain: tuple[tuple[str, int, int], ...]
    plain_views: tuple[tuple[int, np.dtype], ...]
    # big-endian IEEE floats without calibration: the first rows of the 8-octet matrix, 32-bit ones then 64-bit
    # ones, converted a block at a time (one astype for all 32-bit ones, not two per field); names in that order
    floats32: tuple[str, ...]
    floats64: tuple[str, ...]
    others: tuple[tuple[Parameter, int, int, np.dtype | None, np.dtype | None], ...]  # (p, slot, row, view, cast)
    # every field plain or a blocked float (no others, names unique): the engineering values are handed out as a
    # ColumnMatrices, one matrix per (slot, dtype) of plain fields -- (slot, dtype, positions, first row; the rows
    # of one (slot, dtype) are consecutive, in parameter order) -- and the float blocks (positions, in their order)
    names: tuple[str, ...]
    plain_groups: tuple[tuple[int, np.dtype, list[int], int], ...]
    float_positions: tuple[list[int], list[int]]
    matrices: bool


_PLANS: dict[int, _LayoutPlan] = {}  # by id() of a layout's parameter tuple (kept alive by the plan)
_MAX_PLANS = 4_096


def _integer_dtype(p: Parameter) -> np.dtype | None:
    """The dtype of an integer field's raw values, as wide as ccsdspy makes it (its covering octets: 1, 2,
    3-4 -> 4, 5-8 -> 8), int64 for an unsigned field of 33..63 bits; None for other fields."""
    if p.data_type not in ("int", "uint"):
        return None
    covering = (p.bit_offset + p.bit_length - 1) // 8 - p.bit_offset // 8 + 1
    octets = next(w for w in _SLOT_OCTETS if w >= covering)
    if p.data_type == "uint" and octets == 8 and p.bit_length < 64:
        return np.dtype(np.int64)  # the archive's integer type; exact below 2**63
    return np.dtype(f"{'i' if p.data_type == 'int' else 'u'}{octets}")


def decoded_octets_per_octet(definition: PacketDefinition) -> float:
    """Most octets of decoded values one octet of these packets yields: exact for a fixed layout (integers in
    their width, floats and calibrated values 8 octets, derived ones 8); 8 per value otherwise
    (Dictionary.values_per_octet, an upper bound)."""
    if definition.xtce is not None or definition.fields:
        return 8 * definition.values_per_octet
    dtypes = [_integer_dtype(p) for p in definition.parameters]
    octets = sum(8 if p.polynomial or d is None else d.itemsize for p, d in zip(definition.parameters, dtypes))
    return (octets + 8 * len(definition.derived)) / definition.packet_octets


def _plan(parameters: tuple[Parameter, ...]) -> _LayoutPlan:
    """The compiled plan of a layout's parameters (made once per layout)."""
    plan = _PLANS.get(id(parameters))
    if plan is not None and plan.parameters is parameters:
        return plan
    bit = np.array([p.bit_offset for p in parameters], dtype=np.int64)
    bits = np.array([p.bit_length for p in parameters], dtype=np.int64)
    first, last = bit // 8, (bit + bits - 1) // 8
    dtypes = tuple(_integer_dtype(p) for p in parameters)
    views = tuple(d if p.byte_order == "big" else None for p, d in zip(parameters, dtypes))
    slot = [3 if v is None else _SLOT_OCTETS.index(v.itemsize) for v in views]
    unique = len({p.name for p in parameters}) == len(parameters)  # else in order, the last of a name kept
    floating = [
        unique and p.data_type == "float" and p.byte_order == "big" and not p.polynomial and p.bit_length in (32, 64)
        for p in parameters
    ]
    blocked = [i for b in (32, 64) for i, p in enumerate(parameters) if floating[i] and p.bit_length == b]
    row, rows = [0] * len(parameters), [0, 0, 0, len(blocked)]
    for r, i in enumerate(blocked):
        row[i] = r
    by_view: dict[tuple[int, np.dtype], list[int]] = {}  # plain fields by (slot, dtype): consecutive rows each
    rest = []
    for i, (p, s, v) in enumerate(zip(parameters, slot, views)):
        if unique and v is not None and not p.polynomial:
            by_view.setdefault((s, v), []).append(i)
        elif not floating[i]:
            rest.append(i)
    plain_groups = []
    for (s, v), members in by_view.items():
        plain_groups.append((s, v, members, rows[s]))
        for i in members:
            row[i] = rows[s]
            rows[s] += 1
    for i in rest:
        row[i] = rows[slot[i]]
        rows[slot[i]] += 1
    singles = sum(parameters[i].bit_length == 32 for i in blocked)  # blocked: the 32-bit floats, then the 64-bit
    casts = tuple(d if v is None else None for d, v in zip(dtypes, views))
    plain_views: dict[tuple[int, np.dtype], int] = {}
    plain, others = [], []
    for p, s, r, v, c, f in zip(parameters, slot, row, views, casts, floating):
        if unique and v is not None and not p.polynomial:
            plain.append((p.name, plain_views.setdefault((s, v), len(plain_views)), r))
        elif not f:
            others.append((p, s, r, v, c))
    plan = _LayoutPlan(
        parameters,
        first,
        last,
        (8 * (last + 1) - bit - bits).astype(np.uint64),
        np.array([(1 << b) - 1 for b in bits.tolist()], dtype=np.uint64),
        np.array(
            [
                1 << (p.bit_length - 1) if p.data_type == "int" and v is not None else 0
                for p, v in zip(parameters, views)
            ],
            dtype=np.uint64,
        ),
        np.array(slot, dtype=np.int64),
        np.array(row, dtype=np.int64),
        (rows[0], rows[1], rows[2], rows[3]),
        views,
        casts,
        tuple(plain),
        tuple(plain_views),
        tuple(parameters[i].name for i in blocked if parameters[i].bit_length == 32),
        tuple(parameters[i].name for i in blocked if parameters[i].bit_length == 64),
        tuple(others),
        tuple(p.name for p in parameters),
        tuple(plain_groups),
        (blocked[:singles], blocked[singles:]),
        unique and not others,
    )
    if len(_PLANS) >= _MAX_PLANS:
        _PLANS.clear()
    _PLANS[id(parameters)] = plan
    return plan


def _layout_values(
    buf: np.ndarray, offset: np.ndarray, parameters: tuple[Parameter, ...], calibrated: bool
) -> dict[str, np.ndarray]:
    """Raw (calibrated=False) or engineering values of the parameters in the packets at offset of buf, by name.

    Big-endian integers are views of the kernel's rows in the width of their field (no copy), as ccsdspy
    gives them; calibrated ones are float64."""
    plan = _plan(parameters)
    n = offset.shape[0]
    outs = [
        np.empty((rows, n), f"u{w}") if rows else _NO_ROWS[s]
        for s, (rows, w) in enumerate(zip(plan.rows, _SLOT_OCTETS))
    ]
    _field_columns(
        buf,
        np.asarray(offset, dtype=np.int64),
        plan.first,
        plan.last,
        plan.shift,
        plan.mask,
        plan.sign,
        plan.slot,
        plan.row,
        *outs,
    )
    if calibrated and plan.matrices:  # engineering values: the kernel's rows as they are, one matrix per dtype
        return _column_matrices(plan, outs)
    out = {}
    viewed = [outs[s].view(d) for s, d in plan.plain_views]
    for name, k, r in plan.plain:  # a row of its slot's matrix in its dtype: one index per parameter
        out[name] = viewed[k][r]
    if plan.floats32:  # as _raw_value and calibrate do per field: the low 32 bits as float32, float64 calibrated
        singles = outs[3][: len(plan.floats32)].astype(np.uint32).view(np.float32)
        out.update(zip(plan.floats32, singles.astype(np.float64) if calibrated else singles))
    if plan.floats64:
        out.update(
            zip(plan.floats64, outs[3][len(plan.floats32) : len(plan.floats32) + len(plan.floats64)].view(np.float64))
        )
    for p, s, r, view, cast in plan.others:
        raw = outs[s][r].view(view) if view is not None else _raw_value(outs[s][r], p)
        if cast is not None:
            raw = raw.astype(cast, copy=False)
        out[p.name] = calibrate(raw, p) if calibrated and (view is None or p.polynomial) else raw
    if sum(map(bool, (plan.plain, plan.floats32 or plan.floats64, plan.others))) > 1:  # in the parameters' order
        out = {p.name: out[p.name] for p in parameters}  # (plain and floats only when their names are unique)
    return out


def _column_matrices(plan: _LayoutPlan, outs: list[np.ndarray]) -> ColumnMatrices:
    """The engineering values of a layout of plain fields and float blocks (plan.matrices) as a ColumnMatrices of the
    kernel's rows: the archive takes each matrix whole (concatenation, ranges, compression), not column by column.
    The columns are the rows _layout_values hands out otherwise, in the parameters' order."""
    groups = [
        (dtype, positions, outs[s][first : first + len(positions)].view(dtype))
        for s, dtype, positions, first in plan.plain_groups
    ]
    singles, doubles = plan.float_positions
    if singles:  # as _raw_value and calibrate do per field: the low 32 bits as float32, then float64
        as_single = outs[3][: len(singles)].astype(np.uint32).view(np.float32)
        groups.append((_FLOAT64, singles, as_single.astype(np.float64)))
    if doubles:
        groups.append((_FLOAT64, doubles, outs[3][len(singles) : len(singles) + len(doubles)].view(np.float64)))
    return ColumnMatrices(plan.names, groups)


_FLOAT64 = np.dtype(np.float64)


def _raw_values(buf: np.ndarray, offset: np.ndarray, parameters: tuple[Parameter, ...]) -> dict[str, np.ndarray]:
    """Raw values of the parameters in the packets at offset of buf, by name."""
    return _layout_values(buf, offset, parameters, calibrated=False)


def decode_raw(packets: np.ndarray, definition: PacketDefinition) -> dict[str, np.ndarray]:
    """Raw (uncalibrated) values of every parameter of an (n, L) packet matrix (CCSDS 133.0-B-2 §4.1.4 user data)."""
    if packets.dtype != np.uint8 or packets.ndim != 2 or packets.shape[1] != definition.packet_octets:
        expected = f"(n, {definition.packet_octets}) uint8"
        raise ValueError(f"packets: expected {expected}, got {packets.dtype} {packets.shape}")
    flat = np.ascontiguousarray(packets).reshape(-1)
    offset = np.arange(packets.shape[0], dtype=np.int64) * definition.packet_octets
    return _raw_values(flat, offset, definition.parameters)


def calibrate(raw: np.ndarray, p: Parameter) -> np.ndarray:
    """Engineering value of a raw field: polynomial Σ c_k x^k (XTCE PolynomialCalibrator), else the native value
    (floats as float64, integers in their own dtype).

    The sum runs term by term from k = 0, each power of an integer exact and rounded once to float64, as
    space_packet_parser's PolynomialCalibrator computes ``sum(c * x**k)`` on Python ints: the values agree to
    the last bit (Horner's scheme, one rounding per step, differs by an ulp in about one value of ten of a
    cubic, e.g. IMAP-Lo's BHV_DEF_NEG_I). Linear calibrations give c0 + c1·x either way.
    """
    if p.polynomial:
        y = np.full(raw.shape, float(p.polynomial[0]))  # float64 whatever the coefficients type
        for c, power in zip(p.polynomial[1:], _powers(raw, len(p.polynomial) - 1)):
            if c != 0.0:  # a term the calibrator does not list (space_packet_parser sums only those it lists)
                y += c * power
        return y
    if p.data_type == "float":
        return raw.astype(np.float64, copy=False)
    return raw


def _powers(raw: np.ndarray, degree: int) -> Iterator[np.ndarray]:
    """float64 of raw**k for k = 1..degree: for integers the exact power rounded once (Python's ``float(x**k)``),
    in int64 while it fits, else with Python ints; for floats the float64 power (C ``pow``, as Python's)."""
    if raw.dtype.kind == "f":
        x = raw.astype(np.float64, copy=False)
        yield from (x if k == 1 else x**k for k in range(1, degree + 1))
        return
    top = max(abs(int(raw.min())), abs(int(raw.max()))) if raw.size else 0
    power = exact = raw.astype(np.int64) if top < 2**63 else raw.astype(object)  # object: Python ints
    for k in range(1, degree + 1):
        if k > 1:
            power = power * exact if top**k < 2**63 else power.astype(object) * raw.astype(object)
        yield power.astype(np.float64)


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


@njit(cache=True, nogil=True)
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
    code = frames.code  # three comparisons: ~10 us on a chunk's 20 k codes, np.isin ~90 us
    bad = np.flatnonzero(
        (code != ccsds.FrameCode.OK) & (code != ccsds.FrameCode.IDLE) & (code != ccsds.FrameCode.UNDEFINED)
    )
    records = []
    for i in bad:
        off, size = int(frames.offset[i]), int(frames.length[i])
        headed = size >= ccsds.PRIMARY_HEADER_OCTETS and int(buf[off]) >> 5 == 0
        apid = ((int(buf[off]) & 7) << 8) | int(buf[off + 1]) if headed else None
        records.append(QuarantineRecord(off, size, ccsds.FrameCode.NAMES[frames.code[i]], apid))
    return records


def _layout_groups(
    buf: np.ndarray, offset: np.ndarray, length: np.ndarray, definition: PacketDefinition
) -> tuple[list[tuple[np.ndarray, PacketDefinition]], dict[int, str]]:
    """Packets sharing one fixed layout (by length and count-field values), and why the others are too short."""
    short: dict[int, str] = {}
    needed = definition.packet_octets
    for i in np.flatnonzero(length < needed).tolist():
        short[i] = f"packet has {int(length[i])} octets, the definition needs {needed}"
    fits = np.flatnonzero(length >= needed)
    if not definition.variable:
        return ([(fits, definition)] if fits.size else []), short
    counts = definition.count_fields
    keys = length[fits][:, None]
    if counts and fits.size:
        fixed = tuple(p for p in definition.parameters if p.name in counts)
        raw = _raw_values(buf, offset[fits], fixed)
        keys = np.stack([length[fits]] + [raw[c].astype(np.int64) for c in counts], axis=1)
    groups = []
    unique, inverse = np.unique(keys, axis=0, return_inverse=True)
    for g, key in enumerate(unique.tolist()):
        idx = fits[inverse.ravel() == g]
        layout = _resolved(definition, tuple(key), counts)
        if isinstance(layout, str):
            short.update(dict.fromkeys(idx.tolist(), layout))
            continue
        groups.append((idx, layout))
    return groups, short


_LAYOUTS: dict[tuple[int, tuple[int, ...]], tuple[PacketDefinition, PacketDefinition | str]] = {}


def _resolved(definition: PacketDefinition, key: tuple[int, ...], counts: tuple[str, ...]) -> PacketDefinition | str:
    """The fixed layout of a variable definition for (packet octets, count-field values), or why there is none;
    made once per key, so the decoder's compiled plan of that layout is reused chunk after chunk."""
    known = _LAYOUTS.get((id(definition), key))
    if known is not None and known[0] is definition:
        return known[1]
    try:
        params = definition.resolve(key[0], dict(zip(counts, key[1:])))
        layout: PacketDefinition | str = replace(definition, parameters=params, packet_octets=key[0], fields=())
    except ValueError as exc:
        layout = str(exc)
    if len(_LAYOUTS) >= _MAX_PLANS:
        _LAYOUTS.clear()
    _LAYOUTS[(id(definition), key)] = (definition, layout)
    return layout


def _union(parts: list[tuple[np.ndarray, dict[str, np.ndarray]]], n: int) -> dict[str, np.ndarray]:
    """Values of all packets by parameter; float64 NaN where a packet's layout lacks the parameter."""
    if len(parts) == 1 and len(parts[0][0]) == n:
        return parts[0][1]
    names = dict.fromkeys(name for _, values in parts for name in values)
    out = {}
    for name in names:
        pieces = [(idx, values[name]) for idx, values in parts if name in values]
        complete = sum(len(idx) for idx, _ in pieces) == n
        column = np.empty(n, np.result_type(*(v for _, v in pieces))) if complete else np.full(n, np.nan)
        for idx, v in pieces:
            column[idx] = v
        out[name] = column
    return out


@njit(cache=True, nogil=True)
def _gather_octets(buf: np.ndarray, offset: np.ndarray, length: np.ndarray) -> np.ndarray:
    """The packets at offset (of the given lengths, each within buf) back to back (compiled kernel): packets that
    follow one another in buf are one copy."""
    out = np.empty(length.sum(), dtype=np.uint8)
    k, i, n = 0, 0, offset.shape[0]
    while i < n:
        start = offset[i]
        stop = start + length[i]
        i += 1
        while i < n and offset[i] == stop:
            stop += length[i]
            i += 1
        _copy_octets(out, k, buf, start, stop - start)  # type: ignore[call-arg]  # typingctx: numba's
        k += stop - start
    return out


def _packet_times(
    buf: np.ndarray, offset: np.ndarray, raw: dict[str, np.ndarray], layout: PacketDefinition
) -> tuple[np.ndarray, dict[int, str]]:
    """UTC ns of the packets at offset of one layout and, by position, why a packet's time is invalid."""
    if layout.time_fields is not None:
        t, problem = field_times(raw, layout.time_fields)
        return t, {int(i): TIME_PROBLEMS[problem[i]] for i in np.flatnonzero(problem)}
    code = layout.time_code
    assert code is not None
    t_fields = packet_matrix(buf, offset, ccsds.PRIMARY_HEADER_OCTETS + code.octets)[:, ccsds.PRIMARY_HEADER_OCTETS :]
    valid = ccsds.time_fields_valid(t_fields, code)
    return ccsds.decode_time(t_fields, code), {int(i): "invalid time code field" for i in np.flatnonzero(~valid)}


def _time_field_raws(
    buf: np.ndarray, offset: np.ndarray, layout: PacketDefinition, values: dict[str, np.ndarray]
) -> dict[str, np.ndarray]:
    """Raw values of the layout's time fields (their engineering values when no calibration applies)."""
    assert layout.time_fields is not None
    names = set(layout.time_fields.names)
    redo = tuple(p for p in layout.parameters if p.name in names and p.polynomial)
    return {**values, **(_raw_values(buf, offset, redo) if redo else {})}


def _group_values(
    buf: np.ndarray, offset: np.ndarray, groups: list[tuple[np.ndarray, PacketDefinition]], n: int
) -> tuple[np.ndarray, dict[int, str], list[tuple[np.ndarray, dict[str, np.ndarray]]]]:
    """Times, time problems by packet index and calibrated values of each fixed-layout group."""
    t = np.full(n, INVALID_TIME, dtype=np.int64)
    problems: dict[int, str] = {}
    parts = []
    for idx, layout in groups:
        values = _layout_values(buf, offset[idx], layout.parameters, calibrated=True)
        times = values if layout.time_fields is None else _time_field_raws(buf, offset[idx], layout, values)
        t[idx], why = _packet_times(buf, offset[idx], times, layout)
        problems.update((int(idx[i]), w) for i, w in why.items())
        parts.append((idx, values))
    return t, problems, parts


def _xtce_values(
    buf: np.ndarray, offset: np.ndarray, length: np.ndarray, definition: PacketDefinition
) -> tuple[np.ndarray, dict[int, str], list[tuple[np.ndarray, dict[str, np.ndarray]]], dict[int, str]]:
    """Packets of a polymorphic or dynamically sized XTCE definition parsed one by one by space_packet_parser:
    times, time problems, numeric values (raw codes for enumerations, NaN where a container lacks a parameter)
    and the packets it could not parse (shorter than their container)."""
    source = definition.xtce
    assert source is not None
    n = offset.shape[0]
    try:
        calibrated, short, partial = _xtce_bulk(buf, offset, length, source)
        raw = calibrated  # the bulk walk takes no calibrated parameters: engineering value = raw number
        values = {
            name: _narrow(v) if v.dtype.kind == "f" and name not in partial else v for name, v in calibrated.items()
        }
    except xtce_bulk.Unsupported:
        calibrated, raw, short = _xtce_one_by_one(buf, offset, length, source)
        values = {
            name: _narrow(v) if v.dtype.kind == "f" else v
            for name, v in calibrated.items()
            if v.dtype.kind != "f" or not np.isnan(v).all()
        }
    timed = definition.time_fields.names if definition.time_fields is not None else ()
    raw = {name: raw.get(name, np.full(n, np.nan)) for name in timed}
    codes = {name: _narrow(raw[name]) if raw[name].dtype.kind == "f" else raw[name] for name in timed}
    t = np.full(n, INVALID_TIME, dtype=np.int64)
    problems: dict[int, str] = {}
    ok = np.setdiff1d(np.arange(n), list(short))
    if definition.time_fields is not None:
        missing = [k for k in definition.time_fields.names if np.isnan(raw[k][ok]).any()]
        if missing:
            problems.update((int(i), f"time fields {missing} absent") for i in ok if np.isnan(raw[missing[0]][i]))
        good = np.array([i for i in ok.tolist() if i not in problems], dtype=np.int64)
        t[good], why = field_times(
            {k: codes[k][good].astype(np.int64) for k in definition.time_fields.names}, definition.time_fields
        )
        problems.update((int(i), TIME_PROBLEMS[c]) for i, c in zip(good.tolist(), why.tolist()) if c)
    else:
        t[ok], bad_time = _packet_times(buf, offset[ok], {}, definition)
        problems.update((int(ok[i]), w) for i, w in bad_time.items())
    return t, problems, [(np.arange(n), values)], short


_WALKS: dict[int, tuple[object, xtce_bulk.XtceWalk]] = {}  # by id() of a space_packet_parser definition


def _xtce_bulk(
    buf: np.ndarray, offset: np.ndarray, length: np.ndarray, source: XtceSource
) -> tuple[dict[str, np.ndarray], dict[int, str], set[str]]:
    """Numeric values of XTCE packets decoded in bulk by container (telemetry.xtce_bulk): a parameter every
    packet has keeps its decoded integer dtype, others (named in the set returned) are float64 with NaN where a
    packet's container lacks them (parameters no packet has are left out); and why packets could not be parsed.
    Unsupported when the walk meets a construct it does not reproduce exactly."""
    known = _WALKS.get(id(source.definition))
    if known is None or known[0] is not source.definition:
        known = (source.definition, xtce_bulk.XtceWalk(source.definition, xtce_parameter))
        _WALKS[id(source.definition)] = known
    n = offset.shape[0]

    def read(positions: np.ndarray, parameters: tuple[Parameter, ...]) -> dict[str, np.ndarray]:
        return _layout_values(buf, offset[positions], parameters, calibrated=True)

    parts, failed = known[1].parse(np.arange(n), length, read)
    numeric = set(source.numeric)
    pieces: dict[str, list[tuple[np.ndarray, np.ndarray]]] = {}
    for idx, values in parts:
        for name, v in values.items():
            if name in numeric:
                pieces.setdefault(name, []).append((idx, v))
    columns, partial = {}, set()
    for name, have in pieces.items():
        if len(have) == 1 and len(have[0][0]) == n and _exact_in_int64(have[0][1]):
            columns[name] = have[0][1]  # one group of every packet, in order (groups keep ascending positions)
            continue
        every = sum(len(idx) for idx, _ in have) == n
        whole = every and all(_exact_in_int64(v) for _, v in have)
        column = np.empty(n, np.result_type(*(v for _, v in have))) if whole else np.full(n, np.nan)
        for idx, v in have:
            column[idx] = v
        columns[name] = column
        if not every:
            partial.add(name)
    return columns, {i: f"space_packet_parser would fail: {why}" for i, why in failed.items()}, partial


def _exact_in_int64(values: np.ndarray) -> bool:
    """Whether an array is of an integer type int64 holds (any signed one, unsigned below 64 bits)."""
    return values.dtype.kind == "i" or (values.dtype.kind == "u" and values.dtype.itemsize < 8)


def _xtce_one_by_one(
    buf: np.ndarray, offset: np.ndarray, length: np.ndarray, source: XtceSource
) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray], dict[int, str]]:
    """Calibrated and raw numeric values of XTCE packets parsed one by one by space_packet_parser (NaN where a
    packet's container lacks the parameter), and why packets could not be parsed."""
    n = offset.shape[0]
    calibrated = {name: np.full(n, np.nan) for name in source.numeric}
    raw = {name: np.full(n, np.nan) for name in source.numeric}
    short: dict[int, str] = {}
    for i, (o, size) in enumerate(zip(offset.tolist(), length.tolist())):
        try:
            packet = source.definition.parse_bytes(bytes(buf[o : o + size]))
        except Exception as exc:  # spp raises its own errors (EOFError, ValueError …) for a packet it cannot read
            short[i] = f"space_packet_parser: {type(exc).__name__}: {exc}"[:200]
            continue
        for name, value in packet.items():
            if name in raw:
                raw[name][i] = float(value.raw_value)
                calibrated[name][i] = float(value) if isinstance(value, (int, float)) else float(value.raw_value)
    return calibrated, raw, short


def _narrow(column: np.ndarray) -> np.ndarray:
    """int64 when every value is a whole number that float64 holds exactly, else the float64 column with NaN."""
    if not np.isnan(column).any() and np.all(np.abs(column) < 2**53) and np.all(column == np.round(column)):
        return column.astype(np.int64)
    return column


def _decode_apid(
    buf: np.ndarray,
    offset: np.ndarray,
    definition: PacketDefinition,
    window: tuple[int | None, int | None],
    report: IngestReport,
    carry: dict[int, SequenceState] | None = None,
) -> SampleBatch:
    """Validate and decode the framed packets of one APID (any lengths, fixed or variable layout); ``carry``
    (see decode_stream) gives and takes the last accepted packet of the APID."""
    if definition.time_code is None and definition.time_fields is None:
        raise ValueError(
            f"time_code: packet {definition.name} has no time code or time fields to stamp samples "
            "(give --time-code or --time-fields)"
        )
    n, apid = offset.shape[0], definition.apid
    headers = ccsds.parse_primary_headers(packet_matrix(buf, offset, ccsds.PRIMARY_HEADER_OCTETS))
    length = headers.packet_octets
    summary = ApidSummary(apid, definition.name)
    report.apids[apid] = summary
    if n and bool(np.all(length == length[0])):  # the usual case: one length (np.unique sorts: ~30 us)
        summary.packet_octets = {int(length[0]): n}
    else:
        summary.packet_octets = dict(zip(*(a.tolist() for a in np.unique(length, return_counts=True))))
    mismatch = header_mismatch(
        headers, secondary_header=definition.time_code is not None, segments=definition.accepts_segments
    )
    summary.segmented = int(np.count_nonzero(headers.sequence_flags != ccsds.SEQUENCE_FLAGS_UNSEGMENTED))
    if definition.time_code is None:
        mismatch[mismatch == 1] = 0  # time in named fields: the secondary header flag is the mission's business
    records = [
        QuarantineRecord(
            int(offset[i]),
            int(length[i]),
            "bad_header",
            apid,
            int(headers.sequence_count[i]),
            detail=HEADER_PROBLEMS[mismatch[i]],
        )
        for i in np.flatnonzero(mismatch)
    ]
    dropped = mismatch != 0
    if definition.xtce is not None:
        t, time_problems, parts, short = _xtce_values(buf, offset, length, definition)
    else:
        groups, short = _layout_groups(buf, offset, length, definition)
        t, time_problems, parts = _group_values(buf, offset, groups, n)
    for i, why in short.items():
        if not dropped[i]:
            records.append(
                QuarantineRecord(
                    int(offset[i]), int(length[i]), "bad_length", apid, int(headers.sequence_count[i]), detail=why
                )
            )
    summary.shorter_than_definition = len(short)
    dropped[list(short)] = True
    if not definition.variable:
        summary.definition_octets = definition.packet_octets
        summary.longer_than_definition = int(np.count_nonzero(length > definition.packet_octets))
    for i, why in time_problems.items():
        if not dropped[i]:
            dropped[i] = True
            records.append(
                QuarantineRecord(
                    int(offset[i]), int(length[i]), "invalid_time", apid, int(headers.sequence_count[i]), detail=why
                )
            )
    keep = np.flatnonzero(~dropped)
    whole = keep.size == n  # the usual case: every packet kept, its arrays used as they are (no copies)
    kept = (offset, headers.sequence_count, t) if whole else (offset[keep], headers.sequence_count[keep], t[keep])
    previous = None if carry is None else carry.get(apid)
    verdict = validate_packets(apid, *kept, 0, *window, period_s=definition.period_s, previous=previous)
    accepted = keep[verdict.accepted]
    # all in file order (a permutation of 0..n-1 that increases is the identity): the arrays as they are
    in_order = whole and accepted.size == n and bool(np.all(verdict.accepted[1:] > verdict.accepted[:-1]))
    count, t = (headers.sequence_count, t) if in_order else (headers.sequence_count[accepted], t[accepted])
    if carry is not None:
        if verdict.ahead >= 0:  # the step to the next chunk is judged from it (not from a packet kept inside a gap)
            ahead: tuple[int, int] | None = (int(kept[1][verdict.ahead]), int(kept[2][verdict.ahead]))
        else:
            ahead = None if previous is None else (previous.count, previous.t_ns)
        state = SequenceState.after(previous, count, t, ahead)
        if state is not None:
            carry[apid] = state
    joined = _union(parts, n)
    if in_order and isinstance(joined, ColumnMatrices) and not definition.derived:  # the usual case: as decoded
        values: dict[str, np.ndarray] = joined
    else:
        values = {name: v if in_order else v[accepted] for name, v in joined.items()}
    for d in definition.derived:
        values[d.name] = derive(d, values, definition.time_code)
    lengths = length if in_order else length[accepted]
    packets = _gather_octets(buf, offset if in_order else offset[accepted], lengths)
    if lengths.size and bool(np.all(lengths == lengths[0])):  # one length: the (n, L) packet matrix, a free reshape
        packets, lengths = packets.reshape(lengths.size, int(lengths[0])), None
    batch = SampleBatch(
        packet=definition.name,
        apid=apid,
        t_utc_ns=t,
        sequence_count=count,
        values=values,
        packets=packets,
        packet_lengths=lengths,
    )
    for q in verdict.quarantined:
        records.append(replace(q, length=int(length[np.searchsorted(offset, q.offset)])))
    report.quarantined.extend(records)
    report.duplicates += verdict.duplicates
    summary.accepted, summary.duplicates = len(accepted), verdict.duplicates
    summary.missing = sum(max(g.missing, 0) for g in verdict.gaps)
    summary.gaps = verdict.gaps
    if len(accepted):
        summary.t_first_utc_ns, summary.t_last_utc_ns = int(batch.t_utc_ns[0]), int(batch.t_utc_ns[-1])
    return batch


def _undefined_packets(buf: np.ndarray, frames: ccsds.Frames, report: IngestReport) -> list[UndefinedPackets]:
    """Raw packets of APIDs without definition, by APID (gathered in one pass, APID after APID), counted in the
    report."""
    undefined = frames.code == ccsds.FrameCode.UNDEFINED
    apid = ((buf[frames.offset[undefined]].astype(np.int64) & 7) << 8) | buf[frames.offset[undefined] + 1]
    order = np.argsort(apid, kind="stable")
    offset, length, apid = frames.offset[undefined][order], frames.length[undefined][order], apid[order]
    count = ((buf[offset + 2].astype(np.int64) & 0x3F) << 8) | buf[offset + 3]
    octets = _gather_octets(buf, offset, length)
    starts = np.flatnonzero(np.diff(apid, prepend=-1))
    ends = np.append(starts[1:], apid.size)
    first_octet = np.concatenate(([0], np.cumsum(length)))
    out = []
    for a, lo, hi in zip(apid[starts].tolist(), starts.tolist(), ends.tolist()):
        packets = octets[first_octet[lo] : first_octet[hi]]
        out.append(UndefinedPackets(a, packets, length[lo:hi], count[lo:hi]))
        report.undefined_apids[a] = hi - lo
    return out


def decode_stream(
    data: bytes | np.ndarray,
    dictionary: Dictionary,
    source: str = "",
    now_utc_ns: int | None = None,
    final: bool = True,
    carry: dict[int, SequenceState] | None = None,
) -> DecodeResult:
    """Frame, validate and decode a mixed-APID packet stream (CCSDS 133.0-B-2 §4.1) into time-ordered batches.

    Packets of a fixed layout sync on its length; a defined APID's packet of another length is taken
    when what follows confirms its length field (a layout shorter than its packets decodes their
    prefix, a longer one quarantines them as bad_length); variable layouts take any length;
    confirmed packets of undefined APIDs are counted and kept raw. With final=False (a chunk of a
    longer stream) framing stops where the rest of the stream could change a segment
    (telemetry.ccsds.frame_stream): ``consumed`` says where the next chunk starts. A dictionary with
    packet_prefix_octets / packet_suffix_octets has each packet unwrapped first (report offsets then count
    packet octets only).
    ``carry`` (APID → telemetry.validation.SequenceState of its accepted packets) links consecutive chunks:
    each APID's first packet is judged from the previous chunk's last (gap, step back) and repeats of recent
    packets are duplicates, as one pass over the whole stream judges them; the entries are updated.
    """
    buf = np.frombuffer(data, dtype=np.uint8) if isinstance(data, (bytes, bytearray, memoryview)) else data
    buf = np.ascontiguousarray(buf)  # the kernels copy packets with memcpy (no copy: it is, as a rule)
    wrapped, octets_in = dictionary.packet_prefix_octets or dictionary.packet_suffix_octets, int(buf.shape[0])
    if wrapped:
        buf, taken = ccsds.unwrap_packets(buf, dictionary.packet_prefix_octets, dictionary.packet_suffix_octets)
    lengths = {a: 0 if p.variable else p.packet_octets for a, p in dictionary.packets.items()}
    frames = ccsds.frame_stream(buf, lengths, dictionary.crc_apids(), keep_undefined=True, final=final or bool(wrapped))
    consumed = frames.end
    buf = buf[:consumed]
    if wrapped:  # offsets below count unwrapped packet octets; the chunk consumed whole wrapped packets
        consumed = taken
    report = IngestReport(source=source, octets=int(buf.shape[0]))
    report.quarantined.extend(_frame_records(buf, frames))
    if wrapped and final and consumed < octets_in:
        report.quarantined.append(
            QuarantineRecord(
                int(buf.shape[0]),
                octets_in - consumed,
                "truncated",
                detail="incomplete wrapped packet at the end of the data",
            )
        )
    report.idle_packets = int(np.count_nonzero(frames.code == ccsds.FrameCode.IDLE))
    undefined = _undefined_packets(buf, frames, report)
    offset = frames.offset[frames.code == ccsds.FrameCode.OK]
    apid = ((buf[offset].astype(np.int64) & 7) << 8) | buf[offset + 1]
    window = dictionary.time_window(now_utc_ns)
    batches = [
        _decode_apid(buf, offset[apid == a], dictionary.packets[a], window, report, carry)
        for a in np.flatnonzero(np.bincount(apid)).tolist()  # the APIDs in order (np.unique's hashing: ~0.35 ms)
    ]
    report.quarantined.sort(key=lambda q: q.offset)
    for q in report.quarantined:
        if q.apid in report.apids:
            report.apids[q.apid].quarantined += 1
    report.packets_accepted = sum(len(b.t_utc_ns) for b in batches)
    report.samples_accepted = sum(b.n_samples for b in batches)
    return DecodeResult(batches=batches, report=report, undefined=undefined, consumed=consumed)
