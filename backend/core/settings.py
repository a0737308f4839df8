"""One Settings object for the server, read from ACS_TWIN_* environment variables and CLI flags."""

from __future__ import annotations

import ipaddress
from pathlib import Path

from pydantic import Field, field_validator
from pydantic_settings import BaseSettings, SettingsConfigDict

__all__ = ["Settings"]


class Settings(BaseSettings):
    """Server configuration; every field can be set as ACS_TWIN_<FIELD> (e.g. ACS_TWIN_PORT)."""

    model_config = SettingsConfigDict(env_prefix="ACS_TWIN_", extra="forbid")

    data_dir: Path = Field(Path("data"), description="Directory for the SQLite file and job results.")
    database_url: str | None = Field(None, description="SQLAlchemy URL; default SQLite under data_dir.")
    host: str = Field("127.0.0.1", description="Interface to bind; loopback unless told otherwise.")
    port: int = Field(8000, ge=0, le=65535, description="HTTP port of the REST/WebSocket API.")
    viewer_port: int = Field(
        8080, ge=0, le=65533, description="First of the 3 twin monitor ports (actual, simulated, overlay)."
    )
    telemetry_port: int = Field(10025, ge=0, le=65535, description="TCP port of the live listener (0: any).")
    live_enabled: bool = Field(True, description="Listen for a live CCSDS packet stream over TCP.")
    telemetry_sources: list[str] = Field(
        ["127.0.0.0/8", "::1/128"],
        min_length=1,
        description="Networks (CIDR) the live listener takes packets from: "
        "loopback unless set (ACS_TWIN_TELEMETRY_SOURCES='[\"10.1.0.0/16\"]').",
    )
    live_satellite: str = Field("REFSAT", min_length=1, description="Satellite the live stream belongs to.")
    live_dictionary: str = Field("reference_satellite.yaml", description="Dictionary of the live stream.")
    stale_after_s: float = Field(
        10.0,
        gt=0,
        le=3600,
        description="A satellite without telemetry for this long (wall time) is shown stale: twin state, dashboard "
        "indicator, 3D monitors' banner (default 10 s: ten 1 Hz packets missed).",
    )
    auth_enabled: bool = Field(True, description="Require API tokens (turn off only locally).")
    job_workers: int = Field(
        2, ge=1, le=64, description="Jobs run at once, and the worker processes of the server's Dask LocalCluster."
    )
    dask_scheduler: str | None = Field(
        None,
        description="Address of an existing Dask cluster's scheduler (tcp://host:8786) for jobs, sweeps and "
        "diagnoses; default a LocalCluster of job_workers worker processes that the server owns.",
    )
    job_queue_size: int = Field(4, ge=1, le=1000, description="Queued + running jobs before 429.")
    job_retry_after_s: int = Field(10, ge=1, description="Retry-After sent with 429.")
    max_sim_duration_s: float = Field(86_400.0, gt=0, description="Longest simulated time per job.")
    max_batch_size: int = Field(64, ge=1, description="Most fault variants in one job.")
    max_output_mb: float = Field(512.0, gt=0, description="Largest result file a job may write.")
    max_upload_mb: float = Field(256.0, gt=0, description="Largest telemetry/dictionary upload.")
    max_json_kb: float = Field(2_000.0, gt=0, description="Largest JSON request body (scenarios, settings).")
    max_prediction_days: float = Field(31.0, gt=0, le=366, description="Longest pass-prediction window.")
    max_points: int = Field(100_000, ge=2, description="Most points one time-series answer returns.")
    max_export_rows: int = Field(
        20_000_000, ge=1, description="Most rows one full-resolution export may hold (narrow start/end past it)."
    )
    ws_rate_hz: float = Field(10.0, gt=0, le=100, description="Batches per second per WS client.")
    ws_buffer_items: int = Field(5_000, ge=1, description="Items buffered per WS client before thinning.")
    ws_send_timeout_s: float = Field(2.0, gt=0, description="A slower WS send drops the client.")

    @field_validator("telemetry_sources")
    @classmethod
    def _networks(cls, sources: list[str]) -> list[str]:
        for source in sources:
            ipaddress.ip_network(source, strict=False)  # ValueError names the bad entry
        return sources

    def resolved_database_url(self) -> str:
        """Database URL, defaulting to SQLite ``acs-twin.sqlite`` inside ``data_dir``."""
        if self.database_url:
            return self.database_url
        return f"sqlite:///{(self.data_dir / 'acs-twin.sqlite').resolve()}"

    def jobs_dir(self) -> Path:
        """Directory holding one sub-directory of result files per simulation job."""
        return self.data_dir / "jobs"
