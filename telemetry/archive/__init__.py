"""The telemetry archive: SQLAlchemy models, alembic migrations and the repository API."""

from telemetry.archive.batch import DERIVED_APID, PacketBatch, sequence_gaps
from telemetry.archive.migrate import upgrade
from telemetry.archive.models import NAME_MAX
from telemetry.archive.records import (
    AlarmEventRecord,
    AlarmRecord,
    Gap,
    IngestResult,
    PassRecord,
    PendingUpload,
    StationRecord,
    UploadRecord,
)
from telemetry.archive.store import Archive

__all__ = [
    "Archive",
    "DERIVED_APID",
    "NAME_MAX",
    "PacketBatch",
    "sequence_gaps",
    "upgrade",
    "IngestResult",
    "Gap",
    "PendingUpload",
    "UploadRecord",
    "AlarmRecord",
    "AlarmEventRecord",
    "PassRecord",
    "StationRecord",
]
