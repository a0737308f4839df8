"""SQLAlchemy 2 models of the telemetry archive: the tables the migrations create.

Layout chosen for speed (measured in benchmarks/ingest.py): packets of one APID are stored in
time-sorted chunks (``packet_chunk``: times, sequence counts and the raw bytes, byte-exact for
replay) and each decoded parameter of a chunk is one ``value_chunk`` row holding a compressed numpy
array with its min/max.  Times are UTC int64 nanoseconds since the Unix epoch (``*_ns`` columns).
Only :mod:`telemetry.archive.store` touches sessions and these classes.
"""

from __future__ import annotations

from sqlalchemy import (
    BigInteger,
    Float,
    ForeignKey,
    Index,
    Integer,
    LargeBinary,
    MetaData,
    String,
    Text,
    UniqueConstraint,
)
from sqlalchemy.orm import DeclarativeBase, Mapped, mapped_column

from telemetry.dictionary import PARAMETER_NAME_MAX

__all__ = [
    "NAME_MAX",
    "Base",
    "Satellite",
    "GroundStation",
    "Tle",
    "Pass",
    "Upload",
    "Parameter",
    "PacketChunk",
    "UndefinedPacketChunk",
    "ValueChunk",
    "Alarm",
    "AlarmEvent",
]

NAMING_CONVENTION = {
    "ix": "ix_%(column_0_label)s",
    "uq": "uq_%(table_name)s_%(column_0_name)s",
    "fk": "fk_%(table_name)s_%(column_0_name)s_%(referred_table_name)s",
    "pk": "pk_%(table_name)s",
}


NAME_MAX = 64  # satellite, station and actor names: String(NAME_MAX) (PostgreSQL refuses longer, SQLite stores them)


class Base(DeclarativeBase):
    """Declarative base with deterministic constraint names (needed by alembic on SQLite)."""

    metadata = MetaData(naming_convention=NAMING_CONVENTION)


class Satellite(Base):
    """A spacecraft whose telemetry is archived (NORAD id optional)."""

    __tablename__ = "satellite"
    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    name: Mapped[str] = mapped_column(String(NAME_MAX), unique=True)
    norad_id: Mapped[int | None] = mapped_column(Integer)


class GroundStation(Base):
    """A ground station: WGS84 geodetic position and the minimum elevation of a usable pass."""

    __tablename__ = "ground_station"
    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    name: Mapped[str] = mapped_column(String(NAME_MAX), unique=True)
    lat_deg: Mapped[float] = mapped_column(Float)
    lon_deg: Mapped[float] = mapped_column(Float)
    alt_m: Mapped[float] = mapped_column(Float)
    min_elevation_deg: Mapped[float] = mapped_column(Float)


class Tle(Base):
    """A two-line element set of a satellite, keyed by its epoch."""

    __tablename__ = "tle"
    __table_args__ = (UniqueConstraint("satellite_id", "epoch_ns"),)
    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    satellite_id: Mapped[int] = mapped_column(ForeignKey("satellite.id"))
    epoch_ns: Mapped[int] = mapped_column(BigInteger)
    line1: Mapped[str] = mapped_column(String(80))
    line2: Mapped[str] = mapped_column(String(80))


class Pass(Base):
    """A pass over a station, predicted from a TLE or made from received data (origin), and what was received."""

    __tablename__ = "pass"
    __table_args__ = (
        UniqueConstraint("satellite_id", "station_id", "aos_ns"),
        Index("ix_pass_span", "satellite_id", "aos_ns", "los_ns"),
    )
    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    satellite_id: Mapped[int] = mapped_column(ForeignKey("satellite.id"))
    station_id: Mapped[int | None] = mapped_column(ForeignKey("ground_station.id"))  # None: a pass from data
    tle_id: Mapped[int | None] = mapped_column(ForeignKey("tle.id"))
    aos_ns: Mapped[int] = mapped_column(BigInteger)
    los_ns: Mapped[int] = mapped_column(BigInteger)
    max_elevation_ns: Mapped[int] = mapped_column(BigInteger)
    max_elevation_deg: Mapped[float | None] = mapped_column(Float)  # None: a pass from data (no station geometry)
    received_start_ns: Mapped[int | None] = mapped_column(BigInteger)
    received_end_ns: Mapped[int | None] = mapped_column(BigInteger)
    packets_received: Mapped[int] = mapped_column(Integer, default=0)
    packets_missing: Mapped[int] = mapped_column(Integer, default=0)
    # last, as migration 0002 added it: a new archive has the columns in the migrated order
    origin: Mapped[str] = mapped_column(String(16), default="predicted", server_default="predicted")


class Upload(Base):
    """One ingested file or live batch: who, when, from where, its checksum and JSON report."""

    __tablename__ = "upload"
    __table_args__ = (UniqueConstraint("satellite_id", "sha256"),)
    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    satellite_id: Mapped[int] = mapped_column(ForeignKey("satellite.id"))
    uploaded_by: Mapped[str] = mapped_column(String(NAME_MAX))
    uploaded_at_ns: Mapped[int] = mapped_column(BigInteger)
    source: Mapped[str] = mapped_column(String(512))
    sha256: Mapped[str] = mapped_column(String(64))
    packets_accepted: Mapped[int] = mapped_column(Integer)
    samples_accepted: Mapped[int] = mapped_column(BigInteger)
    report_json: Mapped[str] = mapped_column(Text)


class Parameter(Base):
    """A decoded parameter name of a satellite (the dictionary itself lives in telemetry)."""

    __tablename__ = "parameter"
    __table_args__ = (UniqueConstraint("satellite_id", "name"),)
    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    satellite_id: Mapped[int] = mapped_column(ForeignKey("satellite.id"))
    name: Mapped[str] = mapped_column(String(PARAMETER_NAME_MAX))
    apid: Mapped[int] = mapped_column(Integer)


class PacketChunk(Base):
    """Time-sorted packets of one APID: compressed times, sequence counts and raw bytes."""

    __tablename__ = "packet_chunk"
    __table_args__ = (Index("ix_packet_chunk_span", "satellite_id", "apid", "t_start_ns", "t_end_ns"),)
    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    satellite_id: Mapped[int] = mapped_column(ForeignKey("satellite.id"))
    upload_id: Mapped[int] = mapped_column(ForeignKey("upload.id"), index=True)
    apid: Mapped[int] = mapped_column(Integer)
    t_start_ns: Mapped[int] = mapped_column(BigInteger)
    t_end_ns: Mapped[int] = mapped_column(BigInteger)
    n_packets: Mapped[int] = mapped_column(Integer)
    t_blob: Mapped[bytes] = mapped_column(LargeBinary)
    seq_blob: Mapped[bytes] = mapped_column(LargeBinary)
    length_blob: Mapped[bytes] = mapped_column(LargeBinary)
    raw_blob: Mapped[bytes] = mapped_column(LargeBinary)


class UndefinedPacketChunk(Base):
    """Raw packets of one APID the dictionary did not define (no time known): sequence counts, lengths, bytes."""

    __tablename__ = "undefined_packet_chunk"
    __table_args__ = (Index("ix_undefined_packet_chunk_apid", "satellite_id", "apid"),)
    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    satellite_id: Mapped[int] = mapped_column(ForeignKey("satellite.id"))
    upload_id: Mapped[int] = mapped_column(ForeignKey("upload.id"))
    apid: Mapped[int] = mapped_column(Integer)
    n_packets: Mapped[int] = mapped_column(Integer)
    seq_blob: Mapped[bytes] = mapped_column(LargeBinary)
    length_blob: Mapped[bytes] = mapped_column(LargeBinary)
    raw_blob: Mapped[bytes] = mapped_column(LargeBinary)


class ValueChunk(Base):
    """The values of one parameter over one packet chunk (compressed numpy array + min/max)."""

    __tablename__ = "value_chunk"
    __table_args__ = (UniqueConstraint("parameter_id", "chunk_id"),)
    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    parameter_id: Mapped[int] = mapped_column(ForeignKey("parameter.id"))
    chunk_id: Mapped[int] = mapped_column(ForeignKey("packet_chunk.id"), index=True)
    dtype: Mapped[str] = mapped_column(String(8))
    v_min: Mapped[float | None] = mapped_column(Float)
    v_max: Mapped[float | None] = mapped_column(Float)
    v_blob: Mapped[bytes] = mapped_column(LargeBinary)


class Alarm(Base):
    """An out-of-limits condition of a parameter: operator state, worst severity, current level.

    ``state`` is active, acknowledged, shelved or cleared; ``severity`` the worst level seen
    (yellow/red); ``level`` the current one (0 = back in limits, 1 yellow, 2 red).
    """

    __tablename__ = "alarm"
    __table_args__ = (Index("ix_alarm_state", "satellite_id", "state"),)
    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    satellite_id: Mapped[int] = mapped_column(ForeignKey("satellite.id"))
    parameter: Mapped[str] = mapped_column(String(PARAMETER_NAME_MAX))
    state: Mapped[str] = mapped_column(String(16))
    severity: Mapped[str] = mapped_column(String(8))
    level: Mapped[int] = mapped_column(Integer)
    first_t_ns: Mapped[int] = mapped_column(BigInteger)
    last_t_ns: Mapped[int] = mapped_column(BigInteger)
    acknowledged_by: Mapped[str | None] = mapped_column(String(NAME_MAX))
    shelved_until_ns: Mapped[int | None] = mapped_column(BigInteger)


class AlarmEvent(Base):
    """One event of an alarm: enter/leave limits, acknowledge, shelve, clear."""

    __tablename__ = "alarm_event"
    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    alarm_id: Mapped[int] = mapped_column(ForeignKey("alarm.id"), index=True)
    upload_id: Mapped[int | None] = mapped_column(ForeignKey("upload.id"))
    t_ns: Mapped[int] = mapped_column(BigInteger)
    kind: Mapped[str] = mapped_column(String(16))
    severity: Mapped[str | None] = mapped_column(String(8))
    value: Mapped[float | None] = mapped_column(Float)
    actor: Mapped[str | None] = mapped_column(String(NAME_MAX))
