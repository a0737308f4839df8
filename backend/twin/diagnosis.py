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
from typing import Any

from sim_core import engine
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

__all__ = ["diagnose_batches", "diagnose_file", "result_json", "scenario_wheels"]


def scenario_wheels(scenario: Scenario) -> WheelModel:
    """The cluster as the momentum balance needs it, from the scenario's spacecraft (seed 000 eq 1)."""
    p = engine.plant_params(scenario)
    return wheel_model(p.wheel_axes_b, p.wheels.inertia_kg_m2, p.wheels.max_torque_nm, p.wheels.coulomb_nm,
                       scenario.control_dt_s)


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


def diagnose_batches(batches: list[SampleBatch], dictionary: Dictionary, scenario: Scenario,
                     satellite: str | None = None, flyer: Callable[[Scenario], Any] | None = None) -> dict[str, Any]:
    """Diagnose decoded batches of one satellite against its scenario; ValueError naming what is missing.

    ``flyer`` flies the replay batches (:func:`backend.jobs.cluster.flyer` for a Dask cluster)."""
    wm = scenario_wheels(scenario)
    obs = observations(batches, dictionary, satellite, n_wheels=wm.axes_b.shape[1])
    result = diagnose(obs, wm, scenario, flyer=flyer)
    return result_json(result, obs, dictionary.satellite_name, scenario.name)


def diagnose_file(path: str | Path, dictionary: Dictionary, scenario: Scenario, satellite: str | None = None,
                  flyer: Callable[[Scenario], Any] | None = None) -> dict[str, Any]:
    """Diagnose a packet file or a ground CSV/JSONL file (``acs-twin diagnose``)."""
    return diagnose_batches(read_batches(path, dictionary), dictionary, scenario, satellite, flyer)
