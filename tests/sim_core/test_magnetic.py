"""Magnetic driver: torque law against seed 003 eq 27 and numpy, allocation against lstsq and seed 000."""

import numpy as np
import pytest

from sim_core import magnetic as mag
from sim_core.wheels import ge_scheme_axes

EXACT = 1e-15  # round-off on a cross product of O(1e-5 T · 25 A·m²) values, in N·m
RNG = np.random.default_rng(11)
FIELDS_T = RNG.normal(scale=3e-5, size=(50, 3))  # LEO field magnitude ~ 20–50 µT
MOMENTS_AM2 = RNG.uniform(-25.0, 25.0, size=(50, 3))


def _seed_003_eq_27_matrix(b: np.ndarray) -> np.ndarray:
    """T_m = [[0, B_z, −B_y], [−B_z, 0, B_x], [B_y, −B_x, 0]] M, written as seed 003 prints it."""
    bx, by, bz = b
    return np.array([[0.0, bz, -by], [-bz, 0.0, bx], [by, -bx, 0.0]])


def test_torque_matches_seed_003_eq_27_matrix_and_kernel():
    for m, b in zip(MOMENTS_AM2, FIELDS_T):
        expected = _seed_003_eq_27_matrix(b) @ m
        assert np.allclose(mag.magnetic_torque(m, b), expected, atol=EXACT, rtol=0.0)
        assert np.allclose(mag.magnetic_torque_1(m, b), expected, atol=EXACT, rtol=0.0)


def test_torque_is_always_perpendicular_to_the_field():
    torque = mag.magnetic_torque(MOMENTS_AM2, FIELDS_T)
    assert np.allclose(np.sum(torque * FIELDS_T, axis=-1), 0.0, atol=1e-20)


def test_moment_for_torque_is_the_least_squares_minimum_norm_solution():
    """Seed 003 eq 29 L = B × T / B² vs numpy.linalg.lstsq on the singular eq 27 system."""
    torques = RNG.normal(scale=1e-3, size=(50, 3))
    for t, b in zip(torques, FIELDS_T):
        expected = np.linalg.lstsq(_seed_003_eq_27_matrix(b), t, rcond=None)[0]
        got = mag.moment_for_torque(t, b)
        assert np.allclose(got, expected, rtol=1e-9, atol=1e-9)
        assert np.allclose(mag.moment_for_torque_1(t, b), got, rtol=1e-12, atol=0.0)
        t_perp = t - b * np.dot(t, b) / np.dot(b, b)
        assert np.allclose(mag.magnetic_torque(got, b), t_perp, rtol=1e-9, atol=1e-15)


def test_seed_000_driver_moment_yields_plus_m_e_under_the_physical_law():
    """Seed 000 §3: wheels 2 and 4 left, e_pq = (a_2 + a_4)/|·|, e^m = b × e_pq (normalised).

    L = (m^m/B)(b × e^m) must give L × B = +m^m e^m: the physical law, not the seed's −L × B.
    """
    axes = ge_scheme_axes(np.deg2rad(30.0))
    s = axes[:, 1] + axes[:, 3]
    e_pq = s / np.linalg.norm(s)
    for b in FIELDS_T:
        e_m = np.cross(b / np.linalg.norm(b), e_pq)
        e_m /= np.linalg.norm(e_m)
        moment = mag.moment_for_driver_torque(2e-3, e_m, b)
        assert np.allclose(mag.magnetic_torque(moment, b), 2e-3 * e_m, rtol=1e-9, atol=1e-15)


def test_rod_saturation_clips_each_axis_to_l_max():
    """|l_i| ≤ l^m = 25 A·m² (seed 000 §5): (30, −40, 10) → (25, −25, 10)."""
    assert np.allclose(mag.saturate_moment([30.0, -40.0, 10.0], 25.0), [25.0, -25.0, 10.0], atol=0.0)
    assert np.allclose(mag.saturate_moment_1(np.array([30.0, -40.0, 10.0]), 25.0), [25.0, -25.0, 10.0], atol=0.0)


def test_bad_inputs_are_rejected_naming_the_field():
    with pytest.raises(ValueError, match="field_b_t"):
        mag.magnetic_torque([1.0, 0.0, 0.0], [np.nan, 0.0, 0.0])
    with pytest.raises(ValueError, match="moment_b_am2.*shape"):
        mag.magnetic_torque([1.0, 0.0], [1.0, 0.0, 0.0])
    with pytest.raises(ValueError, match="field_b_t.*zero"):
        mag.moment_for_torque([1e-3, 0.0, 0.0], [0.0, 0.0, 0.0])
    with pytest.raises(ValueError, match="max_moment_am2"):
        mag.saturate_moment([1.0, 2.0, 3.0], 0.0)
    with pytest.raises(ValueError, match="torque_dir_b.*perpendicular"):
        mag.moment_for_driver_torque(1e-3, [1.0, 0.0, 0.0], [1e-5, 0.0, 0.0])
