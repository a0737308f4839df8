"""What-if analysis for operators: fault sweeps in one batch, and feasibility of a planned route.

:func:`sweep` flies fault variants of one scenario in one batch from a given initial state (with the
onboard FDIR) and returns per-variant metrics. :func:`feasibility` predicts, without flying the
closed loop, whether the programmed motion of a scenario (a route, a scheduled turn) can be flown by
a given set of healthy wheels: it replays the program through the onboard allocation law (seed 000
§3: 4 → 3 → 2 + MD) as a feed-forward, carrying the wheel momenta, and checks the torque limits, the
momentum limits and the torque the actuators cannot produce (the MD outside its efficiency windows
|κ| ≤ 1/2, or saturated), with the reason and time of the first violation.
:func:`max_feasible_turn_rate` bisects the duration of a route's turn for the fastest feasible one.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, NamedTuple

import numpy as np
import numpy.typing as npt

from sim_core import allocation, engine, environment
from sim_core.fdir import describe_event
from sim_core.modes import MODE_FAULT
from sim_core.quaternion import conjugate_rotate_1
from sim_core.scenario import Scenario, VariantSpec
from sim_core.trajectory import ARCSEC_PER_RAD, Trajectory

__all__ = [
    "POINTING_BUDGET_ARCSEC",
    "Feasibility",
    "sweep",
    "variant_metrics",
    "feasibility",
    "md_windows",
    "max_feasible_turn_rate",
    "TurnRate",
    "kappa_fraction",
    "configuration_table",
    "pair_limit",
    "ROUTE_FLOWN_ARCSEC",
]

POINTING_BUDGET_ARCSEC = 60.0  # drift a scan tolerates from unproduced torque: 1′ ≈ 0.17 m/pixel-scale smear at 600 km
TURN_DURATION_RANGE_S = (10.0, 600.0)  # bisection bracket of a 20° class manoeuvre
BISECTION_STEPS = 10  # 590 s / 2^10 ≈ 0.6 s resolution on the turn duration


@dataclass
class Feasibility:
    """Verdict on flying a program with a wheel set: margins, MD windows and the reason if not."""

    feasible: bool
    reason: str
    torque_margin: float  # 1 − max |m_p| / m^m_p over the program (negative: exceeded)
    momentum_margin: float  # 1 − max |h_p| / h^m_p
    drift_arcsec: float  # largest attitude drift accumulated from torque nobody produced
    first_violation_s: float | None
    md_windows_s: list[tuple[float, float]] = field(default_factory=list)


def _with_initial(s: Scenario, initial: dict[str, Any] | None) -> Scenario:
    if not initial:
        return s
    data = s.model_dump()
    allowed = {"q_ib": "initial_q_ib", "omega_b_rad_s": "initial_omega_b_rad_s"}
    for key, value in initial.items():
        if key in allowed:
            data[allowed[key]] = list(value)
        elif key == "wheel_speed_rpm":
            wheels = data["spacecraft"]["cluster"]["wheels"]
            if len(value) != len(wheels):
                raise ValueError(f"initial.wheel_speed_rpm: expected {len(wheels)} speeds, got {len(value)}")
            for w, rpm in zip(wheels, value):
                w["initial_speed_rpm"] = float(rpm)
        else:
            raise ValueError(f"initial.{key}: unknown; use q_ib, omega_b_rad_s or wheel_speed_rpm")
    return Scenario.model_validate(data)


def sweep(
    scenario: Scenario,
    variants: list[VariantSpec],
    wheel_available: np.ndarray | None = None,
    initial: dict[str, Any] | None = None,
    fdir: bool = True,
    flyer: Callable[[Scenario], Trajectory] | None = None,
) -> list[dict[str, Any]]:
    """Fly the fault variants in one batch from ``initial`` (q_ib, omega_b_rad_s, wheel_speed_rpm) and
    return :func:`variant_metrics` per variant (seed 002 §3.2 fault impact, seed 000 §3 reconfiguration).

    ``flyer`` flies the batch instead of :func:`sim_core.engine.simulate` (e.g. spread over a Dask cluster by
    :func:`backend.jobs.cluster.flyer`); it takes no ``wheel_available``."""
    if not variants:
        raise ValueError("variants: at least one variant is required")
    s = _with_initial(scenario, initial).model_copy(update={"variants": list(variants)})
    s = Scenario.model_validate({**s.model_dump(), "fdir": fdir})
    if flyer is not None and wheel_available is not None:
        raise ValueError("wheel_available: not supported with a flyer; fail the wheels as faults from t = 0")
    traj = flyer(s) if flyer is not None else engine.simulate(s, wheel_available=wheel_available)
    return [variant_metrics(traj, s, v) for v in range(traj.n_variants)]


def variant_metrics(traj: Trajectory, s: Scenario, v: int) -> dict[str, Any]:
    """Max pointing error, settled, wheel momentum margin, MD saturation and fault-mode time, events."""
    err = traj.pointing_error_rad()[v]
    h = np.abs(traj["wheel_speed_rad_s"][v] * traj.wheel_inertia_kg_m2)
    h_max = np.array([w.max_momentum_nms for w in s.spacecraft.cluster.wheels])
    status = traj["allocation_status"][v]
    end = float(traj.t_s[-1])
    fault_mode = [t for t, name, arg in traj.events[v] if name == "mode_change" and arg == MODE_FAULT]
    settle = traj.settling_time_s(traj.extra.get("settle_after_s", 0.0))[v]
    return {
        "variant": traj.variant_names[v],
        "max_pointing_error_arcsec": float(np.max(err) * ARCSEC_PER_RAD),
        "settled": bool(np.isfinite(settle)),
        "wheel_momentum_margin": float(1.0 - np.max(h / h_max)),
        "md_saturation_time_s": float(np.count_nonzero(status == allocation.STATUS_MD_SATURATED) * s.output_dt_s),
        "fault_mode_time_s": float(end - fault_mode[0]) if fault_mode else 0.0,
        "events": [{"t_s": t, "event": name, "subject": describe_event(name, arg)} for t, name, arg in traj.events[v]],
    }


def md_windows(t_s: np.ndarray, kappa: np.ndarray) -> list[tuple[float, float]]:
    """Time intervals where |κ| ≤ 1/2, the MD's efficiency windows (seed 000 §3)."""
    ok = np.abs(np.asarray(kappa)) <= allocation.KAPPA_MAX
    out, start = [], None
    for t, flag in zip(t_s, ok):
        if flag and start is None:
            start = float(t)
        elif not flag and start is not None:
            out.append((start, float(t)))
            start = None
    if start is not None:
        out.append((start, float(t_s[-1])))
    return out


def _pair_kappa(axes: np.ndarray, available: np.ndarray, b_body: np.ndarray) -> np.ndarray | None:
    idx = np.nonzero(available)[0]
    if idx.size != 2:
        return None
    s = axes[:, idx[0]] + axes[:, idx[1]]
    e_pq = s / np.linalg.norm(s)
    kappa: npt.NDArray[np.float64] = (b_body @ e_pq) / np.linalg.norm(b_body, axis=1)
    return kappa


def feasibility(
    scenario: Scenario,
    wheel_available: np.ndarray | None = None,
    window_s: tuple[float, float] | None = None,
    pointing_budget_arcsec: float = POINTING_BUDGET_ARCSEC,
) -> Feasibility:
    """Can the scenario's program be flown by the healthy wheels (+ MD)? Seed 000 eq (1)–(3), §3.

    Replays M^r = J ω̇^p + ω^p × (J ω^p + A h) − M^gg through ``allocate_1`` every T_u over
    ``window_s`` (default: the whole scenario), integrating the wheel momenta; violations: a motor
    torque above m^m, a momentum above h^m, or torque left unproduced (MD refused at |κ| > 1/2 or
    saturated) whose accumulated drift exceeds ``pointing_budget_arcsec``.
    """
    s = scenario
    params = engine.plant_params(s)
    nw = params.n_wheels
    avail = np.ones(nw, dtype=bool) if wheel_available is None else np.asarray(wheel_available, dtype=bool)
    if avail.shape != (nw,):
        raise ValueError(f"wheel_available: expected {nw} flags, got shape {avail.shape}")
    if not pointing_budget_arcsec > 0.0:
        raise ValueError("pointing_budget_arcsec: must be positive")
    t0, t1 = (0.0, s.duration_s) if window_s is None else window_s
    if not 0.0 <= t0 < t1 <= s.duration_s:
        raise ValueError(f"window_s: expected 0 ≤ start < end ≤ duration_s ({s.duration_s} s)")
    t = np.arange(0.0, t1 + 1e-9, s.control_dt_s)
    prog = engine.program_along(s, t)
    j = params.inertia_kg_m2
    axes = params.wheel_axes_b
    m_max = params.wheels.max_torque_nm
    h_max = params.wheels.max_momentum_nms
    alloc = engine.allocation_params(s)
    speeds_rpm = np.array([w.initial_speed_rpm for w in s.spacecraft.cluster.wheels])
    h = params.wheels.inertia_kg_m2 * speeds_rpm * np.pi / 30.0
    b_body = np.array([conjugate_rotate_1(q, b) for q, b in zip(prog.q_ib, prog.b_eci_t)])
    kappa = _pair_kappa(axes, avail, b_body)
    worst_m, worst_h, worst_drift = 0.0, 0.0, 0.0
    impulse, drift = np.zeros(3), 0.0
    first, reason = None, ""
    m_out, dip = np.zeros(nw), np.zeros(3)
    for k, tk in enumerate(t):
        w, wd = prog.omega_b[k], prog.omega_dot_b[k]
        m_req = j @ wd + np.cross(w, j @ w + axes @ h)
        if s.gravity_gradient:
            m_req -= environment.gravity_gradient_torque_1(conjugate_rotate_1(prog.q_ib[k], prog.r_eci_m[k]), j)
        allocation.allocate_1(m_req, axes, avail, h, b_body[k], alloc, m_out, dip)
        produced = -axes @ m_out + np.cross(dip, b_body[k])
        missing = m_req - produced
        h = h + m_out * s.control_dt_s
        if tk < t0:
            continue
        worst_m = max(worst_m, float(np.max(np.abs(m_out) / m_max)))
        worst_h = max(worst_h, float(np.max(np.abs(h) / h_max)))
        if np.linalg.norm(missing) > 1e-12 * max(float(np.linalg.norm(m_req)), 1e-30):
            impulse += missing * s.control_dt_s
            drift += np.linalg.norm(impulse) * s.control_dt_s / np.min(np.linalg.eigvalsh(j))
        else:
            impulse[:], drift = 0.0, 0.0
        worst_drift = max(worst_drift, drift)
        if first is None:
            reason = _violation(worst_m, worst_h, worst_drift * ARCSEC_PER_RAD, pointing_budget_arcsec, kappa, k, tk)
            first = tk if reason else None
    windows = md_windows(t[t >= t0], kappa[t >= t0]) if kappa is not None else []
    return Feasibility(
        feasible=first is None,
        reason=reason or "feasible: within torque, momentum and drift limits",
        torque_margin=1.0 - worst_m,
        momentum_margin=1.0 - worst_h,
        drift_arcsec=worst_drift * ARCSEC_PER_RAD,
        first_violation_s=first,
        md_windows_s=windows,
    )


def _violation(
    worst_m: float, worst_h: float, drift_arcsec: float, budget: float, kappa: np.ndarray | None, k: int, t: float
) -> str:
    if worst_m > 1.0:
        return f"wheel torque {worst_m:.2f}× its limit at t = {t:.1f} s"
    if worst_h > 1.0:
        return f"wheel momentum {worst_h:.2f}× its limit at t = {t:.1f} s"
    if drift_arcsec > budget:
        cause = " > 1/2" if kappa is not None and abs(kappa[k]) > 0.5 else ", MD saturated"
        where = "" if kappa is None else f" (|κ| = {abs(kappa[k]):.2f}{cause})"
        return f"unproduced torque drifts the attitude {drift_arcsec:.0f}″ > {budget:.0f}″ at t = {t:.1f} s{where}"
    return ""


def _turn_index(s: Scenario) -> int:
    turns = [i for i, seg in enumerate(s.guidance.route) if seg.kind == "turn"] if s.guidance.kind == "route" else []
    if not turns:
        raise ValueError("scenario.guidance.route: no turn segment to vary")
    return turns[0]


class TurnRate(NamedTuple):
    """Fastest feasible turn: peak rate (rad/s), its duration (s) and start (s after the epoch)."""

    rate_rad_s: float
    duration_s: float
    start_s: float


def max_feasible_turn_rate(
    scenario: Scenario,
    wheel_available: np.ndarray | None = None,
    duration_range_s: tuple[float, float] = TURN_DURATION_RANGE_S,
    schedule_in_md_window: bool = True,
) -> TurnRate:
    """Fastest feasible first turn of the route by bisection on its duration (seed 001 turn, seed 000 §5).

    With two wheels, seed 000's MD law and ``schedule_in_md_window`` the route is shifted so that the turn
    starts at the longest MD efficiency window of the orbit (|κ| ≤ 1/2, nadir attitude), where seed 000 says
    the pair can fly it (the least-dipole law has no such window: the route stays where it is). NaN figures
    when even the slowest turn of ``duration_range_s`` is infeasible.
    """
    i = _turn_index(scenario)
    route = scenario.guidance.route
    pre, post = sum(seg.duration_s for seg in route[:i]), sum(seg.duration_s for seg in route[i + 1 : i + 2])
    route_start = scenario.guidance.route_start_s
    lo, hi = duration_range_s
    mask = None if wheel_available is None else np.asarray(wheel_available, dtype=bool)
    seed_law = scenario.allocation.md_law == "seed"
    if schedule_in_md_window and seed_law and mask is not None and int(mask.sum()) == 2:
        t, kappa = _nadir_kappa(scenario, mask)
        windows = md_windows(t, kappa)
        if not windows:
            return TurnRate(float("nan"), float("nan"), float("nan"))
        w0, w1 = max(windows, key=lambda w: w[1] - w[0])
        route_start = max(0.0, w0 - pre)
        hi = min(hi, w1 - (route_start + pre) - post)
        if hi <= lo:
            return TurnRate(float("nan"), float("nan"), float("nan"))
    start = route_start + pre

    def trial(duration: float) -> tuple[bool, float]:
        data = scenario.model_dump()
        data["guidance"]["route"][i]["duration_s"] = duration
        data["guidance"]["route_start_s"] = route_start
        end = start + duration + post
        data["duration_s"] = max(scenario.duration_s, end + 2 * scenario.control_dt_s)
        s = Scenario.model_validate(data)
        return feasibility(s, mask, window_s=(start, end)).feasible, engine.turn_peak_rate(s, i)

    ok_hi, rate_hi = trial(hi)
    if not ok_hi:
        return TurnRate(float("nan"), float("nan"), start)
    best = TurnRate(rate_hi, hi, start)
    for _ in range(BISECTION_STEPS):
        mid = 0.5 * (lo + hi)
        ok, rate = trial(mid)
        if ok:
            hi, best = mid, TurnRate(rate, mid, start)
        else:
            lo = mid
    return best


ROUTE_FLOWN_ARCSEC = POINTING_BUDGET_ARCSEC  # a scanning course counts as flown while within the scan budget


def _nadir_kappa(scenario: Scenario, available: np.ndarray, samples: int = 1200) -> tuple[np.ndarray, np.ndarray]:
    """κ = ⟨e_pq, b⟩ of a wheel pair over one orbit in the nadir (ORF) attitude (seed 000 §3)."""
    period = engine.orbit_period_s(scenario)
    nadir = scenario.guidance.model_copy(update={"kind": "orf"})
    s = scenario.model_copy(update={"guidance": nadir, "duration_s": period})
    t = np.linspace(0.0, period, samples, endpoint=False)
    prog = engine.program_along(s, t)
    b_body = np.array([conjugate_rotate_1(q, b) for q, b in zip(prog.q_ib, prog.b_eci_t)])
    kappa = _pair_kappa(engine.plant_params(scenario).wheel_axes_b, available, b_body)
    if kappa is None:
        raise ValueError("available: κ is defined for a pair, exactly two wheels")
    return t, kappa


def kappa_fraction(scenario: Scenario, available: np.ndarray) -> float | None:
    """Fraction of one orbit, nadir-pointed, where the pair's |κ| ≤ 1/2 (seed 000 §3); None unless two wheels."""
    available = np.asarray(available, dtype=bool)
    if int(available.sum()) != 2:
        return None
    _, kappa = _nadir_kappa(scenario, available)
    return float(np.mean(np.abs(kappa) <= allocation.KAPPA_MAX))


SCAN_GEOMETRY_SINE = 0.5  # B within 30° of a pair's normal: the MD's torque across the plane needs ≥ 2× the dipole


def pair_limit(s: Scenario, mask: np.ndarray) -> str:
    """Why a wheel pair + MD (least-dipole law) misses the scanning accuracy, with figures from the programme and
    the field model: the wheels give no torque about n_pq = a_p × a_q; the programme asks τ_n = ⟨J ω̇^p +
    ω^p × J ω^p, n_pq⟩ there, and the rods (|l_i| ≤ l^m) give at most l^m |B| sin∠(B, n_pq) / max_i |u_i| with
    u = b̂ × n_pq / |b̂ × n_pq| (L ∥ B × n_pq). "geometry" when the demand exceeds it with B within 30° of n_pq,
    "dipole limit" when it does so in a better geometry; "loop design" when it never does."""
    axes = engine.plant_params(s).wheel_axes_b[:, np.asarray(mask, dtype=bool)]
    n = np.cross(axes[:, 0], axes[:, 1])
    n /= np.linalg.norm(n)
    t = np.arange(s.guidance.route_start_s, s.duration_s, s.control_dt_s)
    prog = engine.program_along(s, t)
    j = engine.plant_params(s).inertia_kg_m2
    demand = np.abs((prog.omega_dot_b @ j.T + np.cross(prog.omega_b, prog.omega_b @ j.T)) @ n)
    b_body = np.array([conjugate_rotate_1(q, b) for q, b in zip(prog.q_ib, prog.b_eci_t)])
    b_norm = np.linalg.norm(b_body, axis=1)
    b_cross_n = np.cross(b_body / b_norm[:, None], n)
    sine = np.linalg.norm(b_cross_n, axis=1)
    box = np.max(np.abs(b_cross_n), axis=1) / np.maximum(sine, 1e-12)  # largest rod share of the least dipole
    limit = s.spacecraft.md_max_dipole_am2
    capacity = limit * b_norm * sine / box
    over = demand > capacity
    k = int(np.argmax(demand - capacity))
    parts = [
        f"the route asks up to {demand.max():.1e} N·m across the pair plane; at its worst ({t[k]:.0f} s) "
        f"{demand[k]:.1e} N·m where {limit:.0f} A·m² rods give {capacity[k]:.1e} N·m "
        f"(|B| {b_norm[k] * 1e6:.0f} µT, {np.degrees(np.arcsin(min(sine[k], 1.0))):.0f}° from the pair normal)",
        f"over the rods' limit {over.mean():.0%} of the route",
    ]
    causes = []
    if np.any(over & (sine < SCAN_GEOMETRY_SINE)):
        causes.append("geometry")
    if np.any(over & (sine >= SCAN_GEOMETRY_SINE)):
        causes.append("dipole limit")
    return f"{' and '.join(causes) or 'loop design'}: " + "; ".join(parts)


def _courses_rms(err: np.ndarray, observing: np.ndarray) -> list[float]:
    """RMS pointing error of each observing course (runs of ``observing``), arcsec."""
    edges = np.flatnonzero(np.diff(np.concatenate(([0], observing.astype(int), [0]))))
    return [float(np.sqrt(np.mean(err[a:b] ** 2))) for a, b in zip(edges[::2], edges[1::2])]


def _with_md_law(s: Scenario, md_law: str, variants: list[VariantSpec]) -> Scenario:
    data = s.model_dump()
    data["allocation"]["md_law"] = md_law
    data["variants"] = [v.model_dump() for v in variants]
    return Scenario.model_validate(data)


def configuration_table(scenario: Scenario) -> list[dict[str, Any]]:
    """Seed 000 §3/§5 for every wheel configuration (nominal, 4 singles, 6 pairs + MD) from one batch:
    pointing RMS/max while scanning (and per course), |κ| ≤ 1/2 orbit fraction, fastest feasible roll, route
    flown, and for a pair that misses the scanning accuracy the reason with figures (:func:`pair_limit`). Pairs
    fly the least-dipole MD law; their RMS under seed 000's e^m = b × e_pq law (|κ| ≤ 1/2) is flown beside it."""
    from sim_core.faults import configuration_variants

    variants, masks = configuration_variants(len(scenario.spacecraft.cluster.wheels))
    s = _with_md_law(scenario, "least_dipole", variants)
    traj = engine.simulate(s, wheel_available=masks, fdir=True)
    err = traj.pointing_error_rad() * ARCSEC_PER_RAD
    pairs = [v for v, mask in enumerate(masks) if mask.sum() == 2]
    seed_law = _with_md_law(scenario, "seed", [variants[v] for v in pairs])
    traj_seed = engine.simulate(seed_law, wheel_available=masks[pairs], fdir=True)
    err_seed = traj_seed.pointing_error_rad() * ARCSEC_PER_RAD
    rows = []
    for v, mask in enumerate(masks):
        obs = traj["observing"][v] > 0
        scan = err[v, obs] if obs.any() else err[v]
        turn = max_feasible_turn_rate(s, mask)
        metrics = variant_metrics(traj, s, v)
        seed_rms = None
        if v in pairs:
            e_seed = err_seed[pairs.index(v)]
            seed_rms = float(np.sqrt(np.mean((e_seed[obs] if obs.any() else e_seed) ** 2)))
        rows.append(
            {
                "configuration": traj.variant_names[v],
                "wheels": [int(p) + 1 for p in np.nonzero(mask)[0]],
                "pointing_rms_arcsec": float(np.sqrt(np.mean(scan**2))),
                "pointing_max_arcsec": float(np.max(scan)),
                "pointing_rms_seed_law_arcsec": seed_rms,
                "kappa_fraction": kappa_fraction(s, mask),
                "max_roll_rate_deg_s": None if np.isnan(turn.rate_rad_s) else float(np.degrees(turn.rate_rad_s)),
                "fastest_turn_s": None if np.isnan(turn.duration_s) else float(turn.duration_s),
                "fastest_turn_start_s": None if np.isnan(turn.start_s) else float(turn.start_s),
                "route_flown": bool(np.max(scan) <= ROUTE_FLOWN_ARCSEC and metrics["fault_mode_time_s"] == 0.0),
                "md_saturation_time_s": metrics["md_saturation_time_s"],
            }
        )
        rows[-1]["pointing_rms_per_course_arcsec"] = _courses_rms(err[v], obs)
        rows[-1]["why_not_flown"] = None if rows[-1]["route_flown"] or mask.sum() != 2 else pair_limit(s, mask)
    return rows
