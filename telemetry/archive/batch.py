"""The seam between decoding and the archive: one APID's decoded packets as columns.

Sequence counts are the 14-bit CCSDS packet sequence count (CCSDS 133.0-B-2 §4.1.3.4.2.2); they
wrap at 16,384, which is how gaps are counted.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from telemetry.ingest_report import ColumnMatrices, positions_by_dtype

if TYPE_CHECKING:
    from telemetry.ingest_report import SampleBatch

__all__ = [
    "PacketBatch",
    "ColumnMatrices",
    "positions_by_dtype",
    "value_matrices",
    "SEQUENCE_COUNT_MODULUS",
    "DERIVED_APID",
    "sequence_gaps",
]

SEQUENCE_COUNT_MODULUS = 16_384  # 14-bit packet sequence count, CCSDS 133.0-B-2 §4.1.3.4.2.2
MAX_APID = 2_047  # 11-bit APID, CCSDS 133.0-B-2 §4.1.3.3.4
# Archive APID of parameters derived on the ground (the live twin's residuals): no raw packets, sequence counts 0;
# 2047 is the idle packet (CCSDS 133.0-B-2 §4.1.3.3.4.4), so the highest APID a mission may use is 2045 here.
DERIVED_APID = 2_046


def value_matrices(values: Mapping[str, np.ndarray]) -> list[tuple[np.dtype, list[int], np.ndarray]]:
    """The columns as one matrix per dtype: (dtype, the columns' positions, matrix of shape (len(positions), n));
    the columns' own matrices when they are a :class:`ColumnMatrices`, else one copy (np.array of the list: one
    conversion in C, not np.stack's per-column Python), so that each later step is one call per dtype."""
    if isinstance(values, ColumnMatrices):
        return values.groups
    columns = list(values.values())
    return [
        (d, members, np.array([columns[i] for i in members], dtype=d))
        for d, members in positions_by_dtype(columns).items()
    ]


@dataclass(frozen=True)
class PacketBatch:
    """Decoded packets of one APID: times, sequence counts, raw bytes (any contiguous octets: bytes, or a view of
    the decoder's packet array, not copied) and parameter columns."""

    apid: int
    t_utc_ns: np.ndarray
    seq_count: np.ndarray
    raw: bytes | memoryview
    raw_lengths: np.ndarray
    values: Mapping[str, np.ndarray] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if not 0 <= int(self.apid) <= MAX_APID:
            raise ValueError(f"apid: {self.apid} outside 0..{MAX_APID}")
        t = np.asarray(self.t_utc_ns)
        if t.ndim != 1 or t.dtype.kind not in "iu":
            raise ValueError(f"t_utc_ns: expected a 1-D integer array of UTC ns, got {t.dtype}{t.shape}")
        n = t.shape[0]
        seq = np.asarray(self.seq_count)
        if seq.shape != (n,) or (n and (seq.min() < 0 or seq.max() >= SEQUENCE_COUNT_MODULUS)):
            raise ValueError(f"seq_count: expected {n} counts in 0..{SEQUENCE_COUNT_MODULUS - 1}")
        lengths = np.asarray(self.raw_lengths)
        if lengths.shape != (n,) or int(lengths.sum()) != len(self.raw):
            raise ValueError(f"raw_lengths: expected {n} lengths summing to len(raw) = {len(self.raw)}")
        values: Mapping[str, np.ndarray]
        if isinstance(self.values, ColumnMatrices):  # rows of its matrices: their shapes are the columns'
            values = self.values
            for _, _, matrix in values.groups:
                if matrix.ndim != 2 or matrix.shape[1] != n:
                    raise ValueError(f"values: expected matrices of {n} columns, got shape {matrix.shape}")
        else:
            values = dict(self.values)
            if {(type(c), getattr(c, "shape", None)) for c in values.values()} != {(np.ndarray, (n,))}:
                values = {name: c if isinstance(c, np.ndarray) else np.asarray(c) for name, c in values.items()}
                for name, column in values.items():  # one set above for the usual case: ~0.2 us per column
                    if column.shape != (n,):
                        raise ValueError(f"values[{name!r}]: expected shape ({n},), got {column.shape}")
        object.__setattr__(self, "t_utc_ns", t.astype(np.int64, copy=False))
        object.__setattr__(self, "seq_count", seq.astype(np.int64, copy=False))
        object.__setattr__(self, "raw_lengths", lengths.astype(np.int64, copy=False))
        object.__setattr__(self, "values", values)

    @classmethod
    def from_packets(
        cls,
        apid: int,
        t_utc_ns: np.ndarray,
        seq_count: np.ndarray,
        packets: Sequence[bytes],
        values: Mapping[str, np.ndarray],
    ) -> PacketBatch:
        """Batch from a list of raw packets (each ``bytes``) and their decoded columns."""
        lengths = np.fromiter((len(p) for p in packets), dtype=np.int64, count=len(packets))
        return cls(apid, np.asarray(t_utc_ns), np.asarray(seq_count), b"".join(packets), lengths, values)

    @classmethod
    def from_sample_batch(cls, batch: SampleBatch) -> PacketBatch:
        """Batch from the decoder's SampleBatch ((n, L) packet matrix; ground files carry no bytes)."""
        n = len(batch.t_utc_ns)
        if batch.packets is None:
            return cls(batch.apid, batch.t_utc_ns, batch.sequence_count, b"", np.zeros(n, dtype=np.int64), batch.values)
        packets = np.ascontiguousarray(batch.packets, dtype=np.uint8)
        raw = packets.reshape(-1).data  # a view: the decoder's array is the batch's own (no 40 MB copy per file)
        if batch.packet_lengths is not None:
            return cls(batch.apid, batch.t_utc_ns, batch.sequence_count, raw, batch.packet_lengths, batch.values)
        lengths = np.full(n, packets.shape[1] if packets.ndim == 2 else 0, dtype=np.int64)
        return cls(batch.apid, batch.t_utc_ns, batch.sequence_count, raw, lengths, batch.values)

    @property
    def n_packets(self) -> int:
        """Number of packets in the batch."""
        return int(self.t_utc_ns.shape[0])

    def packets(self) -> list[bytes]:
        """The raw packets, one ``bytes`` each, in batch order."""
        ends = np.cumsum(self.raw_lengths)
        starts = ends - self.raw_lengths
        return [bytes(self.raw[s:e]) for s, e in zip(starts.tolist(), ends.tolist())]

    def take(self, index: np.ndarray) -> PacketBatch:
        """A new batch with the packets at ``index`` (in that order)."""
        index = np.asarray(index, dtype=np.int64)
        starts = np.cumsum(self.raw_lengths) - self.raw_lengths
        lengths = self.raw_lengths[index]
        out_starts = np.cumsum(lengths) - lengths
        byte_index = np.repeat(starts[index] - out_starts, lengths) + np.arange(int(lengths.sum()))
        joined = np.frombuffer(self.raw, dtype=np.uint8)[byte_index].tobytes()
        values = {name: np.asarray(col)[index] for name, col in self.values.items()}
        return PacketBatch(
            self.apid, self.t_utc_ns[index], self.seq_count[index], joined, self.raw_lengths[index], values
        )


def sequence_gaps(seq_count: np.ndarray) -> np.ndarray:
    """Packets missing before each packet of a time-ordered stream (0 for the first), mod 2**14."""
    seq = np.asarray(seq_count, dtype=np.int64)
    missing = np.zeros(seq.shape, dtype=np.int64)
    if seq.size > 1:
        missing[1:] = (np.diff(seq) - 1) % SEQUENCE_COUNT_MODULUS
    return missing
