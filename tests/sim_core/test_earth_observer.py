"""Seed 002 eq (15) observer on a noiseless case: its error follows ė = A e and decays at the designed rate."""

import numpy as np
import pytest
from scipy.linalg import expm

from sim_core import earth_observer as eo

GAINS = np.array([0.012, 0.01, 0.008])  # seed 002 Table 1 (K_x, K_y, K_z)
ORBIT_RATE = 0.001  # rad/s, seed 002 Table 1
DT, N = 10.0, 1000


def _truth_kinematics(x, w):
    """Small-angle orbit-frame kinematics that eq (15) copies with K = 0."""
    phi, theta, psi = x
    return np.array([ORBIT_RATE * psi + w[0], ORBIT_RATE + w[1], -ORBIT_RATE * phi + w[2]])


def _noiseless_run(x_true, x_hat0):
    """Observer on a spacecraft held at a fixed orbit-frame attitude (the Earth-pointing case).

    The body rate that holds (φ, θ, ψ) is ω = (−ω_o ψ, −ω_o, ω_o φ); measurements and gyro rates
    are then constant, so the zero-order-hold discretisation is exact and the truth stays put.
    """
    phi_t, _, psi_t = x_true
    rates = np.array([-ORBIT_RATE * psi_t, -ORBIT_RATE, ORBIT_RATE * phi_t])
    assert np.allclose(_truth_kinematics(x_true, rates), 0.0, atol=1e-18)
    phi, gamma = eo.observer_discretisation(GAINS, ORBIT_RATE, DT)
    x_hat = np.array(x_hat0, float)
    err = np.empty((N, 3))
    for k in range(N):
        err[k] = x_hat - x_true
        eo.observer_step_1(x_hat, phi, gamma, rates, x_true[0], x_true[1], ORBIT_RATE)
    return err


def test_observer_error_follows_the_seed_error_dynamics_exactly():
    x_true = np.array([0.03, -0.02, 0.01])
    e0 = np.array([0.02, -0.01, 0.05])
    err = _noiseless_run(x_true, x_true + e0)
    kp, kt, ky = GAINS
    a = np.array([[-kp, 0, ORBIT_RATE], [0, -kt, 0], [-ORBIT_RATE - ky, 0, 0]])  # eq (15) minus truth
    step = expm(a * DT)
    expected = np.empty((N, 3))
    expected[0] = e0
    for k in range(1, N):
        expected[k] = step @ expected[k - 1]
    assert np.allclose(err, expected, atol=1e-9 * np.abs(e0).max())


def test_observer_converges_at_its_designed_rate():
    err = _noiseless_run(np.array([0.01, 0.02, -0.03]), np.zeros(3))
    kp, _, ky = GAINS
    slowest = max(np.roots([1.0, kp, ORBIT_RATE * (ORBIT_RATE + ky)]).real)  # s² + K_φ s + ω_o(ω_o + K_ψ)
    assert np.isclose(max(eo.design_rates(GAINS, ORBIT_RATE).real), slowest, rtol=1e-12)
    t = np.arange(N) * DT
    late = t > 4000.0  # the fast modes (≤ −0.01/s) have died out by 40 time constants
    slope = np.polyfit(t[late], np.log(np.linalg.norm(err[late], axis=-1)), 1)[0]
    assert slope == pytest.approx(slowest, rel=1e-3)
    assert np.linalg.norm(err[-1]) < 1e-3 * np.linalg.norm(err[0])


def test_bad_gains_name_the_field():
    with pytest.raises(ValueError, match="gains_1_s"):
        eo.observer_discretisation([0.01, -0.01, 0.01], ORBIT_RATE, DT)
    with pytest.raises(ValueError, match="orbit_rate_rad_s"):
        eo.observer_matrix(GAINS, 0.0)
