"""What the backend needs of telemetry, as Protocols: the archive the routes and twins read and write.

``telemetry.archive.Archive`` satisfies :class:`TelemetryArchive` (mypy checks it where the gateway
hands its archive out); a test or a future store can stand in with anything of the same shape.
Records and batches are telemetry's own frozen dataclasses, imported as types.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from typing import Any, Protocol

import numpy as np

from telemetry.archive.batch import PacketBatch
from telemetry.archive.records import (
    AlarmEventRecord,
    AlarmRecord,
    IngestResult,
    PassRecord,
    PendingUpload,
    StationRecord,
    UploadRecord,
)
from telemetry.ingest_report import DecodeResult
from telemetry.limits import LimitSet

__all__ = ["TelemetryArchive", "TimeSeries"]

TimeSeries = tuple[np.ndarray, np.ndarray]  # (t_utc_ns int64, values float64), time-sorted


class TelemetryArchive(Protocol):
    """The archive as the backend uses it: satellites, stations, TLEs, ingest, samples, alarms, passes."""

    def close(self) -> None: ...

    def satellites(self, exclude_apids: Sequence[int] = ()) -> list[dict[str, Any]]: ...

    def satellite_id(self, name: str, norad_id: int | None = None) -> int: ...

    def add_ground_station(
        self, name: str, lat_deg: float, lon_deg: float, alt_m: float, min_elevation_deg: float
    ) -> int: ...

    def ground_station(self, name: str) -> StationRecord: ...

    def add_tle(self, satellite: str, line1: str, line2: str, epoch_ns: int | None = None) -> int: ...

    def latest_tle(self, satellite: str, before_ns: int | None = None) -> tuple[int, str, str]: ...

    def ingest(
        self,
        satellite: str,
        batches: Iterable[PacketBatch],
        *,
        source: str,
        uploaded_by: str,
        sha256: str | None = None,
        limits: Mapping[str, LimitSet] | None = None,
        decode_report: Mapping[str, object] | None = None,
    ) -> IngestResult: ...

    def ingest_decoded(
        self,
        satellite: str,
        decoded: DecodeResult,
        *,
        uploaded_by: str,
        sha256: str | None = None,
        limits: Mapping[str, LimitSet] | None = None,
    ) -> IngestResult: ...

    def ingest_many(self, uploads: Sequence[PendingUpload]) -> list[IngestResult]: ...

    def parameters(self, satellite: str) -> dict[str, int]: ...

    def read_parameter(self, satellite: str, name: str, t0_ns: int, t1_ns: int) -> TimeSeries: ...

    def latest_values(self, satellite: str, names: Sequence[str] | None = None) -> dict[str, tuple[int, float]]: ...

    def packet_keys(
        self, satellite: str, t0_ns: int, t1_ns: int, apid: int | None = None
    ) -> dict[int, tuple[np.ndarray, np.ndarray]]: ...

    def replay(self, satellite: str, t0_ns: int, t1_ns: int, apid: int | None = None) -> list[tuple[int, bytes]]: ...

    def undefined_counts(self, satellite: str) -> dict[int, int]: ...

    def uploads(self, satellite: str) -> list[UploadRecord]: ...

    def alarms(
        self, satellite: str, *, now_ns: int | None = None, include_cleared: bool = False
    ) -> list[AlarmRecord]: ...

    def alarm_events(self, alarm_id: int) -> list[AlarmEventRecord]: ...

    def alarm_action(
        self, alarm_id: int, action: str, actor: str, *, t_ns: int | None = None, shelved_until_ns: int | None = None
    ) -> None: ...

    def save_passes(
        self, satellite: str, station: str, passes: Iterable[tuple[int, int, int, float]], tle_id: int | None = None
    ) -> list[int]: ...

    def passes(self, satellite: str, t0_ns: int, t1_ns: int) -> list[PassRecord]: ...

    def pass_record(self, satellite: str, pass_id: int) -> PassRecord: ...
