"""Twin sessions (seed 000 §7): a simulation started from telemetry, flown beside it, and its residuals.

Start: the archived packets around the alignment instant are replayed and decoded into the actual
track (telemetry.actual_state); the library scenario is re-started there with the telemetered
attitude, rates, wheel speeds and GPS orbit, the operator's fault hypothesis and the wheels onboard
FDIR had isolated, and flown as a simulation job (with onboard FDIR, like the satellite).
Residuals: twin minus telemetry at the telemetry sample times, attitude angle |Λ̃_tm ∘ Λ_twin| (rad),
body-rate difference |ω_twin − ω_tm| (rad/s) and wheel-speed differences (rad/s, per wheel).
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from backend.ingest.ports import TelemetryArchive
from sim_core import quaternion
from telemetry.actual_state import ActualTrack
from telemetry.dictionary import Dictionary

__all__ = ["GPS_MARGIN_S", "actual_track_between", "twin_start", "Residuals", "residuals", "variant_names"]

GPS_MARGIN_S = 60.0  # telemetry read before the alignment instant: the GPS fixes the orbit fit uses
TIME_MATCH_NS = 1_000_000  # twin output and telemetry samples closer than 1 ms are the same instant


def actual_track_between(
    archive: TelemetryArchive, dictionary: Dictionary, satellite: str, t0_ns: int, t1_ns: int
) -> ActualTrack:
    """Replay and decode archived packets of [t0_ns, t1_ns] into the actual track (ValueError if none)."""
    from telemetry.actual_state import actual_track
    from telemetry.decoding import decode_stream

    packets = archive.replay(satellite, t0_ns, t1_ns)
    if not packets:
        raise ValueError(f"align_utc: no archived packets of {satellite!r} around this time")
    decoded = decode_stream(b"".join(p for _, p in packets), dictionary, source="twin")
    return actual_track(decoded.batches)


def twin_start(
    track: ActualTrack,
    scenario: str,
    align_ns: int,
    duration_s: float,
    faults: list[str],
    epoch_ns: int | None = None,
    alternatives: dict[str, list[str]] | None = None,
) -> tuple[int, dict[str, Any], dict[str, Any]]:
    """(alignment sample time, twin scenario JSON, engine options) at the first ACS_HK sample ≥ align_ns.

    ``epoch_ns``: when the satellite started flying the scenario's route (default: the library epoch).
    ``alternatives``: what-if variants flown beside the twin from the same state, name → fault hypothesis.
    """
    from sim_core import scenario_library
    from sim_core.faults import parse_fault
    from sim_core.scenario import VariantSpec
    from telemetry.actual_state import aligned_scenario, aligned_wheel_available

    k = int(np.searchsorted(track.t_utc_ns, align_ns))
    if k >= track.t_utc_ns.size:
        raise ValueError("align_utc: after the last archived ACS_HK sample")
    t_align = int(track.t_utc_ns[k])
    if scenario not in scenario_library.names():
        raise ValueError(f"scenario: unknown {scenario!r}; one of {scenario_library.names()}")
    hypothesis = [parse_fault(text) for text in faults]
    base = scenario_library.get(scenario)
    if epoch_ns is not None:
        data = base.model_dump()
        data["orbit"]["epoch_utc"] = f"{np.datetime64(int(epoch_ns), 'ns')}Z"
        base = type(base).model_validate(data)
    twin = aligned_scenario(base, track, t_align, duration_s, hypothesis)
    data = twin.model_dump(mode="json")
    for name, texts in (alternatives or {}).items():
        data["variants"].append(VariantSpec(name=name, faults=[parse_fault(t) for t in texts]).model_dump(mode="json"))
    available = np.repeat(aligned_wheel_available(track, t_align), len(data["variants"]), axis=0)
    return (
        t_align,
        type(twin).model_validate(data).model_dump(mode="json"),
        {"fdir": True, "wheel_available": available.tolist()},
    )


@dataclass(frozen=True)
class Residuals:
    """Twin minus telemetry at common instants: seconds after alignment and the three residuals."""

    t_s: np.ndarray
    attitude_rad: np.ndarray
    rate_rad_s: np.ndarray
    wheel_speed_rad_s: np.ndarray

    def summary(self) -> dict[str, float]:
        """Largest and RMS residuals (arcsec, degrees and rpm at the edge) and how many instants were compared.

        The RMS figures are what the what-if verdict (session_service) holds against the sensors' noise.
        """
        n = self.t_s.size
        return {
            "samples": int(n),
            "attitude_max_deg": float(np.degrees(self.attitude_rad.max(initial=0.0))),
            "rate_max_deg_s": float(np.degrees(self.rate_rad_s.max(initial=0.0))),
            "wheel_speed_max_rpm": float(np.abs(self.wheel_speed_rad_s).max(initial=0.0) * 30.0 / np.pi),
            "attitude_rms_arcsec": float(np.degrees(np.sqrt(np.mean(self.attitude_rad**2))) * 3600.0) if n else 0.0,
            "wheel_speed_rms_rpm": float(np.sqrt(np.mean(self.wheel_speed_rad_s**2)) * 30.0 / np.pi) if n else 0.0,
        }


def residuals(track: ActualTrack, trajectory_npz: Path, align_ns: int, variant: int = 0) -> Residuals:
    """Residuals of one variant of the twin's trajectory.npz against the actual track (seed 000 §7 monitors)."""
    with np.load(trajectory_npz) as twin:
        if not 0 <= variant < twin["q_ib"].shape[0]:
            raise ValueError(f"variant: {variant} outside 0..{twin['q_ib'].shape[0] - 1}")
        t_twin_ns = align_ns + np.round(twin["t_s"] * 1e9).astype(np.int64)
        q_twin, w_twin = twin["q_ib"][variant], twin["omega_b_rad_s"][variant]
        h_twin = twin["wheel_speed_rad_s"][variant]
    k = np.clip(np.searchsorted(track.t_utc_ns, t_twin_ns), 0, track.t_utc_ns.size - 1)
    same = np.abs(track.t_utc_ns[k] - t_twin_ns) <= TIME_MATCH_NS
    k = k[same]
    error = quaternion.multiply(quaternion.conjugate(track.series["q_est_ib"][k]), q_twin[same])
    return Residuals(
        t_s=(t_twin_ns[same] - align_ns) / 1e9,
        attitude_rad=quaternion.angle(error),
        rate_rad_s=np.linalg.norm(w_twin[same] - track.series["omega_est_b_rad_s"][k], axis=-1),
        wheel_speed_rad_s=h_twin[same] - track.series["wheel_speed_rad_s"][k],
    )


def variant_names(trajectory_npz: Path) -> list[str]:
    """Names of the variants in a trajectory.npz (the twin first, then the what-if alternatives)."""
    with np.load(trajectory_npz) as twin:
        return list(json.loads(str(twin["meta"]))["variants"])
