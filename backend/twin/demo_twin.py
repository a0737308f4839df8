"""The twin that ``acs-twin serve`` runs beside the demo satellite, shown on the 3D monitors.

Once the live satellite has sent enough telemetry (GPS fixes for the orbit fit plus a stretch to
compare), a nominal twin session is aligned to it and flown; its SessionFeed then drives the
monitors (frontend.monitors). Runs in a daemon thread; every step is logged to data_dir/twin.log.
"""

from __future__ import annotations

import threading
import time
from datetime import UTC, datetime
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from backend.schemas import TwinSessionCreate, TwinSessionPublic
    from backend.services import Services
    from frontend.monitors import MonitorHandles

__all__ = ["run_demo_twin", "WARMUP_S", "TWIN_S"]

WARMUP_S = 60.0  # GPS fixes the orbit fit needs before the alignment instant (twin_sessions.GPS_MARGIN_S)
TWIN_S = 120.0  # simulated seconds of the demo twin (compared with as much telemetry)
POLL_S = 5.0
HK_APID = 256  # reference satellite ACS_HK


def _telemetry_span_ns(services: Services, satellite: str) -> tuple[int, int] | None:
    from backend.core.errors import ApiError

    try:
        keys = services.telemetry.archive.packet_keys(satellite, 0, 2**62, apid=HK_APID)
    except (ValueError, ApiError):  # archive not open yet, or nothing archived for the satellite yet
        return None
    t = keys.get(HK_APID, (None,))[0]
    return None if t is None or t.size == 0 else (int(t[0]), int(t[-1]))


def _log(services: Services, text: str) -> None:
    with (services.settings.data_dir / "twin.log").open("a") as log:
        log.write(f"{datetime.now(UTC).isoformat()} {text}\n")


def _start_when_admitted(services: Services, body: TwinSessionCreate,
                         stop: threading.Event) -> TwinSessionPublic | None:
    """The twin session, retried while the job queue is full (429) instead of giving up; None if stopped."""
    from backend.core.errors import ApiError
    from backend.twin.session_service import start_session

    while not stop.is_set():
        try:
            return start_session(services, body, "acs-twin serve")
        except ApiError as exc:
            if exc.status != 429:
                raise
            _log(services, f"job queue full, retrying the twin session in {POLL_S:g} s")
            stop.wait(POLL_S)
    return None


def run_demo_twin(services: Services, monitor_ports: dict[str, int], scenario: str,
                  stop: threading.Event) -> MonitorHandles | None:
    """Wait for telemetry, start a nominal twin session, wait for it, serve the monitors; their handles."""
    from backend.schemas import TwinSessionCreate
    from backend.twin.monitor_gate import MonitorGate
    from backend.twin.session_service import session_feed
    from frontend.monitors import serve_monitors

    satellite = services.settings.live_satellite
    while not stop.is_set():
        span = _telemetry_span_ns(services, satellite)
        if span is not None and (span[1] - span[0]) / 1e9 >= WARMUP_S + TWIN_S:
            break
        stop.wait(POLL_S)
    else:
        return None
    align = datetime.fromtimestamp((span[0] + WARMUP_S * 1e9) / 1e9, tz=UTC)
    epoch = datetime.fromtimestamp(span[0] / 1e9, tz=UTC)  # the emulator flies from its first packet
    body = TwinSessionCreate(satellite=satellite, dictionary=services.settings.live_dictionary,
                             scenario=scenario, align_utc=align, duration_s=TWIN_S, scenario_epoch_utc=epoch)
    session = _start_when_admitted(services, body, stop)
    if session is None:
        return None
    _log(services, f"twin session {session.id} aligned at {align.isoformat()}, job {session.job_id}")
    while (job := services.job_repo.get(session.job_id)) is not None and job.status in ("queued", "running") \
            and not stop.is_set():
        time.sleep(1.0)
    feed = session_feed(services, session.id)
    handles = serve_monitors(feed, host="127.0.0.1", ports=dict.fromkeys(monitor_ports, 0))  # private ports
    for role, public in monitor_ports.items():  # the public ports ask for an API token (backend.twin.monitor_gate)
        MonitorGate(services.auth, services.settings.host, public, handles.ports[role]).start()
    _log(services, f"monitors: {monitor_ports} (token-gated) -> viser on {handles.ports}")
    return handles
