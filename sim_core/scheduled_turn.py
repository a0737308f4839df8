"""Scheduled ("programmed") turn of seed 001 (Salmin et al., AIST-2D): Λ^p(t), ω^p(t), ω̇^p(t).

The manoeuvre from (λ_n, ω_n) at t_нпп to (λ_k, ω_k) at t_кпп = t_нпп + τ is the superposition
λ(T) = λ0 ∘ λ1(T) ∘ λ2(T) ∘ λ3(T) of three plane rotations about axes fixed in their bases:
λ1 damps the initial rate ω_n linearly to zero about e1 = ω_n/|ω_n| ("rate damping", ГНС);
λ2 is the positional transition about e2 with the trapezoid rate profile (segments A, B, C;
T1 = 72 s, T2 = τ − T1 when τ ≥ 144 s, else T1 = T2 = τ/2 and no plateau B); λ3 builds the final
rate linearly from zero about e3 = ω_k/|ω_k| ("final-rate acquisition", НКС). After τ (segment D)
the body keeps turning at ω_k about e3: λ = λ_f ∘ [ω_k (T − τ)] about e3.

Quaternions are scalar-first Hamilton, ``q_ib`` convention (body → inertial), rates in body axes,
Λ̇ = ½ Λ ∘ ω (DESIGN.md). Corrections to the seed text, each checked by a test:

* λ2 = λ̃1 ∘ λ̃0 ∘ λ_f ∘ λ̃3 — the seed prints λ̃_f; only λ_f makes λ0∘λ1∘λ2∘λ3 = λ_f at T = τ.
* On segment A the program acceleration is Φ1Y·e2 (the seed prints e3; DESIGN.md).
* φ2 = 2 atan2(|vect λ2|, λ20) and e2 = vect λ2 / |vect λ2|: the seed's arccos with the clamp
  P = 0.0001 when 1 − λ20² < 1e-4 mis-scales e2 for transitions under ~1.15° and breaks the final
  boundary condition by up to 1e-4; atan2 is the same angle and exact for every angle.
* The seed's ε_пр sums the three relative accelerations only. Because e1 is fixed in E1 and e2 in E2
  while the body E3 turns relative to them, the time derivative of its own ω_пр also has the
  transport terms −ω_31 × ω_1b − ω_3 × ω_2b (ω_31 = ω_2b + ω_3); they are added so that ω̇^p is the
  true derivative of ω^p that the control law's feed-forward J ω̇^p needs.
* Below the seed's ε = 1e-8 rad/s a boundary rate is treated as zero (axis and modulus both zero,
  so λ1, λ3 stay unit quaternions).

A planned turn is a flat float64 array (layout below) so the compiled kernel
:func:`scheduled_turn_1` can evaluate it inside the engine's loop.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit

from sim_core.quaternion import multiply_1, normalize_1

__all__ = [
    "PLAN_SIZE",
    "SEGMENT_A",
    "SEGMENT_B",
    "SEGMENT_C",
    "SEGMENT_D",
    "ACCELERATION_TIME_S",
    "TurnEnvelope",
    "plan_scheduled_turn",
    "plan_scheduled_turn_1",
    "scheduled_turn",
    "scheduled_turn_1",
    "turn_segment",
    "turn_segment_1",
    "turn_envelope",
    "shortest_rest_to_rest_duration_s",
]

ACCELERATION_TIME_S = 72.0  # seed 001: T1, the time to reach the maximum transition rate
PLATEAU_THRESHOLD_S = 2.0 * ACCELERATION_TIME_S  # seed 001: no plateau (segment B) below 144 s
RATE_EPSILON_RAD_S = 1e-8  # seed 001: ε below which a boundary rate has no axis
UNIT_NORM_TOLERANCE = 1e-6  # boundary quaternions must be unit to this (then renormalised)

SEGMENT_A, SEGMENT_B, SEGMENT_C, SEGMENT_D = 0, 1, 2, 3  # seed 001 segments of the λ2 profile

# Plan layout: named slots of the flat plan array (seed 001 names in the comments).
Q0 = 0  # λ0 = λ_n, attitude at the turn start (4)
QF = 4  # λ_f = ±λ_k, attitude at the turn end, sign continuous with segment C (4)
E1 = 8  # e1, rate-damping axis (3)
E2 = 11  # e2, positional-transition axis (3)
E3 = 14  # e3, final-rate axis (3)
RATE_START = 17  # C1Г = |ω_n| (rad/s)
RATE_END = 18  # C1H = |ω_k| (rad/s)
ANGLE2 = 19  # ФГ = φ2 total of the positional transition (rad)
TAU = 20  # τ_пм, turn duration (s)
T1 = 21  # T1 (s)
T2 = 22  # T2 (s)
RATE2 = 23  # C1Y, plateau rate of the transition (rad/s)
ACC2 = 24  # Ф1Y, acceleration of the transition on A and C (rad/s²)
ANGLE2_T1 = 25  # C2Y, transition angle reached at T1 (rad)
T_START = 26  # t_нпп, turn start time (s)
PLAN_SIZE = 27


class TurnEnvelope(NamedTuple):
    """Figures a feasibility check needs (seed 001 coefficients; bounds hold over the whole turn)."""

    duration_s: float
    transition_angle_rad: float
    transition_rate_rad_s: float
    transition_acceleration_rad_s2: float
    max_rate_bound_rad_s: float
    max_acceleration_bound_rad_s2: float


@njit(cache=True)
def _axis_turn_1(plan: np.ndarray, axis: int, angle_rad: float) -> np.ndarray:
    """Quaternion (cos φ/2, e sin φ/2) about the plan's axis slot (seed 001 λ1, λ2, λ3)."""
    s = np.sin(0.5 * angle_rad)
    q = np.empty(4)
    q[0] = np.cos(0.5 * angle_rad)
    q[1] = plan[axis] * s
    q[2] = plan[axis + 1] * s
    q[3] = plan[axis + 2] * s
    return q


@njit(cache=True)
def _conjugate_1(q: np.ndarray) -> np.ndarray:
    """Λ̃ = (λ0, −λ) of one quaternion."""
    r = -q
    r[0] = q[0]
    return r


@njit(cache=True)
def _store_axis_1(plan: np.ndarray, slot: int, modulus_slot: int, omega: np.ndarray) -> None:
    """Seed 001 e_i = ω/|ω| if |ω| > ε else 0, with the modulus C1Г / C1H stored beside it."""
    norm = np.sqrt(omega[0] ** 2 + omega[1] ** 2 + omega[2] ** 2)
    if norm > RATE_EPSILON_RAD_S:
        plan[slot : slot + 3] = omega / norm
        plan[modulus_slot] = norm
    else:
        plan[slot : slot + 3] = 0.0
        plan[modulus_slot] = 0.0


@njit(cache=True)
def plan_scheduled_turn_1(
    q_start: np.ndarray,
    omega_start_b: np.ndarray,
    q_end: np.ndarray,
    omega_end_b: np.ndarray,
    duration: float,
    t_start: float,
) -> np.ndarray:
    """Plan array of a scheduled turn, seed 001 initial data (e1, e3, λ1, λ3, λ2, ФГ, C1Y, Ф1Y, C2Y)."""
    plan = np.zeros(PLAN_SIZE)
    plan[Q0 : Q0 + 4] = normalize_1(q_start)
    plan[QF : QF + 4] = normalize_1(q_end)
    _store_axis_1(plan, E1, RATE_START, omega_start_b)
    _store_axis_1(plan, E3, RATE_END, omega_end_b)
    lam1 = _axis_turn_1(plan, E1, 0.5 * plan[RATE_START] * duration)
    lam3 = _axis_turn_1(plan, E3, 0.5 * plan[RATE_END] * duration)
    lam2 = multiply_1(multiply_1(_conjugate_1(lam1), _conjugate_1(plan[Q0 : Q0 + 4])), plan[QF : QF + 4])
    lam2 = multiply_1(lam2, _conjugate_1(lam3))
    if lam2[0] < 0.0:
        lam2 = -lam2
    sin_half = np.sqrt(lam2[1] ** 2 + lam2[2] ** 2 + lam2[3] ** 2)
    plan[ANGLE2] = 2.0 * np.arctan2(sin_half, lam2[0])
    if sin_half > 0.0:
        plan[E2 : E2 + 3] = lam2[1:] / sin_half
    if duration >= PLATEAU_THRESHOLD_S:
        plan[T1], plan[T2] = ACCELERATION_TIME_S, duration - ACCELERATION_TIME_S
    else:
        plan[T1], plan[T2] = 0.5 * duration, 0.5 * duration
    plan[TAU] = duration
    plan[RATE2] = plan[ANGLE2] / plan[T2]
    plan[ACC2] = plan[RATE2] / plan[T1]
    plan[ANGLE2_T1] = 0.5 * plan[RATE2] * plan[T1]
    plan[T_START] = t_start
    # λ_f = λ0∘λ1∘λ2∘λ3 at T = τ: equals ±λ_k, the sign that keeps segment D continuous with C.
    plan[QF : QF + 4] = multiply_1(multiply_1(multiply_1(plan[Q0 : Q0 + 4], lam1), lam2), lam3)
    return plan


@njit(cache=True)
def turn_segment_1(plan: np.ndarray, t: float) -> int:
    """Seed 001 segment (A, B, C, D) of the transition profile at absolute time t (s)."""
    tt = t - plan[T_START]
    if tt >= plan[TAU]:
        return SEGMENT_D
    if tt < plan[T1]:
        return SEGMENT_A
    if tt < plan[T2]:
        return SEGMENT_B
    return SEGMENT_C


@njit(cache=True)
def _transition_1(plan: np.ndarray, segment: int, tt: float) -> tuple[float, float, float]:
    """Seed 001 φ2, |ω_P2|, ε_P2 along e2 on segments A, B, C (A along e2: DESIGN.md correction)."""
    acc, tau = plan[ACC2], plan[TAU]
    if segment == SEGMENT_A:
        return 0.5 * acc * tt * tt, acc * tt, acc
    if segment == SEGMENT_B:
        return plan[ANGLE2_T1] + plan[RATE2] * (tt - plan[T1]), plan[RATE2], 0.0
    return plan[ANGLE2] - 0.5 * acc * (tau - tt) ** 2, acc * (tau - tt), -acc


# Evaluation works on float tuples (no heap allocation in the engine loop: ~10× faster than arrays).


@njit(cache=True)
def _quaternion_t(plan: np.ndarray, slot: int) -> tuple[float, float, float, float]:
    """Plan quaternion slot as a tuple."""
    return plan[slot], plan[slot + 1], plan[slot + 2], plan[slot + 3]


@njit(cache=True)
def _axis_t(plan: np.ndarray, slot: int, angle_rad: float) -> tuple[float, float, float, float]:
    """(cos φ/2, e sin φ/2) about the plan's axis slot, as a tuple (seed 001 λ1, λ2, λ3)."""
    s = np.sin(0.5 * angle_rad)
    return np.cos(0.5 * angle_rad), plan[slot] * s, plan[slot + 1] * s, plan[slot + 2] * s


@njit(cache=True)
def _scaled_t(plan: np.ndarray, slot: int, k: float) -> tuple[float, float, float]:
    """k · (plan axis slot), as a tuple."""
    return k * plan[slot], k * plan[slot + 1], k * plan[slot + 2]


@njit(cache=True)
def _multiply_t(
    a: tuple[float, float, float, float], b: tuple[float, float, float, float]
) -> tuple[float, float, float, float]:
    """Hamilton product a ∘ b on tuples (same algebra as quaternion.multiply_1)."""
    return (
        a[0] * b[0] - a[1] * b[1] - a[2] * b[2] - a[3] * b[3],
        a[0] * b[1] + a[1] * b[0] + a[2] * b[3] - a[3] * b[2],
        a[0] * b[2] - a[1] * b[3] + a[2] * b[0] + a[3] * b[1],
        a[0] * b[3] + a[1] * b[2] - a[2] * b[1] + a[3] * b[0],
    )


@njit(cache=True)
def _conjugate_rotate_t(
    q: tuple[float, float, float, float], v: tuple[float, float, float]
) -> tuple[float, float, float]:
    """Λ̃ ∘ v ∘ Λ on tuples (same algebra as quaternion.conjugate_rotate_1)."""
    tx = 2.0 * (-q[2] * v[2] + q[3] * v[1])
    ty = 2.0 * (-q[3] * v[0] + q[1] * v[2])
    tz = 2.0 * (-q[1] * v[1] + q[2] * v[0])
    return (
        v[0] + q[0] * tx - q[2] * tz + q[3] * ty,
        v[1] + q[0] * ty - q[3] * tx + q[1] * tz,
        v[2] + q[0] * tz - q[1] * ty + q[2] * tx,
    )


@njit(cache=True)
def _cross_t(a: tuple[float, float, float], b: tuple[float, float, float]) -> tuple[float, float, float]:
    """a × b on tuples."""
    return a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]


@njit(cache=True)
def _final_rate_1(plan: np.ndarray, tt: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Segment D: λ = λ_f ∘ [C1H (T − τ)] about e3, ω = C1H e3, ω̇ = 0 (seed 001)."""
    q = _multiply_t(_quaternion_t(plan, QF), _axis_t(plan, E3, (tt - plan[TAU]) * plan[RATE_END]))
    return np.array(q), plan[RATE_END] * plan[E3 : E3 + 3], np.zeros(3)


@njit(cache=True)
def scheduled_turn_1(plan: np.ndarray, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Λ^p, ω^p (body, rad/s), ω̇^p (rad/s²) at absolute time t ≥ t_нпп: seed 001 λ_зад, ω_пр, ε_пр."""
    tt = t - plan[T_START]
    segment = turn_segment_1(plan, t)
    if segment == SEGMENT_D:
        return _final_rate_1(plan, tt)
    tau, w_start, w_end = plan[TAU], plan[RATE_START], plan[RATE_END]
    lam1 = _axis_t(plan, E1, 0.5 * w_start * tt * (2.0 - tt / tau))
    lam3 = _axis_t(plan, E3, 0.5 * w_end * tt * tt / tau)
    phi2, rate2, acc2 = _transition_1(plan, segment, tt)
    lam23 = _multiply_t(_axis_t(plan, E2, phi2), lam3)
    q = _multiply_t(_multiply_t(_quaternion_t(plan, Q0), lam1), lam23)
    w1 = _conjugate_rotate_t(lam23, _scaled_t(plan, E1, w_start * (tau - tt) / tau))
    w2 = _conjugate_rotate_t(lam3, _scaled_t(plan, E2, rate2))
    w3 = _scaled_t(plan, E3, w_end * tt / tau)
    a1 = _conjugate_rotate_t(lam23, _scaled_t(plan, E1, -w_start / tau))
    a2 = _conjugate_rotate_t(lam3, _scaled_t(plan, E2, acc2))
    a3 = _scaled_t(plan, E3, w_end / tau)
    transport_31 = _cross_t((w2[0] + w3[0], w2[1] + w3[1], w2[2] + w3[2]), w1)
    transport_32 = _cross_t(w3, w2)
    w, wd = np.empty(3), np.empty(3)
    for i in range(3):
        w[i] = w1[i] + w2[i] + w3[i]
        wd[i] = a1[i] + a2[i] + a3[i] - transport_31[i] - transport_32[i]
    return np.array(q), w, wd


@njit(cache=True)
def _evaluate_many(plan: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Loop of :func:`scheduled_turn_1` over a time array."""
    n = t.shape[0]
    q, w, wd = np.empty((n, 4)), np.empty((n, 3)), np.empty((n, 3))
    for i in range(n):
        qi, wi, wdi = scheduled_turn_1(plan, t[i])
        q[i], w[i], wd[i] = qi, wi, wdi
    return q, w, wd


def _unit_quaternion(q: np.ndarray, name: str) -> np.ndarray:
    q = np.asarray(q, dtype=float)
    if q.shape != (4,) or not np.all(np.isfinite(q)):
        raise ValueError(f"{name}: expected 4 finite numbers (scalar-first quaternion), got {q!r}")
    if abs(np.linalg.norm(q) - 1.0) > UNIT_NORM_TOLERANCE:
        raise ValueError(f"{name}: not a unit quaternion (norm {np.linalg.norm(q):.9g}); normalise it")
    return q


def _rate_vector(w: np.ndarray, name: str) -> np.ndarray:
    w = np.asarray(w, dtype=float)
    if w.shape != (3,) or not np.all(np.isfinite(w)):
        raise ValueError(f"{name}: expected 3 finite body-rate components in rad/s, got {w!r}")
    return w


def plan_scheduled_turn(
    q_start: np.ndarray,
    omega_start_b_rad_s: np.ndarray,
    q_end: np.ndarray,
    omega_end_b_rad_s: np.ndarray,
    duration_s: float,
    t_start_s: float = 0.0,
) -> np.ndarray:
    """Validated plan of a scheduled turn with boundary conditions (λ_n, ω_n) → (λ_k, ω_k), seed 001."""
    if not (np.isfinite(duration_s) and duration_s > 0.0):
        raise ValueError(f"duration_s: must be a positive number of seconds, got {duration_s!r}")
    if not np.isfinite(t_start_s):
        raise ValueError(f"t_start_s: must be finite, got {t_start_s!r}")
    return plan_scheduled_turn_1(
        _unit_quaternion(q_start, "q_start"),
        _rate_vector(omega_start_b_rad_s, "omega_start_b_rad_s"),
        _unit_quaternion(q_end, "q_end"),
        _rate_vector(omega_end_b_rad_s, "omega_end_b_rad_s"),
        float(duration_s),
        float(t_start_s),
    )


def _plan_array(plan: np.ndarray) -> np.ndarray:
    plan = np.asarray(plan, dtype=float)
    if plan.shape != (PLAN_SIZE,):
        raise ValueError(f"plan: expected a scheduled-turn plan of shape ({PLAN_SIZE},), got {plan.shape}")
    return plan


def _times(plan: np.ndarray, t_s: np.ndarray) -> np.ndarray:
    t = np.atleast_1d(np.asarray(t_s, dtype=float))
    if t.ndim != 1 or not np.all(np.isfinite(t)):
        raise ValueError("t_s: expected a finite scalar or 1-D array of times in seconds")
    if np.any(t < plan[T_START]):
        raise ValueError(f"t_s: times before the turn start t_start_s = {plan[T_START]} s")
    return t


def scheduled_turn(plan: np.ndarray, t_s: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Λ^p (n,4), ω^p (n,3) rad/s, ω̇^p (n,3) rad/s² of a planned turn at times t_s (seed 001)."""
    plan = _plan_array(plan)
    return _evaluate_many(plan, _times(plan, t_s))


def turn_segment(plan: np.ndarray, t_s: np.ndarray) -> np.ndarray:
    """Seed 001 segment codes (SEGMENT_A … SEGMENT_D) at times t_s."""
    plan = _plan_array(plan)
    return np.array([turn_segment_1(plan, t) for t in _times(plan, t_s)], dtype=np.int64)


def turn_envelope(plan: np.ndarray) -> TurnEnvelope:
    """Duration, transition coefficients (seed 001 ФГ, C1Y, Ф1Y) and bounds on |ω^p|, |ω̇^p|.

    |ω^p| ≤ C1Г + C1Y + C1H by the triangle inequality on the three plane rates; |ω̇^p| is bounded
    by the three relative accelerations plus the transport terms |ω_31||ω_1| + |ω_3||ω_2|.
    Both bounds are reached exactly by rest-to-rest turns (C1Г = C1H = 0).
    """
    p = _plan_array(plan)
    w_start, w_end, rate2, acc2, tau = p[RATE_START], p[RATE_END], p[RATE2], p[ACC2], p[TAU]
    acc_bound = (w_start + w_end) / tau + acc2 + (rate2 + w_end) * w_start + w_end * rate2
    return TurnEnvelope(
        duration_s=float(tau),
        transition_angle_rad=float(p[ANGLE2]),
        transition_rate_rad_s=float(rate2),
        transition_acceleration_rad_s2=float(acc2),
        max_rate_bound_rad_s=float(w_start + rate2 + w_end),
        max_acceleration_bound_rad_s2=float(acc_bound),
    )


def shortest_rest_to_rest_duration_s(angle_rad: float, max_rate_rad_s: float, max_acceleration_rad_s2: float) -> float:
    """Shortest τ of a seed 001 rest-to-rest turn by angle_rad within rate and acceleration limits.

    C1Y(τ) and Ф1Y(τ) both decrease with τ and are continuous at 144 s, so the shortest τ is the
    largest of the inversions: τ ≥ 2φ/ω_max, 2√(φ/a_max) below 144 s; τ ≥ T1 + φ/ω_max,
    T1 + φ/(T1 a_max) above.
    """
    for name, value in (("max_rate_rad_s", max_rate_rad_s), ("max_acceleration_rad_s2", max_acceleration_rad_s2)):
        if not (np.isfinite(value) and value > 0.0):
            raise ValueError(f"{name}: must be a positive finite number, got {value!r}")
    if not (np.isfinite(angle_rad) and 0.0 <= angle_rad <= np.pi):
        raise ValueError(f"angle_rad: must lie in [0, π], got {angle_rad!r}")
    short = max(2.0 * angle_rad / max_rate_rad_s, 2.0 * np.sqrt(angle_rad / max_acceleration_rad_s2))
    if short < PLATEAU_THRESHOLD_S:
        return float(short)
    t1 = ACCELERATION_TIME_S
    return float(max(t1 + angle_rad / max_rate_rad_s, t1 + angle_rad / (t1 * max_acceleration_rad_s2)))
