"""Diagnosis service: telemetry (a file or archived batches) + dictionary + scenario → the ranked hypotheses as JSON.

One ranking rule everywhere: :func:`sim_core.diagnosis.diagnose` scores every hypothesis by its
posterior probability (equal priors, likelihood of the telemetry with the sensors' noise and
quantisation, onset marginalised, magnitude penalised), and :func:`result_json` lists them in that
order. The command line (``acs-twin diagnose``), the REST routes and the dashboard all read this JSON:
``hypotheses`` (best first; ``fault``, ``wheel`` 1-based or a list for pairs or null, ``onset_utc``
ISO 8601, ``onset_sigma_s``, ``magnitude``, ``score`` = posterior probability, ``log_evidence``),
``confidence`` (the top score), ``detection`` (detected, alarm time and channel, the stated false-alarm
rate, the analysis window), ``suspected_wheels`` and ``untestable`` (hypotheses the telemetry cannot test).
"""

from __future__ import annotations

from collections.abc import Callable
from datetime import UTC, datetime
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from backend.jobs import cluster
from backend.jobs.cluster import ServerCluster
from backend.twin.diagnosis_repository import DiagnosisRepository
from sim_core.diagnosis import (
    Diagnosis,
    Observations,
    WheelModel,
    diagnose,
    wheel_model,
)
from sim_core.scenario import Scenario
from telemetry.dictionary import Dictionary
from telemetry.housekeeping import observations, read_batches
from telemetry.ingest_report import SampleBatch

if TYPE_CHECKING:
    from backend.ingest.ports import TelemetryArchive
    from backend.schemas import DiagnosisCreate
    from backend.twin.live import LiveDetection

__all__ = [
    "DiagnosisRuns",
    "archived_reader",
    "diagnose_batches",
    "diagnose_detection",
    "diagnose_file",
    "result_json",
    "scenario_observations",
    "scenario_wheels",
    "start_archived",
]

# A file diagnosed offline may be a simulated flight dated after today (each file has its own epoch): the
# ingest's bound against a runaway onboard clock protects the archive, which diagnosing a file never writes.
OFFLINE_CLOCK_UTC_NS = 4_102_444_800 * 10**9  # 2100-01-01T00:00:00Z


def scenario_wheels(scenario: Scenario) -> WheelModel:
    """The cluster as the momentum balance needs it, from the scenario's spacecraft (seed 000 eq 1)."""
    from sim_core.engine import plant_params  # the engine's kernels: loaded by a diagnosis, not with the server

    p = plant_params(scenario)
    limits = np.asarray(p.wheels.max_torque_nm), np.asarray(p.wheels.coulomb_nm)  # (n,) after WheelParams.__post_init__
    return wheel_model(p.wheel_axes_b, p.wheels.inertia_kg_m2, *limits, scenario.control_dt_s)


def _utc(epoch_unix_s: float, t_s: float | None) -> str | None:
    if t_s is None:
        return None
    stamp = datetime.fromtimestamp(epoch_unix_s + t_s, tz=UTC)
    return stamp.isoformat(timespec="milliseconds").replace("+00:00", "Z")


def result_json(d: Diagnosis, obs: Observations, satellite: str, scenario: str) -> dict[str, Any]:
    """The diagnosis as the JSON every client reads (module docstring)."""
    return {
        "satellite": satellite,
        "scenario": scenario,
        "telemetry_start_utc": _utc(obs.epoch_unix_s, 0.0),
        "telemetry_end_utc": _utc(obs.epoch_unix_s, float(obs.t_s[-1])),
        "confidence": d.confidence,
        "detection": {
            "detected": d.detected,
            "alarm_utc": _utc(obs.epoch_unix_s, d.alarm_s),
            "channel": d.alarm_channel,
            "false_alarms_per_day": d.false_alarms_per_day,
            "window_utc": [_utc(obs.epoch_unix_s, d.window_s[0]), _utc(obs.epoch_unix_s, d.window_s[1])],
        },
        "suspected_wheels": d.suspected_wheels,
        "untestable": d.untestable,
        "hypotheses": [
            {
                "fault": h.fault,
                "wheel": h.wheel,
                "onset_utc": _utc(obs.epoch_unix_s, h.onset_s),
                "onset_sigma_s": h.onset_sigma_s,
                "magnitude": h.magnitude,
                "score": h.score,
                "log_evidence": h.log_evidence,
            }
            for h in d.hypotheses
        ],
    }


def diagnose_batches(
    batches: list[SampleBatch],
    dictionary: Dictionary,
    scenario: Scenario,
    satellite: str | None = None,
    flyer: Callable[[Scenario], object] | None = None,
) -> dict[str, Any]:
    """Diagnose decoded batches of one satellite against its scenario; ValueError naming what is missing.

    ``flyer`` flies the replay batches (:func:`backend.jobs.cluster.flyer` for a Dask cluster)."""
    wm = scenario_wheels(scenario)
    obs = scenario_observations(batches, dictionary, scenario, satellite, wm)
    result = diagnose(obs, wm, scenario, flyer=flyer)
    return result_json(result, obs, dictionary.satellite_name, scenario.name)


def scenario_observations(
    batches: list[SampleBatch],
    dictionary: Dictionary,
    scenario: Scenario,
    satellite: str | None = None,
    wheels: WheelModel | None = None,
) -> Observations:
    """The housekeeping the diagnosis reads (and a flown hypothesis is replayed on), for the scenario's spacecraft."""
    wm = wheels or scenario_wheels(scenario)
    return observations(
        batches, dictionary, satellite, n_wheels=wm.axes_b.shape[1], field_model=scenario.magnetic_model
    )


def diagnose_file(
    path: str | Path,
    dictionary: Dictionary,
    scenario: Scenario,
    satellite: str | None = None,
    flyer: Callable[[Scenario], object] | None = None,
) -> dict[str, Any]:
    """Diagnose a packet file or a ground CSV/JSONL file (``acs-twin diagnose``), dated anywhere up to 2100."""
    batches = read_batches(path, dictionary, now_utc_ns=OFFLINE_CLOCK_UTC_NS)
    return diagnose_batches(batches, dictionary, scenario, satellite, flyer)


class DiagnosisRuns:
    """Diagnoses started over REST or by a live twin's detector: one worker thread, the twin replays flown on the
    server's Dask cluster, every run persisted (:class:`DiagnosisRepository`: it survives a restart)."""

    def __init__(self, repo: DiagnosisRepository, cluster: ServerCluster) -> None:
        from concurrent.futures import ThreadPoolExecutor

        self._repo, self._cluster = repo, cluster
        self._pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="diagnosis")

    def start(self) -> int:
        """Diagnoses a previous server left running are failed, saying why; their count."""
        return self._repo.fail_running()

    def submit(
        self,
        read_batches_of: Callable[[], tuple[list[SampleBatch], Dictionary]],
        scenario: Scenario,
        record: dict[str, Any],
        before_run: Callable[[str], None] | None = None,
    ) -> dict[str, Any]:
        """Queue a diagnosis of the batches ``read_batches_of`` returns; the stored record (status running).

        ``before_run(run_id)`` runs in the worker first (a live twin links its alarm there)."""
        import uuid

        run = self._repo.add({**record, "id": uuid.uuid4().hex})

        def work() -> None:
            try:
                if before_run is not None:
                    before_run(run["id"])
                batches, dictionary = read_batches_of()
                flyer = cluster.flyer(self._cluster.client())
                result = diagnose_batches(batches, dictionary, scenario, flyer=flyer)  # the archive keys the satellite
                self._repo.finish(run["id"], "succeeded", result=result)
            except (ValueError, RuntimeError) as exc:  # bad input, or no cluster: the message names it
                self._repo.finish(run["id"], "failed", error=str(exc))
            except Exception as exc:  # noqa: BLE001 (reported to the operator, the server keeps running)
                self._repo.finish(run["id"], "failed", error=f"{type(exc).__name__}: {exc}")

        self._pool.submit(work)
        return run

    def get(self, run_id: str) -> dict[str, Any] | None:
        """The run record, None if unknown."""
        return self._repo.get(run_id)

    def link_alarm(self, run_id: str, alarm_id: int) -> None:
        """Record the alarm whose detection started the run."""
        self._repo.link_alarm(run_id, alarm_id)

    def list(self, alarm_id: int | None = None, satellite: str | None = None) -> list[dict[str, Any]]:
        """Kept runs, newest first (of one alarm or one satellite if given)."""
        return self._repo.list(alarm_id=alarm_id, satellite=satellite)

    def close(self) -> None:
        """Stop taking runs; a running one finishes in its thread (or is failed by the next start)."""
        self._pool.shutdown(wait=False, cancel_futures=True)


ALARM_WAIT_S = 60.0  # how long a live detection's diagnosis waits for its alarm to be archived before it runs


def archived_reader(
    archive: TelemetryArchive, satellite: str, dictionary: Dictionary, t0_ns: int, t1_ns: int
) -> Callable[[], tuple[list[SampleBatch], Dictionary]]:
    """A reader of the satellite's archived packets in [t0_ns, t1_ns], decoded (ValueError when there are none)."""
    from telemetry.decoding import decode_stream

    def read() -> tuple[list[SampleBatch], Dictionary]:
        packets = archive.replay(satellite, t0_ns, t1_ns)
        if not packets:
            raise ValueError(f"telemetry: no archived packets of {satellite!r} in the window")
        return decode_stream(b"".join(p for _, p in packets), dictionary, source="diagnosis").batches, dictionary

    return read


def diagnose_detection(
    diagnoses: DiagnosisRuns,
    archive: Callable[[], TelemetryArchive | None],
    dictionaries: Callable[[str], Dictionary],
    live: LiveDetection,
) -> str:
    """Start the diagnosis of a live twin's detection (``backend.twin.live.LiveDetection``); its id.

    The run reads PRE_ALARM_S before the detection to the newest telemetry and, once the detection's alarm
    (``twin_anomaly``) is archived, records the alarm's id so the alarm links to its diagnosis."""
    from backend.twin.live import ANOMALY_PARAMETER

    t0, t1 = live.window_ns
    fired = live.detection.t_utc_ns
    opened = archive()
    if opened is None:
        raise RuntimeError(f"diagnosis of {live.satellite}: the telemetry archive is closed (the server is stopping)")

    def link_alarm(run_id: str) -> None:
        live.archived.wait(ALARM_WAIT_S)
        alarms = [
            a
            for a in opened.alarms(live.satellite, include_cleared=True)
            if a.parameter == ANOMALY_PARAMETER and a.first_t_ns <= fired
        ]
        if alarms:
            diagnoses.link_alarm(run_id, max(alarms, key=lambda a: a.first_t_ns).id)

    record = {
        "satellite": live.satellite,
        "dictionary": live.dictionary,
        "scenario": live.scenario.name,
        "created_by": "live twin",
        "trigger": "live twin",
        "alarm_utc": _utc(fired / 1e9, 0.0),
        "start_utc": _utc(t0 / 1e9, 0.0),
        "end_utc": _utc(t1 / 1e9, 0.0),
    }
    read = archived_reader(opened, live.satellite, dictionaries(live.dictionary), t0, t1)
    return str(diagnoses.submit(read, live.scenario, record, before_run=link_alarm)["id"])


def start_archived(
    diagnoses: DiagnosisRuns,
    archive: TelemetryArchive,
    dictionaries: Callable[[str], Dictionary],
    body: DiagnosisCreate,
    actor: str,
) -> dict[str, Any]:
    """Check a REST request (window, dictionary, scenario) and queue its diagnosis on archived packets."""
    from backend.core.errors import ApiError
    from backend.schemas import DIAGNOSIS_WINDOW_MAX_S  # declared in the OpenAPI document on end_utc
    from sim_core import scenario_library

    t0, t1 = body.start_utc.timestamp(), body.end_utc.timestamp()
    if not 0.0 < t1 - t0 <= DIAGNOSIS_WINDOW_MAX_S:
        window = f"{DIAGNOSIS_WINDOW_MAX_S:.0f} s"
        raise ApiError(422, f"end_utc: must be after start_utc and within {window} of it", "end_utc")
    try:
        dictionary = dictionaries(body.dictionary)
        scenario = scenario_library.get(body.scenario)
    except ValueError as exc:
        raise ApiError(422, str(exc), "scenario" if "scenario" in str(exc) else "dictionary") from None
    read = archived_reader(archive, body.satellite, dictionary, int(t0 * 1e9), int(t1 * 1e9))
    record = {
        "satellite": body.satellite,
        "dictionary": body.dictionary,
        "scenario": body.scenario,
        "created_by": actor,
        "trigger": "operator",
        "start_utc": _utc(t0, 0.0),
        "end_utc": _utc(t1, 0.0),
    }
    return diagnoses.submit(read, scenario, record)
