"""Static attitude determination from vector measurements: TRIAD and the star-tracker least squares.

Seed 003 §3.2.1.2. Body vectors are measured, reference vectors are known in the inertial frame;
the result is ``q_ib`` (body → inertial, scalar first).

Seed typos corrected here (DESIGN.md asks to decide and document):
- eq (5) reads C_br = C_m · C_r; with the triads written as matrix columns the rotation from the
  reference to the body frame is C_br = C_m · C_rᵀ.
- eq (13) reads K = (HᵀR⁻¹H)⁻¹HᵀR⁻¹H; the least-squares gain has no trailing H:
  K = (HᵀR⁻¹H)⁻¹HᵀR⁻¹.
- eqs (9)–(11): C ≈ I − [α×], so δR = R_m − R_r = [R_r×]α, i.e. h_i = [R_ri×] exactly as printed.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
from numba import njit

from sim_core import quaternion as qt

__all__ = ["triad", "triad_1", "triad_sensors_1", "TRIAD_MIN_SINE", "star_tracker_lsm", "LSM_MAX_ITERATIONS"]

LSM_MAX_ITERATIONS = 8  # Gauss–Newton relinearisations; each squares the residual angle
_COLLINEAR = 1e-9  # |U × V| below which two unit directions carry no attitude about their common axis


def _unit(v: np.ndarray, name: str) -> np.ndarray:
    v = np.asarray(v, dtype=float)
    if v.shape[-1:] != (3,) or not np.all(np.isfinite(v)):
        raise ValueError(f"{name}: expected finite vectors of shape (..., 3), got {v.shape}")
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    if np.any(n == 0.0):
        raise ValueError(f"{name}: zero vector has no direction")
    unit: npt.NDArray[np.float64] = v / n
    return unit


def _triad_frame(u: np.ndarray, v: np.ndarray, names: str) -> np.ndarray:
    """Columns q = U/|U|, r = U×V/|U×V|, s = q×r (seed 003 eq 3)."""
    cross = np.cross(u, v)
    n = np.linalg.norm(cross, axis=-1, keepdims=True)
    if np.any(n < _COLLINEAR):
        raise ValueError(f"{names}: the two vectors are collinear; TRIAD needs two distinct directions")
    r = cross / n
    return np.stack([u, r, np.cross(u, r)], axis=-1)


def triad(u_b: np.ndarray, v_b: np.ndarray, u_i: np.ndarray, v_i: np.ndarray) -> np.ndarray:
    """Attitude q_ib from a main vector U and an auxiliary V measured in body and known in IRF (seed 003 eqs 3–5).

    U is matched exactly, V only in the plane it spans with U. C_br = C_m C_rᵀ (eq 5 corrected).
    """
    c_m = _triad_frame(_unit(u_b, "u_b"), _unit(v_b, "v_b"), "u_b, v_b")
    c_r = _triad_frame(_unit(u_i, "u_i"), _unit(v_i, "v_i"), "u_i, v_i")
    return qt.from_dcm(c_r @ np.swapaxes(c_m, -1, -2))


@njit(cache=True)
def _dcm_to_quat_1(r: np.ndarray) -> np.ndarray:
    """Quaternion of a rotation matrix, Shepperd's largest-component branch (compiled)."""
    tr = r[0, 0] + r[1, 1] + r[2, 2]
    cand = np.array([1.0 + tr, 1.0 + 2.0 * r[0, 0] - tr, 1.0 + 2.0 * r[1, 1] - tr, 1.0 + 2.0 * r[2, 2] - tr])
    k = np.argmax(cand)
    q = np.empty(4)
    if k == 0:
        q[:] = (cand[0], r[2, 1] - r[1, 2], r[0, 2] - r[2, 0], r[1, 0] - r[0, 1])
    elif k == 1:
        q[:] = (r[2, 1] - r[1, 2], cand[1], r[0, 1] + r[1, 0], r[0, 2] + r[2, 0])
    elif k == 2:
        q[:] = (r[0, 2] - r[2, 0], r[0, 1] + r[1, 0], cand[2], r[1, 2] + r[2, 1])
    else:
        q[:] = (r[1, 0] - r[0, 1], r[0, 2] + r[2, 0], r[1, 2] + r[2, 1], cand[3])
    q = q / np.sqrt(np.sum(q * q))
    q_pos: npt.NDArray[np.float64] = -q if q[0] < 0.0 else q
    return q_pos


@njit(cache=True)
def triad_1(u_b: np.ndarray, v_b: np.ndarray, u_i: np.ndarray, v_i: np.ndarray) -> np.ndarray:
    """Compiled TRIAD q_ib of C_bi = C_r C_mᵀ (seed 003 eqs 3–5, eq 5 corrected); inputs must not be collinear."""
    c_m = np.empty((3, 3))
    c_r = np.empty((3, 3))
    for c, u, v in ((c_m, u_b, v_b), (c_r, u_i, v_i)):
        q = u / np.sqrt(np.sum(u * u))
        r = np.cross(u, v)
        r = r / np.sqrt(np.sum(r * r))
        c[:, 0] = q
        c[:, 1] = r
        c[:, 2] = np.cross(q, r)
    return _dcm_to_quat_1(c_r @ c_m.T)


TRIAD_MIN_SINE = np.sin(np.radians(10.0))  # a vector pair closer than 10° gives its cross product poorly


@njit(cache=True)
def _distinct_1(u: np.ndarray, v: np.ndarray) -> bool:
    c = np.cross(u, v)
    return bool(np.sum(c * c) >= TRIAD_MIN_SINE**2 * np.sum(u * u) * np.sum(v * v))


@njit(cache=True)
def triad_sensors_1(
    sun_b: np.ndarray,
    sun_ok: bool,
    nadir_b: np.ndarray,
    nadir_ok: bool,
    mag_b: np.ndarray,
    mag_ok: bool,
    sun_i: np.ndarray,
    nadir_i: np.ndarray,
    mag_i: np.ndarray,
) -> tuple[np.ndarray, bool]:
    """q_ib by TRIAD from the vector sensors that see (seed 003 §3.2.1.2.1): the Sun S (SS) as the main vector with
    the local vertical r (HS) as the auxiliary, else S with the field B (MAG), else r with B (eclipse); pairs
    closer than 10° are skipped, and a sensor whose ``*_ok`` is False (no valid sample). Returns (q_ib, False)
    when no pair is usable."""
    if sun_ok and nadir_ok and _distinct_1(sun_b, nadir_b):
        return triad_1(sun_b, nadir_b, sun_i, nadir_i), True
    if sun_ok and mag_ok and _distinct_1(sun_b, mag_b):
        return triad_1(sun_b, mag_b, sun_i, mag_i), True
    if nadir_ok and mag_ok and _distinct_1(nadir_b, mag_b):
        return triad_1(nadir_b, mag_b, nadir_i, mag_i), True
    return np.array([1.0, 0.0, 0.0, 0.0]), False


def star_tracker_lsm(
    stars_b: np.ndarray, stars_i: np.ndarray, q_prior_ib: np.ndarray, noise_var: float = 1.0
) -> tuple[np.ndarray, np.ndarray]:
    """Least-squares attitude from n ≥ 2 star directions about a prior (seed 003 eqs 8–13).

    Each pass predicts the body directions R_r = C(q̂) R_i, stacks z_i = R_m − R_r and
    h_i = [R_r×], solves α̂ = (HᵀH)⁻¹Hᵀz (eq 13, R = rI) and corrects q̂ ← q̂ ∘ (1, α̂/2);
    repeating removes the small-angle error of eq (9). Returns (q_ib, covariance r(HᵀH)⁻¹ of α̂ in rad²).
    """
    r_m = _unit(stars_b, "stars_b")
    r_i = _unit(stars_i, "stars_i")
    if r_m.ndim != 2 or r_m.shape != r_i.shape or r_m.shape[0] < 2:
        raise ValueError(f"stars_b, stars_i: expected two arrays of shape (n ≥ 2, 3), got {r_m.shape} and {r_i.shape}")
    if not noise_var > 0.0:
        raise ValueError(f"noise_var: must be > 0, got {noise_var}")
    q = qt.normalize(q_prior_ib)
    for _ in range(LSM_MAX_ITERATIONS):
        r_r = qt.rotate(qt.conjugate(q), r_i)
        h = _stacked_cross(r_r)
        hth = h.T @ h
        if np.linalg.cond(hth) > 1e12:
            raise ValueError("stars_b: star directions are collinear; the attitude about them is unobservable")
        alpha = np.linalg.solve(hth, h.T @ (r_m - r_r).reshape(-1))
        q = qt.normalize(qt.multiply(q, np.concatenate([[1.0], 0.5 * alpha])))
        if np.linalg.norm(alpha) < 1e-14:  # below float64 resolution of a unit quaternion
            break
    return q, noise_var * np.linalg.inv(hth)


def _stacked_cross(r: np.ndarray) -> np.ndarray:
    """H = [h_1; …; h_n] with h_i = [R_ri×] (seed 003 eq 12), shape (3n, 3)."""
    h = np.zeros((r.shape[0], 3, 3))
    h[:, 0, 1], h[:, 0, 2] = -r[:, 2], r[:, 1]
    h[:, 1, 0], h[:, 1, 2] = r[:, 2], -r[:, 0]
    h[:, 2, 0], h[:, 2, 1] = -r[:, 1], r[:, 0]
    return h.reshape(-1, 3)
