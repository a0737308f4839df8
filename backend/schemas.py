"""API schemas (request and response bodies), one per direction; ORM models live in models.py."""

from __future__ import annotations

import dataclasses
from datetime import UTC, datetime
from typing import Annotated, Any, Literal, get_type_hints

from pydantic import (
    AfterValidator,
    BaseModel,
    ConfigDict,
    Discriminator,
    Field,
    GetJsonSchemaHandler,
    RootModel,
    Tag,
    TypeAdapter,
    create_model,
)
from pydantic.json_schema import JsonSchemaValue
from pydantic_core import CoreSchema

from backend.ingest.dictionary_catalogue import DICTIONARY_NAME, DICTIONARY_NAME_MAX
from backend.jobs.simulators import LibraryScenario, scenario_kind
from sim_core.rigid_spin import RigidSpinScenario
from sim_core.scenario import Scenario
from telemetry.archive import NAME_MAX
from telemetry.archive.records import AlarmRecord, PassRecord

__all__ = [
    "DB_ID_MAX",
    "DIAGNOSIS_WINDOW_MAX_S",
    "NAME_MAX",
    "SatelliteName",
    "StationName",
    "DbId",
    "Health",
    "TokenCreate",
    "TokenPublic",
    "TokenIssued",
    "AuditPublic",
    "SimulationCreate",
    "JobAccepted",
    "JobPublic",
    "SeriesPublic",
    "FilePublic",
    "TwinSessionCreate",
    "TwinSessionPublic",
    "ResidualsPublic",
    "SATELLITE_NAME",
    "PassPublic",
    "PassSummaryPublic",
    "AlarmActed",
    "SatelliteCreated",
    "TleStored",
    "TlePublic",
    "IngestReportPublic",
    "DictionaryStored",
    "LatestValue",
    "LatestValues",
    "ParameterApids",
    "DictionaryNames",
    "KeptRawCounts",
    "ScenarioNames",
    "ConsoleConstants",
    "Caller",
    "ParameterLimits",
    "ParameterInfo",
    "ParametersInfo",
    "SatellitePublic",
    "TwinIssue",
    "LiveTwinPublic",
    "PARQUET_MEDIA_TYPE",
    "RESULT_FILE_MEDIA_TYPES",
    "SamplesPublic",
    "SatelliteCreate",
    "ShelveRequest",
    "StationCreate",
]

PARQUET_MEDIA_TYPE = "application/vnd.apache.parquet"  # the media type registered for Apache Parquet
RESULT_FILE_MEDIA_TYPES = {  # a job's result files by suffix (CSV and Parquet: its export, streamed)
    ".npz": "application/octet-stream",  # numpy's zip of arrays: no registered type of its own
    ".json": "application/json",
}
SATELLITE_NAME = r"^[^\x00-\x1f\x7f]+$"  # printable: names reach file names and headers (no CR/LF)


def _as_utc(moment: datetime) -> datetime:
    """SQLite drops the zone of stored UTC times: put it back so answers are RFC 3339."""
    return moment.replace(tzinfo=UTC) if moment.tzinfo is None else moment


UtcDatetime = Annotated[datetime, AfterValidator(_as_utc)]
SatelliteName = Annotated[  # the archive's name columns hold NAME_MAX characters: the one bound of every name
    str, Field(min_length=1, max_length=NAME_MAX, pattern=SATELLITE_NAME, examples=["NOAA-20"])
]
StationName = Annotated[str, Field(min_length=1, max_length=NAME_MAX, examples=["Svalbard"])]
DIAGNOSIS_WINDOW_MAX_S = 86_400.0  # one day of housekeeping: 86,400 samples at 1 Hz, a few seconds of diagnosis
DB_ID_MAX = 2**31 - 1  # id columns are INTEGER: 32 bits on PostgreSQL (64 on SQLite); a larger id was a 500 there
DbId = Annotated[
    int, Field(ge=1, le=DB_ID_MAX, description=f"Database id, 1 to {DB_ID_MAX} (a 32-bit INTEGER column).")
]  # every integer id in a path or query: its one bound


class Health(BaseModel):
    """Liveness and what is plugged in."""

    status: Literal["ok"] = "ok"
    version: str
    database: str
    auth_enabled: bool
    components: dict[str, bool] = Field(description="Optional parts present in this build.")
    live: dict[str, Any] = Field(description="Live TCP stream: port and tallies (empty when off).")
    twins: dict[str, Any] = Field(
        default_factory=dict,
        description="Live twins: satellites, batches waiting for their twin, residual uploads waiting for the archive.",
    )


class TokenCreate(BaseModel):
    """Ask for a new API token."""

    name: str = Field(min_length=1, max_length=NAME_MAX, examples=["ops-console"], description="Also its actor name.")
    role: Literal["viewer", "operator", "admin"] = Field(examples=["operator"])


class TokenPublic(BaseModel):
    """A token as listed: never the token nor its hash."""

    model_config = ConfigDict(from_attributes=True)
    id: int
    name: str
    role: str
    created_at: UtcDatetime
    revoked_at: UtcDatetime | None = None


class TokenIssued(TokenPublic):
    """A freshly issued token: the plain token appears here once and is never stored."""

    token: str


class AuditPublic(BaseModel):
    """One audit-log entry."""

    model_config = ConfigDict(from_attributes=True)
    id: int
    at: UtcDatetime
    actor: str
    action: str
    target: str
    detail: dict[str, Any]


class _DocumentedAs:
    """JSON-schema hook: a body taken as a JSON object and validated by its service, documented as ``shape``."""

    def __init__(self, shape: Any) -> None:
        self._core = TypeAdapter(shape).core_schema

    def __get_pydantic_json_schema__(self, _: CoreSchema, handler: GetJsonSchemaHandler) -> JsonSchemaValue:
        return handler(self._core)


# POST /simulations: exactly one of three bodies (each forbids unknown keys; the rigid spin requires its kind, the
# library body its library), told apart by backend.jobs.simulators.scenario_kind. validate_scenario validates it,
# with the limits, in the service: the route takes the JSON object, so the answers and messages are the service's.
SimulationCreate = Annotated[
    dict[str, Any],
    _DocumentedAs(
        Annotated[
            Annotated[RigidSpinScenario, Tag("rigid-spin")]
            | Annotated[LibraryScenario, Tag("library")]
            | Annotated[Scenario, Tag("scenario")],
            Discriminator(scenario_kind),
        ]
    ),
]


class JobAccepted(BaseModel):
    """Answer to a queued simulation."""

    id: str
    status: str
    url: str


class JobPublic(BaseModel):
    """Status, progress and summary of a simulation job."""

    model_config = ConfigDict(from_attributes=True)
    id: str
    status: Literal["queued", "running", "succeeded", "failed", "cancelled", "interrupted"]
    progress: float = Field(ge=0.0, le=1.0)
    summary: dict[str, Any] | None = None
    error: str | None = None
    created_by: str
    created_at: UtcDatetime
    started_at: UtcDatetime | None = None
    finished_at: UtcDatetime | None = None


class TwinSessionCreate(BaseModel):
    """Where to align the twin, how long to fly it, and the operator's fault hypothesis."""

    satellite: str = Field("REFSAT", min_length=1, max_length=NAME_MAX)
    dictionary: str = Field("reference_satellite.yaml", max_length=DICTIONARY_NAME_MAX, pattern=DICTIONARY_NAME)
    scenario: str = Field("somov-ge4-scan", max_length=100, description="Library scenario the satellite flies.")
    align_utc: datetime | None = Field(
        None,
        description="Start of the twin (the first ACS_HK sample at or after "
        "it); default: the newest synchronisation point of the satellite's live twin.",
        examples=["2026-03-20T00:05:00Z"],
    )
    duration_s: float = Field(gt=0, le=86_400, examples=[200.0])
    alternatives: dict[str, list[str]] = Field(
        default_factory=dict,
        max_length=15,
        examples=[{"nominal": [], "wheel-2-fails": ["wheel:2:failure@30"]}],
        description="What-if variants flown from the same state.",
    )
    scenario_epoch_utc: datetime | None = Field(
        None,
        description="When the satellite started the scenario's "
        "route (default: the live twin's, else the library scenario's epoch).",
    )
    faults: list[str] = Field(
        default_factory=list,
        max_length=16,
        examples=[["wheel:1:failure@50"]],
        description="Hypothesis, TARGET:INDEX:TYPE@ONSET[+DUR][,gain=G|,value=V] (onset in s after align).",
    )


class TwinSessionPublic(BaseModel):
    """A twin session with the state of its simulation job."""

    id: str
    satellite: str
    scenario: str
    align_utc_ns: int = Field(description="The ACS_HK sample the twin starts from (UTC ns).")
    duration_s: float
    faults: list[str]
    created_by: str
    variants: list[str] = Field(description="'twin', then the what-if alternatives.")
    job_id: str
    status: str
    progress: float


class ResidualsPublic(BaseModel):
    """Twin minus telemetry of one variant (downsampled), and the summary of every variant."""

    session_id: str
    variant: str
    summary: dict[str, int | float]
    summaries: dict[str, dict[str, int | float]]
    t_s: list[float] = Field(description="Seconds after the alignment instant.")
    attitude_deg: list[float]
    rate_deg_s: list[float]
    wheel_speed_rpm: list[list[float]] = Field(description="One column per wheel.")
    best_match: str | None = Field(
        description="The variant closest to the telemetry among those that fit it (RMS "
        "residuals within the live twin's sensor-noise limits); null when none fits."
    )
    verdict: str = Field(description="Which variant fits best, or that none fits, with the limits used.")


def _record_fields(record: type) -> dict[str, Any]:
    hints = get_type_hints(record)
    return {
        f.name: (hints[f.name], ... if f.default is dataclasses.MISSING else f.default)
        for f in dataclasses.fields(record)
    }


# every field of telemetry's PassRecord (kept in step with it), plus its completeness
PassPublic = create_model(
    "PassPublic",
    __doc__="A pass and what was received in it.",
    **_record_fields(PassRecord),
    completeness=(float, Field(description="Received / (received + missing) packets.")),
)


class PassSummaryPublic(BaseModel):
    """A pass with its completeness, per-parameter count/min/max/mean and the alarms raised during it (further
    keys of telemetry.queries.pass_summary pass through unchanged)."""

    model_config = ConfigDict(extra="allow")
    pass_: PassPublic = Field(alias="pass")  # type: ignore[valid-type]
    completeness: float
    parameters: dict[str, dict[str, int | float]]
    alarms: list[AlarmRecord]


class AlarmActed(BaseModel):
    """An operator action taken on an alarm."""

    alarm_id: int
    action: Literal["acknowledge", "shelve", "unshelve"]


class SatelliteCreated(BaseModel):
    """A registered satellite."""

    id: int
    name: str


class TleStored(BaseModel):
    """A stored two-line element set and its epoch."""

    id: int
    satellite: str
    epoch_utc_ns: int


class TlePublic(BaseModel):
    """The newest two-line element set of a satellite."""

    id: int
    line1: str
    line2: str


class IngestReportPublic(BaseModel):
    """What an upload did: the archive's tallies, the decoder's report and the passes it attached to (further
    keys the ingest pipeline reports pass through unchanged)."""

    model_config = ConfigDict(extra="allow")
    satellite: str
    dictionary: str
    archive: dict[str, Any] = Field(description="Upload id, packets and samples accepted, duplicates, gaps, alarms.")
    decoding: dict[str, Any] = Field(description="The decoder's report: packets read, quarantined and why.")
    passes: list[PassPublic] = Field(default_factory=list)  # type: ignore[valid-type]


class RedecodeReportPublic(BaseModel):
    """What decoding packets kept raw for want of a definition did (archive None: no packet of those APIDs kept)."""

    satellite: str
    dictionary: str
    apids: list[int] = Field(description="The APIDs whose kept packets were decoded.")
    archive: dict[str, Any] | None = Field(description="The new upload's tallies (as for an upload), or null.")
    decoding: dict[str, Any] = Field(
        description="The decoder's report; undefined_apids counts packets it quarantined, which stay kept raw."
    )
    passes: list[PassPublic] = Field(default_factory=list)  # type: ignore[valid-type]


class DictionaryStored(BaseModel):
    """A stored telemetry dictionary and its packets (APID as text → packet name)."""

    name: str
    packets: dict[str, str]


class LatestValue(BaseModel):
    """The newest sample of a parameter."""

    t_utc_ns: int
    value: float


class SeriesPublic(BaseModel):
    """A downsampled time series: x and one or more y columns (bucket min/max kept)."""

    name: str
    t_s: list[float]
    values: list[list[float]]
    columns: list[str]
    total_points: int


class FilePublic(BaseModel):
    """One result file of a job."""

    name: str
    size_bytes: int
    url: str


class DiagnosisCreate(BaseModel):
    """Which satellite and telemetry window to diagnose, with the scenario its ACS flies."""

    satellite: str = Field("REFSAT", min_length=1, max_length=NAME_MAX)
    dictionary: str = Field("reference_satellite.yaml", max_length=DICTIONARY_NAME_MAX, pattern=DICTIONARY_NAME)
    scenario: str = Field("somov-ge4-scan", max_length=100, description="Library scenario the satellite flies.")
    start_utc: datetime = Field(examples=["2026-03-20T00:00:00Z"])
    end_utc: datetime = Field(
        examples=["2026-03-20T00:20:00Z"],
        description=f"After start_utc, at most {DIAGNOSIS_WINDOW_MAX_S:,.0f} s after it (else a 422 naming end_utc: "
        "backend.twin.diagnosis.start_archived checks it).",
    )


class DiagnosisPublic(BaseModel):
    """A diagnosis run: its state and, once succeeded, the ranked hypotheses (backend.twin.diagnosis JSON)."""

    id: str
    satellite: str
    dictionary: str
    scenario: str
    start_utc: str
    end_utc: str
    status: Literal["running", "succeeded", "failed"]
    error: str | None = None
    trigger: Literal["operator", "live twin"] = Field(
        description="Who started it: an operator, or a live twin's detector."
    )
    alarm_id: int | None = Field(None, description="The alarm whose detection started it (GET /alarms).")
    alarm_utc: str | None = Field(None, description="When the live twin's detector fired.")
    created_by: str
    result: dict[str, Any] | None = Field(
        None,
        description="hypotheses best first (fault, wheel, onset_utc, "
        "onset_sigma_s, magnitude, score = posterior), confidence, detection, "
        "suspected_wheels, untestable",
    )


class FlightCreate(BaseModel):
    """Which diagnosed hypothesis to fly on the simulated monitor."""

    diagnosis_id: str = Field(min_length=1, max_length=64, description="A succeeded diagnosis (GET /diagnoses).")
    rank: int = Field(1, ge=1, le=100, description="1 = the top hypothesis, then the next ones in the ranking.")


class FlightPublic(BaseModel):
    """A diagnosed hypothesis flown by the diagnosis' replay from before its onset, against the telemetry."""

    diagnosis_id: str
    rank: int
    satellite: str
    scenario: str
    hypothesis: dict[str, Any] = Field(
        description="The diagnosis' hypothesis as it ranked it (fault, wheel, onset_utc, …)."
    )
    label: str = Field(description="How every monitor panel names the simulated side now.")
    start_utc: str = Field(description="The twin's start: telemetry before the onset.")
    end_utc: str
    summaries: dict[str, dict[str, float]] = Field(
        description="hypothesis and nominal (the no-fault twin): residuals against the telemetry of the window."
    )
    t_s: list[float] = Field(description="Seconds after start_utc of the wheel-speed samples.")
    wheel_speed_rpm: dict[str, list[list[float]]] = Field(
        description="telemetry, hypothesis, nominal: wheel speeds (rpm) per sample, min/max downsampled."
    )
    flown_by: str
    on_monitor: bool = Field(
        description="False when no monitors run (acs-twin serve runs them beside its live satellite)."
    )


class MonitorViewerPublic(BaseModel):
    """One browser connected to a monitor and what its panel names the simulated side."""

    role: str
    client_id: int
    label: str


class SimulatedMonitorPublic(BaseModel):
    """What the simulated monitor flies: the nominal (live) twin or a diagnosed hypothesis."""

    running: bool = Field(description="Whether the 3D monitors run (acs-twin serve with its live satellite).")
    satellite: str | None
    showing: Literal["nominal", "hypothesis"]
    label: str
    monitor_label: str | None = Field(description="The label the monitors themselves hold (null without monitors).")
    viewers: list[MonitorViewerPublic]
    flight: FlightPublic | None = None


class LatestValues(RootModel[dict[str, LatestValue]]):
    """The newest sample of each archived parameter, by name."""


class ParameterApids(RootModel[dict[str, int]]):
    """Archived parameters of a satellite, name → APID of the packet that carries it."""


class DictionaryNames(RootModel[list[str]]):
    """File names of the known telemetry dictionaries (shipped and uploaded)."""


class KeptRawCounts(RootModel[dict[str, int]]):
    """APID (as text) → packets of a satellite kept raw for want of a definition."""


class ScenarioNames(RootModel[list[str]]):
    """Names of the library scenarios."""


class ConsoleConstants(BaseModel):
    """Values the dashboard takes from the server instead of copying them."""

    gps_margin_s: float = Field(description="Telemetry a twin session reads before its alignment instant (GPS fit).")
    stale_after_s: float = Field(description="A live twin without telemetry for this long is stale.")
    max_points: int = Field(description="Most points one time-series answer returns.")
    ws_rate_hz: float = Field(description="Batches per second per WebSocket client.")
    shelve_max_s: float = Field(description="Longest an alarm may be shelved.")
    severities: dict[str, str] = Field(description="Limit colour → alarm severity.")
    auth_enabled: bool


class Caller(BaseModel):
    """The token's name and role (the console greys out what the role may not do)."""

    name: str
    role: str = Field(description="viewer, operator or admin.")


class ParameterLimits(BaseModel):
    """Yellow (warning) and red (alarm) limits in engineering units; null = no limit."""

    yellow_low: float | None = None
    yellow_high: float | None = None
    red_low: float | None = None
    red_high: float | None = None


class ParameterInfo(BaseModel):
    """The dictionary entry of an archived parameter."""

    units: str
    description: str
    limits: ParameterLimits
    enumeration: dict[str, str] | None = Field(None, description="Raw value (as text) → label; null if none.")


class ParametersInfo(RootModel[dict[str, ParameterInfo]]):
    """Dictionary entry of each archived parameter of a satellite, by name (names no dictionary defines left out)."""


class SatellitePublic(BaseModel):
    """One archived satellite: its newest telemetry and its live twin's state in a word."""

    name: str
    norad_id: int | None = None
    first_telemetry_utc: str | None = Field(None, description="Oldest archived packet, ISO 8601 UTC (null if none).")
    latest_telemetry_utc: str | None = Field(None, description="Newest archived packet, ISO 8601 UTC (null if none).")
    twin_state: str | None = Field(
        None,
        description="waiting, synchronised, propagating, stale or actual_only; "
        "null when no attitude mapping fits the satellite's dictionary.",
    )
    acs_model: str | None = Field(None, description="Library scenario the twin flies; null: no ACS model.")


class TwinIssue(BaseModel):
    """A bad-input finding of a live twin (repeats counted, not listed)."""

    kind: str = Field(description="mapping, time_backwards, gap, quaternion, sync or residual.")
    message: str
    utc: str | None = Field(description="ISO 8601 UTC of the telemetry it concerns.")
    count: int


class LiveTwinPublic(BaseModel):
    """State of a satellite's live twin (backend.twin.live), also published on the WebSocket topic ``twin``.

    Times are ISO 8601 UTC or null; residuals are twin minus telemetry."""

    satellite: str
    dictionary: str
    acs_model: str | None = Field(description="Library scenario the twin flies; null without ACS model.")
    model_note: str | None = Field(description="Why there is no twin, else null.")
    state: str = Field(description="waiting, synchronised, propagating, stale or actual_only.")
    stale: bool
    last_packet_age_s: float | None = Field(description="Seconds since telemetry last reached the server.")
    stale_after_s: float
    telemetry_utc: str | None = Field(description="Newest actual sample.")
    twin_utc: str | None = Field(description="Newest instant the twin was compared at.")
    twin_behind_telemetry_s: float | None
    synchronised_utc: str | None = Field(description="Last re-sync instant.")
    route_epoch_utc: str | None = Field(description="Epoch of the flown route; null without ACS model.")
    horizon_utc: str | None = Field(description="End of the flown segment.")
    actual_q_ib: list[float] | None = Field(description="Scalar-first, body → inertial.")
    twin_q_ib: list[float] | None = Field(description="Scalar-first, body → inertial.")
    attitude_residual_arcsec: float | None = Field(description="Actual vs twin at twin_utc; null without ACS model.")
    rate_residual_b_rad_s: list[float] | None = Field(description="[x, y, z].")
    wheel_speed_residual_rad_s: list[float] | None = Field(description="One per wheel.")
    resyncs: int
    forced_resyncs: int = Field(description="Re-syncs forced by a residual beyond the sensors' noise.")
    samples_compared: int
    note: str | None
    issues: list[TwinIssue] = Field(description="The newest bad-input findings.")


class SamplesPublic(BaseModel):
    """Samples of one parameter: UTC ns times and values, downsampled keeping bucket min/max."""

    satellite: str
    name: str
    total_points: int
    t_utc_ns: list[int]
    values: list[float]


class ShelveRequest(BaseModel):
    """Shelve an alarm for a while (it comes back by itself when the time is over)."""

    duration_s: float = Field(gt=0, le=30 * 86_400, examples=[3600.0])


class SatelliteCreate(BaseModel):
    """Register a satellite by name (and NORAD id)."""

    name: SatelliteName
    norad_id: int | None = Field(None, ge=1, le=999_999, examples=[43013])


class StationCreate(BaseModel):
    """A ground station (WGS84 geodetic) and its elevation mask."""

    name: StationName
    lat_deg: float = Field(ge=-90, le=90, examples=[78.23])
    lon_deg: float = Field(ge=-180, le=360, examples=[15.39])
    alt_m: float = Field(0.0, ge=-500, le=10_000, examples=[500.0])
    min_elevation_deg: float = Field(5.0, ge=-90, lt=90, examples=[5.0])
