"""The services one app instance uses, built from Settings in the app factory (no import-time state)."""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import partial

from sqlalchemy import Engine
from sqlalchemy.orm import Session, sessionmaker

from backend.core.audit_repository import AuditRepository
from backend.core.auth import Authenticator
from backend.core.database import DatabaseWatch, create_schema, make_engine, make_session_factory
from backend.core.settings import Settings
from backend.core.token_repository import TokenRepository
from backend.ingest.live_hub import LiveHub
from backend.ingest.telemetry_gateway import TelemetryGateway
from backend.jobs.cluster import ServerCluster
from backend.jobs.job_repository import JobRepository
from backend.jobs.jobs import JobManager
from backend.twin.diagnosis import DiagnosisRuns, diagnose_detection
from backend.twin.diagnosis_repository import DiagnosisRepository
from backend.twin.live import LiveTwins
from backend.twin.monitor_desk import MonitorDesk
from backend.twin.session_repository import TwinSessionRepository

__all__ = ["Services", "build_services"]


@dataclass
class Services:
    """Everything routes need, reached through ``request.app.state.services``."""

    settings: Settings
    engine: Engine
    sessions: sessionmaker[Session]
    tokens: TokenRepository
    audit: AuditRepository
    job_repo: JobRepository
    cluster: ServerCluster
    jobs: JobManager
    auth: Authenticator
    hub: LiveHub
    telemetry: TelemetryGateway
    twin_sessions: TwinSessionRepository
    twins: LiveTwins
    diagnoses: DiagnosisRuns
    database_watch: DatabaseWatch
    monitors: MonitorDesk = field(default_factory=MonitorDesk)  # the 3D monitors, once acs-twin serve runs them

    def close(self) -> None:
        """Stop jobs, diagnoses and the Dask cluster, the telemetry side, dispose of the engine."""
        self.jobs.stop()
        self.diagnoses.close()
        self.cluster.close()
        self.telemetry.close()
        self.engine.dispose()


def build_services(settings: Settings) -> Services:
    """Create the engine, the backend tables, the repositories, the job manager and the hub."""
    settings.data_dir.mkdir(parents=True, exist_ok=True)
    engine = make_engine(settings.resolved_database_url())
    create_schema(engine)
    sessions = make_session_factory(engine)
    tokens, job_repo = TokenRepository(sessions), JobRepository(sessions)
    hub = LiveHub(settings.ws_buffer_items)
    telemetry = TelemetryGateway(settings, hub)
    twins = LiveTwins(
        telemetry.opened_archive,
        hub,
        telemetry.dictionaries.load,
        telemetry.invalidate,
        mapping_folders=[settings.data_dir / "dictionaries"],
        stale_after_s=settings.stale_after_s,
    )
    telemetry.on_commit(twins.submit)
    telemetry.on_backfill(twins.submit_archived)
    cluster = ServerCluster(settings.dask_scheduler, settings.job_workers)
    diagnoses = DiagnosisRuns(DiagnosisRepository(sessions), cluster)
    twins.on_detection = partial(diagnose_detection, diagnoses, telemetry.opened_archive, telemetry.dictionaries.load)
    return Services(
        settings=settings,
        engine=engine,
        sessions=sessions,
        tokens=tokens,
        audit=AuditRepository(sessions),
        job_repo=job_repo,
        cluster=cluster,
        jobs=JobManager(settings, job_repo, cluster),
        auth=Authenticator(tokens, settings.auth_enabled),
        hub=hub,
        telemetry=telemetry,
        twin_sessions=TwinSessionRepository(sessions),
        twins=twins,
        diagnoses=diagnoses,
        database_watch=DatabaseWatch(engine),
    )
