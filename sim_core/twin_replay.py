"""Replay of fault hypotheses: the twin restarted from telemetry before the onset, hypotheses flown as batch variants.

The wheel momentum balance (:mod:`sim_core.diagnosis`) names the wheel and the fault type, but a
wheel commanded a few µN·m changes speed by one tachometer count in minutes, so its onset is loose
there. The closed loop knows more: once a wheel stops delivering, the controller's commands to every
wheel and the attitude respond at once. :func:`replay_scores` restarts the twin at a telemetry instant
(:func:`twin_at`: telemetered attitude, rates and wheel speeds, the programme and the orbit shifted to
that instant), flies every (hypothesis, onset) pair as one variant of a single batch
(:func:`sim_core.engine.simulate`), and scores each against the telemetered wheel torque commands and
attitude with a Gaussian likelihood whose σ is the telemetry resolution and the twin's own mismatch
measured before the onset on the no-fault variant.

A file need not begin where the scenario does (each file has its own epoch): for an inertially pointed
twin the orbit's phase at the file's first sample is unknown, and the gravity-gradient torque the wheels
absorb depends on it. :func:`orbit_phase_deg` finds it from the telemetered commands before the onset
(in fine pointing Σ a_p u_p is the gravity-gradient torque at the telemetered attitude).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

import numpy as np
import numpy.typing as npt

from sim_core import engine, environment, orbit, quaternion
from sim_core.scenario import FaultSpec, Scenario, VariantSpec, shifted_guidance

__all__ = [
    "ARCSEC_FLOOR",
    "effective_samples",
    "fault_specs",
    "orbit_phase_deg",
    "replay_batch",
    "replay_scores",
    "telemetered_steps",
    "twin_at",
]

ARCSEC_FLOOR = 0.05  # arcsec: float32 quaternion components resolve ~0.01″; below this the twin is "exact"
PROGRAM_STEP_RAD = 1e-6  # a change of the guidance quaternion above float32 noise is a new inertial step
TORQUE_FLOOR_NM = 1e-8  # a CSV's engineering torques carry no resolution; the twin's own rounding is below this
FAULT_TYPES = {"failure": "failure", "gain_loss": "gain", "friction": "friction", "stuck": "stuck"}
PHASE_FIT_R2 = 0.9  # the gravity-gradient torque must explain 90 % of the commanded torque to set the orbit phase
PHASE_GAIN_RANGE = (0.8, 1.25)  # and match it in size: commands that are something else (a slew) do not
PHASE_MIN_ROWS = 30  # telemetry rows before the onset the fit needs


def telemetered_steps(t_s: np.ndarray, q_prog_ib: np.ndarray, after_s: float) -> list[tuple[float, list[float]]]:
    """Inertial programme steps (time after ``after_s``, q_ib) where the telemetered guidance quaternion changes."""
    q = quaternion.normalize(np.asarray(q_prog_ib, dtype=float))
    k0 = max(int(np.searchsorted(t_s, after_s, side="right")) - 1, 0)
    steps = [(0.0, q[k0].tolist())]
    turn = quaternion.angle(quaternion.multiply(quaternion.conjugate(q[k0:-1]), q[k0 + 1 :]))  # row k−1 → k
    for k in k0 + 1 + np.flatnonzero(np.all(np.isfinite(q[k0 + 1 :]), axis=1) & (turn > PROGRAM_STEP_RAD)):
        steps.append((float(t_s[k] - after_s), q[k].tolist()))
    return steps


def twin_at(
    base: Scenario,
    epoch_unix_s: float,
    t_s: float,
    q_ib: np.ndarray,
    omega_b: np.ndarray,
    wheel_speed_rad_s: np.ndarray,
    duration_s: float,
    program: tuple[np.ndarray, np.ndarray] | None = None,
    arg_latitude0_deg: float | None = None,
) -> Scenario:
    """``base`` restarted at ``t_s`` after the telemetry epoch with the telemetered state (seed 000 §7 twin).

    An inertial programme is taken from the telemetered guidance quaternions (``program`` = (t_s, q_prog_ib))
    when given, so a file need not begin where the scenario does; other programmes are shifted in time.
    ``arg_latitude0_deg``: the circular orbit's argument of latitude at the telemetry epoch, if known
    (:func:`orbit_phase_deg`; else the scenario's, as if the file began where the scenario does).
    """
    data = base.model_dump()
    stamp = np.datetime64(round((epoch_unix_s + t_s) * 1e9), "ns")
    data["orbit"]["epoch_utc"] = f"{stamp}Z"
    if base.orbit.kind in ("circular", "j2"):
        a = orbit.R_EARTH_M + base.orbit.altitude_m
        n = math.sqrt(orbit.MU_EARTH_M3_S2 / a**3)
        u0 = base.orbit.arg_latitude_deg if arg_latitude0_deg is None else arg_latitude0_deg
        data["orbit"]["arg_latitude_deg"] = (u0 + math.degrees(n * t_s)) % 360.0
    if program is not None and base.guidance.kind == "inertial":
        data["guidance"]["inertial_steps"] = telemetered_steps(program[0], program[1], t_s)
    else:
        data["guidance"] = shifted_guidance(data["guidance"], t_s)
    data["initial_q_ib"] = quaternion.normalize(np.asarray(q_ib, dtype=float)).tolist()
    data["initial_omega_b_rad_s"] = np.asarray(omega_b, dtype=float).tolist()
    for wheel, speed in zip(data["spacecraft"]["cluster"]["wheels"], wheel_speed_rad_s):
        wheel["initial_speed_rpm"] = float(speed) * 30.0 / math.pi
    data["duration_s"] = float(duration_s)
    data["output_dt_s"] = max(data["control_dt_s"], 1.0)
    data["initial_mode"] = None if base.initial_mode is None else base.initial_mode
    return Scenario.model_validate(data)


def orbit_phase_deg(base: Scenario, t_s: np.ndarray, q_ib: np.ndarray, wheel_torque_cmd_nm: np.ndarray) -> float | None:
    """Argument of latitude (deg) at ``t_s[0]`` of the base's circular orbit whose gravity-gradient torque
    (Wertz eq 17-38) at the telemetered attitude best explains the commanded wheel torques Σ a_p u_p (rows before
    the onset); None when it explains less than PHASE_FIT_R2 of them or differs in size (not in fine pointing).
    The torque repeats every half orbit, so the phase is found modulo 180°, which is all the twin needs of it."""
    inclination = base.orbit.inclination_deg
    if base.orbit.kind not in ("circular", "j2") or inclination is None or not base.gravity_gradient:
        return None
    if t_s.shape[0] < PHASE_MIN_ROWS:
        return None
    body = np.nan_to_num(wheel_torque_cmd_nm) @ np.asarray(engine.plant_params(base).wheel_axes_b).T
    inertia = np.asarray(base.spacecraft.inertia_kg_m2, dtype=float)
    t = t_s - t_s[0]

    def misfit(u0_deg: float) -> tuple[float, float]:
        r, _ = orbit.circular_orbit(t, base.orbit.altitude_m, inclination, base.orbit.raan_deg, u0_deg)
        gg = environment.gravity_gradient_torque_nm(r, q_ib, inertia)
        gain = float(np.sum(gg * body) / max(float(np.sum(gg * gg)), 1e-300))
        return float(np.sum((body - gain * gg) ** 2)), gain

    coarse = np.arange(0.0, 180.0, 1.0)
    u0 = float(coarse[int(np.argmin([misfit(u)[0] for u in coarse]))])
    fine = u0 + np.linspace(-1.0, 1.0, 41)
    u0 = float(fine[int(np.argmin([misfit(u)[0] for u in fine]))])
    residual, gain = misfit(u0)
    explained = 1.0 - residual / max(float(np.sum(body**2)), 1e-300)
    if explained < PHASE_FIT_R2 or not PHASE_GAIN_RANGE[0] <= gain <= PHASE_GAIN_RANGE[1]:
        return None
    return u0 % 180.0


def fault_specs(
    fault: str, wheel: int | list[int] | None, onset_s: float, magnitude: float | list[float | None] | None
) -> list[FaultSpec] | None:
    """Engine faults of a wheel hypothesis (1-based wheels, onset after the twin's epoch); None if not flyable."""
    names = fault.split("+")
    wheels = wheel if isinstance(wheel, list) else [wheel]
    mags = magnitude if isinstance(magnitude, list) else [magnitude]
    out = []
    for name, w, m in zip(names, wheels, mags):
        if name not in FAULT_TYPES or w is None:
            return None
        extra: dict[str, float] = {}
        if name == "gain_loss":
            extra["gain"] = float(m if m is not None else 0.5)
        elif name == "friction":
            extra["value"] = float(m if m is not None else 0.0)
        out.append(
            FaultSpec(target="wheel", index=int(w) - 1, type=FAULT_TYPES[name], onset_s=max(onset_s, 0.0), **extra)
        )
    return out


def replay_batch(
    base: Scenario,
    t_s: np.ndarray,
    epoch_unix_s: float,
    q_est_ib: np.ndarray,
    omega_b: np.ndarray,
    wheel_speed_rad_s: np.ndarray,
    wheel_torque_cmd_nm: np.ndarray,
    candidates: Sequence[list[FaultSpec]],
    start: int,
    stop: int,
    reference: int,
    q_prog_ib: np.ndarray | None = None,
) -> Scenario:
    """The replay's batch: the twin restarted at telemetry row ``start`` (:func:`twin_at`, the orbit phase from the
    commands before row ``reference`` for an inertial programme) flying to row ``stop - 1``, one variant ``h<i>``
    per candidate (faults, onsets after ``t_s[start]``) and the no-fault variant ``none`` last.

    The one home of the replay: the diagnosis scores its hypotheses on it (:func:`replay_scores`) and the
    simulated monitor flies a diagnosed hypothesis on it (both through ``sim_core.diagnosis._replay_batch``)."""
    duration = float(t_s[stop - 1] - t_s[start]) + 1.0
    program = None if q_prog_ib is None else (t_s, q_prog_ib)
    phase = None
    if program is not None and base.guidance.kind == "inertial":  # a file cut anywhere in the orbit
        phase = orbit_phase_deg(base, t_s[:reference], q_est_ib[:reference], wheel_torque_cmd_nm[:reference])
    twin = twin_at(
        base,
        epoch_unix_s,
        float(t_s[start]),
        q_est_ib[start],
        omega_b[start],
        wheel_speed_rad_s[start],
        duration,
        program,
        phase,
    )
    variants = [VariantSpec(name=f"h{i}", faults=f) for i, f in enumerate(candidates)]
    variants.append(VariantSpec(name="none"))
    return Scenario.model_validate({**twin.model_dump(), "variants": [v.model_dump() for v in variants]})


def replay_scores(
    batch: Scenario,
    t_s: np.ndarray,
    q_est_ib: np.ndarray,
    wheel_torque_cmd_nm: np.ndarray,
    start: int,
    stop: int,
    reference: int,
    torque_quantum_nm: float = 0.0,
    flyer: Callable[[Scenario], object] | None = None,
    correlation_s: float = 10.0,
) -> np.ndarray:
    """Log-likelihood of telemetry rows [start, stop) under each variant of the replay's ``batch``
    (:func:`replay_batch` from row ``start``: the candidates, then the no-fault variant last); the onboard FDIR
    flies if the batch's scenario does.

    Concentrated Gaussian likelihood (σ unknown, profiled out) of the command and attitude residuals:
    −(N/2) ln(MSE + σ₀²) per channel, with σ₀ the telemetry resolution (and the no-fault variant's
    mismatch before row ``reference``), N the independent samples of the best variant's residual in the
    channel (:func:`effective_samples`), at most span / ``correlation_s`` (the closed loop's settling time):
    a twin drifting slowly from the spacecraft is one error, not one per row.
    """
    traj = (flyer or engine.simulate)(batch)
    rel = t_s[start:stop] - t_s[start]
    k = np.clip(np.round(rel / batch.output_dt_s).astype(int), 0, traj.t_s.shape[0] - 1)  # type: ignore[attr-defined]
    u_twin = traj["wheel_torque_cmd_nm"][:, k]  # type: ignore[index]
    q_twin = traj["q_est_ib"][:, k]  # type: ignore[index]
    u_tm = wheel_torque_cmd_nm[start:stop]
    q_tm = q_est_ib[start:stop]
    att = np.stack([_small_angles(q_twin[v], q_tm) for v in range(q_twin.shape[0])])  # (V, n, 3)
    du = u_twin - u_tm[None]
    pre = max(reference - start, 2)
    sig_u = max(float(np.sqrt(np.nanmean(du[-1, :pre] ** 2))), torque_quantum_nm / math.sqrt(12.0), TORQUE_FLOOR_NM)
    sig_a = max(float(np.sqrt(np.nanmean(att[-1, :pre] ** 2))), ARCSEC_FLOOR * math.pi / 648000.0)
    cap = max((t_s[stop - 1] - t_s[reference]) / correlation_s, 1.0)
    mse_u = np.nanmean(du[:, pre:] ** 2, axis=(1, 2)) + sig_u**2
    mse_a = np.nanmean(att[:, pre:] ** 2, axis=(1, 2)) + sig_a**2
    best = int(np.argmin(np.log(mse_u) + np.log(mse_a)))  # what the best variant leaves is the twin's own mismatch
    n_u = min(cap, effective_samples(du[best, pre:]))
    n_a = min(cap, effective_samples(att[best, pre:]))
    log_likelihood: npt.NDArray[np.float64] = -0.5 * (n_u * np.log(mse_u) + n_a * np.log(mse_a))
    return log_likelihood


def effective_samples(residual: np.ndarray) -> float:
    """Independent samples in residual rows (n, channels) whose errors are AR(1) with the pooled lag-1
    autocorrelation ρ of the rows (about zero, so a constant offset counts as correlated): n (1 − ρ)/(1 + ρ),
    at least 1. A twin mismatch that drifts slowly (ρ → 1) is one error, however many rows it spans."""
    r = residual[np.all(np.isfinite(residual), axis=1)]
    if r.shape[0] < 3:
        return 1.0
    power = float(np.sum(r[:-1] ** 2) + np.sum(r[1:] ** 2))
    rho = float(np.clip(2.0 * np.sum(r[:-1] * r[1:]) / max(power, 1e-300), 0.0, 1.0))
    return max(float(r.shape[0]) * (1.0 - rho) / (1.0 + rho), 1.0)


def _small_angles(q_a: np.ndarray, q_b: np.ndarray) -> np.ndarray:
    """Rotation vector (rad) of conj(q_a) ∘ q_b, per row, small-angle (2 × vector part, hemisphere fixed)."""
    e = quaternion.multiply(quaternion.conjugate(q_a), q_b)
    rotvec: npt.NDArray[np.float64] = 2.0 * np.sign(e[:, :1] + 1e-300) * e[:, 1:]
    return rotvec
