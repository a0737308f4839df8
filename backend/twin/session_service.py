"""The twin-session service behind /api/v1/twin: start a session, its public view, feed and residuals.

Routes parse and answer; this module does the work (align to archived telemetry, queue the twin's
simulation, compare its output with telemetry), so the demo twin and the API share one path.
"""

from __future__ import annotations

import uuid
from datetime import datetime
from pathlib import Path

import numpy as np

from backend.core.errors import ApiError
from backend.core.models import TwinSessionRow
from backend.core.time import utc_ns
from backend.schemas import ResidualsPublic, TwinSessionCreate, TwinSessionPublic
from backend.services import Services
from backend.twin.twin_feed import SessionFeed
from backend.twin.twin_sessions import (
    GPS_MARGIN_S,
    Residuals,
    actual_track_between,
    residuals,
    twin_start,
    variant_names,
)
from telemetry.actual_state import ActualTrack
from telemetry.downsampling import minmax_indices

__all__ = ["start_session", "session_public", "session_row", "session_feed", "session_residuals"]

NS_PER_S = 1_000_000_000


def session_public(services: Services, row: TwinSessionRow) -> TwinSessionPublic:
    """The session as the API shows it, with the state and progress of its simulation job."""
    job = services.job_repo.get(row.job_id)
    return TwinSessionPublic(
        id=row.id,
        satellite=row.satellite,
        scenario=row.scenario,
        align_utc_ns=row.align_utc_ns,
        duration_s=row.duration_s,
        faults=row.faults,
        created_by=row.created_by,
        variants=["twin", *row.alternatives],
        job_id=row.job_id,
        status=job.status if job else "unknown",
        progress=services.jobs.progress(row.job_id) or (job.progress if job else 0.0),
    )


def _live_defaults(services: Services, body: TwinSessionCreate) -> tuple[int, int | None]:
    """(alignment instant, route epoch): align_utc or the live twin's newest synchronisation point, and the live
    twin's route epoch (None: the library scenario's)."""
    state = services.twins.state(body.satellite) or {}
    epoch = state.get("route_epoch_utc")
    epoch_ns = None if epoch is None else utc_ns(datetime.fromisoformat(epoch.replace("Z", "+00:00")), 0)
    if body.align_utc is not None:
        return utc_ns(body.align_utc, 0), epoch_ns
    synced = state.get("synchronised_utc")
    if synced is None:
        raise ApiError(
            422, f"align_utc: the live twin of {body.satellite!r} has not synchronised yet; give align_utc", "align_utc"
        )
    return utc_ns(datetime.fromisoformat(synced.replace("Z", "+00:00")), 0), epoch_ns


def _verdict(names: list[str], found: list[Residuals]) -> tuple[str | None, str]:
    """The best-fitting variant among those whose RMS residuals (Residuals.summary) stay within the live twin's
    limits, or none."""
    from backend.twin.live import ATTITUDE_LIMIT_ARCSEC, WHEEL_LIMIT_RAD_S

    limit_wheel_rpm = WHEEL_LIMIT_RAD_S * 30.0 / np.pi
    scores = {}
    for name, r in zip(names, found):
        s = r.summary()
        attitude, wheel = s["attitude_rms_arcsec"] / ATTITUDE_LIMIT_ARCSEC, s["wheel_speed_rms_rpm"] / limit_wheel_rpm
        if s["samples"] and attitude <= 1.0 and wheel <= 1.0:
            scores[name] = attitude + wheel
    limits = f"attitude RMS <= {ATTITUDE_LIMIT_ARCSEC:g} arcsec, wheel RMS <= {limit_wheel_rpm:g} rpm"
    if not scores:
        return None, f"none fits: every variant leaves residuals beyond the sensors' noise ({limits})"
    best = min(scores, key=scores.__getitem__)
    return best, f"{best} fits best of {len(scores)} fitting variant(s) ({limits})"


def start_session(services: Services, body: TwinSessionCreate, actor: str) -> TwinSessionPublic:
    """Align a twin to archived telemetry and queue its simulation; the session as answered by the API."""
    align_ns, live_epoch_ns = _live_defaults(services, body)
    dictionary = services.telemetry.dictionaries.load(body.dictionary)
    track = actual_track_between(
        services.telemetry.archive,
        dictionary,
        body.satellite,
        align_ns - int(GPS_MARGIN_S * NS_PER_S),
        align_ns + int(body.duration_s * NS_PER_S),
    )
    epoch_ns = live_epoch_ns if body.scenario_epoch_utc is None else utc_ns(body.scenario_epoch_utc, 0)
    t_align, scenario, options = twin_start(
        track, body.scenario, align_ns, body.duration_s, body.faults, epoch_ns, body.alternatives
    )
    job_id = services.jobs.submit(scenario, actor, options)
    row = services.twin_sessions.add(
        id=uuid.uuid4().hex,
        job_id=job_id,
        satellite=body.satellite,
        dictionary=body.dictionary,
        scenario=body.scenario,
        align_utc_ns=t_align,
        duration_s=body.duration_s,
        faults=body.faults,
        alternatives=body.alternatives,
        created_by=actor,
    )
    return session_public(services, row)


def session_row(services: Services, session_id: str) -> TwinSessionRow:
    """The stored session, 404 naming ``session_id`` when unknown."""
    row = services.twin_sessions.get(session_id)
    if row is None:
        raise ApiError(404, f"no twin session {session_id!r}", "session_id")
    return row


def _finished_track(services: Services, row: TwinSessionRow, waiting: str) -> tuple[ActualTrack, Path]:
    """Telemetry of the session's window and its twin's trajectory.npz; 409 until the simulation succeeded."""
    job = services.job_repo.get(row.job_id)
    if job is None or job.status != "succeeded":
        raise ApiError(409, f"twin simulation is {job.status if job else 'missing'}{waiting}", "session_id")
    dictionary = services.telemetry.dictionaries.load(row.dictionary)
    t1 = row.align_utc_ns + int(row.duration_s * NS_PER_S)
    track = actual_track_between(services.telemetry.archive, dictionary, row.satellite, row.align_utc_ns, t1)
    return track, services.jobs.result_dir(row.job_id) / "trajectory.npz"


def session_feed(services: Services, session_id: str) -> SessionFeed:
    """The monitors' TwinFeed of a finished session (telemetry of its window against its twin)."""
    row = session_row(services, session_id)
    track, npz = _finished_track(services, row, "")
    alarms = services.telemetry.archive.alarms(row.satellite, include_cleared=True)
    return SessionFeed(track, npz, row.align_utc_ns, alarms)


def _all_residuals(services: Services, row: TwinSessionRow) -> tuple[list[str], list[Residuals]]:
    """Every variant's residuals, computed once (archive window read and decoded) and kept until telemetry
    ingested into the session's window or a new version of its dictionary changes them (the twin's trajectory
    never changes once it succeeded)."""

    def compute() -> tuple[list[str], list[Residuals]]:
        track, npz = _finished_track(services, row, ": residuals once it succeeded")
        names = variant_names(npz)
        return names, [residuals(track, npz, row.align_utc_ns, v) for v in range(len(names))]

    t1 = row.align_utc_ns + int(row.duration_s * NS_PER_S)
    what = f"twin-session residuals {row.id}"
    return services.telemetry.window_result(row.satellite, what, row.align_utc_ns, t1, compute, row.dictionary)


def session_residuals(services: Services, session_id: str, variant: int, max_points: int) -> ResidualsPublic:
    """Attitude angle (deg), rate difference (deg/s), wheel-speed differences (rpm) of one variant, min/max
    downsampled to ``max_points``, with the summary of every variant (the what-if comparison)."""
    names, found = _all_residuals(services, session_row(services, session_id))
    if variant >= len(names):
        raise ApiError(422, f"variant: {variant} outside 0..{len(names) - 1}", "variant")
    chosen = found[variant]
    columns = np.column_stack(
        [np.degrees(chosen.attitude_rad), np.degrees(chosen.rate_rad_s), chosen.wheel_speed_rad_s * 30.0 / np.pi]
    )
    keep = minmax_indices(columns, max_points) if chosen.t_s.size else np.arange(0)
    summaries = {name: r.summary() for name, r in zip(names, found)}
    best, verdict = _verdict(names, found)
    return ResidualsPublic(
        session_id=session_id,
        variant=names[variant],
        summary=summaries[names[variant]],
        best_match=best,
        verdict=verdict,
        summaries=summaries,
        t_s=chosen.t_s[keep].tolist(),
        attitude_deg=columns[keep, 0].tolist(),
        rate_deg_s=columns[keep, 1].tolist(),
        wheel_speed_rpm=columns[keep, 2:].tolist(),
    )
