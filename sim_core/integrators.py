"""Integrators of the plant (seed 000 eq 1): fixed-step RK4 kernels and a high-accuracy reference.

``rk4_step_1`` is the classical fourth-order Runge–Kutta step with the wheel motor torque and the
external torque held over the step (zero-order hold, seed 000 eq 3), followed by renormalisation of
the quaternion Λ. ``reference_propagate`` integrates the same derivative with scipy's DOP853 at
rtol 1e-12 for tests; it does not renormalise, so its quaternion norm is itself a check.
State layout: see ``sim_core.spacecraft``.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np
from numba import njit
from numpy.typing import ArrayLike
from scipy.integrate import solve_ivp

from sim_core.spacecraft import PlantArrays, PlantParams, plant_derivative_1, plant_derivative_into, state_size

__all__ = ["rk4_step", "rk4_step_1", "rk4_step_into", "rk4_propagate", "rk4_propagate_1", "reference_propagate"]

REFERENCE_RTOL = 1e-12  # DOP853 tolerance of the reference path (near float64 round-off)


@njit(cache=True)
def rk4_step_into(
    x: np.ndarray,
    dt: float,
    wheel_motor_torque: np.ndarray,
    ext_torque_b: np.ndarray,
    p: PlantArrays,
    work: np.ndarray,
    out: np.ndarray,
) -> None:
    """RK4 step of seed 000 eq (1) into ``out`` (may alias x); ``work`` is scratch of shape (6, len(x))."""
    n = x.shape[0]
    force = work[5, : p.mass_inv.shape[0]]
    k, stage, acc = work[0], work[1], work[2]
    plant_derivative_into(x, wheel_motor_torque, ext_torque_b, p, force, k)
    for i in range(n):
        acc[i] = k[i]
        stage[i] = x[i] + 0.5 * dt * k[i]
    plant_derivative_into(stage, wheel_motor_torque, ext_torque_b, p, force, k)
    for i in range(n):
        acc[i] += 2.0 * k[i]
        stage[i] = x[i] + 0.5 * dt * k[i]
    plant_derivative_into(stage, wheel_motor_torque, ext_torque_b, p, force, k)
    for i in range(n):
        acc[i] += 2.0 * k[i]
        stage[i] = x[i] + dt * k[i]
    plant_derivative_into(stage, wheel_motor_torque, ext_torque_b, p, force, k)
    for i in range(n):
        out[i] = x[i] + (dt / 6.0) * (acc[i] + k[i])
    norm = np.sqrt(out[0] * out[0] + out[1] * out[1] + out[2] * out[2] + out[3] * out[3])
    for i in range(4):
        out[i] /= norm


@njit(cache=True)
def rk4_step_1(
    x: np.ndarray, dt: float, wheel_motor_torque: np.ndarray, ext_torque_b: np.ndarray, p: PlantArrays
) -> np.ndarray:
    """One RK4 step of seed 000 eq (1) with held torques, Λ renormalised (compiled kernel)."""
    out = np.empty(x.shape[0])
    rk4_step_into(x, dt, wheel_motor_torque, ext_torque_b, p, np.empty((6, x.shape[0])), out)
    return out


@njit(cache=True)
def rk4_propagate_1(
    x0: np.ndarray,
    dt: float,
    wheel_motor_torque: np.ndarray,
    ext_torque_b: np.ndarray,
    p: PlantArrays,
    every: int,
) -> np.ndarray:
    """RK4 over len(torque rows) steps; returns x at steps 0, every, 2·every, … (compiled kernel)."""
    n_steps = wheel_motor_torque.shape[0]
    out = np.empty((n_steps // every + 1, x0.shape[0]))
    out[0] = x0
    x = x0.copy()
    work = np.empty((6, x0.shape[0]))
    for k in range(n_steps):
        rk4_step_into(x, dt, wheel_motor_torque[k], ext_torque_b[k], p, work, x)
        if (k + 1) % every == 0:
            out[(k + 1) // every] = x
    return out


def _check_dt(dt_s: float) -> float:
    dt = float(dt_s)
    if not np.isfinite(dt) or dt <= 0.0:
        raise ValueError(f"dt_s: must be a finite positive step, got {dt_s}")
    return dt


def _check_x(x: ArrayLike, params: PlantParams) -> np.ndarray:
    n = state_size(params.n_modes, params.n_wheels)
    xs = np.ascontiguousarray(np.asarray(x, dtype=float))
    if xs.shape != (n,) or not np.all(np.isfinite(xs)):
        raise ValueError(f"x: expected a finite state of shape ({n},), got {xs.shape}")
    return xs


def _torque(value: ArrayLike, name: str, shape: tuple[int, ...]) -> np.ndarray:
    arr = np.ascontiguousarray(np.asarray(value, dtype=float))
    if arr.shape != shape or not np.all(np.isfinite(arr)):
        raise ValueError(f"{name}: expected finite shape {shape}, got {arr.shape}")
    return arr


def rk4_step(
    x: ArrayLike, dt_s: float, wheel_motor_torque_nm: ArrayLike, ext_torque_b_nm: ArrayLike, params: PlantParams
) -> np.ndarray:
    """One RK4 step of seed 000 eq (1) with held torques (validated wrapper of ``rk4_step_1``)."""
    m = _torque(wheel_motor_torque_nm, "wheel_motor_torque_nm", (params.n_wheels,))
    t = _torque(ext_torque_b_nm, "ext_torque_b_nm", (3,))
    return rk4_step_1(_check_x(x, params), _check_dt(dt_s), m, t, params.pack())


def rk4_propagate(
    x0: ArrayLike,
    dt_s: float,
    wheel_motor_torque_nm: ArrayLike,
    ext_torque_b_nm: ArrayLike,
    params: PlantParams,
    every: int = 1,
) -> np.ndarray:
    """States every ``every`` RK4 steps under per-step torques of shape (n_steps, n_w) and (n_steps, 3)."""
    n_steps = np.shape(wheel_motor_torque_nm)[0] if np.ndim(wheel_motor_torque_nm) == 2 else -1
    m = _torque(wheel_motor_torque_nm, "wheel_motor_torque_nm", (n_steps, params.n_wheels))
    t = _torque(ext_torque_b_nm, "ext_torque_b_nm", (n_steps, 3))
    if int(every) < 1:
        raise ValueError(f"every: must be a positive integer, got {every}")
    return rk4_propagate_1(_check_x(x0, params), _check_dt(dt_s), m, t, params.pack(), int(every))


TorqueFn = Callable[[float], np.ndarray]


def reference_propagate(
    x0: ArrayLike,
    t_eval_s: Sequence[float],
    params: PlantParams,
    wheel_motor_torque_fn: TorqueFn | None = None,
    ext_torque_fn: TorqueFn | None = None,
    breakpoints_s: Sequence[float] = (),
    rtol: float = REFERENCE_RTOL,
) -> np.ndarray:
    """States at ``t_eval_s`` by DOP853 (rtol 1e-12) on seed 000 eq (1); restarts at torque breakpoints."""
    x = _check_x(x0, params)
    t_eval = np.asarray(t_eval_s, dtype=float)
    if t_eval.ndim != 1 or t_eval.size == 0 or np.any(np.diff(t_eval) < 0.0) or t_eval[0] < 0.0:
        raise ValueError("t_eval_s: expected a non-empty, non-decreasing sequence of times ≥ 0")
    p = params.pack()
    zero_m, zero_t = np.zeros(params.n_wheels), np.zeros(3)

    def rhs(t: float, y: np.ndarray) -> np.ndarray:
        m = zero_m if wheel_motor_torque_fn is None else np.asarray(wheel_motor_torque_fn(t), dtype=float)
        e = zero_t if ext_torque_fn is None else np.asarray(ext_torque_fn(t), dtype=float)
        return plant_derivative_1(y, m, e, p)

    edges = np.unique(np.concatenate([[0.0], [b for b in breakpoints_s if 0.0 < b < t_eval[-1]], [t_eval[-1]]]))
    out = np.empty((t_eval.size, x.size))
    out[t_eval == 0.0] = x
    for t0, t1 in zip(edges[:-1], edges[1:]):
        inside = (t_eval > t0) & (t_eval <= t1)
        seg_t = np.unique(np.append(t_eval[inside], t1))
        sol = solve_ivp(rhs, (t0, t1), x, method="DOP853", rtol=rtol, atol=rtol * 1e-3, t_eval=seg_t)
        if not sol.success:
            raise RuntimeError(f"reference integration failed on [{t0}, {t1}] s: {sol.message}")
        out[inside] = sol.y.T[np.searchsorted(seg_t, t_eval[inside])]
        x = sol.y[:, -1]
    return out
