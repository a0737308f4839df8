"""The onboard-equivalent closed loop in one compiled function: the whole block diagram of the ACS.

sensors (T_q) → estimator (T_q) → guidance (T_u) → control law (T_u) → allocation (T_u) →
actuators (zero-order hold, seed 000 eq 3) → plant (RK4 at dt, seed 000 eq 1), with the faults of the
variant applied where they act. One call flies one variant; :func:`run_batch` flies all of them in
parallel (one variant per thread, its own random stream seeded at its start, so results do not depend
on the thread count). Everything is plain float64/int64 arrays; :mod:`sim_core.engine` packs them.
"""

from __future__ import annotations

import os
from typing import NamedTuple

import numpy as np
from numba import njit

from sim_core import (
    allocation,
    control,
    environment,
    fdir,
    guidance,
    magnetic,
    mekf,
    modes,
    sensors,
)
from sim_core import faults as faults_mod
from sim_core.faults import T_EARTH, T_GYRO, T_MAG, T_SUN
from sim_core.integrators import rk4_step_into
from sim_core.quaternion import conjugate_rotate_1, multiply_1
from sim_core.spacecraft import PlantArrays

# Guidance kinds.
PROGRAM_INERTIAL, PROGRAM_ROUTE = 0, 1
# Control laws.
LAW_SEED000, LAW_MRP_FEEDBACK, LAW_QUATERNION_PD = 0, 1, 2
# Estimators.
ESTIMATOR_TRUTH, ESTIMATOR_STAR_TRACKER, ESTIMATOR_MEKF = 0, 1, 2

# Fault codes live in sim_core.faults (re-exported here for the record's readers).
TARGET_CODES, TYPE_CODES, FAULT_COLUMNS = faults_mod.TARGET_CODES, faults_mod.TYPE_CODES, faults_mod.FAULT_COLUMNS

# Attitude sensors used when the star tracker gives no sample (failed, blinded or rejected by FDIR).
EARTH_SENSOR_SIGMA_RAD = np.radians(0.05)  # static infrared earth sensor class (seed 002 eq 14 gives none)
STAR_RESET_SIGMA_RAD = np.radians(1.0)  # attitude uncertainty re-opened after a wheel is isolated (a seizure's kick)
MAG_DIRECTION_FLOOR_RAD = np.radians(0.5)  # field-model error in direction (IGRF vs crustal/external fields)

# Event codes (sim_core.trajectory.EVENT_NAMES).
EV_MODE_CHANGE, EV_ALLOCATION, EV_MD_SATURATED = 1, 7, 8

# Output channels of the float record (columns of ``rec``), per sample.
R_Q, R_W, R_QE, R_WE, R_QP, R_WP = 0, 4, 7, 11, 15, 19
R_MD, R_TORQUE, R_R, R_OBS, R_STATUS, R_FAULTS = 22, 25, 28, 31, 32, 33
R_MODE = 34  # onboard mode (sim_core.modes codes; −1 when the mode machine is off)
R_WHEELS = 35  # then: speeds (nw), commands (nw), delivered torques (nw), availability after FDIR (nw)

# Per-variant FDIR configuration (sim_core.fdir): on/off, bound on the error of a change of the
# estimated body rate (rad/s), star-tracker χ²(3) limit, Gaussian threshold in σ, bound on the
# external torque the loop does not model (N·m).
FD_ON, FD_RATE_NOISE, FD_NIS_MAX, FD_N_SIGMA, FD_DIST_TORQUE = range(5)
FDIR_CONFIG_SIZE = 5


# ``times`` entries of the onboard mode machine (sim_core.modes), used when TM_ON is non-zero.
TM_ON, TM_INITIAL, TM_BDOT_GAIN, TM_THRESHOLDS = 13, 14, 15, 16
T_GYRO_COMPENSATION = 21  # ``times`` entry: add ω × (Jω + A h) to seed 000's law (7) when non-zero
SUN_AXIS_B = np.array([0.0, 0.0, 1.0])  # solar-array normal the Sun/safe mode points at the Sun
WHEEL_CAPTURE_RAD_S = np.radians(1.0)  # below this the wheels take over rate damping from B-dot
RATE_DAMPING_TAU_S = 20.0  # time constant of the wheel rate brake (10 T_u at T_u = 2 s)
FINE_POINTING_RAD = np.radians(2.0)  # ORF mode hands over from the acquisition PD to the scenario's law
ACQUISITION_OMEGA_RAD_S = 0.02  # Sun/ORF acquisition bandwidth: slews ≤ 0.57 °/s, under the 1 °/s rate-lost limit
UNLOADING_GAIN_PER_S = 1e-3  # seed 003 eq 29 unloading gain k: the cluster momentum decays in ~1/k s


SUN_SENSOR_COS_HALF_FOV = -1.0  # coarse Sun sensors on every face: the whole sphere, blind only in eclipse


class SeedModels(NamedTuple):
    """Seed models flown when set (zero switches each off): residual dipole m_res (A·m², torque m_res × B),
    gyro Markov drift (stationary σ, τ; seed 002 eq 13), Sun sensor noise (rad; seed 003 SS)."""

    residual_dipole_am2: np.ndarray
    gyro_markov_sigma_rad_s: float
    gyro_markov_tau_s: float
    sun_sensor_sigma_rad: float


def record_width(n_wheels: int) -> int:
    """Number of float channels per output sample for n_wheels wheels."""
    return R_WHEELS + 4 * n_wheels


@njit(cache=True)
def hermite_orbit_into(
    table: np.ndarray, t0: float, step: float, t: float, r: np.ndarray, v: np.ndarray, acc: np.ndarray
) -> None:
    """ECI r, v, a at t from a table of rows (r, v, a) every ``step`` s by cubic Hermite interpolation, in place."""
    u = (t - t0) / step
    i = min(max(int(np.floor(u)), 0), table.shape[0] - 2)
    s = u - i
    s2, s3 = s * s, s * s * s
    h00, h10, h01, h11 = 2 * s3 - 3 * s2 + 1, s3 - 2 * s2 + s, -2 * s3 + 3 * s2, s3 - s2
    d00, d10, d01, d11 = (6 * s2 - 6 * s) / step, 3 * s2 - 4 * s + 1, (-6 * s2 + 6 * s) / step, 3 * s2 - 2 * s
    for j in range(3):
        r[j] = (
            h00 * table[i, j] + h10 * step * table[i, 3 + j] + h01 * table[i + 1, j] + h11 * step * table[i + 1, 3 + j]
        )
        v[j] = d00 * table[i, j] + d10 * table[i, 3 + j] + d01 * table[i + 1, j] + d11 * table[i + 1, 3 + j]
        acc[j] = (1 - s) * table[i, 6 + j] + s * table[i + 1, 6 + j]


@njit(cache=True)
def linear_into(table: np.ndarray, t0: float, step: float, t: float, out: np.ndarray) -> None:
    """Row of ``table`` (sampled every ``step`` s from t0) linearly interpolated at t, into ``out``."""
    u = (t - t0) / step
    i = min(max(int(np.floor(u)), 0), table.shape[0] - 2)
    s = u - i
    for j in range(out.shape[0]):
        out[j] = (1.0 - s) * table[i, j] + s * table[i + 1, j]


@njit(cache=True)
def conjugate_rotate_into(x: np.ndarray, v: np.ndarray, out: np.ndarray) -> None:
    """Λ̃ ∘ v ∘ Λ with Λ = x[0:4] (inertial → body), written into ``out``."""
    q0, q1, q2, q3 = x[0], -x[1], -x[2], -x[3]
    tx = 2.0 * (q2 * v[2] - q3 * v[1])
    ty = 2.0 * (q3 * v[0] - q1 * v[2])
    tz = 2.0 * (q1 * v[1] - q2 * v[0])
    out[0] = v[0] + q0 * tx + q2 * tz - q3 * ty
    out[1] = v[1] + q0 * ty + q3 * tx - q1 * tz
    out[2] = v[2] + q0 * tz + q1 * ty - q2 * tx


@njit(cache=True)
def add_gravity_gradient_into(x: np.ndarray, r_eci: np.ndarray, inertia: np.ndarray, ext: np.ndarray) -> None:
    """ext += 3μ/r⁵ r_b × (J r_b) (environment.gravity_gradient_torque_1) without allocation."""
    r_b = np.empty(3)
    conjugate_rotate_into(x, r_eci, r_b)
    tq = environment.gravity_gradient_torque_1(r_b, inertia)
    ext[0] += tq[0]
    ext[1] += tq[1]
    ext[2] += tq[2]


@njit(cache=True)
def limit_motor_torque_into(
    m: np.ndarray, x: np.ndarray, i0: int, inertia: np.ndarray, max_torque: np.ndarray, max_momentum: np.ndarray
) -> None:
    """Seed 000 eq (2) on the delivered torques in place (as wheels.limited_motor_torque_1)."""
    for p in range(m.shape[0]):
        mm = min(max_torque[p], max(-max_torque[p], m[p]))
        h = inertia[p] * x[i0 + p]
        if (h >= max_momentum[p] and mm > 0.0) or (h <= -max_momentum[p] and mm < 0.0):
            mm = 0.0
        m[p] = mm


@njit(cache=True)
def _program_1(
    kind: int,
    steps_t: np.ndarray,
    steps_q: np.ndarray,
    route: np.ndarray,
    t: float,
    t0_unix: float,
    r: np.ndarray,
    v: np.ndarray,
    a: np.ndarray,
    c_pn: np.ndarray,
    dut1: float,
):
    """Λ^p, ω^p, ω̇^p (program axes) and the observing flag at t (seed 000 §2, seed 001)."""
    if kind == PROGRAM_INERTIAL:
        k = 0
        while k + 1 < steps_t.shape[0] and t >= steps_t[k + 1]:
            k += 1
        return steps_q[k].copy(), np.zeros(3), np.zeros(3), False
    return guidance.route_1(route, t0_unix + t, r, v, a, c_pn, dut1)


@njit(cache=True)
def _earth_sensor_nadir_1(faults: np.ndarray, t: float, x: np.ndarray, r: np.ndarray) -> tuple[np.ndarray, bool]:
    """Nadir direction in body axes from an earth-sensor sample (roll, pitch; seed 002 eq 14) with the
    variant's earth-sensor faults; False if the sensor has failed."""
    roll, pitch = sensors.nadir_roll_pitch_1(x[0:4], r)
    normal = np.random.standard_normal(2)
    angles = np.zeros(3)
    angles[0] = roll + EARTH_SENSOR_SIGMA_RAD * normal[0]
    angles[1] = pitch + EARTH_SENSOR_SIGMA_RAD * normal[1]
    ok = faults_mod.sensor_faults_1(faults, T_EARTH, t, angles, angles, EARTH_SENSOR_SIGMA_RAD, np.zeros(3))
    nadir = np.empty(3)
    nadir[0] = np.cos(angles[1]) * np.cos(angles[0])
    nadir[1] = -np.sin(angles[1])
    nadir[2] = np.cos(angles[1]) * np.sin(angles[0])
    return nadir, ok


@njit(cache=True)
def _earth_and_field_update_1(
    nadir: np.ndarray,
    earth_ok: bool,
    r: np.ndarray,
    b_eci: np.ndarray,
    mag: np.ndarray,
    mag_noise: float,
    q_est: np.ndarray,
    bias_est: np.ndarray,
    p_cov: np.ndarray,
) -> None:
    """Without a star-tracker sample: MEKF updates on the earth sensor's nadir (seed 002 eq 14) and on
    the magnetometer's field direction (seed 003 §3.2)."""
    if earth_ok:
        mekf.mekf_vector_update_1(q_est, bias_est, p_cov, nadir, -r, EARTH_SENSOR_SIGMA_RAD)
    b_norm = np.sqrt(b_eci[0] ** 2 + b_eci[1] ** 2 + b_eci[2] ** 2)
    if mag_noise > 0.0 and b_norm > 0.0:
        mekf.mekf_vector_update_1(q_est, bias_est, p_cov, mag, b_eci, mag_noise / b_norm + MAG_DIRECTION_FLOOR_RAD)


@njit(cache=True)
def _sun_direction_1(
    faults: np.ndarray,
    t: float,
    x: np.ndarray,
    q_est: np.ndarray,
    sun_eci: np.ndarray,
    r: np.ndarray,
    sigma: float,
    frozen: np.ndarray,
) -> np.ndarray:
    """Sun direction in body axes from the Sun sensor (sensors.sun_sensor_1) under its faults; in eclipse
    or when failed, the ephemeris Sun seen through the attitude estimate."""
    normals = np.random.standard_normal(3)
    s_b, ok = sensors.sun_sensor_1(x[0:4], sun_eci, r, SUN_AXIS_B, SUN_SENSOR_COS_HALF_FOV, sigma, normals)
    ok = faults_mod.sensor_faults_1(faults, T_SUN, t, s_b, frozen, sigma, normals) and ok
    frozen[:] = s_b
    n = np.sqrt(s_b @ s_b)
    if not ok or n == 0.0:
        s_b = conjugate_rotate_1(q_est, sun_eci)
        n = np.sqrt(s_b @ s_b)
    return s_b / n


@njit(cache=True)
def _event(ev: np.ndarray, n_ev: np.ndarray, t: float, code: int, arg: int) -> None:
    if n_ev[0] < ev.shape[0]:
        ev[n_ev[0], 0], ev[n_ev[0], 1], ev[n_ev[0], 2] = t, code, arg
        n_ev[0] += 1


@njit(cache=True)
def _angle_between_1(a: np.ndarray, b: np.ndarray) -> float:
    """Angle (rad) between two non-zero vectors."""
    c = np.cross(a, b)
    return np.arctan2(np.sqrt(c @ c), a @ b)


@njit(cache=True)
def _attitude_difference_1(q_a: np.ndarray, q_b: np.ndarray) -> float:
    """Rotation angle (rad, in [0, π]) between two attitudes."""
    d = abs(q_a[0] * q_b[0] + q_a[1] * q_b[1] + q_a[2] * q_b[2] + q_a[3] * q_b[3])
    return 2.0 * np.arccos(min(d, 1.0))


@njit(cache=True)
def _sun_safe_program_1(q_est: np.ndarray, s_b: np.ndarray) -> np.ndarray:
    """One-axis Sun orientation (seed 001): the attitude nearest q_est that puts SUN_AXIS_B on the Sun
    direction s_b (unit, body axes, as the Sun sensor sees it)."""
    axis = np.cross(SUN_AXIS_B, s_b)
    n = np.sqrt(axis @ axis)
    ang = np.arctan2(n, SUN_AXIS_B @ s_b)
    dq = np.array([1.0, 0.0, 0.0, 0.0])
    if n > 1e-12:
        dq[0] = np.cos(0.5 * ang)
        dq[1:] = np.sin(0.5 * ang) * axis / n
    return multiply_1(q_est, dq)


@njit(cache=True)
def _mode_program_1(mode: int, q_est, r, v, a, sun_b, q_p, w_p, wd_p) -> None:
    """Program of the Sun/safe and ORF modes (seed 001 one- and three-axis orientation), in place."""
    if mode == modes.MODE_SUN_SAFE:
        q_p[:] = _sun_safe_program_1(q_est, sun_b)
        w_p[:] = 0.0
        wd_p[:] = 0.0
    else:
        q_o, w_o, wd_o = guidance.orf_hold_1(np.array([1.0, 0.0, 0.0, 0.0]), r, v, a)
        q_p[:] = q_o
        w_p[:] = w_o
        wd_p[:] = wd_o


@njit(cache=True)
def _rate_damping_1(
    mode,
    w_est,
    mag,
    mag_prev,
    have_mag_prev,
    t_u,
    bdot_gain,
    md_max,
    p,
    available,
    h_wheels,
    alloc_params,
    wheel_limits,
    body_torque,
    cmd,
    dipole,
    wheel_out,
    dip_out,
) -> None:
    """Rate damping (seed 001 initial mode, seed 003 eq 29–30): B-dot above 1 °/s or in the fault mode;
    below it the wheels brake the body (−J ω / RATE_DAMPING_TAU_S) while the rods unload the cluster."""
    body_torque[:] = 0.0
    cmd[:] = 0.0
    dipole[:] = 0.0
    rate = np.sqrt(w_est @ w_est)
    if mode == modes.MODE_FAULT or rate > WHEEL_CAPTURE_RAD_S or np.sum(available) < 2:
        if have_mag_prev:
            dipole[:] = control.bdot_dipole_step(mag, mag_prev, t_u, bdot_gain, md_max)
        return
    body_torque[:] = -(p.inertia @ w_est) / RATE_DAMPING_TAU_S
    allocation.allocate_1(body_torque, p.wheel_axes, available, h_wheels, mag, alloc_params, wheel_out, dip_out)
    for w in range(cmd.shape[0]):
        cmd[w] = control.wheel_torque_command_1(wheel_out[w], wheel_limits[2, w], wheel_limits[0, w])
    dipole[:] = control.unloading_dipole_step(mag, p.wheel_axes @ h_wheels, np.zeros(3), UNLOADING_GAIN_PER_S, md_max)


@njit(cache=True, nogil=True)
def fly_variant(
    x0,
    p: PlantArrays,
    truth: PlantArrays,
    wheel_limits,
    steps,
    times,
    program,
    orbit,
    env,
    gains,
    est,
    alloc_params,
    available,
    faults,
    fdir_cfg,
    seed,
    rec,
    ev,
    n_ev,
    shared,
    slot,
    models: SeedModels,
) -> None:
    """Fly one variant and fill its output record ``rec`` (samples × channels) and events ``ev``.

    ``p``: the plant the onboard software models (control law, allocation, FDIR); ``truth``: the plant
    the dynamics fly (the same arrays unless the scenario states a truth that differs).

    ``wheel_limits``: rows max torque, max momentum, torque quantum, per wheel.
    ``steps``: [n_steps, meas_every, ctrl_every, out_every, law_kind, estimator_kind, program_kind,
    gravity_gradient_on, mrp_law_type]; ``times``: [dt, t0_unix, md_max, dut1, st_sigma,
    gyro_noise, mag_noise, tach_quantum, pd_kp, pd_kd, mrp_k, mrp_p, gyro_tau].
    ``program``: (steps_t, steps_q, route); ``orbit``: (table, t0, step); ``env``: (B table, t0,
    step, c_pn); ``est``: (true gyro bias (3,), initial MEKF covariance (6, 6)); ``fdir_cfg``: FD_*
    entries (onboard FDIR of :mod:`sim_core.fdir`: wheels each T_u, star tracker, gyro drift and
    magnetometer each T_q with the MEKF; it may drop wheels from ``available``). ``shared[0]`` non-zero
    cancels the run (checked each T_u); ``models``: the :class:`SeedModels` switched on.
    ``shared[slot]`` receives the number of steps done, for progress reports from another thread.
    """
    np.random.seed(seed)
    n_steps, meas_every, ctrl_every, out_every = steps[0], steps[1], steps[2], steps[3]
    law_kind, est_kind, prog_kind, gg_on, mrp_law = steps[4], steps[5], steps[6], steps[7], steps[8]
    dt, t0_unix, md_max, dut1 = times[0], times[1], times[2], times[3]
    st_sigma, gyro_noise, mag_noise, tach_q = times[4], times[5], times[6], times[7]
    pd_kp, pd_kd, mrp_k, mrp_p = times[8], times[9], times[10], times[11]
    steps_t, steps_q, route = program
    orbit_tab, orbit_t0, orbit_step = orbit
    b_tab, b_t0, b_step, c_pn = env
    nw = p.wheel_inertia.shape[0]
    nq = p.flex_mass.shape[0]
    n = x0.shape[0]

    x = x0.copy()
    m_res = models.residual_dipole_am2
    res_on = m_res[0] != 0.0 or m_res[1] != 0.0 or m_res[2] != 0.0
    markov_on = models.gyro_markov_sigma_rad_s > 0.0
    markov_decay = np.full(3, np.exp(-times[0] * steps[1] / models.gyro_markov_tau_s))
    markov_step = models.gyro_markov_sigma_rad_s * np.sqrt(1.0 - markov_decay**2)
    gyro_drift = models.gyro_markov_sigma_rad_s * np.random.standard_normal(3) if markov_on else np.zeros(3)
    gyro_noise3 = np.full(3, times[5])
    sun_frozen = np.zeros(3)
    total_dipole = np.zeros(3)
    work = np.zeros((6, n + 3 + nq + nw))
    j_inv = np.linalg.inv(truth.inertia)
    base_friction = p.friction.copy()
    friction = truth.friction.copy()
    plant = PlantArrays(
        truth.inertia,
        truth.mass_inv,
        truth.wheel_axes,
        truth.wheel_inertia,
        friction,
        truth.flex_coupling,
        truth.flex_mass,
        truth.flex_freq,
        truth.flex_decrement,
    )
    g = np.zeros(3)  # lead-lag state of seed 000 eq (8)
    cmd = np.zeros(nw)
    frozen_cmd = np.zeros(nw)
    delivered = np.zeros(nw)
    dipole = np.zeros(3)
    body_torque = np.zeros(3)
    frozen_torque = np.zeros(3)
    available = available.copy()
    wheel_out = np.zeros(nw)
    dip_out = np.zeros(3)
    ext = np.zeros(3)
    q_est = x[0:4].copy()
    w_est = x[4:7].copy()
    bias_est = np.zeros(3)
    gyro_bias, p_cov0 = est
    p_cov = p_cov0.copy()
    st_frozen = q_est.copy()
    gyro_frozen = np.zeros(3)
    w_meas = np.zeros(3)
    q_p = x[0:4].copy()
    w_p = np.zeros(3)
    wd_p = np.zeros(3)
    observing = False
    status = 0
    fault_state = np.zeros(faults.shape[0], dtype=np.bool_)
    mag = np.zeros(3)
    out_i = 0
    fdir_on = fdir_cfg[FD_ON] != 0.0
    rate_noise, nis_max, n_sigma = fdir_cfg[FD_RATE_NOISE], fdir_cfg[FD_NIS_MAX], fdir_cfg[FD_N_SIGMA]
    wheel_fd = fdir.wheel_state_1(nw)
    star_fd = np.zeros(fdir.STAR_STATE_SIZE)
    star_fd[0:4] = np.nan
    gyro_fd = np.zeros(fdir.GYRO_STATE_SIZE)
    gyro_fd[fdir.GS_T0] = np.nan
    gyro_fd[fdir.GS_SIGMA_U] = times[12]
    sigma_u = times[12]
    mag_fd = np.full(fdir.MAG_STATE_SIZE, np.nan)
    earth_fd = np.zeros(fdir.EARTH_STATE_SIZE)
    w_prev = np.zeros(3)
    md_torque = np.zeros(3)
    j_eff = p.inertia.copy()
    for w in range(nw):
        for i in range(3):
            for c in range(3):
                j_eff[i, c] -= p.wheel_axes[i, w] * p.wheel_inertia[w] * p.wheel_axes[c, w]
    j_eff_inv = np.linalg.inv(j_eff)
    decouple = fdir.wheel_decoupling_1(p.wheel_axes, p.wheel_inertia, j_eff_inv)

    r, v, a, b_eci = np.empty(3), np.empty(3), np.empty(3), np.empty(3)
    hermite_orbit_into(orbit_tab, orbit_t0, orbit_step, 0.0, r, v, a)
    linear_into(b_tab, b_t0, b_step, 0.0, b_eci)
    b_body = conjugate_rotate_1(x[0:4], b_eci)
    flags = 0
    md_on = False
    modes_on = times[TM_ON] != 0.0
    mode = int(times[TM_INITIAL]) if modes_on else -1
    mode_state = np.full(modes.STATE_SIZE, np.nan)
    mode_state[modes.S_MODE], mode_state[modes.S_ENTERED] = max(mode, 0), 0.0
    mode_thresholds = times[TM_THRESHOLDS : TM_THRESHOLDS + 5].copy()
    mag_prev = np.zeros(3)
    have_mag_prev = False
    j_max = max(p.inertia[0, 0], p.inertia[1, 1], p.inertia[2, 2])
    acq_kp = j_max * ACQUISITION_OMEGA_RAD_S**2  # seed 002 eq 18 PD for the large-angle acquisitions
    acq_kd = 2.0 * j_max * ACQUISITION_OMEGA_RAD_S  # steady slew rate ≤ kp/kd = ω_n/2 per unit error
    attitude_valid = True
    for k in range(n_steps):
        t = k * dt
        control_tick = k % ctrl_every == 0
        if gg_on or md_on or control_tick or k % meas_every == 0 or k % out_every == 0:
            hermite_orbit_into(orbit_tab, orbit_t0, orbit_step, t, r, v, a)
        if md_on or res_on or k % meas_every == 0:
            linear_into(b_tab, b_t0, b_step, t, b_eci)
            conjugate_rotate_into(x, b_eci, b_body)
        if faults.shape[0] > 0:
            flags = faults_mod.fault_transitions_1(faults, t, fault_state, ev, n_ev)
            if flags < 0:
                flags = -flags - 1
                frozen_cmd[:] = cmd
                frozen_torque[:] = body_torque
                gyro_frozen[:] = w_meas

        if k % meas_every == 0:
            normals = np.random.standard_normal(6)
            drift_normals = np.random.standard_normal(3) if markov_on else np.zeros(3)
            w_meas, _ = sensors.gyro_1(
                x[4:7],
                gyro_bias,
                gyro_drift,
                gyro_noise3,
                markov_decay,
                markov_step,
                np.inf,
                np.concatenate((normals[0:3], drift_normals)),
            )
            gyro_ok = faults_mod.sensor_faults_1(faults, T_GYRO, t, w_meas, gyro_frozen, gyro_noise, normals[0:3])
            sig3 = np.full(3, st_sigma)
            q_m, st_ok = sensors.star_tracker_1(x[0:4], x[4:7], sig3, 1e9, normals[3:6])
            st_ok = faults_mod.star_tracker_faults_1(faults, t, q_m, st_frozen, st_sigma, normals[3:6]) and st_ok
            mag[:] = b_body + mag_noise * np.random.standard_normal(3)
            faults_mod.sensor_faults_1(faults, T_MAG, t, mag, mag, mag_noise, normals[0:3])
            if fdir_on:
                fdir.magnetometer_check_1(
                    mag_fd, mag, conjugate_rotate_1(q_est, b_eci), mag_noise, n_sigma, ev, n_ev, t
                )
            if est_kind == ESTIMATOR_TRUTH:
                q_est[:] = x[0:4]
                w_est[:] = x[4:7]
            elif est_kind == ESTIMATOR_STAR_TRACKER:
                if st_ok:
                    q_est[:] = q_m
                if gyro_ok:
                    w_est[:] = w_meas
            else:
                if k > 0 and gyro_ok:
                    # mean of the samples bracketing the step: the held sample's ½ ω̇ T_q² error would
                    # make the filter overconfident in manoeuvres (and the FDIR innovation test with it)
                    mekf.mekf_propagate_1(
                        q_est,
                        bias_est,
                        p_cov,
                        0.5 * (w_meas + w_prev),
                        meas_every * dt,
                        gyro_noise * np.sqrt(meas_every * dt),
                        sigma_u,
                    )
                w_prev[:] = w_meas
                st_raw_ok = st_ok
                if fdir_on and st_ok:
                    st_scale = fdir.star_tracker_check_1(
                        star_fd, q_est, p_cov, q_m, sig3, nis_max, gyro_fd[fdir.GS_ISOLATED] != 0.0, ev, n_ev, t
                    )
                    st_ok = st_scale > 0.0
                    sig3 *= max(st_scale, 1.0)
                if fdir_on and gyro_ok:
                    sigma_u = fdir.gyro_drift_step_1(
                        gyro_fd,
                        t,
                        w_meas,
                        meas_every * dt,
                        q_m,
                        st_ok,
                        st_sigma,
                        gyro_noise,
                        times[12],
                        n_sigma,
                        ev,
                        n_ev,
                    )
                if not st_ok:
                    nadir, earth_ok = _earth_sensor_nadir_1(faults, t, x, r)
                    if fdir_on and earth_ok:
                        earth_ok = fdir.earth_sensor_check_1(
                            earth_fd, q_est, p_cov, nadir, -r, EARTH_SENSOR_SIGMA_RAD, ev, n_ev, t
                        )
                    if fdir_on and earth_ok and st_raw_ok:
                        st_ok = fdir.star_readmit_1(
                            star_fd, q_est, q_m, p_cov, nadir, -r, EARTH_SENSOR_SIGMA_RAD, n_sigma, ev, n_ev, t
                        )
                    if not st_ok:
                        _earth_and_field_update_1(nadir, earth_ok, r, b_eci, mag, mag_noise, q_est, bias_est, p_cov)
                if st_ok:
                    mekf.mekf_update_1(q_est, bias_est, p_cov, q_m, sig3)
                attitude_valid = st_ok
                w_est[:] = w_meas - bias_est

        if k % ctrl_every == 0:
            shared[slot] = k
            if shared[0] != 0:
                break
            q_p, w_p, wd_p, observing = _program_1(prog_kind, steps_t, steps_q, route, t, t0_unix, r, v, a, c_pn, dut1)
            if modes_on:
                q_orf, _, _ = guidance.orf_hold_1(np.array([1.0, 0.0, 0.0, 0.0]), r, v, a)
                sun_b = _sun_direction_1(
                    faults,
                    t,
                    x,
                    q_est,
                    environment.sun_position_1(t0_unix + t),
                    r,
                    models.sun_sensor_sigma_rad,
                    sun_frozen,
                )
                new_mode = modes.mode_step_1(
                    mode_state,
                    mode_thresholds,
                    t,
                    np.sqrt(w_est @ w_est),
                    attitude_valid,
                    _angle_between_1(SUN_AXIS_B, sun_b),
                    _attitude_difference_1(q_est, q_orf),
                    True,
                    np.sum(available) < 2,
                    False,
                )
                if new_mode != mode:
                    _event(ev, n_ev, t, EV_MODE_CHANGE, new_mode)
                    g[:] = 0.0
                    mode = new_mode
                if mode == modes.MODE_SUN_SAFE or mode == modes.MODE_ORF:
                    _mode_program_1(mode, q_est, r, v, a, sun_b, q_p, w_p, wd_p)
            speeds = x[7 + 2 * nq : 7 + 2 * nq + nw].copy()
            if tach_q > 0.0:
                speeds = tach_q * np.floor(speeds / tach_q + 0.5)
            h_wheels = p.wheel_inertia * speeds
            if fdir_on:
                n_before = np.sum(available)
                fdir.wheel_check_1(
                    wheel_fd,
                    speeds,
                    w_est,
                    p.wheel_inertia,
                    wheel_limits[1],
                    base_friction,
                    tach_q,
                    ctrl_every * dt,
                    decouple,
                    available,
                    ev,
                    n_ev,
                    t,
                )
                if est_kind == ESTIMATOR_MEKF and np.sum(available) < n_before:
                    fdir.star_reset_1(star_fd, p_cov, STAR_RESET_SIGMA_RAD)
            coarse = mode == modes.MODE_SUN_SAFE or (
                mode == modes.MODE_ORF and _attitude_difference_1(q_est, q_p) > FINE_POINTING_RAD
            )
            if modes_on and coarse:
                body_torque = control.quaternion_pd_step(
                    q_est, w_est, q_p, w_p, acq_kp, acq_kd
                ) + control.gyroscopic_torque_1(w_est, p.inertia, p.wheel_axes @ h_wheels)
            elif law_kind == LAW_SEED000:
                body_torque = control.digital_law_step(q_est, w_est, q_p, w_p, wd_p, g, p.inertia, gains)
                if times[T_GYRO_COMPENSATION] != 0.0:
                    body_torque += control.gyroscopic_torque_1(w_est, p.inertia, p.wheel_axes @ h_wheels)
            elif law_kind == LAW_MRP_FEEDBACK:
                qpc = q_p.copy()
                qpc[1:] = -qpc[1:]
                e = multiply_1(qpc, q_est)
                if e[0] < 0.0:
                    e = -e
                sigma = e[1:] / (1.0 + e[0])
                w_rn_b = conjugate_rotate_1(e, w_p)
                wd_rn_b = conjugate_rotate_1(e, wd_p)
                body_torque = control.mrp_feedback_step(
                    sigma,
                    w_est - w_rn_b,
                    w_rn_b,
                    wd_rn_b,
                    p.inertia,
                    p.wheel_axes,
                    p.wheel_inertia,
                    speeds,
                    available,
                    mrp_k,
                    mrp_p,
                    mrp_law,
                )
            else:
                body_torque = control.quaternion_pd_step(q_est, w_est, q_p, w_p, pd_kp, pd_kd)
            faults_mod.controller_faults_1(faults, t, body_torque, frozen_torque)
            status = allocation.allocate_1(
                body_torque, p.wheel_axes, available, h_wheels, mag, alloc_params, wheel_out, dip_out
            )
            for w in range(nw):
                cmd[w] = control.wheel_torque_command_1(wheel_out[w], wheel_limits[2, w], wheel_limits[0, w])
            dipole[:] = dip_out
            faults_mod.rod_faults_1(faults, t, dipole)
            for i in range(3):
                dipole[i] = min(max(dipole[i], -md_max), md_max)
            if modes_on and (mode == modes.MODE_SUN_SAFE or mode == modes.MODE_ORF) and status == 0:
                # continuous magnetic unloading of the cluster momentum (seed 003 eq 29)
                dipole[:] = control.unloading_dipole_step(
                    mag, p.wheel_axes @ h_wheels, np.zeros(3), UNLOADING_GAIN_PER_S, md_max
                )
            if modes_on and (mode == modes.MODE_RATE_DAMPING or mode == modes.MODE_FAULT):
                _rate_damping_1(
                    mode,
                    w_est,
                    mag,
                    mag_prev,
                    have_mag_prev,
                    ctrl_every * dt,
                    times[TM_BDOT_GAIN],
                    md_max,
                    p,
                    available,
                    h_wheels,
                    alloc_params,
                    wheel_limits,
                    body_torque,
                    cmd,
                    dipole,
                    wheel_out,
                    dip_out,
                )
            mag_prev[:] = mag
            have_mag_prev = True
            md_on = dipole[0] != 0.0 or dipole[1] != 0.0 or dipole[2] != 0.0
            if fdir_on:
                md_torque[0] = dipole[1] * mag[2] - dipole[2] * mag[1]
                md_torque[1] = dipole[2] * mag[0] - dipole[0] * mag[2]
                md_torque[2] = dipole[0] * mag[1] - dipole[1] * mag[0]
                fdir.wheel_hold_1(
                    wheel_fd,
                    speeds,
                    w_est,
                    p.wheel_axes,
                    cmd,
                    p.wheel_inertia,
                    wheel_limits[0],
                    wheel_limits[1],
                    base_friction,
                    p.inertia,
                    j_eff_inv,
                    md_torque,
                    fdir_cfg[FD_DIST_TORQUE],
                    rate_noise,
                    ctrl_every * dt,
                )

        if k % out_every == 0 and out_i < rec.shape[0]:
            row = rec[out_i]
            row[R_Q : R_Q + 4] = x[0:4]
            row[R_W : R_W + 3] = x[4:7]
            row[R_QE : R_QE + 4] = q_est
            row[R_WE : R_WE + 3] = w_est
            q_now, w_now, _, obs_now = _program_1(prog_kind, steps_t, steps_q, route, t, t0_unix, r, v, a, c_pn, dut1)
            row[R_QP : R_QP + 4] = q_now
            e = multiply_1(np.array([q_now[0], -q_now[1], -q_now[2], -q_now[3]]), x[0:4])
            row[R_WP : R_WP + 3] = conjugate_rotate_1(e, w_now)
            row[R_MD : R_MD + 3] = dipole
            row[R_TORQUE : R_TORQUE + 3] = body_torque
            row[R_R : R_R + 3] = r
            row[R_OBS] = 1.0 if obs_now else 0.0
            row[R_STATUS] = status
            row[R_FAULTS] = flags
            row[R_MODE] = mode
            row[R_WHEELS : R_WHEELS + nw] = x[7 + 2 * nq : 7 + 2 * nq + nw]
            row[R_WHEELS + nw : R_WHEELS + 2 * nw] = cmd
            row[R_WHEELS + 2 * nw : R_WHEELS + 3 * nw] = delivered
            for w in range(nw):
                row[R_WHEELS + 3 * nw + w] = 1.0 if available[w] else 0.0
            out_i += 1

        faults_mod.wheel_commands_1(faults, t, cmd, frozen_cmd, delivered)
        limit_motor_torque_into(delivered, x, 7 + 2 * nq, p.wheel_inertia, wheel_limits[0], wheel_limits[1])
        if faults.shape[0] > 0:
            faults_mod.extra_friction_1(faults, t, friction, base_friction)
        ext[:] = 0.0
        if md_on or res_on:
            total_dipole[:] = dipole + m_res
            ext[:] = magnetic.magnetic_torque_1(total_dipole, b_body)
        if gg_on:
            add_gravity_gradient_into(x, r, truth.inertia, ext)
        rk4_step_into(x, dt, delivered, ext, plant, work, x)
        if faults.shape[0] > 0:
            faults_mod.lock_stuck_wheels_1(faults, t + dt, x, plant, j_inv)
    else:
        shared[slot] = n_steps


def run_batch(
    x0,
    p,
    truth,
    wheel_limits,
    steps,
    times,
    program,
    orbit,
    env,
    gains,
    est,
    alloc_params,
    available,
    faults,
    n_faults,
    fdir_cfg,
    seeds,
    rec,
    ev,
    n_ev,
    shared,
    models: SeedModels,
) -> None:
    """Fly every variant (axis 0 of x0, available, faults, fdir_cfg, seeds, rec, ev), one thread per core;
    ``p`` is the modelled plant, ``truth`` the flown one (see :func:`fly_variant`).

    ``fly_variant`` releases the GIL, so the threads run in parallel; each variant seeds its own
    random stream, so results do not depend on the thread count or order.
    """
    from concurrent.futures import ThreadPoolExecutor

    def one(v: int) -> None:
        fly_variant(
            x0[v],
            p,
            truth,
            wheel_limits,
            steps,
            times,
            program,
            orbit,
            env,
            gains,
            est,
            alloc_params,
            available[v],
            faults[v, : n_faults[v]],
            fdir_cfg[v],
            seeds[v],
            rec[v],
            ev[v],
            n_ev[v],
            shared,
            1 + v,
            models,
        )

    n = x0.shape[0]
    if n == 1:
        one(0)
        return
    with ThreadPoolExecutor(max_workers=min(n, os.cpu_count() or 1)) as pool:
        list(pool.map(one, range(n)))
