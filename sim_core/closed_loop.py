"""The onboard-equivalent closed loop: the block diagram of the ACS, one compiled call per variant.

    sensors (T_q) → estimator (T_q) → guidance + modes (T_u) → control law (T_u) → allocation (T_u)
    → actuators (zero-order hold, seed 000 eq 3) → disturbances → plant (RK4 at dt, seed 000 eq 1)

:func:`fly_variant` is that diagram: each stage is one call of a ``_stage`` function below, and each
stage only wires the component kernels (:mod:`~sim_core.sensors`, :mod:`~sim_core.mekf`,
:mod:`~sim_core.guidance`, :mod:`~sim_core.modes`, :mod:`~sim_core.control`,
:mod:`~sim_core.allocation`, :mod:`~sim_core.wheels`, :mod:`~sim_core.magnetic`,
:mod:`~sim_core.environment`, :mod:`~sim_core.faults`, :mod:`~sim_core.fdir`,
:mod:`~sim_core.integrators`); none of them holds physics of its own. The configuration is typed:
:class:`LoopConfig` (shared by the batch) and :class:`Variant` (one per variant) are NamedTuples that
numba compiles as structs. :func:`run_batch` flies all variants in parallel (one variant per thread, its
own random stream seeded at its start, so results do not depend on the thread count).
:mod:`sim_core.engine` builds the configuration from a :class:`~sim_core.scenario.Scenario`.
"""

from __future__ import annotations

import ctypes
from typing import NamedTuple

import numpy as np
from numba import njit

from sim_core import (
    allocation,
    attitude_filters,
    control,
    earth_observer,
    environment,
    estimation,
    fdir,
    guidance,
    magnetic,
    mekf,
    modes,
    orbit,
    sensors,
    wheels,
)
from sim_core import faults as faults_mod
from sim_core.faults import T_EARTH, T_GYRO, T_MAG, T_SUN, T_WHEEL, Y_FRICTION, Y_STUCK
from sim_core.integrators import rk4_step_into
from sim_core.quaternion import (
    angle_between_1,
    attitude_difference_1,
    conjugate_rotate_1,
    conjugate_rotate_into,
    dot3_1,
)
from sim_core.spacecraft import PlantArrays, free_wheel_inertia_1
from sim_core.threads import single_threaded_kernel_blas, thread_budget

single_threaded_kernel_blas()  # the kernels' BLAS: tiny products, no worker thread spinning beside them

# Guidance kinds.
PROGRAM_INERTIAL, PROGRAM_ROUTE = 0, 1
# Control laws.
LAW_SEED000, LAW_MRP_FEEDBACK, LAW_QUATERNION_PD = 0, 1, 2
# Estimators.
ESTIMATOR_TRUTH, ESTIMATOR_STAR_TRACKER, ESTIMATOR_MEKF, ESTIMATOR_SEED000, ESTIMATOR_SEED003 = 0, 1, 2, 3, 4
ESTIMATOR_TRIAD, ESTIMATOR_EARTH_OBSERVER = 5, 6

# Fault codes live in sim_core.faults (re-exported here for the record's readers).
TARGET_CODES, TYPE_CODES, FAULT_COLUMNS = faults_mod.TARGET_CODES, faults_mod.TYPE_CODES, faults_mod.FAULT_COLUMNS

# Attitude sensors used when the star tracker gives no sample (failed, blinded or rejected by FDIR).
STAR_RESET_SIGMA_RAD = np.radians(1.0)  # attitude uncertainty re-opened after a wheel is isolated (a seizure's kick)
MAG_DIRECTION_FLOOR_RAD = np.radians(0.5)  # field-model error in direction (IGRF vs crustal/external fields)
NO_RATE_LIMIT_RAD_S = 1e9  # star tracker without a rate limit (seed 000 §4 gives none)
NEVER_BLINDED_COS = 2.0  # cosine of a Sun exclusion cone no direction falls in (blinding off)

# Event codes (sim_core.trajectory.EVENT_NAMES).
EV_MODE_CHANGE, EV_ALLOCATION, EV_MD_SATURATED = 1, 7, 8

# Output channels of the float record (columns of ``rec``), per sample.
R_Q, R_W, R_QE, R_WE, R_QP, R_WP = 0, 4, 7, 11, 15, 19
R_MD, R_TORQUE, R_R, R_OBS, R_STATUS, R_FAULTS = 22, 25, 28, 31, 32, 33
R_MODE = 34  # onboard mode (sim_core.modes codes; −1 when the mode machine is off)
R_READINGS = 35  # sensor readings (Sensed.readings[0:RD_TACH]): magnetometer (3), gyro (3), star tracker (4)
R_WHEELS = R_READINGS + 10  # then per wheel (nw each): speeds, commands, delivered torques, availability, tachometer

# Slots of Sensed.readings, the sensors' last outputs as the onboard software took them (zeros: no valid sample).
RD_MAG, RD_GYRO, RD_STAR, RD_TACH = 0, 3, 6, 10  # the tachometers' nw readings from RD_TACH on

SUN_AXIS_B = np.array([0.0, 0.0, 1.0])  # solar-array normal the Sun/safe mode points at the Sun
WHEEL_CAPTURE_RAD_S = np.radians(1.0)  # below this the wheels take over rate damping from B-dot
RATE_DAMPING_TAU_S = 20.0  # time constant of the wheel rate brake (10 T_u at T_u = 2 s)
FINE_POINTING_RAD = np.radians(2.0)  # ORF mode hands over from the acquisition PD to the scenario's law
ACQUISITION_OMEGA_RAD_S = 0.02  # Sun/ORF acquisition bandwidth: slews ≤ 0.57 °/s, under the 1 °/s rate-lost limit
UNLOADING_GAIN_PER_S = 1e-3  # seed 003 eq 29 unloading gain k: the cluster momentum decays in ~1/k s
SUN_SENSOR_COS_HALF_FOV = -1.0  # coarse Sun sensors on every face: the whole sphere, blind only in eclipse


# --- configuration (typed; numba compiles NamedTuples as structs) ---------------------------------------


class Clock(NamedTuple):
    """Multi-rate schedule (seed 000 §4): RK4 step and the measurement, control and output periods in steps."""

    n_steps: int
    dt_s: float
    measure_every: int  # T_q / dt
    control_every: int  # T_u / dt
    output_every: int
    t0_unix_s: float  # epoch of t = 0
    dut1_s: float  # UT1 − UTC frozen over the run (sim_core.frames)


class Ephemeris(NamedTuple):
    """Orbit (rows r, v, a every ``orbit_step_s``) and geomagnetic field (ECI, T) tables of the batch."""

    orbit_table: np.ndarray
    orbit_t0_s: float
    orbit_step_s: float
    field_table: np.ndarray
    field_t0_s: float
    field_step_s: float
    c_pn: np.ndarray  # precession–nutation matrix frozen over the run


class Program(NamedTuple):
    """Programmed motion Λ^p(t): timed inertial steps or a compiled route (sim_core.guidance rows)."""

    kind: int  # PROGRAM_*
    steps_t: np.ndarray
    steps_q: np.ndarray
    route: np.ndarray


class SensorModels(NamedTuple):
    """Sensor models flown (seed 000 §4, seed 002 eq 13, seed 003 §3.2): zero switches a noise term off."""

    star_sigma_rad: float
    gyro_noise_rad_s: float
    gyro_bias_rad_s: np.ndarray  # true constant bias (3,)
    gyro_markov_sigma_rad_s: float  # stationary σ of the Markov drift (seed 002 eq 13)
    gyro_markov_tau_s: float
    magnetometer_noise_t: float
    tachometer_quantum_rad_s: float
    sun_sensor_sigma_rad: float
    star_boresight_b: np.ndarray  # star-tracker boresight (unit, body axes)
    star_cos_sun_exclusion: float  # cos of the Sun exclusion half-angle (seed 003 §3.2.3.1); NEVER_BLINDED_COS: off
    star_max_rate_rad_s: float  # star tracker invalid above this body rate; NO_RATE_LIMIT_RAD_S: off
    earth_sigma_rad: float  # earth sensor φ_n, θ_n σ (seed 002 eq 14)
    earth_bias_rad: np.ndarray  # earth sensor (φ_b, θ_b) (seed 002 eq 14)


class EstimatorConfig(NamedTuple):
    """Attitude determination the law reads (``kind``): ESTIMATOR_TRUTH (the true state), _STAR_TRACKER (star
    sample and gyro as they come), _MEKF (sim_core.mekf on gyro + star tracker, earth sensor and magnetometer
    without stars), _SEED000 (seed 000 §4's filter of the mismatch ε and the gyro rate, sim_core.attitude_filters)
    or _SEED003 (seed 003's gyro-less body-rate estimator, eqs 15–19, on the star tracker's mismatch angles) or
    _TRIAD (seed 003 §3.2.1.2.1: TRIAD of the Sun sensor, earth sensor and magnetometer each T_q, gyro rates) or
    _EARTH_OBSERVER (seed 002 eq 15: gyro + earth-sensor observer of roll, pitch, yaw about the orbit frame)."""

    kind: int
    covariance0: np.ndarray  # initial MEKF covariance (6, 6)
    gyro_drift_density: float  # σ_u the MEKF assumes for the bias random walk
    k_alpha: float  # seed 000 filter: discrete steady-state gains (attitude_filters.discrete_gains)
    k_omega: float
    smoothing: float  # seed 000 filter: 1 − exp(−T_q/T) of the gyro-rate smoother
    rate_phi: np.ndarray  # seed 003 estimator: (Φ, Γ) of attitude_filters.body_rate_discretisation at T_q
    rate_gamma: np.ndarray
    observer_phi: np.ndarray  # seed 002 eq 15: exact ZOH (Φ, Γ) at T_q (earth_observer.observer_discretisation)
    observer_gamma: np.ndarray
    orbit_rate_rad_s: float  # ω_o the observer's Φ, Γ were built with
    observer_initial: np.ndarray  # (φ̂, θ̂, ψ̂) at t = 0 when observer_initial_given
    observer_initial_given: bool  # else the first earth-sensor sample with ψ̂ = 0
    observer_gain_min: float  # seed 002 eq 15: the smallest and largest of K_φ, K_θ, K_ψ (FDIR's gyro/earth split)
    observer_gain_max: float


class LawConfig(NamedTuple):
    """Control law (LAW_*): seed 000 eq (7)–(8) gains, MRP feedback (peer) or quaternion PD (seed 002 eq 18)."""

    kind: int
    digital_gains: np.ndarray  # control.DigitalLawGains.as_array
    gyroscopic_compensation: bool  # add ω × (Jω + A h) to seed 000's law (7)
    pd_kp_nm: float
    pd_kd_nms: float
    mrp_k_nm: float
    mrp_p_nms: float
    mrp_law_type: int


class MotorModel(NamedTuple):
    """Wheel motor electrics behind a voltage-limited driver (seed 002 eq 2–3; wheels.driven_motor_torque_1)."""

    on: bool
    inductance_h: float
    resistance_ohm: float
    torque_constant_nm_a: float
    back_emf_v_s: float
    max_voltage_v: float


class Actuators(NamedTuple):
    """Wheel limits (seed 000 eq 2), torque quanta (eq 3), seed 002's motor electrics, noise and imbalance torques,
    and the magnetic driver's dipole limit."""

    max_torque_nm: np.ndarray
    max_momentum_nms: np.ndarray
    torque_quantum_nm: np.ndarray
    md_max_am2: float
    allocation: np.ndarray  # allocation.AllocationConfig.as_array
    motor: MotorModel
    noise_nm: np.ndarray  # K_x per wheel (seed 002 eq 4)
    imbalance_nm_s2: np.ndarray  # K_d per wheel (seed 002 eq 4)
    disturbed: bool  # any K_x or K_d non-zero


class Surfaces(NamedTuple):
    """Outer flat plates (rows) for the aerodynamic and solar-pressure torques (sim_core.environment)."""

    normals_b: np.ndarray  # (n, 3)
    areas_m2: np.ndarray
    centroids_b_m: np.ndarray  # (n, 3) from the centre of mass
    specular: np.ndarray
    diffuse: np.ndarray
    drag_coefficient: float


class Disturbances(NamedTuple):
    """External torques flown by the plant: gravity gradient, residual dipole m_res (m_res × B), aerodynamic and
    solar-pressure torques on ``surfaces``."""

    gravity_gradient: bool
    residual_dipole_am2: np.ndarray
    aerodynamic: bool
    solar_pressure: bool
    surfaces: Surfaces


class ModeConfig(NamedTuple):
    """Onboard mode machine (sim_core.modes; seed 001/003): off flies the scenario's law from t = 0."""

    on: bool
    initial: int
    bdot_gain: float  # B-dot gain k/|B|² (A·m² per T/s)
    thresholds: np.ndarray  # modes.ModeThresholds.to_array


class FdirConfig(NamedTuple):
    """Thresholds of the onboard FDIR (sim_core.fdir), from the scenario's sensor noise."""

    rate_noise_rad_s: float  # bound on the error of a change of the estimated body rate
    star_nis_max: float  # star-tracker χ²(3) limit
    n_sigma: float  # Gaussian threshold in σ
    disturbance_bound_nm: float  # external torque the loop does not model
    wheel_noise_sigma_nms: np.ndarray  # per wheel: σ_N of seed 002's noise momentum in one T_u (fdir.wheel_noise_sigma)


class LoopConfig(NamedTuple):
    """Everything the batch shares: the modelled plant (law, allocation, FDIR), the flown one and each block."""

    model: PlantArrays
    truth: PlantArrays
    clock: Clock
    ephemeris: Ephemeris
    program: Program
    sensors: SensorModels
    estimator: EstimatorConfig
    law: LawConfig
    actuators: Actuators
    disturbances: Disturbances
    modes: ModeConfig
    fdir: FdirConfig


class Variant(NamedTuple):
    """One variant: initial state, wheels the allocation may use, its fault rows, FDIR on/off, random seed."""

    x0: np.ndarray
    available: np.ndarray
    faults: np.ndarray  # sim_core.faults.fault_table rows
    fdir_on: bool
    seed: int


class Batch(NamedTuple):
    """Per-variant inputs stacked on axis 0 (``faults`` padded, ``n_faults`` rows used per variant)."""

    x0: np.ndarray
    available: np.ndarray
    faults: np.ndarray
    n_faults: np.ndarray
    fdir_on: np.ndarray
    seeds: np.ndarray


class Record(NamedTuple):
    """Outputs of the batch: samples × channels per variant, events (t, code, arg) and their counts, and the
    shared progress/cancel array (``shared[0]`` non-zero cancels; ``shared[1 + v]`` steps done by variant v)."""

    rec: np.ndarray
    ev: np.ndarray
    n_ev: np.ndarray
    shared: np.ndarray


def record_width(n_wheels: int) -> int:
    """Number of float channels per output sample for n_wheels wheels."""
    return R_WHEELS + 5 * n_wheels


# --- loop state (arrays the stages update in place) -------------------------------------------------------


class Position(NamedTuple):
    """Where the spacecraft is: ECI r, v, a, the field in ECI and body axes, r in body axes, the Sun."""

    r: np.ndarray
    v: np.ndarray
    a: np.ndarray
    b_eci: np.ndarray
    b_body: np.ndarray
    sun_eci: np.ndarray  # Sun position (m), refreshed each T_q when a model needs it
    r_body: np.ndarray  # r in body axes, refreshed each step when the gravity gradient is flown


class Sensed(NamedTuple):
    """Latest samples and the sensors' own state (Markov drift, held outputs). ``*_frozen`` are the outputs a frozen
    fault holds: the gyro's, Sun sensor's, earth sensor's (φ_e, θ_e, 0) and magnetometer's are NaN until the sensor
    has given one (faults.held_sensor_faults_1), the star tracker's is its last attitude (star_tracker_faults_1).
    ``readings`` (RD_* slots) are what the record shows of the sensors: the magnetometer's field (T), the gyro's
    rate (rad/s) and the star tracker's Λ^m of the last T_q, the tachometers' speeds (rad/s) of the last T_u, each
    zeros while its sensor gives no valid sample (failed; the star tracker also blinded or beyond its rate limit),
    as the telemetry sends them."""

    omega: np.ndarray  # gyro ω_g
    omega_prev: np.ndarray
    gyro_drift: np.ndarray
    gyro_frozen: np.ndarray
    star_frozen: np.ndarray
    mag: np.ndarray
    mag_prev: np.ndarray
    sun_frozen: np.ndarray
    earth_frozen: np.ndarray
    mag_frozen: np.ndarray
    readings: np.ndarray  # RD_* slots: what each sensor last output under its faults, zeros when it gave no sample


class StarSample(NamedTuple):
    """One T_q's star-tracker sample Λ^m with its σ per axis, and whether the star tracker, the gyro and the
    magnetometer gave one (a failed sensor's output is read by nothing: Sensed.mag, .omega keep what it would
    have output, for the held-output faults only)."""

    q: np.ndarray
    sigma: np.ndarray
    star_ok: bool
    gyro_ok: bool
    mag_ok: bool


class Estimate(NamedTuple):
    """What the law reads: attitude, body rate, and the MEKF's bias and covariance."""

    q: np.ndarray
    omega: np.ndarray
    bias: np.ndarray
    covariance: np.ndarray
    filter_state: np.ndarray  # seed 000: ε^f, ε̇^f, ω^f; seed 003: α̂ (3), ω̂ of the mismatch (3); seed 002: φ̂, θ̂, ψ̂


class Commands(NamedTuple):
    """Control outputs: body torque, wheel commands and delivered torques, dipole, lead-lag state."""

    body_torque: np.ndarray
    frozen_torque: np.ndarray
    lead_lag: np.ndarray  # g of seed 000 eq (8)
    wheel_cmd: np.ndarray
    frozen_cmd: np.ndarray
    delivered: np.ndarray
    dipole: np.ndarray
    wheel_alloc: np.ndarray
    dipole_alloc: np.ndarray
    program: np.ndarray  # Λ^p (4), ω^p (3), ω̇^p (3) of the last control tick
    motor_current: np.ndarray  # armature currents (A) when the motor electrics are flown
    moment: np.ndarray  # dipole flown: MD dipole + residual dipole (A·m²)
    rotor_phase: np.ndarray  # rotor angles φ = ∫Ω dt (rad) when the imbalance is flown (seed 002 eq 4)


class Monitors(NamedTuple):
    """FDIR states (sim_core.fdir) and the wheels the allocation may use."""

    wheel: np.ndarray
    star: np.ndarray
    gyro: np.ndarray
    mag: np.ndarray
    earth: np.ndarray
    witness: np.ndarray  # the gyros against the dynamics (fdir.rate_witness_step_1), seed 002's observer only
    available: np.ndarray
    decouple: np.ndarray
    j_eff_inv: np.ndarray


# Slots of Carry.scalars: the next step to fly, mode, σ_u, fault flags, allocation status, MD on, field held, valid,
# magnetometer valid (its last sample).
C_STEP, C_MODE, C_SIGMA_U, C_FLAGS, C_STATUS, C_MD_ON, C_MAG_PREV, C_VALID, C_MAG_OK = 0, 1, 2, 3, 4, 5, 6, 7, 8
N_SCALARS = 9


class Carry(NamedTuple):
    """The loop's whole state between two calls of :func:`fly_variant` (a flight flown in segments), updated in
    place: state vector, sensors, estimate, commands, monitors, position, flown friction, fault and mode state,
    the scalars (C_* slots) and ``rng``, the bytes of the thread's numba random state (run_batch keeps it)."""

    x: np.ndarray
    sensed: Sensed
    est: Estimate
    cmd: Commands
    mon: Monitors
    pos: Position
    friction: np.ndarray
    fault_state: np.ndarray
    mode_state: np.ndarray
    scalars: np.ndarray
    rng: np.ndarray


# --- small pieces of the diagram ----------------------------------------------------------------------------


@njit(cache=True)
def program_1(
    g: Program, t: float, t0_unix: float, r: np.ndarray, v: np.ndarray, a: np.ndarray, c_pn: np.ndarray, dut1: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray, bool]:
    """Λ^p, ω^p, ω̇^p (program axes) and the observing flag of program ``g`` at t (s after the epoch t0_unix;
    seed 000 §2, seed 001): the current inertial step, or the compiled route (sim_core.guidance.route_1)."""
    if g.kind == PROGRAM_INERTIAL:
        k = 0
        while k + 1 < g.steps_t.shape[0] and t >= g.steps_t[k + 1]:
            k += 1
        return g.steps_q[k].copy(), np.zeros(3), np.zeros(3), False
    route: tuple[np.ndarray, np.ndarray, np.ndarray, bool] = guidance.route_1(g.route, t0_unix + t, r, v, a, c_pn, dut1)
    return route


@njit(cache=True)
def program_at(
    g: Program, clk: Clock, c_pn: np.ndarray, t: float, r: np.ndarray, v: np.ndarray, a: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, bool]:
    """:func:`program_1` of program ``g`` where the spacecraft is at t (ECI ``r``, ``v``, ``a``; ``c_pn``:
    Ephemeris.c_pn). Takes Position's arrays, not the tuple (each array passed costs a reference count)."""
    sample: tuple[np.ndarray, np.ndarray, np.ndarray, bool] = program_1(g, t, clk.t0_unix_s, r, v, a, c_pn, clk.dut1_s)
    return sample


@njit(cache=True)
def _event(ev: np.ndarray, n_ev: np.ndarray, t: float, code: int, arg: int) -> None:
    if n_ev[0] < ev.shape[0]:
        ev[n_ev[0], 0], ev[n_ev[0], 1], ev[n_ev[0], 2] = t, code, arg
        n_ev[0] += 1


@njit(cache=True)
def _earth_sensor_angles_1(
    sigma: float, bias: np.ndarray, faults: np.ndarray, t: float, x: np.ndarray, r: np.ndarray, frozen: np.ndarray
) -> tuple[np.ndarray, bool]:
    """Earth-sensor roll φ_e and pitch θ_e (``angles[0:2]``; sensors.earth_sensor_1, seed 002 eq 14: truth +
    ``bias`` + noise σ) under the variant's earth-sensor faults, a frozen one holding ``frozen``; False if the
    sensor has failed."""
    roll, pitch = sensors.nadir_roll_pitch_1(x[0:4], r)
    normals = np.zeros(3)  # the sample's noise normals: a noise fault scales these (sim_core.faults)
    normals[0:2] = np.random.standard_normal(2)
    meas, _ = sensors.earth_sensor_1(roll, pitch, bias, np.full(2, sigma), np.inf, normals[0:2])
    angles = np.zeros(3)
    angles[0:2] = meas
    ok = faults_mod.held_sensor_faults_1(faults, T_EARTH, t, angles, frozen, sigma, normals)
    return angles, ok


@njit(cache=True)
def _earth_sensor_nadir_1(
    sigma: float, bias: np.ndarray, faults: np.ndarray, t: float, x: np.ndarray, r: np.ndarray, frozen: np.ndarray
) -> tuple[np.ndarray, bool]:
    """Nadir in body axes from an earth-sensor sample (:func:`_earth_sensor_angles_1`); False if it has failed."""
    angles, ok = _earth_sensor_angles_1(sigma, bias, faults, t, x, r, frozen)
    return sensors.nadir_from_roll_pitch_1(angles[0], angles[1]), ok


@njit(cache=True)
def _sun_direction_1(
    sigma: float,
    t0_unix_s: float,
    faults: np.ndarray,
    t: float,
    x: np.ndarray,
    q_est: np.ndarray,
    r: np.ndarray,
    frozen: np.ndarray,
) -> np.ndarray:
    """Sun direction in body axes from the Sun sensor (sensors.sun_sensor_1, noise σ) under its faults; in
    eclipse or when failed, the ephemeris Sun seen through the attitude estimate."""
    sun_eci = environment.sun_position_1(t0_unix_s + t)
    s_b, ok = _sun_sensor_sample_1(sigma, faults, t, x, sun_eci, r, frozen)
    n = np.sqrt(dot3_1(s_b, s_b))
    if not ok or n == 0.0:
        s_b = conjugate_rotate_1(q_est, sun_eci)
        n = np.sqrt(dot3_1(s_b, s_b))
    unit: np.ndarray = s_b / n
    return unit


@njit(cache=True)
def _sun_sensor_sample_1(
    sigma: float, faults: np.ndarray, t: float, x: np.ndarray, sun_eci: np.ndarray, r: np.ndarray, frozen: np.ndarray
) -> tuple[np.ndarray, bool]:
    """A Sun-sensor sample in body axes (sensors.sun_sensor_1, noise σ) under its faults, and whether it is valid."""
    normals = np.random.standard_normal(3)
    s_b, ok = sensors.sun_sensor_1(x[0:4], sun_eci, r, SUN_AXIS_B, SUN_SENSOR_COS_HALF_FOV, sigma, normals)
    ok = faults_mod.held_sensor_faults_1(faults, T_SUN, t, s_b, frozen, sigma, normals) and ok
    return s_b, ok and dot3_1(s_b, s_b) > 0.0


@njit(cache=True)
def _triad_stage(
    s: SensorModels,
    t0_unix_s: float,
    faults: np.ndarray,
    t: float,
    x: np.ndarray,
    pos: Position,
    sensed: Sensed,
    gyro_ok: bool,
    mag_ok: bool,
    est: Estimate,
) -> bool:
    """Seed 003's vector-sensor determination (estimation.triad_sensors_1): Sun sensor, earth sensor (local
    vertical) and magnetometer against the ephemeris Sun, −r and the field model; rates from the gyro. Returns
    whether a sensor pair gave the attitude (else the estimate holds)."""
    sun_eci = environment.sun_position_1(t0_unix_s + t)
    sun_b, sun_ok = _sun_sensor_sample_1(s.sun_sensor_sigma_rad, faults, t, x, sun_eci, pos.r, sensed.sun_frozen)
    nadir_b, nadir_ok = _earth_sensor_nadir_1(
        s.earth_sigma_rad, s.earth_bias_rad, faults, t, x, pos.r, sensed.earth_frozen
    )
    q, ok = estimation.triad_sensors_1(sun_b, sun_ok, nadir_b, nadir_ok, sensed.mag, mag_ok, sun_eci, -pos.r, pos.b_eci)
    if ok:
        est.q[:] = q if q @ est.q >= 0.0 else -q
    if gyro_ok:
        est.omega[:] = sensed.omega
    return ok


# --- stages: each takes the blocks of the configuration it reads, never the whole LoopConfig -------------------


@njit(cache=True)
def _hold_outputs_stage(cmd: Commands) -> None:
    """At a fault onset: the commands in hand are what a 'frozen' wheel or controller fault holds (sim_core.faults;
    the sensors keep their own held outputs, faults.held_sensor_faults_1)."""
    cmd.frozen_cmd[:] = cmd.wheel_cmd
    cmd.frozen_torque[:] = cmd.body_torque


@njit(cache=True)
def _flies_wheel_fault(faults: np.ndarray, kind: int) -> bool:
    """Whether the variant's fault table holds a wheel fault of ``kind`` (sim_core.faults codes)."""
    for f in range(faults.shape[0]):
        if int(faults[f, faults_mod.F_TARGET]) == T_WHEEL and int(faults[f, faults_mod.F_TYPE]) == kind:
            return True
    return False


@njit(cache=True)
def _sense_stage(
    s: SensorModels, faults: np.ndarray, t: float, x: np.ndarray, markov: np.ndarray, pos: Position, sensed: Sensed
) -> StarSample:
    """Gyro (seed 002 eq 13), star tracker (seed 000 §4) and magnetometer (seed 003 MAG) samples under the
    variant's faults. ``markov``: decay and step σ of the gyro drift."""
    normals = np.random.standard_normal(6)
    drift_normals = np.random.standard_normal(3) if s.gyro_markov_sigma_rad_s > 0.0 else np.zeros(3)
    w_meas, _ = sensors.gyro_1(
        x[4:7],
        s.gyro_bias_rad_s,
        sensed.gyro_drift,
        np.full(3, s.gyro_noise_rad_s),
        markov[0],
        markov[1],
        np.inf,
        np.concatenate((normals[0:3], drift_normals)),
    )
    sensed.omega[:] = w_meas
    gyro_ok = faults_mod.held_sensor_faults_1(
        faults, T_GYRO, t, sensed.omega, sensed.gyro_frozen, s.gyro_noise_rad_s, normals[0:3]
    )
    sig3 = np.full(3, s.star_sigma_rad)
    q_m, st_ok = sensors.star_tracker_1(x[0:4], x[4:7], sig3, s.star_max_rate_rad_s, normals[3:6])
    if s.star_cos_sun_exclusion <= 1.0:
        blinded = sensors.star_tracker_blinded_1(
            x[0:4], pos.sun_eci, pos.r, s.star_boresight_b, s.star_cos_sun_exclusion
        )
        st_ok = st_ok and not blinded
    st_ok = (
        faults_mod.star_tracker_faults_1(faults, t, q_m, sensed.star_frozen, s.star_sigma_rad, normals[3:6]) and st_ok
    )
    mag_normals = np.random.standard_normal(3)  # the sample's own noise normals: a noise fault scales these
    mag, _ = sensors.magnetometer_1(x[0:4], pos.b_eci, np.zeros(3), s.magnetometer_noise_t, np.inf, mag_normals)
    sensed.mag[:] = mag
    mag_ok = faults_mod.held_sensor_faults_1(
        faults, T_MAG, t, sensed.mag, sensed.mag_frozen, s.magnetometer_noise_t, mag_normals
    )
    readings = sensed.readings
    for i in range(3):
        readings[RD_MAG + i] = sensed.mag[i] if mag_ok else 0.0
        readings[RD_GYRO + i] = sensed.omega[i] if gyro_ok else 0.0
    for i in range(4):
        readings[RD_STAR + i] = q_m[i] if st_ok else 0.0
    return StarSample(q_m, sig3, st_ok, gyro_ok, mag_ok)


@njit(cache=True)
def _magnetometer_monitor_stage(
    s: SensorModels,
    fd: FdirConfig,
    t: float,
    pos: Position,
    sensed: Sensed,
    est: Estimate,
    mon: Monitors,
    ev: np.ndarray,
    n_ev: np.ndarray,
) -> None:
    """Magnetometer FDIR at T_q (sim_core.fdir.magnetometer_check_1) against the field model seen through the
    estimate, before the estimator reads the sample."""
    fdir.magnetometer_check_1(
        mon.mag, sensed.mag, conjugate_rotate_1(est.q, pos.b_eci), s.magnetometer_noise_t, fd.n_sigma, ev, n_ev, t
    )


@njit(cache=True)
def _mekf_stage(
    e: EstimatorConfig,
    s: SensorModels,
    fd: FdirConfig,
    t_q: float,
    var: Variant,
    k: int,
    t: float,
    x: np.ndarray,
    pos: Position,
    sensed: Sensed,
    sample: StarSample,
    sigma_u: float,
    est: Estimate,
    mon: Monitors,
    ev: np.ndarray,
    n_ev: np.ndarray,
) -> tuple[bool, float]:
    """MEKF (sim_core.mekf) on gyro + star tracker; without a star sample, on the earth sensor's nadir and the
    magnetometer's field direction; each sensor screened by FDIR when the variant flies it, and a sensor that gives
    no valid sample not read (no propagation and the last rate without the gyro). Returns (attitude valid, σ_u)."""
    fdir_on, q_m, sig3, st_ok = var.fdir_on, sample.q, sample.sigma, sample.star_ok
    if k > 0 and sample.gyro_ok:
        # mean of the samples bracketing the step: the held sample's ½ ω̇ T_q² error would
        # make the filter overconfident in manoeuvres (and the FDIR innovation test with it)
        mekf.mekf_propagate_1(
            est.q,
            est.bias,
            est.covariance,
            0.5 * (sensed.omega + sensed.omega_prev),
            t_q,
            s.gyro_noise_rad_s * np.sqrt(t_q),
            sigma_u,
        )
    sensed.omega_prev[:] = sensed.omega
    if fdir_on and st_ok:
        st_scale = fdir.star_tracker_check_1(
            mon.star, est.q, est.covariance, q_m, sig3, fd.star_nis_max, mon.gyro[fdir.GS_ISOLATED] != 0.0, ev, n_ev, t
        )
        st_ok = st_scale > 0.0
        sig3 *= max(st_scale, 1.0)
    if fdir_on and sample.gyro_ok:
        sigma_u = fdir.gyro_drift_step_1(
            mon.gyro,
            t,
            sensed.omega,
            t_q,
            q_m,
            st_ok,
            s.star_sigma_rad,
            s.gyro_noise_rad_s,
            e.gyro_drift_density,
            fd.n_sigma,
            ev,
            n_ev,
        )
    if not st_ok:
        sigma_e = s.earth_sigma_rad
        nadir, earth_ok = _earth_sensor_nadir_1(sigma_e, s.earth_bias_rad, var.faults, t, x, pos.r, sensed.earth_frozen)
        if fdir_on and earth_ok:
            earth_ok = fdir.earth_sensor_check_1(mon.earth, est.q, est.covariance, nadir, -pos.r, sigma_e, ev, n_ev, t)
        if fdir_on and earth_ok and sample.star_ok:
            st_ok = fdir.star_readmit_1(
                mon.star, est.q, q_m, est.covariance, nadir, -pos.r, sigma_e, fd.n_sigma, ev, n_ev, t
            )
        if not st_ok:
            if earth_ok:
                mekf.mekf_vector_update_1(est.q, est.bias, est.covariance, nadir, -pos.r, sigma_e)
            b_norm = np.sqrt(dot3_1(pos.b_eci, pos.b_eci))
            if sample.mag_ok and s.magnetometer_noise_t > 0.0 and b_norm > 0.0:
                sigma_dir = s.magnetometer_noise_t / b_norm + MAG_DIRECTION_FLOOR_RAD
                mekf.mekf_vector_update_1(est.q, est.bias, est.covariance, sensed.mag, pos.b_eci, sigma_dir)
    if st_ok:
        mekf.mekf_update_1(est.q, est.bias, est.covariance, q_m, sig3)
    if sample.gyro_ok:  # a failed gyro's rate is not read: the estimate keeps the last one
        est.omega[:] = sensed.omega - est.bias
    return bool(st_ok), float(sigma_u)


@njit(cache=True)
def _earth_observer_stage(
    e: EstimatorConfig,
    s: SensorModels,
    p: PlantArrays,
    n_sigma: float,
    fdir_on: bool,
    faults: np.ndarray,
    k: int,
    t: float,
    t_q: float,
    x: np.ndarray,
    tach_speeds: np.ndarray,
    pos: Position,
    sensed: Sensed,
    gyro_ok: bool,
    est: Estimate,
    mon: Monitors,
    ev: np.ndarray,
    n_ev: np.ndarray,
) -> bool:
    """Seed 002's attitude determination (§2.2.6, eq 15; sim_core.earth_observer): gyros and the two earth sensors
    (eq 14: roll φ_e, pitch θ_e of the nadir) drive the observer of roll φ̂, pitch θ̂ and yaw ψ̂ about the orbit
    frame, advanced each T_q by its exact zero-order hold on the mean of the two gyro samples bracketing the step
    and the earth sample at its end. Yaw is not measured: it is observed through the orbit-rate coupling of roll
    and yaw (ψ̂̇ = −ω_o φ̂ + ω_gz + K_ψ (φ_m − φ̂), gyrocompassing), so a yaw error decays at the slow root of
    s² + K_φ s + ω_o (ω_o + K_ψ). The law reads Λ = Λ_o ∘ [ψ̂]_1 ∘ [θ̂]_3 ∘ [φ̂]_2 (earth_observer.
    attitude_from_angles_1, Λ_o the orbit frame where the spacecraft is) and the gyro's body rate (eq 15 has no
    gyro-bias state, so the rate is the gyro's as measured). The earth sensor is screened by FDIR when the variant
    flies it (fdir.earth_witness_check_1 against the estimate, with the observer's steady-state error covariance),
    the gyros against the rigid-body dynamics of the model plant ``p`` and the tachometers ``tach_speeds``
    (fdir.rate_witness_step_1: the gravity gradient at the estimated attitude, known to the screen's limit + the
    earth noise bound), so that the one residual of two sensors is not blamed on the earth sensor when the gyro
    drifts; a rejected or failed sample leaves the step to the gyros (φ_m, θ_m := φ̂, θ̂). Starts from
    ``e.observer_initial`` or the first earth sample with ψ̂ = 0. A failed gyro is not read: the observer steps on the
    last valid rate. Returns whether the earth sample was used."""
    f = est.filter_state
    angles, earth_ok = _earth_sensor_angles_1(
        s.earth_sigma_rad, s.earth_bias_rad, faults, t, x, pos.r, sensed.earth_frozen
    )
    chi = -2.0 * np.log(fdir.FALSE_ALARM_PROBABILITY)
    p_max = max(est.covariance[0, 0], est.covariance[1, 1], est.covariance[2, 2])
    att_bound = np.sqrt(chi) * (np.sqrt(s.earth_sigma_rad**2 + p_max) + s.earth_sigma_rad)
    if fdir_on and gyro_ok and k > 0:
        fdir.rate_witness_step_1(
            mon.witness, t, t_q, sensed.omega, tach_speeds, p.inertia, p.wheel_axes, p.wheel_inertia,
            s.tachometer_quantum_rad_s, s.gyro_noise_rad_s, s.gyro_markov_sigma_rad_s,
            conjugate_rotate_1(est.q, pos.r), att_bound, n_sigma, ev, n_ev,
        )  # fmt: skip
    if fdir_on and earth_ok:
        nadir = sensors.nadir_from_roll_pitch_1(angles[0], angles[1])
        earth_ok = fdir.earth_witness_check_1(
            mon.earth, mon.witness, est.q, est.covariance, nadir, -pos.r, s.earth_sigma_rad, e.observer_gain_min,
            e.observer_gain_max, t_q, ev, n_ev, t,
        )  # fmt: skip
    if k == 0:
        if e.observer_initial_given:
            f[0:3] = e.observer_initial
        elif earth_ok:
            f[0], f[1], f[2] = angles[0], angles[1], 0.0
    else:
        roll_m, pitch_m = (angles[0], angles[1]) if earth_ok else (f[0], f[1])
        # a failed gyro is not read: the step takes the last valid rate (est.omega)
        rate = 0.5 * (sensed.omega + sensed.omega_prev) if gyro_ok else est.omega.copy()
        earth_observer.body_observer_step_1(
            f[0:3], e.observer_phi, e.observer_gamma, rate, roll_m, pitch_m, e.orbit_rate_rad_s
        )
    sensed.omega_prev[:] = sensed.omega
    q = earth_observer.attitude_from_angles_1(f[0:3], pos.r, pos.v)
    est.q[:] = q if q @ est.q >= 0.0 else -q
    if gyro_ok:
        est.omega[:] = sensed.omega
    return bool(earth_ok)


@njit(cache=True)
def _mismatch_filter_stage(
    e: EstimatorConfig, t_q: float, q_p: np.ndarray, w_p: np.ndarray, sensed: Sensed, sample: StarSample, est: Estimate
) -> None:
    """Seed 000 §4 (gyro + star tracker) or seed 003 eqs 15–19 (star tracker only) per-axis steady-state filters
    of the mismatch ε = −2 e0 e of E = Λ̃^p ∘ Λ^m (sim_core.attitude_filters) against the program Λ^p, ω^p at
    t; the estimate is Λ^p ∘ E^f and the filtered gyro rate (seed 000) or ω^p − ε̂̇ (seed 003: ε̇ = −(ω − ω^p)
    in body axes)."""
    f = est.filter_state
    if e.kind == ESTIMATOR_SEED000:
        rate = sensed.omega if sample.gyro_ok else f[6:9].copy()
        attitude_filters.mismatch_filter_step_1(
            f, q_p, sample.q, rate, sample.star_ok, e.k_alpha, e.k_omega, e.smoothing, t_q
        )
        q, w = attitude_filters.filtered_attitude_1(f, q_p)
        est.q[:] = q
        est.omega[:] = w
        return
    z = f[0:3].copy()
    if sample.star_ok:
        z = attitude_filters.mismatch_1(q_p, sample.q)
    attitude_filters.body_rate_step_1(f[0:3], f[3:6], z, e.rate_phi, e.rate_gamma)
    q, _ = attitude_filters.filtered_attitude_1(f, q_p)
    est.q[:] = q
    est.omega[:] = control.program_in_body_1(q_p, q, w_p) - f[3:6]


@njit(cache=True)
def _sample_estimate_stage(
    kind: int, x: np.ndarray, gyro: np.ndarray, sample: StarSample, q_est: np.ndarray, w_est: np.ndarray
) -> None:
    """The estimates that need no filter, into the estimate's ``q_est``, ``w_est``: the true state
    (ESTIMATOR_TRUTH) or the star tracker and ``gyro`` (Sensed.omega) as sampled (ESTIMATOR_STAR_TRACKER; a
    missing sample keeps the last one)."""
    if kind == ESTIMATOR_TRUTH:
        q_est[:] = x[0:4]
        w_est[:] = x[4:7]
        return
    if sample.star_ok:
        q_est[:] = sample.q
    if sample.gyro_ok:
        w_est[:] = gyro


@njit(cache=True)
def _mode_stage(
    mc: ModeConfig,
    t: float,
    pos: Position,
    sun_b: np.ndarray,
    mode_state: np.ndarray,
    mode: int,
    valid: bool,
    est: Estimate,
    available: np.ndarray,
    cmd: Commands,
    ev: np.ndarray,
    n_ev: np.ndarray,
) -> int:
    """Mode machine step (sim_core.modes, seed 001/003) on the Sun direction ``sun_b`` (body axes, from
    :func:`_sun_direction_1`) and the ORF; in the Sun/safe and ORF modes their program replaces the scenario's in
    ``cmd.program``. Returns the mode."""
    q_orf, _, _ = guidance.orf_hold_1(np.array([1.0, 0.0, 0.0, 0.0]), pos.r, pos.v, pos.a)
    new_mode = modes.mode_step_1(
        mode_state,
        mc.thresholds,
        t,
        np.sqrt(dot3_1(est.omega, est.omega)),
        valid,
        angle_between_1(SUN_AXIS_B, sun_b),
        attitude_difference_1(est.q, q_orf),
        True,
        np.sum(available) < 2,
        False,
    )
    if new_mode != mode:
        _event(ev, n_ev, t, EV_MODE_CHANGE, new_mode)
        cmd.lead_lag[:] = 0.0
        mode = new_mode
    if mode == modes.MODE_SUN_SAFE:
        cmd.program[0:4] = guidance.sun_pointing_1(est.q, sun_b, SUN_AXIS_B)
        cmd.program[4:10] = 0.0
    elif mode == modes.MODE_ORF:
        q_p, w_p, wd_p = guidance.orf_hold_1(np.array([1.0, 0.0, 0.0, 0.0]), pos.r, pos.v, pos.a)
        cmd.program[0:4] = q_p
        cmd.program[4:7] = w_p
        cmd.program[7:10] = wd_p
    return mode


@njit(cache=True)
def _tachometer_stage(quantum_rad_s: float, faults: np.ndarray, t: float, wheel_speeds: np.ndarray) -> np.ndarray:
    """Wheel speeds as the tachometers read them (sensors.wheel_tachometer_1; exact when the quantum is 0) under
    the tachometer faults (faults.tachometer_faults_1)."""
    speeds = wheel_speeds.copy()
    if quantum_rad_s > 0.0:
        speeds, _ = sensors.wheel_tachometer_1(speeds, quantum_rad_s, np.inf)
    faults_mod.tachometer_faults_1(faults, t, speeds)
    return speeds


@njit(cache=True)
def _law_stage(
    inertia: np.ndarray,
    wheel_axes: np.ndarray,
    wheel_inertia: np.ndarray,
    law: LawConfig,
    modes_on: bool,
    mode: int,
    q_est: np.ndarray,
    w_est: np.ndarray,
    speeds: np.ndarray,
    h_wheels: np.ndarray,
    available: np.ndarray,
    program: np.ndarray,
    lead_lag: np.ndarray,
    body_torque: np.ndarray,
) -> None:
    """Body torque of the configured law (LawConfig.kind) on the estimate, into ``body_torque``, tracking
    ``program`` (Commands.program); in the Sun/safe mode and the ORF acquisition the seed 002 eq (18) PD with
    gyroscopic compensation (acquisition bandwidth). Takes the modelled plant's and the estimate's arrays, not
    their tuples (each array passed costs a reference count)."""
    q_p, w_p, wd_p = program[0:4], program[4:7], program[7:10]
    coarse = mode == modes.MODE_SUN_SAFE or (
        mode == modes.MODE_ORF and attitude_difference_1(q_est, q_p) > FINE_POINTING_RAD
    )
    if modes_on and coarse:
        j_max = max(inertia[0, 0], inertia[1, 1], inertia[2, 2])
        kp = j_max * ACQUISITION_OMEGA_RAD_S**2  # steady slew rate ≤ kp/kd = ω_n/2 per unit error
        kd = 2.0 * j_max * ACQUISITION_OMEGA_RAD_S
        body_torque[:] = control.quaternion_pd_step(q_est, w_est, q_p, w_p, kp, kd) + control.gyroscopic_torque_1(
            w_est, inertia, wheel_axes @ h_wheels
        )
    elif law.kind == LAW_SEED000:
        body_torque[:] = control.digital_law_step(q_est, w_est, q_p, w_p, wd_p, lead_lag, inertia, law.digital_gains)
        if law.gyroscopic_compensation:
            body_torque[:] += control.gyroscopic_torque_1(w_est, inertia, wheel_axes @ h_wheels)
    elif law.kind == LAW_MRP_FEEDBACK:
        body_torque[:] = control.mrp_tracking_step(
            q_est,
            w_est,
            q_p,
            w_p,
            wd_p,
            inertia,
            control.MrpWheels(wheel_axes, wheel_inertia, speeds, available),
            control.MrpGains(law.mrp_k_nm, law.mrp_p_nms, law.mrp_law_type),
        )
    else:
        body_torque[:] = control.quaternion_pd_step(q_est, w_est, q_p, w_p, law.pd_kp_nm, law.pd_kd_nms)


@njit(cache=True)
def _allocate_1(
    wheel_axes: np.ndarray,
    params: np.ndarray,
    torque_quantum_nm: np.ndarray,
    max_torque_nm: np.ndarray,
    available: np.ndarray,
    h_wheels: np.ndarray,
    mag: np.ndarray,
    body_torque: np.ndarray,
    wheel_alloc: np.ndarray,
    dipole_alloc: np.ndarray,
    wheel_cmd: np.ndarray,
) -> int:
    """Body torque → wheel torques and MD dipole (seed 000 eq 6, §3; allocation.allocate_1 with
    Actuators.allocation ``params``) on the magnetometer's ``mag``, then the quantised, limited wheel commands
    (seed 000 eq 3); returns the allocation status. Takes Commands' arrays, not the tuple (reference counts)."""
    status: int = allocation.allocate_1(
        body_torque, wheel_axes, available, h_wheels, mag, params, wheel_alloc, dipole_alloc
    )
    for w in range(wheel_cmd.shape[0]):
        wheel_cmd[w] = control.wheel_torque_command_1(wheel_alloc[w], torque_quantum_nm[w], max_torque_nm[w])
    return status


@njit(cache=True)
def _allocation_stage(
    wheel_axes: np.ndarray,
    params: np.ndarray,
    torque_quantum_nm: np.ndarray,
    max_torque_nm: np.ndarray,
    md_max_am2: float,
    faults: np.ndarray,
    t: float,
    mag: np.ndarray,
    h_wheels: np.ndarray,
    available: np.ndarray,
    body_torque: np.ndarray,
    frozen_torque: np.ndarray,
    wheel_alloc: np.ndarray,
    dipole_alloc: np.ndarray,
    wheel_cmd: np.ndarray,
    dipole: np.ndarray,
) -> int:
    """Controller faults on the body torque, then wheel torques and MD dipole (seed 000 eq 6, §3; sim_core.
    allocation, Actuators.allocation ``params``) with rod faults and the dipole limit. Returns the allocation
    status. Takes the Actuators' and Commands' arrays, not the tuples (each array passed costs a reference count)."""
    faults_mod.controller_faults_1(faults, t, body_torque, frozen_torque)
    status = _allocate_1(
        wheel_axes, params, torque_quantum_nm, max_torque_nm, available, h_wheels, mag, body_torque, wheel_alloc,
        dipole_alloc, wheel_cmd,
    )  # fmt: skip
    dipole[:] = dipole_alloc
    faults_mod.rod_faults_1(faults, t, dipole)
    for i in range(3):
        dipole[i] = min(max(dipole[i], -md_max_am2), md_max_am2)
    return status


@njit(cache=True)
def _mode_actuation_stage(
    p: PlantArrays,
    act: Actuators,
    bdot_gain: float,
    t_u: float,
    mode: int,
    status: int,
    est: Estimate,
    sensed: Sensed,
    field: np.ndarray,
    have_mag_prev: bool,
    h_wheels: np.ndarray,
    available: np.ndarray,
    cmd: Commands,
) -> None:
    """The modes' actuation after the allocation (mode machine on). Rate-damping and fault modes (seed 001
    initial mode, seed 003 eq 29–30): B-dot above 1 °/s, in the fault mode or with fewer than two wheels; below
    it the wheels brake the body (control.rate_brake_torque_1) while the rods unload the cluster. Sun/safe and
    ORF modes: continuous magnetic unloading of the cluster momentum (seed 003 eq 29). The rods act on the
    magnetometer's ``field`` (zeros while it gives no valid sample: no dipole); ``have_mag_prev``: the previous and
    this sample are both valid (B-dot differences them)."""
    if mode == modes.MODE_RATE_DAMPING or mode == modes.MODE_FAULT:
        cmd.body_torque[:] = 0.0
        cmd.wheel_cmd[:] = 0.0
        cmd.dipole[:] = 0.0
        rate = np.sqrt(dot3_1(est.omega, est.omega))
        if mode == modes.MODE_FAULT or rate > WHEEL_CAPTURE_RAD_S or np.sum(available) < 2:
            if have_mag_prev:
                cmd.dipole[:] = control.bdot_dipole_step(sensed.mag, sensed.mag_prev, t_u, bdot_gain, act.md_max_am2)
            return
        cmd.body_torque[:] = control.rate_brake_torque_1(p.inertia, est.omega, RATE_DAMPING_TAU_S)
        _allocate_1(
            p.wheel_axes, act.allocation, act.torque_quantum_nm, act.max_torque_nm, available, h_wheels, field,
            cmd.body_torque, cmd.wheel_alloc, cmd.dipole_alloc, cmd.wheel_cmd,
        )  # fmt: skip
    elif not ((mode == modes.MODE_SUN_SAFE or mode == modes.MODE_ORF) and status == 0):
        return
    cmd.dipole[:] = control.unloading_dipole_step(
        field, p.wheel_axes @ h_wheels, np.zeros(3), UNLOADING_GAIN_PER_S, act.md_max_am2
    )


@njit(cache=True)
def _wheel_monitor_stage(
    p: PlantArrays,
    act: Actuators,
    tachometer_quantum_rad_s: float,
    wheel_noise_sigma_nms: np.ndarray,
    t_u: float,
    star_reset: bool,
    t: float,
    speeds: np.ndarray,
    h_wheels: np.ndarray,
    mag: np.ndarray,
    est: Estimate,
    mon: Monitors,
    ev: np.ndarray,
    n_ev: np.ndarray,
) -> None:
    """Wheel FDIR at T_u (sim_core.fdir.wheel_check_1); it may drop wheels from ``mon.available`` (not a partly
    working one whose removal the allocation on ``mag`` could not fly). After an isolation a MEKF (``star_reset``)
    trusts the star tracker again (a seizing wheel kicks the body)."""
    n_before = np.sum(mon.available)
    fdir.wheel_check_1(
        mon.wheel,
        speeds,
        est.omega,
        p.wheel_inertia,
        act.max_momentum_nms,
        p.friction,
        tachometer_quantum_rad_s,
        wheel_noise_sigma_nms,
        t_u,
        mon.decouple,
        mon.available,
        p.wheel_axes,
        h_wheels,
        mag,
        act.allocation,
        ev,
        n_ev,
        t,
    )
    if star_reset and np.sum(mon.available) < n_before:
        fdir.star_reset_1(mon.star, est.covariance, STAR_RESET_SIGMA_RAD)


@njit(cache=True)
def _wheel_hold_stage(
    p: PlantArrays,
    act: Actuators,
    fd: FdirConfig,
    t_u: float,
    speeds: np.ndarray,
    est: Estimate,
    field: np.ndarray,
    cmd: Commands,
    mon: Monitors,
) -> None:
    """Wheel FDIR's prediction for the next T_u (sim_core.fdir.wheel_hold_1) from the commands just sent and
    the MD torque L × B (sim_core.magnetic) on the magnetometer's ``field`` (zeros: no valid sample)."""
    fdir.wheel_hold_1(
        mon.wheel,
        speeds,
        est.omega,
        p.wheel_axes,
        cmd.wheel_cmd,
        p.wheel_inertia,
        act.max_torque_nm,
        act.max_momentum_nms,
        p.friction,
        p.inertia,
        mon.j_eff_inv,
        magnetic.magnetic_torque_1(cmd.dipole, field),
        fd.disturbance_bound_nm,
        fd.rate_noise_rad_s,
        t_u,
    )


@njit(cache=True)
def _record_stage(
    n_modes: int,
    x: np.ndarray,
    q_p: np.ndarray,
    w_p: np.ndarray,
    observing: bool,
    r: np.ndarray,
    q_est: np.ndarray,
    w_est: np.ndarray,
    dipole: np.ndarray,
    body_torque: np.ndarray,
    wheel_cmd: np.ndarray,
    delivered: np.ndarray,
    available: np.ndarray,
    readings: np.ndarray,
    status: int,
    flags: int,
    mode: int,
    row: np.ndarray,
) -> None:
    """One output sample (R_* channels): truth, estimate, the scenario's program Λ^p, ω^p (program axes) and
    observing flag at the sample's time, position ``r``, actuators (MD dipole, body torque, wheel commands and
    delivered torques), wheels, the sensors' last ``readings`` (Sensed.readings). Takes the arrays, not their
    tuples (each array passed costs a reference count)."""
    nw = wheel_cmd.shape[0]
    row[R_Q : R_Q + 4] = x[0:4]
    row[R_W : R_W + 3] = x[4:7]
    row[R_QE : R_QE + 4] = q_est
    row[R_WE : R_WE + 3] = w_est
    row[R_QP : R_QP + 4] = q_p
    row[R_WP : R_WP + 3] = control.program_in_body_1(q_p, x[0:4], w_p)
    row[R_MD : R_MD + 3] = dipole
    row[R_TORQUE : R_TORQUE + 3] = body_torque
    row[R_R : R_R + 3] = r
    row[R_OBS] = 1.0 if observing else 0.0
    row[R_STATUS] = status
    row[R_FAULTS] = flags
    row[R_MODE] = mode
    row[R_WHEELS : R_WHEELS + nw] = x[7 + 2 * n_modes : 7 + 2 * n_modes + nw]
    row[R_WHEELS + nw : R_WHEELS + 2 * nw] = wheel_cmd
    row[R_WHEELS + 2 * nw : R_WHEELS + 3 * nw] = delivered
    for w in range(nw):
        row[R_WHEELS + 3 * nw + w] = 1.0 if available[w] else 0.0
    row[R_READINGS:R_WHEELS] = readings[0:RD_TACH]
    row[R_WHEELS + 4 * nw : R_WHEELS + 5 * nw] = readings[RD_TACH : RD_TACH + nw]


# --- initial state -----------------------------------------------------------------------------------------


@njit(cache=True)
def _markov_1(s: SensorModels, t_q: float) -> np.ndarray:
    """Rows decay e^{−T_q/τ} and step σ √(1 − decay²) of the gyro's Markov drift (seed 002 eq 13), per axis."""
    out = np.empty((2, 3))
    out[0, :] = np.exp(-t_q / s.gyro_markov_tau_s)
    out[1, :] = s.gyro_markov_sigma_rad_s * np.sqrt(1.0 - out[0] ** 2)
    return out


@njit(cache=True)
def _initial_monitors(p: PlantArrays, gyro_drift_density: float, available: np.ndarray) -> Monitors:
    nw = p.wheel_inertia.shape[0]
    star = np.zeros(fdir.STAR_STATE_SIZE)
    star[0:4] = np.nan
    gyro = np.zeros(fdir.GYRO_STATE_SIZE)
    gyro[fdir.GS_T0] = np.nan
    gyro[fdir.GS_SIGMA_U] = gyro_drift_density
    j_eff_inv = np.linalg.inv(free_wheel_inertia_1(p))
    return Monitors(
        fdir.wheel_state_1(nw),
        star,
        gyro,
        np.full(fdir.MAG_STATE_SIZE, np.nan),
        np.zeros(fdir.EARTH_STATE_SIZE),
        fdir.witness_state_1(),
        available.copy(),
        fdir.wheel_decoupling_1(p.wheel_axes, p.wheel_inertia, j_eff_inv),
        j_eff_inv,
    )


@njit(cache=True)
def _flown_plant(t: PlantArrays, friction: np.ndarray) -> PlantArrays:
    """The truth plant with the flight's own ``friction`` array (wheel friction faults change it during the flight)."""
    return PlantArrays(
        t.inertia,
        t.mass_inv,
        t.wheel_axes,
        t.wheel_inertia,
        friction,
        t.flex_coupling,
        t.flex_mass,
        t.flex_freq,
        t.flex_decrement,
    )


@njit(cache=True)
def _initial_commands(nw: int) -> Commands:
    return Commands(
        np.zeros(3),
        np.zeros(3),
        np.zeros(3),
        np.zeros(nw),
        np.zeros(nw),
        np.zeros(nw),
        np.zeros(3),
        np.zeros(nw),
        np.zeros(3),
        np.zeros(10),
        np.zeros(nw),
        np.zeros(3),
        np.zeros(nw),
    )


@njit(cache=True)
def initial_carry(c: LoopConfig, var: Variant) -> Carry:
    """The loop's state at t = 0 for variant ``var`` (initial state, estimate at it; the position is filled by the
    first step, a measurement tick); seeds the thread's random stream with ``var.seed`` and takes its first draw
    (the gyro's Markov drift)."""
    np.random.seed(var.seed)
    sens, estc, p, mc = c.sensors, c.estimator, c.model, c.modes
    x = var.x0.copy()
    sig_m = sens.gyro_markov_sigma_rad_s
    drift0 = sig_m * np.random.standard_normal(3) if sig_m > 0.0 else np.zeros(3)
    held = np.full(3, np.nan)  # no output given yet (faults.held_sensor_faults_1)
    sensed = Sensed(
        np.zeros(3), np.zeros(3), drift0, held.copy(), x[0:4].copy(), np.zeros(3), np.zeros(3), held.copy(),
        held.copy(), held.copy(), np.zeros(RD_TACH + p.wheel_inertia.shape[0]),
    )  # fmt: skip
    filt = np.zeros(9)
    filt[6:9] = x[4:7]
    est = Estimate(x[0:4].copy(), x[4:7].copy(), np.zeros(3), estc.covariance0.copy(), filt)
    pos = Position(np.zeros(3), np.zeros(3), np.zeros(3), np.zeros(3), np.zeros(3), np.zeros(3), np.zeros(3))
    mode = mc.initial if mc.on else -1
    mode_state = np.full(modes.STATE_SIZE, np.nan)
    mode_state[modes.S_MODE], mode_state[modes.S_ENTERED] = max(mode, 0), 0.0
    scalars = np.zeros(N_SCALARS)
    scalars[C_MODE], scalars[C_SIGMA_U], scalars[C_VALID], scalars[C_MAG_OK] = mode, estc.gyro_drift_density, 1.0, 1.0
    return Carry(
        x,
        sensed,
        est,
        _initial_commands(p.wheel_inertia.shape[0]),
        _initial_monitors(p, estc.gyro_drift_density, var.available),
        pos,
        c.truth.friction.copy(),
        np.zeros(var.faults.shape[0], dtype=np.bool_),
        mode_state,
        scalars,
        np.zeros(0, dtype=np.uint8),
    )


# --- the block diagram ---------------------------------------------------------------------------------------


@njit(cache=True, nogil=True)
def fly_variant(
    c: LoopConfig,
    var: Variant,
    carry: Carry,
    rec: np.ndarray,
    ev: np.ndarray,
    n_ev: np.ndarray,
    shared: np.ndarray,
    slot: int,
) -> None:
    """Fly one variant from the state ``carry`` (its step ``C_STEP`` on, :func:`initial_carry` at t = 0) to the
    clock's last step, updating ``carry`` in place, and fill its output record ``rec`` (samples × R_* channels)
    and events ``ev``. The thread's random stream continues (initial_carry seeds it; run_batch restores it).

    ``c.model`` is the plant the onboard software models (law, allocation, FDIR); ``c.truth`` the one the
    dynamics fly. The law reads the estimate of ``c.estimator.kind`` (see :class:`EstimatorConfig`: the true
    state, the raw star tracker + gyro, the MEKF, seed 000 §4's mismatch filter, seed 003's body-rate
    estimator or TRIAD, or seed 002's gyro + earth-sensor observer); every seed model in ``c`` whose switch is
    off costs nothing and draws no random number. A sensor that gives no valid sample (failed; the star tracker
    also blinded or beyond its rate limit) is read by no stage: the estimators skip it, and without a magnetometer
    sample the rods act on no field (no dipole; two wheels give the in-plane torque, allocation.STATUS_NO_FIELD).
    Each stage receives only the blocks of ``c`` it reads (a call that carried all of ``c`` would pass and
    reference-count each of its arrays, at every dynamics step).
    ``shared[0]`` non-zero cancels the run (checked each T_u); ``shared[slot]`` receives the steps done.
    """
    clk, eph, prog, sens, estc, act, dist, mc = (
        c.clock,
        c.ephemeris,
        c.program,
        c.sensors,
        c.estimator,
        c.actuators,
        c.disturbances,
        c.modes,
    )
    p = c.model
    nq, nw = p.flex_mass.shape[0], p.wheel_inertia.shape[0]
    t_q, t_u = clk.measure_every * clk.dt_s, clk.control_every * clk.dt_s
    faults, fdir_on = var.faults, var.fdir_on
    has_faults = faults.shape[0] > 0
    friction_faults, stuck_faults = _flies_wheel_fault(faults, Y_FRICTION), _flies_wheel_fault(faults, Y_STUCK)
    x, sensed, est, cmd, mon, pos = carry.x, carry.sensed, carry.est, carry.cmd, carry.mon, carry.pos
    fault_state, mode_state, scalars = carry.fault_state, carry.mode_state, carry.scalars
    wheel_speeds = x[7 + 2 * nq : 7 + 2 * nq + nw]  # view: the integrator updates x in place
    markov = _markov_1(sens, t_q)
    plant = _flown_plant(c.truth, carry.friction)
    j_inv = np.linalg.inv(plant.inertia)
    work = np.zeros((6, x.shape[0] + 3 + nq + nw))
    ext = np.zeros(3)
    res = dist.residual_dipole_am2
    res_on = res[0] != 0.0 or res[1] != 0.0 or res[2] != 0.0
    mode, sigma_u = int(scalars[C_MODE]), scalars[C_SIGMA_U]
    flags, status, out_i = int(scalars[C_FLAGS]), int(scalars[C_STATUS]), 0
    md_on, have_mag_prev, valid = scalars[C_MD_ON] != 0.0, scalars[C_MAG_PREV] != 0.0, scalars[C_VALID] != 0.0
    mag_ok = scalars[C_MAG_OK] != 0.0
    no_field = np.zeros(3)  # the field the actuation reads while the magnetometer gives no valid sample
    every_step = dist.gravity_gradient or dist.aerodynamic or dist.solar_pressure  # models that need r, v each step
    sun_wanted = dist.solar_pressure or sens.star_cos_sun_exclusion <= 1.0
    k_next = clk.n_steps
    q_p, w_p, obs_p = np.zeros(4), np.zeros(3), False  # the scenario's program, sampled at T_u and output ticks
    # The arrays the per-step stages read, bound once: a tuple's array read inside the loop, or handed to a
    # stage function, is reference-counted (atomic, not pruned across the loop's branches) at every step.
    r_eci, v_eci, a_eci, b_eci, b_body, sun_eci, r_body = pos
    wheel_cmd, frozen_cmd, delivered, dipole = cmd.wheel_cmd, cmd.frozen_cmd, cmd.delivered, cmd.dipole
    moment, motor_current, rotor_phase, wheel_inertia = cmd.moment, cmd.motor_current, cmd.rotor_phase, p.wheel_inertia
    max_torque, max_momentum = act.max_torque_nm, act.max_momentum_nms
    noise_nm, imbalance = act.noise_nm, act.imbalance_nm_s2
    orbit_table, field_table, inertia_flown = eph.orbit_table, eph.field_table, plant.inertia
    friction_flown, friction_base, m = plant.friction, c.truth.friction, act.motor
    q_est, w_est, body_torque, available = est.q, est.omega, cmd.body_torque, mon.available
    frozen_torque, wheel_alloc, dipole_alloc, mag = cmd.frozen_torque, cmd.wheel_alloc, cmd.dipole_alloc, sensed.mag
    readings = sensed.readings
    wheel_axes, alloc_params, torque_quantum, c_pn = p.wheel_axes, act.allocation, act.torque_quantum_nm, eph.c_pn
    plate_normals, plate_areas, plate_centroids = (
        dist.surfaces.normals_b,
        dist.surfaces.areas_m2,
        dist.surfaces.centroids_b_m,
    )
    plate_specular, plate_diffuse, drag_coefficient = (
        dist.surfaces.specular,
        dist.surfaces.diffuse,
        dist.surfaces.drag_coefficient,
    )

    for k in range(int(scalars[C_STEP]), clk.n_steps):
        t = k * clk.dt_s
        measure = k % clk.measure_every == 0
        control_tick = k % clk.control_every == 0
        output = k % clk.output_every == 0
        orbit_due = every_step or md_on or control_tick or measure or output
        # ephemeris: orbit and field from the batch's tables (field into body axes by the true attitude), the Sun
        if sun_wanted and measure:
            sun_eci[:] = environment.sun_position_1(clk.t0_unix_s + t)
        if orbit_due:
            orbit.hermite_state_into(orbit_table, eph.orbit_t0_s, eph.orbit_step_s, t, r_eci, v_eci, a_eci)
        if md_on or res_on or measure:
            environment.field_table_into(field_table, eph.field_t0_s, eph.field_step_s, t, b_eci)
            conjugate_rotate_into(x, b_eci, b_body)
        if has_faults:
            flags = faults_mod.fault_transitions_1(faults, t, fault_state, ev, n_ev)
            if flags < 0:  # a fault began
                flags = -flags - 1
                _hold_outputs_stage(cmd)

        if measure:
            sample = _sense_stage(sens, faults, t, x, markov, pos, sensed)
            mag_ok = sample.mag_ok
            if fdir_on and mag_ok:
                _magnetometer_monitor_stage(sens, c.fdir, t, pos, sensed, est, mon, ev, n_ev)
            if estc.kind == ESTIMATOR_MEKF:
                valid, sigma_u = _mekf_stage(
                    estc, sens, c.fdir, t_q, var, k, t, x, pos, sensed, sample, sigma_u, est, mon, ev, n_ev
                )
            elif estc.kind == ESTIMATOR_TRIAD:
                valid = _triad_stage(sens, clk.t0_unix_s, faults, t, x, pos, sensed, sample.gyro_ok, sample.mag_ok, est)
            elif estc.kind == ESTIMATOR_EARTH_OBSERVER:
                tach = _tachometer_stage(sens.tachometer_quantum_rad_s, faults, t, wheel_speeds)
                valid = _earth_observer_stage(
                    estc, sens, p, c.fdir.n_sigma, fdir_on, faults, k, t, t_q, x, tach, pos, sensed, sample.gyro_ok,
                    est, mon, ev, n_ev,
                )  # fmt: skip
            elif estc.kind == ESTIMATOR_SEED000 or estc.kind == ESTIMATOR_SEED003:
                q_p, w_p, _, _ = program_at(prog, clk, c_pn, t, r_eci, v_eci, a_eci)
                _mismatch_filter_stage(estc, t_q, q_p, w_p, sensed, sample, est)
                valid = sample.star_ok
            else:
                _sample_estimate_stage(estc.kind, x, sensed.omega, sample, q_est, w_est)

        if control_tick:
            shared[slot] = k
            if shared[0] != 0:
                k_next = k
                break
            q_p, w_p, wd_p, obs_p = program_at(prog, clk, c_pn, t, r_eci, v_eci, a_eci)
            cmd.program[0:4] = q_p
            cmd.program[4:7] = w_p
            cmd.program[7:10] = wd_p
            if mc.on:
                sun_b = _sun_direction_1(
                    sens.sun_sensor_sigma_rad, clk.t0_unix_s, faults, t, x, est.q, pos.r, sensed.sun_frozen
                )
                mode = _mode_stage(mc, t, pos, sun_b, mode_state, mode, valid, est, mon.available, cmd, ev, n_ev)
            field = mag if mag_ok else no_field  # no valid sample: no field, the MD gives nothing (allocation)
            speeds = _tachometer_stage(sens.tachometer_quantum_rad_s, faults, t, wheel_speeds)
            readings[RD_TACH:] = speeds
            h_wheels = p.wheel_inertia * speeds
            if fdir_on:
                star_reset = estc.kind == ESTIMATOR_MEKF
                _wheel_monitor_stage(
                    p, act, sens.tachometer_quantum_rad_s, c.fdir.wheel_noise_sigma_nms, t_u, star_reset, t, speeds,
                    h_wheels, field, est, mon, ev, n_ev,
                )  # fmt: skip
            _law_stage(
                p.inertia, p.wheel_axes, p.wheel_inertia, c.law, mc.on, mode, q_est, w_est, speeds, h_wheels,
                available, cmd.program, cmd.lead_lag, body_torque,
            )  # fmt: skip
            status = _allocation_stage(
                wheel_axes, alloc_params, torque_quantum, max_torque, act.md_max_am2, faults, t, field, h_wheels,
                available, body_torque, frozen_torque, wheel_alloc, dipole_alloc, wheel_cmd, dipole,
            )  # fmt: skip
            if mc.on:
                _mode_actuation_stage(
                    p, act, mc.bdot_gain, t_u, mode, status, est, sensed, field, have_mag_prev and mag_ok, h_wheels,
                    mon.available, cmd,
                )  # fmt: skip
            sensed.mag_prev[:] = sensed.mag
            have_mag_prev = mag_ok  # B-dot differences two valid samples
            md_on = cmd.dipole[0] != 0.0 or cmd.dipole[1] != 0.0 or cmd.dipole[2] != 0.0
            if fdir_on:
                _wheel_hold_stage(p, act, c.fdir, t_u, speeds, est, field, cmd, mon)

        if output and out_i < rec.shape[0]:
            if not control_tick:  # a control tick has just sampled the scenario's program at t
                q_p, w_p, _, obs_p = program_at(prog, clk, c_pn, t, r_eci, v_eci, a_eci)
            _record_stage(
                nq, x, q_p, w_p, obs_p, r_eci, q_est, w_est, dipole, body_torque, wheel_cmd, delivered, available,
                readings, status, flags, mode, rec[out_i],
            )  # fmt: skip
            out_i += 1

        # actuators: the held commands (frozen ones for a frozen controller) under wheel faults, seed 000 eq (2)
        # limits, then (when flown) seed 002's motor electrics (eq 2-3), noise and imbalance (eq 1, 4)
        if has_faults:
            faults_mod.wheel_commands_1(faults, t, wheel_cmd, frozen_cmd, delivered)
        else:
            for w in range(nw):
                delivered[w] = wheel_cmd[w]
        wheels.limit_motor_torque_into(delivered, wheel_speeds, wheel_inertia, max_torque, max_momentum)
        if m.on:
            delivered[:] = wheels.driven_motor_torque_1(
                motor_current, delivered, wheel_speeds, clk.dt_s, m.inductance_h, m.resistance_ohm,
                m.torque_constant_nm_a, m.back_emf_v_s, m.max_voltage_v,
            )  # fmt: skip
        if act.disturbed:
            white = np.asarray(np.random.uniform(-1.0, 1.0, nw))
            delivered[:] = wheels.delivered_torque_1(delivered, wheel_speeds, rotor_phase, noise_nm, imbalance, white)
            wheels.advance_rotor_phase_1(rotor_phase, wheel_speeds, clk.dt_s)
        if friction_faults:
            faults_mod.extra_friction_1(faults, t, friction_flown, friction_base)
        # disturbances on the flown body: (MD + residual dipole) x B (sim_core.magnetic), gravity gradient
        ext[:] = 0.0
        if md_on or res_on:
            for i in range(3):
                moment[i] = dipole[i] + res[i]
            magnetic.magnetic_torque_into(moment, b_body, ext)
        if dist.gravity_gradient:
            conjugate_rotate_into(x, r_eci, r_body)
            environment.add_gravity_gradient_torque_into(r_body, inertia_flown, ext)
        if dist.aerodynamic:  # flat plates (sim_core.environment), allocation-free
            environment.add_aerodynamic_torque_orbit_into(
                x, r_eci, v_eci, drag_coefficient, plate_normals, plate_areas, plate_centroids, ext
            )
        if dist.solar_pressure:
            environment.add_solar_pressure_torque_orbit_into(
                x, r_eci, sun_eci, plate_normals, plate_areas, plate_centroids, plate_specular, plate_diffuse, ext
            )
        rk4_step_into(x, clk.dt_s, delivered, ext, plant, work, x)
        if stuck_faults:
            faults_mod.lock_stuck_wheels_1(faults, t + clk.dt_s, x, plant, j_inv)
    shared[slot] = k_next
    scalars[C_STEP], scalars[C_MODE], scalars[C_SIGMA_U], scalars[C_FLAGS], scalars[C_STATUS] = (
        k_next,
        mode,
        sigma_u,
        flags,
        status,
    )
    scalars[C_MD_ON], scalars[C_MAG_PREV], scalars[C_VALID], scalars[C_MAG_OK] = md_on, have_mag_prev, valid, mag_ok


def run_batch(config: LoopConfig, batch: Batch, out: Record, carries: list[Carry] | None = None) -> list[Carry]:
    """Fly every variant of ``batch`` with ``config``, one thread per core (this process' share of them:
    :func:`sim_core.threads.thread_budget`), into ``out``; returns each variant's
    :class:`Carry` at the end.

    ``fly_variant`` releases the GIL, so the threads run in parallel; each variant seeds its own
    random stream, so results do not depend on the thread count or order. ``carries`` (one per variant, from
    the previous call, whose clock ended where this one's flight begins): each variant resumes where it
    stopped, its random stream included, so that the segments joined are one flight.
    """
    from concurrent.futures import ThreadPoolExecutor

    def one(v: int) -> Carry:
        var = Variant(
            batch.x0[v],
            batch.available[v],
            batch.faults[v, : batch.n_faults[v]],
            bool(batch.fdir_on[v]),
            int(batch.seeds[v]),
        )
        if carries is None:
            carry = initial_carry(config, var)
        else:
            carry = carries[v]
            _set_random_state(carry.rng)
        fly_variant(config, var, carry, out.rec[v], out.ev[v], out.n_ev[v], out.shared, 1 + v)
        return carry._replace(rng=_random_state())

    n = batch.x0.shape[0]
    if n == 1:
        return [one(0)]
    with ThreadPoolExecutor(max_workers=min(n, thread_budget())) as pool:
        return list(pool.map(one, range(n)))


class _NumbaRandomState(ctypes.Structure):
    """numba's per-thread NumPy random state (``rnd_state_t`` of numba/_random.c): the Mersenne Twister and the
    second Gaussian of the last Box–Muller pair, which numba keeps for the next draw."""

    _fields_ = [
        ("index", ctypes.c_int),
        ("mt", ctypes.c_uint * 624),
        ("has_gauss", ctypes.c_int),
        ("gauss", ctypes.c_double),
        ("is_initialized", ctypes.c_int),
    ]


def _random_state() -> np.ndarray:
    """This thread's numba random state as bytes (numba's own get_state leaves out the kept Gaussian)."""
    from numba import _helperlib

    raw = ctypes.string_at(_helperlib.rnd_get_np_state_ptr(), ctypes.sizeof(_NumbaRandomState))  # type: ignore[attr-defined]
    return np.frombuffer(raw, dtype=np.uint8).copy()


def _set_random_state(state: np.ndarray) -> None:
    """Restore this thread's numba random state from :func:`_random_state`'s bytes."""
    from numba import _helperlib

    if state.dtype != np.uint8 or state.size != ctypes.sizeof(_NumbaRandomState):
        raise ValueError(f"carry.rng: expected {ctypes.sizeof(_NumbaRandomState)} bytes of random state")
    pointer = _helperlib.rnd_get_np_state_ptr()  # type: ignore[attr-defined]
    ctypes.memmove(pointer, np.ascontiguousarray(state).ctypes.data, state.size)
