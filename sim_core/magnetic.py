"""Magnetic driver (MD): three orthogonal magnetic torque rods along the body axes.

Physics: a dipole L (A·m², body axes) in the field B (T, body axes) feels the torque
M^m = L × B (seed 003 eq 26–27). Each rod saturates at |l_i| ≤ l^m (seed 000 §2, l^m = 25 A·m²).

Sign convention. Seed 000 §2 writes M^m = −L × B = e^m m^m, yet two lines later it commands the
moment L = (m^m/B)(b × e^m). With the physical law, that L gives
L × B = m^m (b × e^m) × b = m^m (e^m − b⟨b, e^m⟩) = m^m e^m because e^m = b × e_pq ⟂ b, i.e. exactly
the torque the seed asks for; with the seed's −L × B it would give −m^m e^m. So the seed's allocation
formula is right and its "−L × B" is a sign slip: we use M^m = L × B everywhere and keep the seed's
L formula (``moment_for_driver_torque``). Seed 003's minimum-norm command L = B × T / B² (eq 29)
is consistent with the same law and yields the component of T perpendicular to B.
The ``*_1`` functions are numba kernels for the simulation loop.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
from numba import njit
from numpy.typing import ArrayLike

__all__ = [
    "magnetic_torque",
    "magnetic_torque_1",
    "magnetic_torque_into",
    "saturate_moment",
    "saturate_moment_1",
    "moment_for_torque",
    "moment_for_torque_1",
    "moment_for_driver_torque",
]


@njit(cache=True)
def magnetic_torque_1(moment_b: np.ndarray, field_b: np.ndarray) -> np.ndarray:
    """Torque L × B on the body, N·m, from dipole L (A·m²) and field B (T) in body axes (seed 003 eq 26)."""
    out = np.empty(3)
    magnetic_torque_into(moment_b, field_b, out)
    return out


@njit(cache=True)
def magnetic_torque_into(moment_b: np.ndarray, field_b: np.ndarray, torque_b_nm: np.ndarray) -> None:
    """:func:`magnetic_torque_1` written into ``torque_b_nm`` without allocating (the flight loop, every step)."""
    torque_b_nm[0] = moment_b[1] * field_b[2] - moment_b[2] * field_b[1]
    torque_b_nm[1] = moment_b[2] * field_b[0] - moment_b[0] * field_b[2]
    torque_b_nm[2] = moment_b[0] * field_b[1] - moment_b[1] * field_b[0]


@njit(cache=True)
def saturate_moment_1(moment_b: np.ndarray, max_moment_am2: float) -> np.ndarray:
    """Rod moments clipped to |l_i| ≤ l^m, A·m² (seed 000 §2 MD bound)."""
    out = np.empty(3)
    for i in range(3):
        out[i] = min(max_moment_am2, max(-max_moment_am2, moment_b[i]))
    return out


@njit(cache=True)
def moment_for_torque_1(torque_b: np.ndarray, field_b: np.ndarray) -> np.ndarray:
    """Minimum-norm dipole L = B × T / B², A·m² (seed 003 eq 29); zero where B = 0."""
    b2 = field_b[0] * field_b[0] + field_b[1] * field_b[1] + field_b[2] * field_b[2]
    out = np.zeros(3)
    if b2 > 0.0:
        out[0] = (field_b[1] * torque_b[2] - field_b[2] * torque_b[1]) / b2
        out[1] = (field_b[2] * torque_b[0] - field_b[0] * torque_b[2]) / b2
        out[2] = (field_b[0] * torque_b[1] - field_b[1] * torque_b[0]) / b2
    return out


def _vec3(value: ArrayLike, name: str) -> np.ndarray:
    arr = np.ascontiguousarray(np.asarray(value, dtype=float))
    if arr.shape[-1:] != (3,):
        raise ValueError(f"{name}: expected shape (..., 3), got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name}: contains NaN or infinite values")
    return arr


def magnetic_torque(moment_b_am2: ArrayLike, field_b_t: ArrayLike) -> np.ndarray:
    """Torque L × B, N·m, batch over leading axes (seed 003 eq 26; seed 000 M^m with the physical sign)."""
    return np.cross(_vec3(moment_b_am2, "moment_b_am2"), _vec3(field_b_t, "field_b_t"))


def saturate_moment(moment_b_am2: ArrayLike, max_moment_am2: float) -> np.ndarray:
    """Rod moments clipped to |l_i| ≤ l^m, A·m² (seed 000 §2)."""
    l_max = float(max_moment_am2)
    if not np.isfinite(l_max) or l_max <= 0.0:
        raise ValueError(f"max_moment_am2: must be finite and positive, got {max_moment_am2}")
    moment_am2: npt.NDArray[np.float64] = np.clip(_vec3(moment_b_am2, "moment_b_am2"), -l_max, l_max)
    return moment_am2


def moment_for_torque(torque_b_nm: ArrayLike, field_b_t: ArrayLike) -> np.ndarray:
    """Minimum-norm dipole L = B × T / B², A·m² (seed 003 eq 29); raises where B = 0."""
    t, b = _vec3(torque_b_nm, "torque_b_nm"), _vec3(field_b_t, "field_b_t")
    b2 = np.sum(b * b, axis=-1, keepdims=True)
    if np.any(b2 == 0.0):
        raise ValueError("field_b_t: zero field, no magnetic torque can be commanded")
    moment_am2: npt.NDArray[np.float64] = np.cross(b, t) / b2
    return moment_am2


def moment_for_driver_torque(torque_mag_nm: ArrayLike, torque_dir_b: ArrayLike, field_b_t: ArrayLike) -> np.ndarray:
    """Seed 000 §3 MD command L = (m^m/B)(b × e^m) for the torque m^m e^m, e^m ⟂ b, A·m²."""
    e_m, b = _vec3(torque_dir_b, "torque_dir_b"), _vec3(field_b_t, "field_b_t")
    b_norm = np.linalg.norm(b, axis=-1, keepdims=True)
    if np.any(b_norm == 0.0):
        raise ValueError("field_b_t: zero field, no magnetic torque can be commanded")
    if not np.allclose(np.linalg.norm(e_m, axis=-1), 1.0, atol=1e-9):
        raise ValueError("torque_dir_b: e^m must be a unit vector")
    unit_b = b / b_norm
    if np.any(np.abs(np.sum(e_m * unit_b, axis=-1)) > 1e-9):
        raise ValueError("torque_dir_b: e^m must be perpendicular to the field (e^m = b × e_pq)")
    m = np.asarray(torque_mag_nm, dtype=float)[..., None]
    moment_am2: npt.NDArray[np.float64] = m / b_norm * np.cross(unit_b, e_m)
    return moment_am2
