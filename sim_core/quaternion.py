"""Batch quaternion algebra: scalar-first Hamilton quaternions Λ = (λ0, λ) of shape (..., 4).

Convention (DESIGN.md, seed 000 §2): ``q_ib`` rotates body vectors into the inertial frame,
v_i = Λ ∘ v_b ∘ Λ̃, and the kinematics are Λ̇ = ½ Λ ∘ ω with ω in body axes (seed 000 eq 1).
The ``*_1`` functions are numba kernels on single quaternions, for compiled inner loops.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, cast

import numpy as np
import numpy.typing as npt
from numba import njit, types
from numba.extending import intrinsic

__all__ = [
    "multiply",
    "conjugate",
    "normalize",
    "rotate",
    "to_dcm",
    "from_dcm",
    "to_mrp",
    "from_mrp",
    "from_axis_angle",
    "angle",
    "from_euler_132",
    "to_euler_132",
    "slerp",
    "derivative",
    "multiply_1",
    "rotate_1",
    "conjugate_rotate_1",
    "conjugate_rotate_into",
    "conjugate_rotate_components_1",
    "attitude_difference_1",
    "angle_between_1",
    "dot3_1",
    "dot3_floats",
    "normalize_1",
]


def _as_quat(q: np.ndarray, name: str = "q") -> np.ndarray:
    q = np.asarray(q, dtype=float)
    if q.shape[-1:] != (4,):
        raise ValueError(f"{name}: expected shape (..., 4), got {q.shape}")
    if not np.all(np.isfinite(q)):
        raise ValueError(f"{name}: contains NaN or infinite values")
    return q


def multiply(p: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Hamilton product p ∘ q (seed 000 §2 quaternion composition)."""
    p, q = np.asarray(p, dtype=float), np.asarray(q, dtype=float)
    p0, pv = p[..., :1], p[..., 1:]
    q0, qv = q[..., :1], q[..., 1:]
    s = p0 * q0 - np.sum(pv * qv, axis=-1, keepdims=True)
    v = p0 * qv + q0 * pv + np.cross(pv, qv)
    return np.concatenate([s, v], axis=-1)


def conjugate(q: np.ndarray) -> np.ndarray:
    """Conjugate Λ̃ = (λ0, −λ), the inverse of a unit quaternion."""
    q = np.asarray(q, dtype=float)
    q_conj: npt.NDArray[np.float64] = q * np.array([1.0, -1.0, -1.0, -1.0])
    return q_conj


def normalize(q: np.ndarray) -> np.ndarray:
    """Unit quaternion with non-negative scalar part (the same rotation)."""
    q = _as_quat(q)
    n = np.linalg.norm(q, axis=-1, keepdims=True)
    if np.any(n == 0.0):
        raise ValueError("q: zero quaternion cannot be normalised")
    q = q / n
    return np.where(q[..., :1] < 0.0, -q, q)


def rotate(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Rotate vectors by Λ: Λ ∘ v ∘ Λ̃ (body → inertial for ``q_ib``)."""
    q, v = np.asarray(q, dtype=float), np.asarray(v, dtype=float)
    q0, qv = q[..., :1], q[..., 1:]
    t = 2.0 * np.cross(qv, v)
    return v + q0 * t + np.cross(qv, t)


def to_dcm(q: np.ndarray) -> np.ndarray:
    """Rotation matrix R(Λ) with R @ v = Λ ∘ v ∘ Λ̃ (columns are body axes in the reference frame)."""
    q = np.asarray(q, dtype=float)
    w, x, y, z = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    r = np.empty(q.shape[:-1] + (3, 3))
    r[..., 0, 0] = 1 - 2 * (y * y + z * z)
    r[..., 0, 1] = 2 * (x * y - w * z)
    r[..., 0, 2] = 2 * (x * z + w * y)
    r[..., 1, 0] = 2 * (x * y + w * z)
    r[..., 1, 1] = 1 - 2 * (x * x + z * z)
    r[..., 1, 2] = 2 * (y * z - w * x)
    r[..., 2, 0] = 2 * (x * z - w * y)
    r[..., 2, 1] = 2 * (y * z + w * x)
    r[..., 2, 2] = 1 - 2 * (x * x + y * y)
    return r


def from_dcm(r: np.ndarray) -> np.ndarray:
    """Quaternion of a rotation matrix (inverse of :func:`to_dcm`), Shepperd's method."""
    r = np.asarray(r, dtype=float)
    if r.shape[-2:] != (3, 3):
        raise ValueError(f"dcm: expected shape (..., 3, 3), got {r.shape}")
    d0, d1, d2 = r[..., 0, 0], r[..., 1, 1], r[..., 2, 2]
    a, b, c = r[..., 2, 1] - r[..., 1, 2], r[..., 0, 2] - r[..., 2, 0], r[..., 1, 0] - r[..., 0, 1]
    e, f, g = r[..., 0, 1] + r[..., 1, 0], r[..., 0, 2] + r[..., 2, 0], r[..., 1, 2] + r[..., 2, 1]
    cand = np.stack(
        [
            np.stack([1 + d0 + d1 + d2, a, b, c], axis=-1),
            np.stack([a, 1 + d0 - d1 - d2, e, f], axis=-1),
            np.stack([b, e, 1 - d0 + d1 - d2, g], axis=-1),
            np.stack([c, f, g, 1 - d0 - d1 + d2], axis=-1),
        ],
        axis=-2,
    )  # row i is 4 q_i q (Shepperd), best conditioned where q_i is largest
    k = np.argmax(np.stack([1 + d0 + d1 + d2, 1 + d0 - d1 - d2, 1 - d0 + d1 - d2, 1 - d0 - d1 + d2], -1), -1)
    q = np.take_along_axis(cand, k[..., None, None], axis=-2)[..., 0, :]
    return normalize(q)


def to_mrp(q: np.ndarray) -> np.ndarray:
    """Modified Rodrigues parameters σ = λ / (1 + λ0), short rotation (|σ| ≤ 1), as Basilisk uses."""
    q = normalize(q)
    return q[..., 1:] / (1.0 + q[..., :1])


def from_mrp(sigma: np.ndarray) -> np.ndarray:
    """Quaternion of MRP σ: λ0 = (1 − σ²)/(1 + σ²), λ = 2σ/(1 + σ²)."""
    s = np.asarray(sigma, dtype=float)
    s2 = np.sum(s * s, axis=-1, keepdims=True)
    return normalize(np.concatenate([(1 - s2), 2 * s], axis=-1) / (1 + s2))


def from_axis_angle(axis: np.ndarray, angle_rad: np.ndarray | float) -> np.ndarray:
    """Quaternion (cos θ/2, e sin θ/2) of a turn by θ about unit axis e."""
    axis = np.asarray(axis, dtype=float)
    n = np.linalg.norm(axis, axis=-1, keepdims=True)
    if np.any(n == 0.0):
        raise ValueError("axis: zero vector has no direction")
    half = 0.5 * np.asarray(angle_rad, dtype=float)[..., None]
    return np.concatenate([np.cos(half), np.sin(half) * axis / n], axis=-1)


def angle(q: np.ndarray) -> np.ndarray:
    """Rotation angle of Λ in [0, π] (rad): 2 atan2(|λ|, |λ0|)."""
    q = np.asarray(q, dtype=float)
    angle_rad: npt.NDArray[np.float64] = 2.0 * np.arctan2(np.linalg.norm(q[..., 1:], axis=-1), np.abs(q[..., 0]))
    return angle_rad


def _turn(i: int, phi: np.ndarray) -> np.ndarray:
    """Quaternion of the simple turn [φ]_i about axis i (1, 2, 3 = x, y, z)."""
    axis = np.zeros(np.shape(phi) + (3,))
    axis[..., i - 1] = 1.0
    return from_axis_angle(axis, phi)


def from_euler_132(yaw_rad: npt.ArrayLike, roll_rad: npt.ArrayLike, pitch_rad: npt.ArrayLike) -> np.ndarray:
    """Quaternion of seed 000's sequence 132: yaw φ1 about x, then roll φ2 about y… as C^o = [φ2]_2 [φ3]_3 [φ1]_1.

    C^o maps reference-frame coordinates to body coordinates (a passive matrix), so the active
    quaternion rotating body vectors into the reference frame is Λ = [φ1]_1 ∘ [φ3]_3 ∘ [φ2]_2.
    """
    yaw, roll, pitch = (np.asarray(a, dtype=float) for a in (yaw_rad, roll_rad, pitch_rad))
    return multiply(multiply(_turn(1, yaw), _turn(3, pitch)), _turn(2, roll))


def to_euler_132(q: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Yaw φ1, roll φ2, pitch φ3 (rad) of C^o = [φ2]_2 [φ3]_3 [φ1]_1 from Λ (inverse of from_euler_132).

    With R = C^oᵗ = R_x(φ1) R_z(φ3) R_y(φ2): R01 = −sin φ3, R21/R11 = tan φ1, R02/R00 = tan φ2.
    """
    r = to_dcm(q)
    pitch = np.arcsin(np.clip(-r[..., 0, 1], -1.0, 1.0))
    yaw = np.arctan2(r[..., 2, 1], r[..., 1, 1])
    roll = np.arctan2(r[..., 0, 2], r[..., 0, 0])
    return yaw, roll, pitch


def slerp(q0: np.ndarray, q1: np.ndarray, tau: np.ndarray | float) -> np.ndarray:
    """Spherical linear interpolation from q0 (τ = 0) to q1 (τ = 1) along the short arc."""
    q0, q1 = normalize(q0), normalize(q1)
    tau = np.asarray(tau, dtype=float)[..., None]
    d = np.sum(q0 * q1, axis=-1, keepdims=True)
    q1 = np.where(d < 0.0, -q1, q1)
    d = np.abs(d)
    theta = np.arccos(np.clip(d, -1.0, 1.0))
    small = theta < 1e-8
    st = np.where(small, 1.0, np.sin(theta))
    w0 = np.where(small, 1.0 - tau, np.sin((1.0 - tau) * theta) / st)
    w1 = np.where(small, tau, np.sin(tau * theta) / st)
    return normalize(w0 * q0 + w1 * q1)


def derivative(q: np.ndarray, omega_b: np.ndarray) -> np.ndarray:
    """Kinematics Λ̇ = ½ Λ ∘ ω, ω in body axes (seed 000 eq 1)."""
    w = np.asarray(omega_b, dtype=float)
    return 0.5 * multiply(q, np.concatenate([np.zeros(w.shape[:-1] + (1,)), w], axis=-1))


@njit(cache=True, fastmath=False)
def multiply_1(p: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Hamilton product p ∘ q of two single quaternions (compiled kernel)."""
    r = np.empty(4)
    r[0] = p[0] * q[0] - p[1] * q[1] - p[2] * q[2] - p[3] * q[3]
    r[1] = p[0] * q[1] + p[1] * q[0] + p[2] * q[3] - p[3] * q[2]
    r[2] = p[0] * q[2] - p[1] * q[3] + p[2] * q[0] + p[3] * q[1]
    r[3] = p[0] * q[3] + p[1] * q[2] - p[2] * q[1] + p[3] * q[0]
    return r


@njit(cache=True)
def rotate_1(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Λ ∘ v ∘ Λ̃ for one quaternion and one vector (compiled kernel)."""
    tx = 2.0 * (q[2] * v[2] - q[3] * v[1])
    ty = 2.0 * (q[3] * v[0] - q[1] * v[2])
    tz = 2.0 * (q[1] * v[1] - q[2] * v[0])
    r = np.empty(3)
    r[0] = v[0] + q[0] * tx + q[2] * tz - q[3] * ty
    r[1] = v[1] + q[0] * ty + q[3] * tx - q[1] * tz
    r[2] = v[2] + q[0] * tz + q[1] * ty - q[2] * tx
    return r


@njit(cache=True)
def conjugate_rotate_1(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Λ̃ ∘ v ∘ Λ (inertial → body for ``q_ib``), compiled kernel."""
    out = np.empty(3)
    conjugate_rotate_into(q, v, out)
    return out


@njit(cache=True)
def conjugate_rotate_into(q: np.ndarray, v: np.ndarray, out: np.ndarray) -> None:
    """Λ̃ ∘ v ∘ Λ with Λ = q[0:4] (inertial → body for ``q_ib``) written into ``out``, no allocation."""
    out[0], out[1], out[2] = conjugate_rotate_components_1(q, v[0], v[1], v[2])


@njit(cache=True)
def conjugate_rotate_components_1(q: np.ndarray, v0: float, v1: float, v2: float) -> tuple[float, float, float]:
    """Λ̃ ∘ v ∘ Λ with Λ = q[0:4] for v = (v0, v1, v2), as three floats (kernels that keep vectors in registers)."""
    q0, q1, q2, q3 = q[0], -q[1], -q[2], -q[3]
    tx = 2.0 * (q2 * v2 - q3 * v1)
    ty = 2.0 * (q3 * v0 - q1 * v2)
    tz = 2.0 * (q1 * v1 - q2 * v0)
    return v0 + q0 * tx + q2 * tz - q3 * ty, v1 + q0 * ty + q3 * tx - q1 * tz, v2 + q0 * tz + q1 * ty - q2 * tx


@njit(cache=True)
def attitude_difference_1(q_a: np.ndarray, q_b: np.ndarray) -> float:
    """Rotation angle (rad, in [0, π]) between two attitudes."""
    d = abs(q_a[0] * q_b[0] + q_a[1] * q_b[1] + q_a[2] * q_b[2] + q_a[3] * q_b[3])
    return float(2.0 * np.arccos(min(d, 1.0)))


def _fma_llvm(typingctx: Any, a: Any, b: Any, c: Any) -> Any:
    def codegen(context: Any, builder: Any, signature: Any, args: Any) -> Any:
        return builder.fma(*args)

    return types.float64(types.float64, types.float64, types.float64), codegen


# a·b + c rounded once, in compiled code (LLVM's llvm.fma: the FMA instruction where the CPU has one, else libm's)
_fma = cast("Callable[[float, float, float], float]", intrinsic(_fma_llvm))


@njit(cache=True)
def dot3_floats(a0: float, a1: float, a2: float, b0: float, b1: float, b2: float) -> float:
    """a · b of two 3-vectors given as floats, summed as OpenBLAS's ddot sums three terms on an FMA CPU,
    fma(a2, b2, fma(a1, b1, fma(a0, b0, 0))): the bits of numba's ``a @ b`` there (a BLAS call, ≈ 50 ns) in a
    few cycles, without arrays (0 differences in 200,000 random pairs, zeros and signs included)."""
    return _fma(a2, b2, _fma(a1, b1, _fma(a0, b0, 0.0)))


@njit(cache=True)
def dot3_1(a: np.ndarray, b: np.ndarray) -> float:
    """a · b of two 3-vectors (:func:`dot3_floats`): the bits of numba's ``a @ b`` without its BLAS call.

    >>> dot3_1(np.array([1.0, 2.0, 3.0]), np.array([4.0, -5.0, 6.0]))
    12.0
    """
    return dot3_floats(a[0], a[1], a[2], b[0], b[1], b[2])


@njit(cache=True)
def angle_between_1(a: np.ndarray, b: np.ndarray) -> float:
    """Angle (rad) between two non-zero vectors, atan2(|a × b|, a · b)."""
    c = np.cross(a, b)
    return float(np.arctan2(np.sqrt(dot3_1(c, c)), dot3_1(a, b)))


@njit(cache=True)
def normalize_1(q: np.ndarray) -> np.ndarray:
    """Unit quaternion of a single quaternion (compiled kernel; sign kept)."""
    q_unit: npt.NDArray[np.float64] = q / np.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    return q_unit
