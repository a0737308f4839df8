"""The result of a simulation batch: time histories per variant, events, and summary metrics.

Arrays carry a leading variant axis (batch first, DESIGN.md) and are sampled at the scenario's
output rate, so memory grows with output samples, not with integration steps.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from sim_core import quaternion

__all__ = ["Trajectory", "EVENT_NAMES", "SERIES_UNITS"]

ARCSEC_PER_RAD = 180.0 / np.pi * 3600.0
SETTLED_ERROR_RAD = np.radians(0.01)  # "settled": attitude error below 0.01° from then on

# Event codes written by the engine (code → name); the argument is a wheel index, mode, etc.
EVENT_NAMES = {
    1: "mode_change",
    2: "fault_onset",
    3: "fault_cleared",
    4: "fault_detected",
    5: "fault_isolated",
    6: "reconfigured",
    7: "allocation_infeasible",
    8: "md_saturated",
    9: "wheel_momentum_limit",
    10: "reconfiguration_refused",
}

SERIES_UNITS = {
    "q_ib": "1",
    "omega_b_rad_s": "rad/s",
    "q_est_ib": "1",
    "omega_est_b_rad_s": "rad/s",
    "q_prog_ib": "1",
    "omega_prog_b_rad_s": "rad/s",
    "error_angle_rad": "rad",
    "error_vector_rad": "rad",
    "wheel_speed_rad_s": "rad/s",
    "wheel_torque_cmd_nm": "N·m",
    "wheel_torque_nm": "N·m",
    "md_dipole_am2": "A·m²",
    "control_torque_b_nm": "N·m",
    "r_eci_m": "m",
    "observing": "1",
    "mode": "1",
    "fault_flags": "1",
    "wheel_available": "1",
    # sensor readings as the onboard software took them (closed_loop.Sensed.readings), zeros while a sensor gives no
    # valid sample; names as the telemetry's (the tachometers' there: wheel_speed_rad_s)
    "b_mag_b_t": "T",
    "omega_gyro_b_rad_s": "rad/s",
    "q_st_ib": "1",
    "wheel_tachometer_rad_s": "rad/s",
}


@dataclass
class Trajectory:
    """Time histories (variant, sample, …) of truth, estimates, program, commands, actuators and sensor readings."""

    scenario_name: str
    variant_names: list[str]
    t_s: np.ndarray
    series: dict[str, np.ndarray]
    events: list[list[tuple[float, str, int]]]
    wheel_inertia_kg_m2: np.ndarray
    wall_time_s: float = 0.0
    simulated_time_s: float = 0.0
    extra: dict[str, float] = field(default_factory=dict)

    @property
    def n_variants(self) -> int:
        """Number of variants in the batch."""
        return len(self.variant_names)

    def __getitem__(self, name: str) -> np.ndarray:
        return self.series[name]

    def pointing_error_rad(self) -> np.ndarray:
        """Angle between the true and the programmed attitude, (variant, sample), rad."""
        e = quaternion.multiply(quaternion.conjugate(self.series["q_prog_ib"]), self.series["q_ib"])
        return quaternion.angle(e)

    def settling_time_s(self, after_s: float = 0.0) -> np.ndarray:
        """Per variant: time after ``after_s`` until the error stays below 0.01° (NaN if never)."""
        err = self.pointing_error_rad()
        out = np.full(self.n_variants, np.nan)
        sel = self.t_s >= after_s
        for v in range(self.n_variants):
            bad = np.nonzero(err[v, sel] > SETTLED_ERROR_RAD)[0]
            if bad.size == 0:
                out[v] = 0.0
            elif bad[-1] < sel.sum() - 1:
                out[v] = self.t_s[sel][bad[-1] + 1] - after_s
        return out

    def summary(self, variant: int = 0) -> dict[str, Any]:
        """Summary metrics of one variant (the keys ``acs-twin simulate --summary-json`` writes)."""
        err = self.pointing_error_rad()[variant]
        obs = self.series["observing"][variant] > 0
        sel = err[obs] if obs.any() else err
        rate_err = self.series["omega_b_rad_s"][variant] - self.series["omega_prog_b_rad_s"][variant]
        h = self.series["wheel_speed_rad_s"][variant] * self.wheel_inertia_kg_m2
        settle = self.settling_time_s(self.extra.get("settle_after_s", 0.0))[variant]
        return {
            "scenario": self.scenario_name,
            "variant": self.variant_names[variant],
            "pointing_error_rms_arcsec": float(np.sqrt(np.mean(sel**2)) * ARCSEC_PER_RAD),
            "pointing_error_max_arcsec": float(np.max(sel) * ARCSEC_PER_RAD),
            "observing_samples": int(obs.sum()),
            "rate_error_max_deg_s": float(np.degrees(np.max(np.linalg.norm(rate_err, axis=-1)))),
            "max_wheel_momentum_Nms": float(np.max(np.abs(h))),
            "max_md_moment_Am2": float(np.max(np.abs(self.series["md_dipole_am2"][variant]))),
            "settling_time_s": None if np.isnan(settle) else float(settle),
            "events": [{"t_s": t, "event": name, "arg": arg} for t, name, arg in self.events[variant]],
            "wall_time_s": self.wall_time_s,
            "simulated_time_s": self.simulated_time_s,
        }
