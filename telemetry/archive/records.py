"""Plain records the archive hands out (never ORM objects): uploads, alarms, passes, results."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, fields
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from telemetry.archive.batch import PacketBatch
    from telemetry.limits import LimitSet

__all__ = [
    "IngestResult",
    "Gap",
    "AlarmRecord",
    "AlarmEventRecord",
    "PassRecord",
    "PendingUpload",
    "UploadRecord",
    "StationRecord",
]


@dataclass(frozen=True)
class Gap:
    """Packets missing between two consecutive received packets of one APID (sequence counts)."""

    apid: int
    after_t_ns: int
    before_t_ns: int
    missing: int


@dataclass(frozen=True)
class IngestResult:
    """What one upload did: accepted, duplicates, gaps, alarm events; a duplicate upload is a no-op."""

    upload_id: int
    duplicate_upload: bool
    packets_accepted: int = 0
    packets_duplicate: int = 0
    samples_accepted: int = 0
    alarm_events: int = 0
    gaps: list[Gap] = field(default_factory=list)
    duplicates_by_apid: dict[int, int] = field(default_factory=dict)

    def as_report(self) -> dict[str, Any]:
        """JSON-ready dictionary of the result: dataclasses.asdict's, fields in order, without its recursive walk
        (~0.1 ms of a small live upload's ~1 ms)."""
        report = {f.name: getattr(self, f.name) for f in _RESULT_FIELDS}
        report["gaps"] = [{f.name: getattr(g, f.name) for f in _GAP_FIELDS} for g in self.gaps]
        report["duplicates_by_apid"] = dict(self.duplicates_by_apid)
        return report


_RESULT_FIELDS, _GAP_FIELDS = fields(IngestResult), fields(Gap)


@dataclass(frozen=True)
class PendingUpload:
    """One upload to commit with others (Archive.ingest_many): whose, what, from where, by whom, its limits."""

    satellite: str
    batches: Sequence[PacketBatch]
    source: str
    uploaded_by: str
    limits: Mapping[str, LimitSet] | None = None


@dataclass(frozen=True)
class UploadRecord:
    """An upload row: who, when, source, checksum and its stored report."""

    id: int
    uploaded_by: str
    uploaded_at_ns: int
    source: str
    sha256: str
    packets_accepted: int
    samples_accepted: int
    report: dict[str, Any]


@dataclass(frozen=True)
class AlarmRecord:
    """An alarm of a parameter with its operator state, worst severity and current level."""

    id: int
    parameter: str
    state: str
    severity: str
    level: int
    first_t_ns: int
    last_t_ns: int
    acknowledged_by: str | None
    shelved_until_ns: int | None


@dataclass(frozen=True)
class AlarmEventRecord:
    """One alarm event: enter, leave, acknowledge, shelve, unshelve or clear."""

    alarm_id: int
    t_ns: int
    kind: str
    severity: str | None
    value: float | None
    actor: str | None


@dataclass(frozen=True)
class StationRecord:
    """A ground station (WGS84 geodetic) and its minimum elevation."""

    id: int
    name: str
    lat_deg: float
    lon_deg: float
    alt_m: float
    min_elevation_deg: float


@dataclass(frozen=True)
class PassRecord:
    """A predicted pass and what was received in it (completeness from sequence-count gaps)."""

    id: int
    station: str | None
    aos_ns: int
    los_ns: int
    max_elevation_ns: int
    max_elevation_deg: float | None
    received_start_ns: int | None
    received_end_ns: int | None
    packets_received: int
    packets_missing: int
    origin: str = "predicted"  # or "data": made from telemetry no predicted pass covered (AOS/LOS = first/last sample)

    @property
    def completeness(self) -> float:
        """Received / (received + missing) packets; 0 when nothing was received."""
        total = self.packets_received + self.packets_missing
        return self.packets_received / total if total else 0.0
