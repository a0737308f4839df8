"""The batch engine: turns a :class:`~sim_core.scenario.Scenario` into arrays, flies every variant
through :func:`sim_core.closed_loop.run_batch` and returns a :class:`~sim_core.trajectory.Trajectory`.

Multi-rate (seed 000 §4): dynamics at ``dynamics_dt_s`` (RK4), measurements and estimation at
``measurement_dt_s`` (T_q), guidance, control and allocation at ``control_dt_s`` (T_u), output at
``output_dt_s``. The orbit and the magnetic field are tabulated once per batch (orbit every
``ORBIT_TABLE_STEP_S`` with velocity and acceleration for cubic Hermite interpolation, field every
``FIELD_TABLE_STEP_S``) so that the compiled loop needs no ephemeris calls.
"""

from __future__ import annotations

import functools
import time
from collections.abc import Callable, Sequence
from datetime import datetime
from typing import NamedTuple

import numpy as np
import numpy.typing as npt

from sim_core import (
    allocation,
    attitude_filters,
    closed_loop,
    earth_observer,
    environment,
    frames,
    guidance,
    mekf,
    modes,
    orbit,
    quaternion,
    wheels,
)
from sim_core import faults as fault_kernels
from sim_core import fdir as fdir_kernels
from sim_core.control import DigitalLawGains
from sim_core.guidance import OrbitState
from sim_core.scenario import Scenario
from sim_core.spacecraft import PlantParams, pack_state
from sim_core.trajectory import EVENT_NAMES, Trajectory

__all__ = [
    "simulate",
    "plant_params",
    "orbit_state",
    "allocation_params",
    "program_along",
    "ProgramSamples",
    "orbit_period_s",
    "turn_peak_rate",
    "MAX_EVENTS",
    "loop_config",
    "Flight",
]

ORBIT_TABLE_STEP_S = 10.0  # Hermite error ~ (ωh)⁴ r / 384 ≈ 0.2 mm at LEO
FIELD_TABLE_STEP_S = 30.0  # linear error ~ (2ω h)² B / 8 ≈ 1e-4 B (a few nT)
# rows of one IGRF date: magnetic_field_ecef_t dates its coefficients per hour of data from the first time
FIELD_CHUNK_ROWS = int(environment._CHUNK_S / FIELD_TABLE_STEP_S)
MAX_EVENTS = 256
ARCSEC = np.pi / 180.0 / 3600.0
PROGRESS_POLL_S = 0.2
MEKF_SIGMA0_RAD = 1e-3  # initial attitude uncertainty of the MEKF (≈ 3.4′): the start is the program
GG_BOUND_MARGIN = 1.5  # gravity-gradient bound 3μ/r³ (J_max − J_min), with room for eccentricity and perigee
MEKF_BIAS0_RAD_S = 1e-5  # initial gyro-bias uncertainty (≈ 2°/h)


LAWS = {
    "seed000": closed_loop.LAW_SEED000,
    "mrp_feedback": closed_loop.LAW_MRP_FEEDBACK,
    "quaternion_pd": closed_loop.LAW_QUATERNION_PD,
}
ESTIMATORS = {
    "truth": closed_loop.ESTIMATOR_TRUTH,
    "star_tracker": closed_loop.ESTIMATOR_STAR_TRACKER,
    "mekf": closed_loop.ESTIMATOR_MEKF,
    "seed000_filter": closed_loop.ESTIMATOR_SEED000,
    "seed003_rate": closed_loop.ESTIMATOR_SEED003,
    "triad": closed_loop.ESTIMATOR_TRIAD,
    "earth_observer": closed_loop.ESTIMATOR_EARTH_OBSERVER,
}


def _epoch_unix_s(text: str) -> float:
    try:
        return datetime.fromisoformat(text.replace("Z", "+00:00")).timestamp()
    except ValueError as exc:
        raise ValueError(f"orbit.epoch_utc: not an ISO-8601 time ({text!r})") from exc


def cluster_axes(s: Scenario) -> np.ndarray:
    """Wheel spin axes (3, n_w) in body axes for the scenario's cluster geometry (seed 000 §2)."""
    c = s.spacecraft.cluster
    if c.geometry == "ge":
        return allocation.ge_axes(np.radians(c.gamma_deg))
    if c.geometry == "orthogonal3":
        return wheels.orthogonal_axes()
    if c.geometry == "skew4":
        return wheels.skew_3plus1_axes()
    axes = np.asarray(c.axes_b, dtype=float).T
    unit_axes: npt.NDArray[np.float64] = axes / np.linalg.norm(axes, axis=0)
    return unit_axes


def plant_params(s: Scenario, truth: bool = False) -> PlantParams:
    """Plant of seed 000 eq (1) from the scenario; hub inertia gets the wheels added if asked.

    ``truth``: the plant as flown (the scenario's :class:`~sim_core.scenario.TruthSpec` inertia and wheel
    axes where given); otherwise the modelled one the onboard software holds."""
    t = s.truth if truth else None
    axes = cluster_axes(s)
    if t is not None and t.wheel_axes_b is not None:
        axes = np.asarray(t.wheel_axes_b, dtype=float).T
        axes = axes / np.linalg.norm(axes, axis=0)
    ws = s.spacecraft.cluster.wheels
    jr = np.array([w.inertia_kg_m2 for w in ws])
    j = np.asarray(s.spacecraft.inertia_kg_m2 if t is None or t.inertia_kg_m2 is None else t.inertia_kg_m2, dtype=float)
    if not s.spacecraft.inertia_includes_wheels:
        # Basilisk's balanced wheel: J_s along the spin axis, J_t = J_s/2 across it.
        for col, js in zip(axes.T, jr):
            gg = np.outer(col, col)
            j = j + js * gg + 0.5 * js * (np.eye(3) - gg)
    modes = s.spacecraft.flex_modes
    return PlantParams(
        inertia_kg_m2=j,
        wheel_axes_b=axes,
        wheels=wheels.WheelParams(
            inertia_kg_m2=jr,
            max_torque_nm=np.array([w.max_torque_nm for w in ws]),
            max_momentum_nms=np.array([w.max_momentum_nms for w in ws]),
            coulomb_nm=np.array([w.coulomb_nm for w in ws]),
            coulomb_sat_speed_rad_s=np.array([w.coulomb_sat_speed_rad_s for w in ws]),
            viscous_nm_s=np.array([w.viscous_nm_s for w in ws]),
            aero_drag_nm_s15=np.array([w.aero_drag_nm_s15 for w in ws]),
            noise_nm=np.array([w.noise_nm for w in ws]),
            imbalance_nm_s2=np.array([w.imbalance_nm_s2 for w in ws]),
        ),
        flex_coupling=np.array([m.coupling_b for m in modes]).T if modes else None,
        flex_modal_mass=np.array([m.modal_mass for m in modes]) if modes else None,
        flex_freq_rad_s=np.array([2 * np.pi * m.freq_hz for m in modes]) if modes else None,
        flex_log_decrement=np.array([m.log_decrement for m in modes]) if modes else None,
    )


def orbit_state(s: Scenario) -> OrbitState:
    """Callable t_unix_s → ECI r, v, a of the scenario's orbit (circular, J2 or SGP4)."""
    o = s.orbit
    t0 = _epoch_unix_s(o.epoch_utc)
    inc = (
        o.inclination_deg
        if o.inclination_deg is not None
        else float(orbit.sun_synchronous_inclination_deg(o.altitude_m))
    )
    if o.kind == "tle":
        if o.tle_line1 is None or o.tle_line2 is None:  # the Scenario validator already refuses this
            raise ValueError("orbit.tle_line1/tle_line2: both lines are required when kind is 'tle'")
        sat = orbit.parse_tle(o.tle_line1, o.tle_line2)

        def tle_state(t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
            r, v = orbit.propagate_tle(sat, t)
            return r, v, orbit.j2_acceleration(r)

        return tle_state
    if o.kind == "circular":

        def circular_state(t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
            r, v = orbit.circular_orbit(np.asarray(t) - t0, o.altitude_m, inc, o.raan_deg, o.arg_latitude_deg)
            rn = np.linalg.norm(r, axis=-1, keepdims=True)
            return r, v, -orbit.MU_EARTH_M3_S2 * r / rn**3

        return circular_state
    r0, v0 = orbit.circular_orbit(np.array([0.0]), o.altitude_m, inc, o.raan_deg, o.arg_latitude_deg)

    def j2_state(t_unix_s: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        t = np.atleast_1d(np.asarray(t_unix_s, dtype=float))
        order = np.argsort(t)
        r, v = np.empty((t.size, 3)), np.empty((t.size, 3))
        rr, vv = orbit.propagate_j2(r0[0], v0[0], np.maximum(t[order] - t0, 0.0))
        r[order], v[order] = rr, vv
        return r, v, orbit.j2_acceleration(r)

    return j2_state


Table = tuple[np.ndarray, float, float]  # rows, time of the first row (s from the epoch), step


def _orbit_rows(state: OrbitState, t0: float, duration_s: float, first: int = 0) -> np.ndarray:
    """Rows ``first``… of the orbit table to ``duration_s``: r, v, a every ORBIT_TABLE_STEP_S from −1 step."""
    t = np.arange(-ORBIT_TABLE_STEP_S, duration_s + 3 * ORBIT_TABLE_STEP_S, ORBIT_TABLE_STEP_S)[first:]
    if t.size == 0:
        return np.zeros((0, 9))
    r, v, a = state(t0 + t)
    return np.hstack([r, v, a])


def _field_rows(state: OrbitState, t0: float, duration_s: float, model: str, first: int = 0) -> np.ndarray:
    """Rows ``first``… of the field table to ``duration_s``: B (ECI, T) every FIELD_TABLE_STEP_S from −1 step
    (whole IGRF dates from row ``first`` on when it is a multiple of FIELD_CHUNK_ROWS)."""
    t = np.arange(-FIELD_TABLE_STEP_S, duration_s + 3 * FIELD_TABLE_STEP_S, FIELD_TABLE_STEP_S)[first:]
    if t.size == 0:
        return np.zeros((0, 3))
    r, _, _ = state(t0 + t)
    return environment.magnetic_field_eci_t(r, t0 + t, model)


def _orbit_table(state: OrbitState, t0: float, duration_s: float) -> Table:
    return np.ascontiguousarray(_orbit_rows(state, t0, duration_s)), -ORBIT_TABLE_STEP_S, ORBIT_TABLE_STEP_S


def _field_table(state: OrbitState, t0: float, duration_s: float, model: str) -> Table:
    rows = _field_rows(state, t0, duration_s, model)
    return np.ascontiguousarray(rows), -FIELD_TABLE_STEP_S, FIELD_TABLE_STEP_S


def _route_segments(s: Scenario) -> list[guidance.Segment]:
    g = s.guidance
    segs: list[guidance.Segment] = [guidance.OrfHold(g.route_start_s)] if g.route_start_s > 0 else []
    for seg in g.route:
        if seg.kind == "turn":
            segs.append(guidance.Turn(seg.duration_s))
        else:
            segs.append(guidance.OrfHold(seg.duration_s, seg.yaw_deg, seg.roll_deg, seg.pitch_deg, seg.observing))
    used = sum(x.duration_s for x in segs)
    tail = s.duration_s + 2 * s.control_dt_s - used
    if tail > 0:
        last = g.route[-1]
        segs.append(guidance.OrfHold(tail, last.yaw_deg, last.roll_deg, last.pitch_deg))
    return segs


def _program(
    s: Scenario, state: OrbitState, t0: float, c_pn: np.ndarray, w_pm: np.ndarray, dut1: float
) -> closed_loop.Program:
    g = s.guidance
    if g.kind == "inertial":
        steps_t = np.array([t for t, _ in g.inertial_steps], dtype=float)
        steps_q = quaternion.normalize(np.array([q for _, q in g.inertial_steps], dtype=float))
        order = np.argsort(steps_t)
        return closed_loop.Program(
            closed_loop.PROGRAM_INERTIAL,
            np.ascontiguousarray(steps_t[order]),
            np.ascontiguousarray(steps_q[order]),
            np.zeros((1, guidance.ROW_SIZE)),
        )
    segs = [guidance.OrfHold(s.duration_s + 2 * s.control_dt_s)] if g.kind == "orf" else _route_segments(s)
    route = guidance.compile_route(segs, t0, state, c_pn, dut1, w_pm)
    return closed_loop.Program(
        closed_loop.PROGRAM_ROUTE, np.zeros(1), np.array([[1.0, 0, 0, 0]]), np.ascontiguousarray(route)
    )


def _mode_config(s: Scenario, field_eci_t: np.ndarray) -> closed_loop.ModeConfig:
    """The onboard mode machine (sim_core.modes) of the scenario: on, initial mode, B-dot gain and the
    thresholds of :class:`sim_core.modes.ModeThresholds`. The route's window is always open: a route
    begins with its ORF hold, so ORF → route happens once the ORF pointing is ready.

    B-dot gain k/|B|² with k = 2n(1 + sin ξ)J_min (Avanzini & Giulietti 2012, ξ ≈ 90° on a polar
    or Sun-synchronous orbit), |B|² the orbit mean of the field table: L = −k Ḃ/|B|².
    """
    thresholds = np.ascontiguousarray(modes.ModeThresholds().to_array(), dtype=float)
    if s.initial_mode is None:
        return closed_loop.ModeConfig(False, 0, 0.0, thresholds)
    a = orbit.R_EARTH_M + s.orbit.altitude_m
    n = np.sqrt(orbit.MU_EARTH_M3_S2 / a**3)
    j_min = float(np.min(np.linalg.eigvalsh(np.asarray(s.spacecraft.inertia_kg_m2, dtype=float))))
    gain = 2.0 * n * 2.0 * j_min / float(np.mean(np.sum(field_eci_t**2, axis=1)))
    initial = {
        "rate_damping": modes.MODE_RATE_DAMPING,
        "sun_safe": modes.MODE_SUN_SAFE,
        "orf": modes.MODE_ORF,
        "route": modes.MODE_ROUTE,
    }[s.initial_mode]
    return closed_loop.ModeConfig(True, int(initial), float(gain), thresholds)


def allocation_params(s: Scenario) -> np.ndarray:
    """Parameter vector of ``allocation.allocate_1`` for the scenario's cluster (seed 000 eq 6, §3)."""
    a = s.allocation
    ws = s.spacecraft.cluster.wheels
    law4 = (
        allocation.LAW_GE_DISTRIBUTION
        if (a.kind == "ge_explicit" and s.spacecraft.cluster.geometry == "ge")
        else allocation.LAW_PSEUDO_INVERSE
    )
    return allocation.AllocationConfig(
        law4=law4,
        gamma_rad=np.radians(min(s.spacecraft.cluster.gamma_deg, 44.9)),
        rho=a.rho,
        mu_rho_per_s=a.mu_rho_per_s,
        phi_rho_per_s=a.phi_rho_per_s,
        h_max_nms=min(w.max_momentum_nms for w in ws),
        l_max_am2=s.spacecraft.md_max_dipole_am2,
        md_law=allocation.MD_LAW_SEED if a.md_law == "seed" else allocation.MD_LAW_PAIR_NORMAL,
    ).as_array()


def _fdir_flags(s: Scenario, on: bool | Sequence[bool]) -> np.ndarray:
    """One FDIR on/off flag per variant."""
    nv = len(s.variants)
    flags = np.broadcast_to(np.asarray(on, dtype=bool), (nv,)) if np.ndim(on) == 0 else np.asarray(on, dtype=bool)
    if flags.shape != (nv,):
        raise ValueError(f"fdir: expected one flag or {nv} flags (one per variant), got shape {flags.shape}")
    return np.ascontiguousarray(flags)


@functools.cache
def _fdir_quantiles() -> tuple[float, float]:
    """The FDIR tests' Gaussian σ multiple and star-tracker χ² threshold (scipy quantiles, ~2 ms: computed once)."""
    return fdir_kernels.gaussian_sigmas(), fdir_kernels.star_nis_threshold()


def _fdir_config(s: Scenario) -> closed_loop.FdirConfig:
    """FDIR thresholds from the sensor noise of the scenario (sim_core.fdir)."""
    n_sigma, nis_threshold = _fdir_quantiles()
    rate_noise = 0.0 if s.estimator.kind == "truth" else n_sigma * np.sqrt(2.0) * s.sensors.gyro_noise_rad_s
    bound = 0.0
    if s.gravity_gradient:
        r0 = np.linalg.norm(orbit_state(s)(np.array([_epoch_unix_s(s.orbit.epoch_utc)]))[0][0])
        eig = np.linalg.eigvalsh(np.asarray(s.spacecraft.inertia_kg_m2, dtype=float))
        bound = GG_BOUND_MARGIN * 3.0 * orbit.MU_EARTH_M3_S2 / r0**3 * (eig[-1] - eig[0])
    noise = fdir_kernels.wheel_noise_sigma(  # the loop draws seed 002's W once per dynamics step
        np.array([w.noise_nm for w in s.spacecraft.cluster.wheels], dtype=float), s.dynamics_dt_s, s.control_dt_s
    )
    return closed_loop.FdirConfig(float(rate_noise), float(nis_threshold), float(n_sigma), float(bound), noise)


class ProgramSamples(NamedTuple):
    """The programmed motion and its environment at sample times (engine frames and units)."""

    q_ib: np.ndarray
    omega_b: np.ndarray
    omega_dot_b: np.ndarray
    observing: np.ndarray
    r_eci_m: np.ndarray
    b_eci_t: np.ndarray


def program_along(s: Scenario, t_s: np.ndarray) -> ProgramSamples:
    """Λ^p, ω^p, ω̇^p, observing flag, ECI position and field at t_s after the epoch (seed 000 §5, seed 001)."""
    t = np.asarray(t_s, dtype=float)
    if t.ndim != 1 or not np.all(np.isfinite(t)) or np.any(t < 0.0) or np.any(t > s.duration_s + s.control_dt_s):
        raise ValueError(f"t_s: expected finite times within [0, duration_s = {s.duration_s}] s")
    t0 = _epoch_unix_s(s.orbit.epoch_utc)
    state = orbit_state(s)
    c_pn, w_pm, dut1 = frames.earth_orientation_frozen(t0)
    g = _program(s, state, t0, c_pn, w_pm, dut1)
    r, v, a = state(t0 + t)
    q, w, wd = np.empty((t.size, 4)), np.empty((t.size, 3)), np.empty((t.size, 3))
    obs = np.empty(t.size, dtype=bool)
    for i, ti in enumerate(t):
        q[i], w[i], wd[i], obs[i] = closed_loop.program_1(g, ti, t0, r[i], v[i], a[i], c_pn, dut1)
    b = environment.magnetic_field_eci_t(r, t0 + t, s.magnetic_model)
    return ProgramSamples(q, w, wd, obs, r, b)


def orbit_period_s(s: Scenario) -> float:
    """Keplerian period 2π √(a³/μ) of the scenario's orbit at its epoch, s."""
    t0 = _epoch_unix_s(s.orbit.epoch_utc)
    r, v, _ = orbit_state(s)(np.array([t0]))
    rn, vn = np.linalg.norm(r[0]), np.linalg.norm(v[0])
    sma = 1.0 / (2.0 / rn - vn * vn / orbit.MU_EARTH_M3_S2)
    return float(2.0 * np.pi * np.sqrt(sma**3 / orbit.MU_EARTH_M3_S2))


def turn_peak_rate(s: Scenario, route_index: int) -> float:
    """Bound on the rate of the turn ``guidance.route[route_index]`` as compiled (seed 001 envelope), rad/s."""
    g = s.guidance
    if g.kind != "route" or not 0 <= route_index < len(g.route) or g.route[route_index].kind != "turn":
        raise ValueError(f"route_index: guidance.route[{route_index}] is not a turn")
    t0 = _epoch_unix_s(s.orbit.epoch_utc)
    c_pn, w_pm, dut1 = frames.earth_orientation_frozen(t0)
    route = _program(s, orbit_state(s), t0, c_pn, w_pm, dut1).route
    shift = 1 if g.route_start_s > 0 else 0
    envelopes = dict(guidance.turn_envelopes(route))
    return float(envelopes[route_index + shift].max_rate_bound_rad_s)


class Cancelled(RuntimeError):
    """The run was cancelled through its ``cancel`` callback."""


def simulate(
    scenario: Scenario,
    progress: Callable[[float], None] | None = None,
    wheel_available: np.ndarray | None = None,
    cancel: Callable[[], bool] | None = None,
    fdir: bool | Sequence[bool] | None = None,
) -> Trajectory:
    """Fly every variant of the scenario and return the batch trajectory (seed 000 §7 twin).

    ``wheel_available`` (variants × wheels, optional): which wheels the onboard allocation may use
    from the start (a reconfigured cluster); default all. ``fdir`` (one flag, or one per variant;
    default: the scenario's ``fdir`` field) switches on the onboard FDIR of :mod:`sim_core.fdir`,
    which may drop wheels as it isolates them. ``progress`` gets the fraction done every ``PROGRESS_POLL_S``;
    ``cancel`` returning True stops the run and raises :class:`Cancelled`.
    """
    s = scenario
    start = time.perf_counter()
    flight = Flight(s, wheel_available, fdir)
    params = flight.params
    config = loop_config(s, params, flight.orbit, flight.t0_unix_s, flight.c_pn, flight.dut1_s, flight.start_program)
    out = _record(config.clock, 0, len(s.variants), params.n_wheels)
    _run_watched(config, flight.batch, out, config.clock.n_steps, progress, cancel, None)
    span = out.rec.shape[1] * config.clock.output_every * config.clock.dt_s
    return _trajectory(s, out, params, 0, min(span, s.duration_s), time.perf_counter() - start)


class Flight:
    """A flight flown in segments, without end (the emulator's stream): each :meth:`fly` goes on where the last
    stopped, handing over the loop's whole state (closed_loop.Carry: attitude, rates, wheel speeds, estimator,
    controller and monitors, fault and mode state, random streams), so that the segments joined are one
    flight, bit for bit the same as one ``fly`` of their summed duration. The scenario's ``duration_s`` is not
    used: the route's last hold lasts to the end of each segment; the ephemeris tables keep the epoch as origin
    (orbit and field of the flown span, the field in whole IGRF dates; each segment computes only its own rows,
    but for a J2 orbit, propagated from the epoch) and the Earth orientation stays frozen at the epoch; the B-dot
    gain of the mode machine is the first orbit's. :func:`simulate` flies one such segment,
    its tables only as long as its own duration (the field of its last IGRF hour dated at that hour's data)."""

    def __init__(
        self,
        scenario: Scenario,
        wheel_available: np.ndarray | None = None,
        fdir: bool | Sequence[bool] | None = None,
    ) -> None:
        s = scenario
        self.scenario, self.params = s, plant_params(s)
        self.t0_unix_s = _epoch_unix_s(s.orbit.epoch_utc)
        self.orbit = orbit_state(s)
        self.c_pn, self.w_pm, self.dut1_s = frames.earth_orientation_frozen(self.t0_unix_s)
        self.start_program = self.program(s)  # the route to the scenario's own duration
        self.batch = _initial_batch(s, self, wheel_available, fdir)
        self.steps_flown = 0
        self._carries: list[closed_loop.Carry] | None = None
        self._modes: closed_loop.ModeConfig | None = None
        self._orbit_rows, self._field_rows = np.zeros((0, 9)), np.zeros((0, 3))

    @property
    def flown_s(self) -> float:
        """Seconds flown since the epoch."""
        return self.steps_flown * self.scenario.dynamics_dt_s

    def program(self, s: Scenario) -> closed_loop.Program:
        """The programmed motion of ``s`` (this flight's scenario, or a copy flown to another end)."""
        return _program(s, self.orbit, self.t0_unix_s, self.c_pn, self.w_pm, self.dut1_s)

    def fly(self, duration_s: float) -> Trajectory:
        """Fly ``duration_s`` more (a whole number of dynamics steps) and return that segment's trajectory (times
        since the epoch)."""
        s, start = self.scenario, time.perf_counter()
        steps = round(duration_s / s.dynamics_dt_s) if np.isfinite(duration_s) else 0
        if steps < 1 or abs(steps * s.dynamics_dt_s - duration_s) > 1e-9 * max(duration_s, 1.0):
            raise ValueError(
                f"duration_s: expected a whole number (≥ 1) of {s.dynamics_dt_s} s steps, got {duration_s}"
            )
        end = self.steps_flown + steps
        seg = s.model_copy(update={"duration_s": end * s.dynamics_dt_s})
        tables = self._tables(seg.duration_s)
        config = loop_config(
            seg, self.params, self.orbit, self.t0_unix_s, self.c_pn, self.dut1_s, self.program(seg), tables
        )
        if self._modes is None:
            orbit_rows = int(orbit_period_s(s) // FIELD_TABLE_STEP_S) + 1
            self._modes = _mode_config(s, config.ephemeris.field_table[:orbit_rows])
        config = config._replace(modes=self._modes)
        out = _record(config.clock, self.steps_flown, len(s.variants), self.params.n_wheels)
        carries = _run_watched(config, self.batch, out, end, None, None, self._carries)
        first = -(-self.steps_flown // config.clock.output_every)
        self._carries, self.steps_flown = carries, end
        return _trajectory(s, out, self.params, first, duration_s, time.perf_counter() - start)

    def _tables(self, end_s: float) -> tuple[Table, Table]:
        """Orbit and field tables from the epoch to ``end_s`` (the field to a whole IGRF date): the last segment's
        rows and this one's, all recomputed for a J2 orbit (its propagation steps from the epoch to each time)."""
        s, t0 = self.scenario, self.t0_unix_s
        rows = -(-(end_s + 4 * FIELD_TABLE_STEP_S) // FIELD_TABLE_STEP_S)
        until = (-(-rows // FIELD_CHUNK_ROWS) * FIELD_CHUNK_ROWS - 4) * FIELD_TABLE_STEP_S
        kept_orbit, kept_field = (0, 0) if s.orbit.kind == "j2" else (len(self._orbit_rows), len(self._field_rows))
        new_orbit = _orbit_rows(self.orbit, t0, until, kept_orbit)
        new_field = _field_rows(self.orbit, t0, until, s.magnetic_model, kept_field)
        self._orbit_rows = np.concatenate([self._orbit_rows[:kept_orbit], new_orbit])
        self._field_rows = np.concatenate([self._field_rows[:kept_field], new_field])
        return (
            (self._orbit_rows, -ORBIT_TABLE_STEP_S, ORBIT_TABLE_STEP_S),
            (self._field_rows, -FIELD_TABLE_STEP_S, FIELD_TABLE_STEP_S),
        )


def _initial_batch(
    s: Scenario, flight: Flight, wheel_available: np.ndarray | None, fdir: bool | Sequence[bool] | None
) -> closed_loop.Batch:
    """Every variant's start: the scenario's attitude, else the programmed one at t = 0 turned by ``initial_q_pb``
    (moving with the program: its rate in body axes), wheel speeds, the wheels the allocation may use, fault rows,
    FDIR flag and random seed."""
    params, t0 = flight.params, flight.t0_unix_s
    nw, nv = params.n_wheels, len(s.variants)
    r0, v0, a0 = flight.orbit(np.array([t0]))
    q_p0, w_p0, _, _ = closed_loop.program_1(
        flight.start_program, 0.0, t0, r0[0], v0[0], a0[0], flight.c_pn, flight.dut1_s
    )
    q_init, w_init = q_p0, w_p0
    if s.initial_q_ib is not None:
        q_init = quaternion.normalize(np.array(s.initial_q_ib))
    elif s.initial_q_pb is not None:
        q_pb = quaternion.normalize(np.array(s.initial_q_pb))
        q_init, w_init = quaternion.multiply(q_p0, q_pb), quaternion.rotate(quaternion.conjugate(q_pb), w_p0)
    if s.initial_omega_b_rad_s is not None:
        w_init = np.array(s.initial_omega_b_rad_s)
    speeds = np.array([w.initial_speed_rpm for w in s.spacecraft.cluster.wheels]) * np.pi / 30.0
    x0 = pack_state(params, q_init, w_init, speeds)
    avail = np.ones((nv, nw), dtype=np.bool_) if wheel_available is None else np.asarray(wheel_available, bool)
    if avail.shape != (nv, nw):
        raise ValueError(f"wheel_available: expected shape ({nv}, {nw}), got {avail.shape}")
    faults, n_faults = fault_kernels.fault_table(s.variants)
    seeds = np.array([s.seed * 1000 + i * 7919 + v.seed_offset for i, v in enumerate(s.variants)], dtype=np.int64)
    return closed_loop.Batch(
        np.repeat(x0[None], nv, axis=0),
        np.ascontiguousarray(avail),
        faults,
        n_faults,
        _fdir_flags(s, s.fdir if fdir is None else fdir),
        seeds,
    )


def _record(clock: closed_loop.Clock, first_step: int, nv: int, nw: int) -> closed_loop.Record:
    """Empty outputs for the steps first_step … clock.n_steps − 1 of nv variants."""
    n_out = -(-clock.n_steps // clock.output_every) - (-(-first_step // clock.output_every))
    return closed_loop.Record(
        np.zeros((nv, n_out, closed_loop.record_width(nw))),
        np.zeros((nv, MAX_EVENTS, 3)),
        np.zeros((nv, 1), dtype=np.int64),
        np.zeros(nv + 1, dtype=np.int64),
    )


def _unit(v: Sequence[float]) -> np.ndarray:
    a = np.array(v, dtype=float)
    n = float(np.linalg.norm(a))
    if n == 0.0:
        raise ValueError("sensors.star_tracker_boresight_b: a zero vector has no direction")
    return a / n


def _motor_model(s: Scenario) -> closed_loop.MotorModel:
    """Seed 002 motor electrics of the cluster (off when ``spacecraft.cluster.motor`` is None)."""
    m = s.spacecraft.cluster.motor
    if m is None:
        return closed_loop.MotorModel(False, 1.0, 1.0, 1.0, 1.0, 1.0)
    return closed_loop.MotorModel(
        True,
        float(m.inductance_h),
        float(m.resistance_ohm),
        float(m.torque_constant_nm_a),
        float(m.back_emf_v_s),
        float(m.max_voltage_v),
    )


def _surfaces(s: Scenario) -> closed_loop.Surfaces:
    """The spacecraft's outer plates as arrays (rows), for the aerodynamic and solar-pressure torques."""
    sf = s.spacecraft.surfaces
    if (s.aerodynamic_torque or s.solar_pressure_torque) and not sf:
        raise ValueError("spacecraft.surfaces: aerodynamic_torque/solar_pressure_torque need at least one plate")
    return closed_loop.Surfaces(
        np.array([p.normal_b for p in sf], dtype=float).reshape(-1, 3),
        np.array([p.area_m2 for p in sf], dtype=float),
        np.array([p.centroid_b_m for p in sf], dtype=float).reshape(-1, 3),
        np.array([p.specular for p in sf], dtype=float),
        np.array([p.diffuse for p in sf], dtype=float),
        float(s.spacecraft.drag_coefficient),
    )


@functools.lru_cache(maxsize=64)
def _filter_gains(q: float, r: float, t_q: float) -> tuple[float, float, float, np.ndarray, np.ndarray]:
    """k_α, k_ω, the smoother's 1 − exp(−T_q/T) and (Φ, Γ) of the per-axis filters for densities q, r at T_q
    (sim_core.attitude_filters; a Riccati solution and a matrix exponential, ~9 ms: a live twin re-synchronising
    the same satellite asks for the same ones every time). Callers copy Φ and Γ."""
    k_alpha, k_omega = attitude_filters.discrete_gains(q, r, t_q)
    k12, k22 = attitude_filters.continuous_gains(q, r)
    time_constant, _ = attitude_filters.time_constant_and_damping(k12, k22)
    phi, gamma = attitude_filters.body_rate_discretisation(k12, k22, t_q)
    return k_alpha, k_omega, float(1.0 - np.exp(-t_q / time_constant)), phi, gamma


def _estimator_config(s: Scenario, orbit_rate_rad_s: float) -> closed_loop.EstimatorConfig:
    """The estimator the law reads, with the steady-state gains of the per-axis filters (sim_core.attitude_filters):
    measurement density r = σ_st² T_q, disturbance density q = ``estimator.disturbance_density_rad2_s3``; for seed
    002's observer (eq 15) its exact ZOH at T_q and orbital rate ω_o, and as the estimate's covariance (what the
    earth-sensor screen of sim_core.fdir reads) the observer's steady-state error covariance."""
    t_q, est = s.measurement_dt_s, s.estimator
    r = max((s.sensors.star_tracker_sigma_arcsec * ARCSEC) ** 2 * t_q, 1e-30)
    k_alpha, k_omega, smoothing, phi, gamma = _filter_gains(est.disturbance_density_rad2_s3, r, t_q)
    gains = np.array(est.observer_gains_1_s, dtype=float)
    obs_phi, obs_gamma = earth_observer.observer_discretisation(gains, orbit_rate_rad_s, t_q)
    covariance = mekf.initial_covariance(MEKF_SIGMA0_RAD, MEKF_BIAS0_RAD_S)
    if est.kind == "earth_observer":
        covariance = np.zeros((6, 6))
        p_err = earth_observer.error_covariance(gains, orbit_rate_rad_s, s.sensors.earth_sensor_sigma_rad, t_q)
        order = [1, 2, 0]  # the seed's (φ, θ, ψ) are about body y, z, x
        covariance[np.ix_(order, order)] = p_err
    return closed_loop.EstimatorConfig(
        ESTIMATORS[est.kind],
        covariance,
        float(s.sensors.gyro_drift_density_rad_s_sqrt_s),
        k_alpha,
        k_omega,
        smoothing,
        np.array(phi, order="C"),
        np.array(gamma, order="C"),
        np.ascontiguousarray(obs_phi),
        np.ascontiguousarray(obs_gamma),
        float(orbit_rate_rad_s),
        np.array(est.observer_initial_rad or [0.0, 0.0, 0.0], dtype=float),
        est.observer_initial_rad is not None,
        float(np.min(gains)),
        float(np.max(gains)),
    )


def loop_config(
    s: Scenario,
    params: PlantParams,
    state: OrbitState,
    t0: float,
    c_pn: np.ndarray,
    dut1: float,
    program: closed_loop.Program,
    tables: tuple[Table, Table] | None = None,
) -> closed_loop.LoopConfig:
    """The typed configuration of :func:`sim_core.closed_loop.fly_variant` for the scenario: every block's
    parameters by name (plant as modelled and as flown, clock, ephemeris tables, sensors, estimator, law,
    actuators, disturbances, modes, FDIR). ``tables``: the orbit and field tables (default: to the scenario's
    duration)."""
    dt = s.dynamics_dt_s
    every = [int(round(getattr(s, name) / dt)) for name in ("measurement_dt_s", "control_dt_s", "output_dt_s")]
    clock = closed_loop.Clock(
        int(round(s.duration_s / dt)), float(dt), every[0], every[1], every[2], float(t0), float(dut1)
    )
    orbit_tab, field_tab = tables or (
        _orbit_table(state, t0, s.duration_s),
        _field_table(state, t0, s.duration_s, s.magnetic_model),
    )
    ephemeris = closed_loop.Ephemeris(*orbit_tab, *field_tab, np.ascontiguousarray(c_pn))
    sn, c, ws = s.sensors, s.controller, s.spacecraft.cluster.wheels
    sensor_models = closed_loop.SensorModels(
        float(sn.star_tracker_sigma_arcsec * ARCSEC),
        float(sn.gyro_noise_rad_s),
        np.array(sn.gyro_bias_rad_s, dtype=float),
        float(sn.gyro_markov_sigma_rad_s),
        float(sn.gyro_markov_tau_s),
        float(sn.magnetometer_noise_t),
        float(sn.tachometer_quantum_rad_s),
        float(sn.sun_sensor_sigma_rad),
        _unit(sn.star_tracker_boresight_b),
        float(np.cos(np.radians(sn.star_tracker_sun_exclusion_deg)))
        if sn.star_tracker_sun_exclusion_deg > 0.0
        else closed_loop.NEVER_BLINDED_COS,
        float(sn.star_tracker_max_rate_rad_s or closed_loop.NO_RATE_LIMIT_RAD_S),
        float(sn.earth_sensor_sigma_rad),
        np.array(sn.earth_sensor_bias_rad, dtype=float),
    )
    r0, v0, _ = state(np.array([t0]))
    estimator = _estimator_config(s, float(np.linalg.norm(np.cross(r0[0], v0[0])) / (r0[0] @ r0[0])))  # ω_o = |h|/r²
    law = closed_loop.LawConfig(
        LAWS[c.kind],
        DigitalLawGains(c.gain_k_per_s2, c.tau1_s, c.tau2_s, s.control_dt_s).as_array(),
        bool(c.gyroscopic_compensation),
        float(c.pd_kp_nm),
        float(c.pd_kd_nms),
        float(c.mrp_k_nm),
        float(c.mrp_p_nms),
        0,
    )
    actuators = closed_loop.Actuators(
        np.array([w.max_torque_nm for w in ws], dtype=float),
        np.array([w.max_momentum_nms for w in ws], dtype=float),
        np.array([w.torque_quantum_nm for w in ws], dtype=float),
        float(s.spacecraft.md_max_dipole_am2),
        allocation_params(s),
        _motor_model(s),
        np.array([w.noise_nm for w in ws], dtype=float),
        np.array([w.imbalance_nm_s2 for w in ws], dtype=float),
        any(w.noise_nm > 0.0 or w.imbalance_nm_s2 > 0.0 for w in ws),
    )
    disturbances = closed_loop.Disturbances(
        bool(s.gravity_gradient),
        np.array(s.spacecraft.residual_dipole_am2, dtype=float),
        bool(s.aerodynamic_torque),
        bool(s.solar_pressure_torque),
        _surfaces(s),
    )
    packed = params.pack()
    flown = plant_params(s, truth=True).pack() if s.truth is not None else packed
    return closed_loop.LoopConfig(
        packed,
        flown,
        clock,
        ephemeris,
        program,
        sensor_models,
        estimator,
        law,
        actuators,
        disturbances,
        _mode_config(s, field_tab[0]),
        _fdir_config(s),
    )


def _run_watched(
    config: closed_loop.LoopConfig,
    batch: closed_loop.Batch,
    out: closed_loop.Record,
    n_steps: int,
    progress: Callable[[float], None] | None,
    cancel: Callable[[], bool] | None,
    carries: list[closed_loop.Carry] | None,
) -> list[closed_loop.Carry]:
    """Run the compiled batch (from ``carries`` if given); if watched, in a thread while this one reports
    progress and polls cancel. Returns the variants' carries."""
    if progress is None and cancel is None:
        return closed_loop.run_batch(config, batch, out, carries)
    import threading

    shared, done = out.shared, []
    worker = threading.Thread(
        target=lambda: done.extend(closed_loop.run_batch(config, batch, out, carries)), daemon=True
    )
    worker.start()
    while worker.is_alive():
        worker.join(PROGRESS_POLL_S)
        if cancel is not None and cancel():
            shared[0] = 1
        if progress is not None:
            progress(float(shared[1:].min()) / max(n_steps, 1))
    if shared[0]:
        raise Cancelled("simulation cancelled")
    return done


def _trajectory(
    s: Scenario, out: closed_loop.Record, params: PlantParams, first: int, span: float, wall: float
) -> Trajectory:
    """The trajectory of a record whose first sample is output number ``first`` since the epoch."""
    cl, rec, ev, n_ev, nw = closed_loop, out.rec, out.ev, out.n_ev, params.n_wheels
    w0 = cl.R_WHEELS
    series = {
        "q_ib": rec[..., cl.R_Q : cl.R_Q + 4],
        "omega_b_rad_s": rec[..., cl.R_W : cl.R_W + 3],
        "q_est_ib": rec[..., cl.R_QE : cl.R_QE + 4],
        "omega_est_b_rad_s": rec[..., cl.R_WE : cl.R_WE + 3],
        "q_prog_ib": rec[..., cl.R_QP : cl.R_QP + 4],
        "omega_prog_b_rad_s": rec[..., cl.R_WP : cl.R_WP + 3],
        "md_dipole_am2": rec[..., cl.R_MD : cl.R_MD + 3],
        "control_torque_b_nm": rec[..., cl.R_TORQUE : cl.R_TORQUE + 3],
        "r_eci_m": rec[..., cl.R_R : cl.R_R + 3],
        "observing": rec[..., cl.R_OBS],
        "allocation_status": rec[..., cl.R_STATUS].astype(np.int64),
        "fault_flags": rec[..., cl.R_FAULTS].astype(np.int64),
        "mode": rec[..., cl.R_MODE].astype(np.int64),
        "wheel_speed_rad_s": rec[..., w0 : w0 + nw],
        "wheel_torque_cmd_nm": rec[..., w0 + nw : w0 + 2 * nw],
        "wheel_torque_nm": rec[..., w0 + 2 * nw : w0 + 3 * nw],
        "wheel_available": rec[..., w0 + 3 * nw : w0 + 4 * nw] > 0.5,
        "b_mag_b_t": rec[..., cl.R_READINGS + cl.RD_MAG : cl.R_READINGS + cl.RD_MAG + 3],
        "omega_gyro_b_rad_s": rec[..., cl.R_READINGS + cl.RD_GYRO : cl.R_READINGS + cl.RD_GYRO + 3],
        "q_st_ib": rec[..., cl.R_READINGS + cl.RD_STAR : cl.R_READINGS + cl.RD_STAR + 4],
        "wheel_tachometer_rad_s": rec[..., w0 + 4 * nw : w0 + 5 * nw],
    }
    events = [
        [
            (float(ev[v, i, 0]), EVENT_NAMES.get(int(ev[v, i, 1]), str(int(ev[v, i, 1]))), int(ev[v, i, 2]))
            for i in range(int(n_ev[v, 0]))
        ]
        for v in range(len(s.variants))
    ]
    t = (first + np.arange(rec.shape[1])) * s.output_dt_s
    return Trajectory(
        scenario_name=s.name,
        variant_names=[v.name for v in s.variants],
        t_s=t,
        series=series,
        events=events,
        wheel_inertia_kg_m2=params.wheels.inertia_kg_m2.copy(),
        wall_time_s=wall,
        simulated_time_s=float(span),
        extra={"epoch_unix_s": _epoch_unix_s(s.orbit.epoch_utc)},
    )
