"""The 3D monitors ``acs-twin serve`` runs beside its live satellite: they follow the satellite's live twin.

No one-shot replay: the demo satellite is just the first satellite with a live twin (backend.twin.live). Its
route starts with each run of telemetry (the emulator starts with the server), so the twin is told so; once
the twin holds attitude and GPS samples the monitors start on a LiveFeed, each viewer in live follow (a few
seconds behind real time; STALE in the alarm list when telemetry stops) with any past window of the archive
replayable (ArchiveWindows), viser on private loopback ports behind the token gate (backend.twin.monitor_gate)
on the public ones. Runs in a daemon thread; steps are logged to data_dir/twin.log.
"""

from __future__ import annotations

import threading
from datetime import UTC, datetime
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from backend.services import Services
    from frontend.monitors import MonitorHandles
    from telemetry.archive.records import AlarmRecord

__all__ = ["run_demo_twin", "serve_live_monitors", "POLL_S"]

POLL_S = 0.5  # how often the start-up checks whether the live twin has its first samples


def _log(services: Services, text: str) -> None:
    with (services.settings.data_dir / "twin.log").open("a") as log:
        log.write(f"{datetime.now(UTC).isoformat()} {text}\n")


def serve_live_monitors(services: Services, satellite: str, ports: dict[str, int]) -> MonitorHandles:
    """The monitors on ``satellite``'s live twin (it must hold attitude and GPS samples) on loopback ``ports``:
    every viewer in live follow, any past window of the archive replayable, registered with the services so that a
    diagnosed hypothesis can be flown on them (backend.twin.monitor_desk)."""
    from backend.twin.live_feed import ArchiveWindows, LiveFeed
    from frontend.monitors import serve_monitors

    def alarms() -> list[AlarmRecord]:
        archive = services.telemetry.opened_archive()
        try:
            return [] if archive is None else list(archive.alarms(satellite))
        except ValueError:  # nothing archived for the satellite yet
            return []

    feed = LiveFeed(services.twins, satellite, alarms)
    windows = ArchiveWindows(services.telemetry.opened_archive, services.twins, satellite, alarms)
    handles = serve_monitors(feed, host="127.0.0.1", ports=ports, live=True, windows=windows)
    services.monitors.attach(handles, feed, satellite)
    return handles


def run_demo_twin(
    services: Services, monitor_ports: dict[str, int], scenario: str, stop: threading.Event
) -> MonitorHandles | None:
    """Wait for the live satellite's first samples, serve the monitors on its live twin in live follow; handles."""
    from backend.twin.monitor_gate import MonitorGate

    satellite = services.settings.live_satellite
    twins = services.twins

    def progress() -> str:
        recent = twins.recent(satellite)
        if not recent:
            return f"waiting for the first telemetry of {satellite}"
        return (
            f"the live twin of {satellite} holds {recent['t_ns'].size} attitude sample(s) and "
            f"{recent['gps_t_ns'].size} GPS fix(es); the view needs 2 and 3"
        )

    gates = {  # the public ports answer from the start: a progress page until the monitors are up
        role: MonitorGate(services.auth, services.settings.host, public, None, role=role, progress=progress)
        for role, public in monitor_ports.items()
    }
    for gate in gates.values():
        gate.start()
    while not stop.is_set():
        recent = twins.recent(satellite)
        if recent and recent["t_ns"].size >= 2 and recent["gps_t_ns"].size >= 3:
            break
        stop.wait(POLL_S)
    else:
        for gate in gates.values():
            gate.stop()
        return None
    handles = serve_live_monitors(services, satellite, dict.fromkeys(monitor_ports, 0))  # private ports
    for role, gate in gates.items():  # the public ports ask for an API token (backend.twin.monitor_gate)
        gate.attach(handles.ports[role])
    _log(
        services,
        f"monitors on the live twin of {satellite} ({scenario}): {monitor_ports} (token-gated) -> "
        f"viser on {handles.ports}",
    )
    return handles
