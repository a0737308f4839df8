"""Programmed motion Λ^p(t), ω^p(t), ω̇^p(t): ORF stabilisation, ground-target pointing, routes.

Seed 000 §2–§5: the body attitude relative to the ORF is Λ^o = Λ̃_o ∘ Λ, so holding the ORF offset
Λ^o_d (yaw φ1 about x, roll φ2 about y, pitch φ3 about z, sequence 132) means the program
Λ^p = Λ_o(t) ∘ Λ^o_d with ω^p = Λ̃^o_d ∘ ω_o ∘ Λ^o_d and ω̇^p likewise, ω_o being the ORF rate in
ORF axes. A trace-scanning route (seed 000 §5, Figs 3–4) chains such holds (scanning courses) with
seed 001 scheduled turns between them (e.g. the 20° roll manoeuvre: a roll about y^o moves the
boresight +x across track). A ground-target segment points +x at an ECEF point with body +z kept as
close as possible to a fixed inertial direction (the yaw constraint).

Conventions (DESIGN.md, sim_core.frames): ``q_ib`` quaternions, rates in body axes, ECI metres;
route times are UTC seconds since the Unix epoch (``t_unix_s``) because ground targets turn with the
Earth. The ORF turns at ω_o = (−r (a·ĥ)/h, 0, −h/r²) in ORF axes (h = r × v; the x^o part is the
orbit plane turning under out-of-plane forces, ≈4e-7 rad/s from J2 at 600 km); ω̇_o keeps the
z^o part exactly and drops d/dt of the x^o part, which needs the jerk (≈ 2n·ω_x ≈ 1e-9 rad/s², J2).

A route is compiled into a 2-D float64 array (one row per segment, layout below) that the kernel
:func:`route_1` evaluates inside the engine loop.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
from numba import njit

from sim_core import frames, quaternion
from sim_core.quaternion import dot3_1, multiply_1
from sim_core.scheduled_turn import PLAN_SIZE, TurnEnvelope, plan_scheduled_turn, scheduled_turn_1, turn_envelope

__all__ = [
    "OrfHold",
    "GroundTarget",
    "Turn",
    "KIND_ORF_HOLD",
    "KIND_TURN",
    "KIND_TARGET",
    "ROW_SIZE",
    "OrbitState",
    "orf_rates_1",
    "orf_hold_1",
    "sun_pointing_1",
    "orf_hold_program",
    "orf_angles_deg",
    "target_pointing_1",
    "target_pointing_program",
    "ground_target_state_1",
    "segment_program_1",
    "route_1",
    "compile_route",
    "route_program",
    "turn_envelopes",
    "two_course_scan",
]

KIND_ORF_HOLD, KIND_TURN, KIND_TARGET = 0, 1, 2

# Route row layout.
COL_KIND = 0  # KIND_* code
COL_T0 = 1  # segment start, t_unix_s
COL_T1 = 2  # segment end, t_unix_s
COL_OBSERVING = 3  # 1.0 when the payload observes on this segment
COL_OFFSET = 4  # ORF hold: Λ^o_d (4)
COL_PLAN = 8  # turn: scheduled-turn plan (PLAN_SIZE)
COL_TARGET = COL_PLAN + PLAN_SIZE  # target: ECEF position, m (3)
COL_YAW_REF = COL_TARGET + 3  # target: inertial yaw-reference direction u (3)
COL_POLAR = COL_YAW_REF + 3  # target: frozen polar-motion matrix W (TIRS → ITRS), row-major (9)
ROW_SIZE = COL_POLAR + 9

OrbitState = Callable[[np.ndarray], tuple[np.ndarray, np.ndarray, np.ndarray]]
"""Callable t_unix_s (n,) → ECI r (n,3) m, v (n,3) m/s, a (n,3) m/s² of the spacecraft centre."""


@njit(cache=True)
def _orf_rate_1(r_eci: np.ndarray, v_eci: np.ndarray, a_eci: np.ndarray) -> tuple[float, float, float]:
    """ω_o·x^o = −r (a·ĥ)/h, ω_o·z^o = −h/r² and d/dt(ω_o·z^o) = −ḣ/r² + 2h(r·v)/r⁴, ḣ = ĥ·(r × a)."""
    hx = r_eci[1] * v_eci[2] - r_eci[2] * v_eci[1]
    hy = r_eci[2] * v_eci[0] - r_eci[0] * v_eci[2]
    hz = r_eci[0] * v_eci[1] - r_eci[1] * v_eci[0]
    h = np.sqrt(hx * hx + hy * hy + hz * hz)
    r2 = r_eci[0] ** 2 + r_eci[1] ** 2 + r_eci[2] ** 2
    rv = r_eci[0] * v_eci[0] + r_eci[1] * v_eci[1] + r_eci[2] * v_eci[2]
    a_normal = (a_eci[0] * hx + a_eci[1] * hy + a_eci[2] * hz) / h
    h_dot = (
        hx * (r_eci[1] * a_eci[2] - r_eci[2] * a_eci[1])
        + hy * (r_eci[2] * a_eci[0] - r_eci[0] * a_eci[2])
        + hz * (r_eci[0] * a_eci[1] - r_eci[1] * a_eci[0])
    ) / h
    return -np.sqrt(r2) * a_normal / h, -h / r2, -h_dot / r2 + 2.0 * h * rv / (r2 * r2)


@njit(cache=True)
def orf_rates_1(r_eci: np.ndarray, v_eci: np.ndarray, a_eci: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """ORF rate ω_o and ω̇_o in ORF axes from the orbital motion (seed 000 §2 ORF; see module notes)."""
    wx, wz, wdz = _orf_rate_1(r_eci, v_eci, a_eci)
    w, wd = np.zeros(3), np.zeros(3)
    w[0], w[2], wd[2] = wx, wz, wdz
    return w, wd


@njit(cache=True)
def orf_hold_1(
    q_offset: np.ndarray, r_eci: np.ndarray, v_eci: np.ndarray, a_eci: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """ORF stabilisation Λ^p = Λ_o ∘ Λ^o_d, ω^p = Λ̃^o_d ∘ ω_o ∘ Λ^o_d, ω̇^p likewise (seed 000 §2)."""
    wx, wz, wdz = _orf_rate_1(r_eci, v_eci, a_eci)
    q0, q1, q2, q3 = q_offset[0], q_offset[1], q_offset[2], q_offset[3]
    x_b0, x_b1, x_b2 = 1.0 - 2.0 * (q2 * q2 + q3 * q3), 2.0 * (q1 * q2 - q0 * q3), 2.0 * (q1 * q3 + q0 * q2)
    z_b0, z_b1, z_b2 = 2.0 * (q1 * q3 - q0 * q2), 2.0 * (q2 * q3 + q0 * q1), 1.0 - 2.0 * (q1 * q1 + q2 * q2)
    w, wd = np.empty(3), np.empty(3)  # x^o, z^o in body axes: first and third rows of R(Λ^o_d)
    w[0], w[1], w[2] = wx * x_b0 + wz * z_b0, wx * x_b1 + wz * z_b1, wx * x_b2 + wz * z_b2
    wd[0], wd[1], wd[2] = wdz * z_b0, wdz * z_b1, wdz * z_b2
    return multiply_1(frames.orf_quaternion_1(r_eci, v_eci), q_offset), w, wd


@njit(cache=True)
def _unit_derivatives_1(a: np.ndarray, ad: np.ndarray, add: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """n = a/|a| and its first two time derivatives from a, ȧ, ä (exact differentiation)."""
    s = np.sqrt(dot3_1(a, a))
    n = a / s
    sd = dot3_1(n, ad)
    nd = (ad - sd * n) / s
    sdd = dot3_1(nd, ad) + dot3_1(n, add)
    ndd = (add - sdd * n - 2.0 * sd * nd) / s
    return n, nd, ndd


@njit(cache=True)
def _quaternion_of_axes_1(x: np.ndarray, y: np.ndarray, z: np.ndarray) -> np.ndarray:
    """Quaternion whose body axes are the orthonormal columns x, y, z (Shepperd, largest pivot)."""
    m00, m11, m22 = x[0], y[1], z[2]
    tr = m00 + m11 + m22
    q = np.empty(4)
    if tr >= m00 and tr >= m11 and tr >= m22:
        q[0] = 0.5 * np.sqrt(1.0 + tr)
        f = 0.25 / q[0]
        q[1], q[2], q[3] = (y[2] - z[1]) * f, (z[0] - x[2]) * f, (x[1] - y[0]) * f
    elif m00 >= m11 and m00 >= m22:
        q[1] = 0.5 * np.sqrt(1.0 + 2.0 * m00 - tr)
        f = 0.25 / q[1]
        q[0], q[2], q[3] = (y[2] - z[1]) * f, (y[0] + x[1]) * f, (z[0] + x[2]) * f
    elif m11 >= m22:
        q[2] = 0.5 * np.sqrt(1.0 + 2.0 * m11 - tr)
        f = 0.25 / q[2]
        q[0], q[1], q[3] = (z[0] - x[2]) * f, (y[0] + x[1]) * f, (z[1] + y[2]) * f
    else:
        q[3] = 0.5 * np.sqrt(1.0 + 2.0 * m22 - tr)
        f = 0.25 / q[3]
        q[0], q[1], q[2] = (x[1] - y[0]) * f, (z[0] + x[2]) * f, (z[1] + y[2]) * f
    return q


@njit(cache=True)
def target_pointing_1(
    r_eci: np.ndarray,
    v_eci: np.ndarray,
    a_eci: np.ndarray,
    r_target: np.ndarray,
    v_target: np.ndarray,
    a_target: np.ndarray,
    yaw_ref: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Boresight +x at the target, +z nearest the inertial u; ω^p, ω̇^p by exact differentiation (seed 000 §6 LOS)."""
    x, xd, xdd = _unit_derivatives_1(r_target - r_eci, v_target - v_eci, a_target - a_eci)
    ux, uxd, uxdd = dot3_1(yaw_ref, x), dot3_1(yaw_ref, xd), dot3_1(yaw_ref, xdd)
    zt = yaw_ref - ux * x
    ztd = -uxd * x - ux * xd
    ztdd = -uxdd * x - 2.0 * uxd * xd - ux * xdd
    z, zd, zdd = _unit_derivatives_1(zt, ztd, ztdd)
    y = np.cross(z, x)
    yd = np.cross(zd, x) + np.cross(z, xd)
    ydd = np.cross(zdd, x) + 2.0 * np.cross(zd, xd) + np.cross(z, xdd)
    w = np.array([dot3_1(yd, z), dot3_1(zd, x), dot3_1(xd, y)])  # Ṙ = R[ω]× with R = [x y z]
    wd = np.array([dot3_1(ydd, z) + dot3_1(yd, zd), dot3_1(zdd, x) + dot3_1(zd, xd), dot3_1(xdd, y) + dot3_1(xd, yd)])
    return _quaternion_of_axes_1(x, y, z), w, wd


@njit(cache=True)
def ground_target_state_1(
    r_ecef: np.ndarray, c_pn: np.ndarray, w_pm: np.ndarray, era_rad: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """ECI position, velocity ω⊕ × r, acceleration ω⊕ × (ω⊕ × r) of an Earth-fixed point (frozen C, W)."""
    r = frames.ecef_to_eci_1(r_ecef, c_pn, w_pm, era_rad)
    spin = frames.EARTH_ROTATION_RATE_RAD_S * c_pn[2, :]  # CIP axis in ECI: Cᵗ e_z
    v = np.cross(spin, r)
    return r, v, np.cross(spin, v)


@njit(cache=True)
def segment_program_1(
    row: np.ndarray, t: float, r_eci: np.ndarray, v_eci: np.ndarray, a_eci: np.ndarray, c_pn: np.ndarray, dut1: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Λ^p, ω^p, ω̇^p of one route segment at t_unix_s (seed 000 §5 route, seed 001 turn)."""
    kind = int(row[COL_KIND])
    if kind == KIND_TURN:
        return scheduled_turn_1(row[COL_PLAN : COL_PLAN + PLAN_SIZE], t)
    if kind == KIND_ORF_HOLD:
        return orf_hold_1(row[COL_OFFSET : COL_OFFSET + 4], r_eci, v_eci, a_eci)
    w_pm = np.empty((3, 3))
    for i in range(3):
        for j in range(3):
            w_pm[i, j] = row[COL_POLAR + 3 * i + j]
    era = frames.earth_rotation_angle_1(t + dut1)
    r_t, v_t, a_t = ground_target_state_1(row[COL_TARGET : COL_TARGET + 3], c_pn, w_pm, era)
    return target_pointing_1(r_eci, v_eci, a_eci, r_t, v_t, a_t, row[COL_YAW_REF : COL_YAW_REF + 3])


@njit(cache=True)
def route_1(
    route: np.ndarray, t: float, r_eci: np.ndarray, v_eci: np.ndarray, a_eci: np.ndarray, c_pn: np.ndarray, dut1: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray, bool]:
    """Λ^p, ω^p, ω̇^p and the observing flag of a compiled route at t_unix_s (seed 000 §5, Fig. 4)."""
    k = 0
    while k + 1 < route.shape[0] and t >= route[k + 1, COL_T0]:
        k += 1
    q, w, wd = segment_program_1(route[k], t, r_eci, v_eci, a_eci, c_pn, dut1)
    return q, w, wd, route[k, COL_OBSERVING] != 0.0 and t < route[k, COL_T1]


@dataclass(frozen=True)
class OrfHold:
    """ORF stabilisation with a constant yaw/roll/pitch offset (seed 000 sequence 132), e.g. a scanning course."""

    duration_s: float
    yaw_deg: float = 0.0
    roll_deg: float = 0.0
    pitch_deg: float = 0.0
    observing: bool = False


@dataclass(frozen=True)
class GroundTarget:
    """Boresight +x on an Earth-fixed point; body +z nearest ``yaw_ref_eci`` (default: z^o at the start)."""

    duration_s: float
    target_ecef_m: tuple[float, float, float]
    observing: bool = True
    yaw_ref_eci: tuple[float, float, float] | None = None


@dataclass(frozen=True)
class Turn:
    """Seed 001 scheduled turn from the end state of the previous segment to the start of the next."""

    duration_s: float


Segment = OrfHold | GroundTarget | Turn


def _offset_quaternion(seg: OrfHold) -> np.ndarray:
    return quaternion.from_euler_132(*np.radians([seg.yaw_deg, seg.roll_deg, seg.pitch_deg]))


def _check_segments(segments: Sequence[Segment]) -> None:
    if not segments:
        raise ValueError("segments: a route needs at least one segment")
    for i, seg in enumerate(segments):
        if not isinstance(seg, (OrfHold, GroundTarget, Turn)):
            raise ValueError(f"segments[{i}]: expected OrfHold, GroundTarget or Turn, got {type(seg).__name__}")
        if not (np.isfinite(seg.duration_s) and seg.duration_s > 0.0):
            raise ValueError(f"segments[{i}].duration_s: must be positive, got {seg.duration_s!r}")
        if isinstance(seg, OrfHold):
            for name in ("yaw_deg", "roll_deg", "pitch_deg"):
                if not np.isfinite(getattr(seg, name)):
                    raise ValueError(f"segments[{i}].{name}: must be a finite angle in degrees")
        is_turn = isinstance(seg, Turn)
        if is_turn and (
            i == 0 or i == len(segments) - 1 or isinstance(segments[i - 1], Turn) or isinstance(segments[i + 1], Turn)
        ):
            raise ValueError(f"segments[{i}]: a Turn must sit between two non-turn segments")


def _static_row(seg: Segment, t0: float, t1: float, state0: tuple[np.ndarray, ...], w_pm: np.ndarray) -> np.ndarray:
    row = np.zeros(ROW_SIZE)
    row[COL_T0], row[COL_T1], row[COL_OBSERVING] = t0, t1, float(getattr(seg, "observing", False))
    if isinstance(seg, OrfHold):
        row[COL_KIND] = KIND_ORF_HOLD
        row[COL_OFFSET : COL_OFFSET + 4] = _offset_quaternion(seg)
    elif isinstance(seg, GroundTarget):
        row[COL_KIND] = KIND_TARGET
        target = np.asarray(seg.target_ecef_m, dtype=float)
        if target.shape != (3,) or not np.all(np.isfinite(target)):
            raise ValueError("target_ecef_m: expected 3 finite ECEF coordinates in metres")
        row[COL_TARGET : COL_TARGET + 3] = target
        r0, v0 = state0[0], state0[1]
        u = np.cross(-r0, v0) if seg.yaw_ref_eci is None else np.asarray(seg.yaw_ref_eci, dtype=float)
        if u.shape != (3,) or not np.all(np.isfinite(u)) or np.linalg.norm(u) == 0.0:
            raise ValueError("yaw_ref_eci: expected a non-zero finite ECI direction")
        row[COL_YAW_REF : COL_YAW_REF + 3] = u / np.linalg.norm(u)
        row[COL_POLAR : COL_POLAR + 9] = w_pm.ravel()
    return row


def compile_route(
    segments: Sequence[Segment],
    t_start_unix_s: float,
    orbit_state: OrbitState,
    c_pn: np.ndarray | None = None,
    dut1_s: float = 0.0,
    w_pm: np.ndarray | None = None,
) -> np.ndarray:
    """Route array (n_segments, ROW_SIZE) with each turn planned between its neighbours (seed 000 §5, seed 001).

    ``orbit_state`` gives the spacecraft's ECI r, v, a at the segment joins (the same orbit the engine
    flies, so the joins are continuous); ``c_pn``, ``dut1_s``, ``w_pm`` are the frozen Earth
    orientation (``frames.earth_orientation_frozen``) that the kernel uses for ground targets
    (identity C and W when omitted; W is stored in the target rows).
    """
    _check_segments(segments)
    if not np.isfinite(t_start_unix_s):
        raise ValueError(f"t_start_unix_s: must be finite, got {t_start_unix_s!r}")
    c_pn = np.eye(3) if c_pn is None else np.asarray(c_pn, dtype=float)
    w_pm = np.eye(3) if w_pm is None else np.asarray(w_pm, dtype=float)
    for name, m in (("c_pn", c_pn), ("w_pm", w_pm)):
        if m.shape != (3, 3) or not np.all(np.isfinite(m)):
            raise ValueError(f"{name}: expected a finite 3×3 rotation matrix, got shape {m.shape}")
    bounds = t_start_unix_s + np.concatenate([[0.0], np.cumsum([s.duration_s for s in segments])])
    r, v, a = (np.asarray(x, dtype=float) for x in orbit_state(bounds))
    route = np.stack([_static_row(s, bounds[i], bounds[i + 1], (r[i], v[i]), w_pm) for i, s in enumerate(segments)])
    for i, seg in enumerate(segments):
        if isinstance(seg, Turn):
            j = i + 1
            q0, w0, _ = segment_program_1(route[i - 1], bounds[i], r[i], v[i], a[i], c_pn, dut1_s)
            q1, w1, _ = segment_program_1(route[j], bounds[j], r[j], v[j], a[j], c_pn, dut1_s)
            route[i, COL_KIND] = KIND_TURN
            route[i, COL_PLAN : COL_PLAN + PLAN_SIZE] = plan_scheduled_turn(q0, w0, q1, w1, seg.duration_s, bounds[i])
    return route


def turn_envelopes(route: np.ndarray) -> list[tuple[int, TurnEnvelope]]:
    """(segment index, seed 001 envelope) of every turn of a compiled route, for feasibility checks."""
    route = _route_array(route)
    return [
        (i, turn_envelope(row[COL_PLAN : COL_PLAN + PLAN_SIZE]))
        for i, row in enumerate(route)
        if int(row[COL_KIND]) == KIND_TURN
    ]


def _route_array(route: np.ndarray) -> np.ndarray:
    route = np.asarray(route, dtype=float)
    if route.ndim != 2 or route.shape[1] != ROW_SIZE:
        raise ValueError(f"route: expected a compiled route of shape (n, {ROW_SIZE}), got {route.shape}")
    return route


@njit(cache=True)
def _route_many(
    route: np.ndarray, t: np.ndarray, r: np.ndarray, v: np.ndarray, a: np.ndarray, c_pn: np.ndarray, dut1: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    n = t.shape[0]
    q, w, wd, obs = np.empty((n, 4)), np.empty((n, 3)), np.empty((n, 3)), np.empty(n, dtype=np.bool_)
    for i in range(n):
        qi, wi, wdi, oi = route_1(route, t[i], r[i], v[i], a[i], c_pn, dut1)
        q[i], w[i], wd[i], obs[i] = qi, wi, wdi, oi
    return q, w, wd, obs


def _state_arrays(n: int, **arrays: np.ndarray) -> list[np.ndarray]:
    out = []
    for name, x in arrays.items():
        x = np.asarray(x, dtype=float)
        if x.shape != (n, 3) or not np.all(np.isfinite(x)):
            raise ValueError(f"{name}: expected finite shape ({n}, 3), got {x.shape}")
        out.append(x)
    return out


def route_program(
    route: np.ndarray,
    t_unix_s: np.ndarray,
    r_eci_m: np.ndarray,
    v_eci_m_s: np.ndarray,
    a_eci_m_s2: np.ndarray,
    c_pn: np.ndarray | None = None,
    dut1_s: float = 0.0,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Λ^p (n,4), ω^p (n,3), ω̇^p (n,3), observing (n,) of a compiled route along an orbit (seed 000 §5)."""
    route = _route_array(route)
    t = np.atleast_1d(np.asarray(t_unix_s, dtype=float))
    if t.ndim != 1 or not np.all(np.isfinite(t)):
        raise ValueError("t_unix_s: expected a finite 1-D array of times")
    r, v, a = _state_arrays(t.size, r_eci_m=r_eci_m, v_eci_m_s=v_eci_m_s, a_eci_m_s2=a_eci_m_s2)
    c_pn = np.eye(3) if c_pn is None else np.asarray(c_pn, dtype=float)
    return _route_many(route, t, r, v, a, c_pn, float(dut1_s))


@njit(cache=True)
def _orf_many(
    q_offset: np.ndarray, r: np.ndarray, v: np.ndarray, a: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    n = r.shape[0]
    q, w, wd = np.empty((n, 4)), np.empty((n, 3)), np.empty((n, 3))
    for i in range(n):
        qi, wi, wdi = orf_hold_1(q_offset, r[i], v[i], a[i])
        q[i], w[i], wd[i] = qi, wi, wdi
    return q, w, wd


def orf_hold_program(
    r_eci_m: np.ndarray,
    v_eci_m_s: np.ndarray,
    yaw_deg: float = 0.0,
    roll_deg: float = 0.0,
    pitch_deg: float = 0.0,
    a_eci_m_s2: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """ORF stabilisation program along an orbit (n,3): Λ_o ∘ Λ^o_d and its rates (seed 000 §2).

    ``a_eci_m_s2`` (default: central gravity, i.e. no out-of-plane force) adds the orbit-plane turn.
    """
    n = np.atleast_2d(r_eci_m).shape[0]
    a = np.zeros((n, 3)) if a_eci_m_s2 is None else np.atleast_2d(a_eci_m_s2)
    r, v, a = _state_arrays(n, r_eci_m=np.atleast_2d(r_eci_m), v_eci_m_s=np.atleast_2d(v_eci_m_s), a_eci_m_s2=a)
    if np.any(np.linalg.norm(np.cross(r, v), axis=1) == 0.0):
        raise ValueError("v_eci_m_s: velocity parallel to position leaves the ORF undefined")
    return _orf_many(_offset_quaternion(OrfHold(1.0, yaw_deg, roll_deg, pitch_deg)), r, v, a)


def orf_angles_deg(
    q_ib: np.ndarray, r_eci_m: np.ndarray, v_eci_m_s: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Yaw φ1, roll φ2, pitch φ3 (deg) of Λ^o = Λ̃_o ∘ Λ, sequence 132: seed 000 Fig. 4's program angles."""
    q = np.atleast_2d(np.asarray(q_ib, dtype=float))
    if q.shape[-1] != 4 or not np.all(np.isfinite(q)):
        raise ValueError(f"q_ib: expected finite quaternions of shape (n, 4), got {q.shape}")
    r, v = _state_arrays(q.shape[0], r_eci_m=np.atleast_2d(r_eci_m), v_eci_m_s=np.atleast_2d(v_eci_m_s))
    q_o = np.array([frames.orf_quaternion_1(r[i], v[i]) for i in range(q.shape[0])])
    yaw, roll, pitch = quaternion.to_euler_132(quaternion.multiply(quaternion.conjugate(q_o), q))
    return np.degrees(yaw), np.degrees(roll), np.degrees(pitch)


def target_pointing_program(
    r_eci_m: np.ndarray,
    v_eci_m_s: np.ndarray,
    a_eci_m_s2: np.ndarray,
    r_target_eci_m: np.ndarray,
    v_target_eci_m_s: np.ndarray,
    a_target_eci_m_s2: np.ndarray,
    yaw_ref_eci: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Vectorised :func:`target_pointing_1` over n samples of spacecraft and target ECI motion."""
    n = np.atleast_2d(r_eci_m).shape[0]
    states = _state_arrays(
        n,
        r_eci_m=np.atleast_2d(r_eci_m),
        v_eci_m_s=np.atleast_2d(v_eci_m_s),
        a_eci_m_s2=np.atleast_2d(a_eci_m_s2),
        r_target_eci_m=np.atleast_2d(r_target_eci_m),
        v_target_eci_m_s=np.atleast_2d(v_target_eci_m_s),
        a_target_eci_m_s2=np.atleast_2d(a_target_eci_m_s2),
    )
    u = np.asarray(yaw_ref_eci, dtype=float)
    if u.shape != (3,) or not np.isfinite(np.linalg.norm(u)) or np.linalg.norm(u) == 0.0:
        raise ValueError("yaw_ref_eci: expected a non-zero finite ECI direction")
    los = states[3] - states[0]
    if np.any(np.linalg.norm(np.cross(los, u), axis=1) <= 1e-9 * np.linalg.norm(los, axis=1)):
        raise ValueError("yaw_ref_eci: parallel to the line of sight, the yaw is undefined")
    q, w, wd = np.empty((n, 4)), np.empty((n, 3)), np.empty((n, 3))
    for i in range(n):
        r, v, a, r_target, v_target, a_target = (s[i] for s in states)
        q[i], w[i], wd[i] = target_pointing_1(r, v, a, r_target, v_target, a_target, u / np.linalg.norm(u))
    return q, w, wd


def two_course_scan(
    course_s: float, turn_s: float, first_roll_deg: float = 0.0, second_roll_deg: float = 20.0
) -> list[Segment]:
    """Seed 000 §5 (Figs 3–4): scanning course, scheduled roll manoeuvre (20° by default), second course."""
    return [
        OrfHold(course_s, roll_deg=first_roll_deg, observing=True),
        Turn(turn_s),
        OrfHold(course_s, roll_deg=second_roll_deg, observing=True),
    ]


@njit(cache=True)
def sun_pointing_1(q_ib: np.ndarray, sun_b: np.ndarray, axis_b: np.ndarray) -> np.ndarray:
    """One-axis Sun orientation (seed 001): the attitude nearest q_ib that puts the body axis ``axis_b`` on the
    Sun direction ``sun_b`` (unit, body axes, as the Sun sensor sees it), by the shortest rotation."""
    axis = np.cross(axis_b, sun_b)
    n = np.sqrt(dot3_1(axis, axis))
    ang = np.arctan2(n, dot3_1(axis_b, sun_b))
    dq = np.array([1.0, 0.0, 0.0, 0.0])
    if n > 1e-12:
        dq[0] = np.cos(0.5 * ang)
        dq[1:] = np.sin(0.5 * ang) * axis / n
    return multiply_1(q_ib, dq)
