"""Fly a diagnosed hypothesis on the simulated monitor (issue 14 item 3), behind /api/v1/monitors/simulated.

A finished diagnosis names hypotheses with an onset and a magnitude; one of them (default the top one), of any
fault type, is flown by the diagnosis' own replay (:func:`sim_core.diagnosis.hypothesis_replay`: the twin restarted
from the telemetry REPLAY_LEAD_S before the onset, the fault as engine faults
(:func:`sim_core.diagnosis.hypothesis_faults`), the no-fault twin beside it as a second variant) on the server's
Dask cluster, up to FLIGHT_AFTER_S after the onset. The flight is compared with the telemetry of the same window
(residuals of the hypothesis and of the nominal twin: attitude, rate and wheel speeds as the what-if's, the wheel
speeds as the twin's tachometers read them, and the gyro, magnetometer and star tracker as the twin's would have
read them, :func:`sim_core.diagnosis.flight_sensor_residuals`) and put on the monitors
(backend.twin.monitor_desk): the actual monitor replays that telemetry, the simulated one the twin with the
hypothesis, named on every panel. :func:`land_flight` puts the live twin back.
"""

from __future__ import annotations

from datetime import datetime
from typing import TYPE_CHECKING, Any

import numpy as np

from backend.core.errors import ApiError
from backend.twin.diagnosis import archived_reader, scenario_observations
from backend.twin.twin_feed import SessionFeed
from backend.twin.twin_sessions import GPS_MARGIN_S, actual_track_between, residuals
from telemetry.downsampling import minmax_indices

if TYPE_CHECKING:
    from pathlib import Path

    from backend.services import Services

__all__ = ["fly_hypothesis", "hypothesis_label", "land_flight", "MAX_POINTS"]

NS_PER_S = 1_000_000_000
MAX_POINTS = 300  # wheel-speed samples per series in the answer (min/max downsampled)
RPM_PER_RAD_S = 30.0 / np.pi
VARIANTS = ("hypothesis", "nominal")  # the replay's variants h0 and none, in that order


def _unix_s(iso: str) -> float:
    return datetime.fromisoformat(iso.replace("Z", "+00:00")).timestamp()


def _wheels(wheel: int | list[int] | None) -> str:
    if wheel is None:
        return ""
    return " " + "+".join(f"RW{w}" for w in (wheel if isinstance(wheel, list) else [wheel]))


def hypothesis_label(run: dict[str, Any], rank: int) -> str:
    """How the panels name a flown hypothesis: rank, fault, wheel(s), onset and the diagnosis."""
    h = run["result"]["hypotheses"][rank - 1]
    return f"hypothesis #{rank}: {h['fault']}{_wheels(h['wheel'])} from {h['onset_utc']} (diagnosis {run['id'][:8]})"


def _chosen(services: Services, diagnosis_id: str, rank: int) -> tuple[dict[str, Any], dict[str, Any]]:
    """The diagnosis and its hypothesis of that rank; 404/409/422 saying what is wrong."""
    run = services.diagnoses.get(diagnosis_id)
    if run is None:
        raise ApiError(404, f"no diagnosis {diagnosis_id!r}", "diagnosis_id")
    if run["status"] != "succeeded":
        why = f" ({run['error']})" if run.get("error") else ""
        raise ApiError(
            409, f"diagnosis {diagnosis_id}: {run['status']}{why}; only a succeeded one can be flown", "diagnosis_id"
        )
    hypotheses = run["result"]["hypotheses"]
    if not 1 <= rank <= len(hypotheses):
        raise ApiError(422, f"rank: {rank} outside 1..{len(hypotheses)} (the hypotheses the diagnosis ranked)", "rank")
    h = hypotheses[rank - 1]
    if h["fault"] == "none":
        raise ApiError(
            422, f"rank: hypothesis #{rank} is 'none' (no fault), the nominal twin: DELETE the flight to see it", "rank"
        )
    return run, h


def _wheel_series(npz: Path, found: list[Any]) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """Seconds after the flight's start and the wheel speeds (rad/s) of telemetry and of each variant there."""
    with np.load(npz) as twin:
        t_twin, w = twin["t_s"], twin["wheel_speed_rad_s"]
    r = found[0]
    k = np.clip(np.searchsorted(t_twin, r.t_s - 1e-6), 0, t_twin.size - 1)  # residual instants are twin instants
    series = {"telemetry": w[0][k] - r.wheel_speed_rad_s, "hypothesis": w[0][k], "nominal": w[-1][k]}
    return r.t_s, series


def fly_hypothesis(services: Services, diagnosis_id: str, rank: int, actor: str) -> dict[str, Any]:
    """Fly hypothesis ``rank`` (1 = top) of a finished diagnosis and put it on the monitors; the flight as answered."""
    from backend.jobs import cluster
    from backend.jobs.trajectory_files import write_npz
    from sim_core import scenario_library
    from sim_core.diagnosis import flight_sensor_residuals, hypothesis_replay, tachometer_readings

    run, h = _chosen(services, diagnosis_id, rank)
    try:
        scenario = scenario_library.get(run["scenario"])
        dictionary = services.telemetry.dictionaries.load(run["dictionary"])
    except ValueError as exc:
        raise ApiError(409, f"diagnosis {diagnosis_id}: {exc}", "diagnosis_id") from None
    archive = services.telemetry.archive
    t0, t1 = (round(_unix_s(run[k]) * NS_PER_S) for k in ("start_utc", "end_utc"))
    try:
        batches, _ = archived_reader(archive, run["satellite"], dictionary, t0, t1)()
        obs = scenario_observations(batches, dictionary, scenario)
    except ValueError as exc:  # the telemetry was deleted or re-decoded since the diagnosis
        raise ApiError(409, f"diagnosis {diagnosis_id}: {exc}", "diagnosis_id") from None
    onset_s = _unix_s(h["onset_utc"]) - obs.epoch_unix_s if h["onset_utc"] else None
    try:
        batch, first, stop = hypothesis_replay(obs, scenario, h["fault"], h["wheel"], onset_s, h["magnitude"])
    except ValueError as exc:  # "hypothesis: <what>": none, not flyable, no onset in the telemetry
        raise ApiError(422, f"rank: hypothesis #{rank}: {str(exc).removeprefix('hypothesis: ')}", "rank") from None
    out = services.settings.data_dir / "flights"
    out.mkdir(parents=True, exist_ok=True)
    traj = cluster.flyer(services.cluster.client())(batch)
    traj.series["wheel_speed_rad_s"] = tachometer_readings(batch, traj.t_s, traj["wheel_speed_rad_s"])
    assert onset_s is not None  # hypothesis_replay refuses a hypothesis without one
    sensors = flight_sensor_residuals(obs, batch, traj.t_s, traj.series, first, onset_s)
    npz = write_npz(traj, out / f"{diagnosis_id}-{rank}.npz")
    align_ns = round((obs.epoch_unix_s + float(obs.t_s[first])) * NS_PER_S)
    end_ns = round((obs.epoch_unix_s + float(obs.t_s[stop - 1])) * NS_PER_S)
    track = actual_track_between(archive, dictionary, run["satellite"], align_ns - int(GPS_MARGIN_S * NS_PER_S), end_ns)
    found = [residuals(track, npz, align_ns, v) for v in range(len(VARIANTS))]
    t_s, series = _wheel_series(npz, found)
    columns = np.column_stack(list(series.values()))
    keep = minmax_indices(columns, MAX_POINTS) if t_s.size > MAX_POINTS else np.arange(t_s.size)
    flight: dict[str, Any] = {
        "diagnosis_id": diagnosis_id,
        "rank": rank,
        "satellite": run["satellite"],
        "scenario": run["scenario"],
        "hypothesis": h,
        "label": hypothesis_label(run, rank),
        "start_utc": _iso(align_ns),
        "end_utc": _iso(end_ns),
        "summaries": {name: {**r.summary(), **sensor} for name, r, sensor in zip(VARIANTS, found, sensors)},
        "t_s": t_s[keep].tolist(),
        "wheel_speed_rpm": {name: (s[keep] * RPM_PER_RAD_S).tolist() for name, s in series.items()},
        "flown_by": actor,
        "on_monitor": services.monitors.running,
    }
    feed = SessionFeed(track, npz, align_ns, archive.alarms(run["satellite"], include_cleared=True))
    flight["on_monitor"] = services.monitors.show_flight(feed, flight)
    return flight


def _iso(t_ns: int) -> str:
    return str(np.datetime_as_string(np.datetime64(t_ns, "ns"), unit="ms")) + "Z"


def land_flight(services: Services) -> dict[str, Any]:
    """The nominal (live) twin back on the monitors; the simulated monitor's state."""
    services.monitors.show_nominal()
    return services.monitors.state()
