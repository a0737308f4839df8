"""Smooth attitude between telemetry samples: a cubic Hermite spline on the rotation group.

Seed 000 §7: "approximation of a satellite attitude motion by the vector splines makes it possible
to simplify computer animation". On each interval [t_i, t_{i+1}] (h = t_{i+1} − t_i, τ = (t − t_i)/h)

    Λ(t) = Λ_i ∘ exp(p(τ)),   p cubic in rotation-vector space,
    p(0) = 0,  p(1) = φ_i = log(Λ̃_i ∘ Λ_{i+1}),  p'(0) = h ω_i,  p'(1) = h J_r(φ_i)⁻¹ ω_{i+1},

where exp maps a rotation vector φ to the quaternion (cos |φ|/2, sin(|φ|/2) φ/|φ|) and J_r is the
right Jacobian of SO(3). The body rate of Λ_i ∘ exp(p) is ω = J_r(p) ṗ (Λ̇ = ½ Λ ∘ ω, seed 000
eq 1), so the spline hits every sample exactly and its body rate equals ω_i on both sides of every
knot: the attitude is C¹ for any sample spacing (Shoemake's SQUAD is C¹ only for uniform spacing).
The knot rates ω_i are the telemetry rates when given, else the time-weighted mean of the two
neighbouring chord rates (exact for a constant-rate rotation).
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from sim_core import quaternion

__all__ = ["AttitudeSpline", "exp_rotation", "log_rotation", "right_jacobian", "right_jacobian_inverse"]

_SMALL_ANGLE_RAD = 1e-6  # below this, series expansions replace the closed forms (error < 1e-18)


def exp_rotation(phi: np.ndarray) -> np.ndarray:
    """Quaternion exp(φ) = (cos θ/2, sin(θ/2) φ/θ), θ = |φ| (seed 000 §2 Euler parameters), shape (..., 4)."""
    phi = np.asarray(phi, dtype=float)
    theta = np.linalg.norm(phi, axis=-1, keepdims=True)
    small = theta < _SMALL_ANGLE_RAD
    safe = np.where(small, 1.0, theta)
    k = np.where(small, 0.5 - theta**2 / 48.0, np.sin(0.5 * safe) / safe)
    return np.concatenate([np.cos(0.5 * theta), k * phi], axis=-1)


def log_rotation(q: np.ndarray) -> np.ndarray:
    """Rotation vector φ = θ e of the short rotation of Λ (inverse of :func:`exp_rotation`), shape (..., 3)."""
    q = quaternion.normalize(q)
    s = np.linalg.norm(q[..., 1:], axis=-1, keepdims=True)
    theta = 2.0 * np.arctan2(s, q[..., :1])
    small = s < 0.5 * _SMALL_ANGLE_RAD
    return np.where(small, 2.0 * q[..., 1:], theta * q[..., 1:] / np.where(small, 1.0, s))


def _hat(phi: np.ndarray) -> np.ndarray:
    z = np.zeros(phi.shape[:-1])
    x, y, w = phi[..., 0], phi[..., 1], phi[..., 2]
    return np.stack([np.stack([z, -w, y], -1), np.stack([w, z, -x], -1), np.stack([-y, x, z], -1)], -2)


def right_jacobian(phi: np.ndarray) -> np.ndarray:
    """J_r(φ) = I − (1 − cos θ)/θ² [φ×] + (θ − sin θ)/θ³ [φ×]², body rate ω = J_r(p) ṗ of exp(p), (..., 3, 3)."""
    phi = np.asarray(phi, dtype=float)
    theta = np.linalg.norm(phi, axis=-1)[..., None, None]
    small = theta < _SMALL_ANGLE_RAD
    t = np.where(small, 1.0, theta)
    a = np.where(small, 0.5 - theta**2 / 24.0, (1.0 - np.cos(t)) / t**2)
    b = np.where(small, 1.0 / 6.0 - theta**2 / 120.0, (t - np.sin(t)) / t**3)
    k = _hat(phi)
    jacobian: npt.NDArray[np.float64] = np.eye(3) - a * k + b * (k @ k)
    return jacobian


def right_jacobian_inverse(phi: np.ndarray) -> np.ndarray:
    """J_r(φ)⁻¹ = I + ½[φ×] + (1/θ² − (1 + cos θ)/(2θ sin θ)) [φ×]², shape (..., 3, 3)."""
    phi = np.asarray(phi, dtype=float)
    theta = np.linalg.norm(phi, axis=-1)[..., None, None]
    small = theta < _SMALL_ANGLE_RAD
    t = np.where(small, 1.0, theta)
    c = np.where(small, 1.0 / 12.0 + theta**2 / 720.0, 1.0 / t**2 - (1.0 + np.cos(t)) / (2.0 * t * np.sin(t)))
    k = _hat(phi)
    jacobian_inv: npt.NDArray[np.float64] = np.eye(3) + 0.5 * k + c * (k @ k)
    return jacobian_inv


class AttitudeSpline:
    """C¹ attitude spline through samples (t_i, Λ_i) with optional body rates ω_i (seed 000 §7 vector splines)."""

    def __init__(self, t_s: np.ndarray, q_ib: np.ndarray, omega_b_rad_s: np.ndarray | None = None) -> None:
        t = np.asarray(t_s, dtype=float)
        if t.ndim != 1 or t.size < 2:
            raise ValueError("t_s: expected a 1-D array of at least two sample times")
        if not np.all(np.isfinite(t)) or np.any(np.diff(t) <= 0.0):
            raise ValueError("t_s: sample times must be finite and strictly increasing")
        q = np.asarray(q_ib, dtype=float)
        if q.shape != (t.size, 4):
            raise ValueError(f"q_ib: expected shape ({t.size}, 4), got {q.shape}")
        q = _continuous_signs(quaternion.normalize(q))
        h = np.diff(t)
        phi = log_rotation(quaternion.multiply(quaternion.conjugate(q[:-1]), q[1:]))
        omega = _knot_rates(phi, h) if omega_b_rad_s is None else _checked_rates(omega_b_rad_s, t.size)
        self.t_s, self.q_ib, self.omega_b_rad_s = t, q, omega
        self._h, self._phi = h, phi
        self._m0 = h[:, None] * omega[:-1]
        self._m1 = h[:, None] * np.einsum("nij,nj->ni", right_jacobian_inverse(phi), omega[1:])

    def _locate(self, t_s: np.ndarray | float) -> tuple[np.ndarray, np.ndarray]:
        t = np.asarray(t_s, dtype=float)
        if not np.all(np.isfinite(t)):
            raise ValueError("t_s: query times must be finite")
        if np.any((t < self.t_s[0]) | (t > self.t_s[-1])):
            raise ValueError(f"t_s: query outside the samples [{self.t_s[0]}, {self.t_s[-1]}] s")
        i = np.clip(np.searchsorted(self.t_s, t, side="right") - 1, 0, self.t_s.size - 2)
        return i, (t - self.t_s[i]) / self._h[i]

    def _cubic(self, i: np.ndarray, tau: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """p(τ) and dp/dτ of the Hermite cubic on interval i."""
        tau = tau[..., None]
        h10, h01, h11 = tau**3 - 2 * tau**2 + tau, -2 * tau**3 + 3 * tau**2, tau**3 - tau**2
        d10, d01, d11 = 3 * tau**2 - 4 * tau + 1, -6 * tau**2 + 6 * tau, 3 * tau**2 - 2 * tau
        m0, m1, phi = self._m0[i], self._m1[i], self._phi[i]
        return h10 * m0 + h01 * phi + h11 * m1, d10 * m0 + d01 * phi + d11 * m1

    def attitude(self, t_s: np.ndarray | float) -> np.ndarray:
        """Interpolated q_ib at the query times (seed 000 §7), shape (..., 4)."""
        i, tau = self._locate(t_s)
        p, _ = self._cubic(i, tau)
        return quaternion.multiply(self.q_ib[i], exp_rotation(p))

    def rate_b_rad_s(self, t_s: np.ndarray | float) -> np.ndarray:
        """Body rate ω = J_r(p) ṗ of the spline (seed 000 eq 1 kinematics), rad/s, shape (..., 3)."""
        i, tau = self._locate(t_s)
        p, dp = self._cubic(i, tau)
        omega_rad_s: npt.NDArray[np.float64] = (
            np.einsum("...ij,...j->...i", right_jacobian(p), dp) / self._h[i][..., None]
        )
        return omega_rad_s


def _continuous_signs(q: np.ndarray) -> np.ndarray:
    """Flip signs so that consecutive quaternions lie in the same hemisphere (short arcs)."""
    flips = np.concatenate([[1.0], np.sign(np.sum(q[1:] * q[:-1], axis=-1))])
    flips[flips == 0.0] = 1.0
    return q * np.cumprod(flips)[:, None]


def _knot_rates(phi: np.ndarray, h: np.ndarray) -> np.ndarray:
    """Knot body rates: chord rates φ/h at the ends, their time-weighted mean inside."""
    chord = phi / h[:, None]
    inner = (h[1:, None] * chord[:-1] + h[:-1, None] * chord[1:]) / (h[:-1] + h[1:])[:, None]
    return np.concatenate([chord[:1], inner, chord[-1:]])


def _checked_rates(omega_b_rad_s: np.ndarray, n: int) -> np.ndarray:
    w = np.asarray(omega_b_rad_s, dtype=float)
    if w.shape != (n, 3):
        raise ValueError(f"omega_b_rad_s: expected shape ({n}, 3), got {w.shape}")
    if not np.all(np.isfinite(w)):
        raise ValueError("omega_b_rad_s: contains NaN or infinite values")
    return w
