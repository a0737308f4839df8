"""The job runner's built-in workload against the exact axisymmetric solution and conservation laws."""

from __future__ import annotations

import numpy as np
import pytest

from sim_core import quaternion as qt
from sim_core.rigid_spin import RigidSpinScenario, simulate

RK4_RATE_TOLERANCE = 1e-10  # rad/s: RK4 at 0.01 s, error ∝ (ΩΔt)^4 with ΩΔt ~ 1e-2
INERTIAL_MOMENTUM_TOLERANCE = 1e-9  # relative: H_i constant if kinematics and dynamics agree


def test_axisymmetric_body_matches_the_exact_precession() -> None:
    j1, j3, w0 = 30.0, 50.0, np.array([0.1, -0.05, 0.4])
    spin = RigidSpinScenario(duration_s=20.0, dt_s=0.01, inertia_kg_m2=[[j1, j1, j3]], omega0_rad_s=[w0.tolist()])
    trajectory = simulate(spin)
    rate = (j3 - j1) / j1 * w0[2]
    t = trajectory.t_s
    exact = (w0[0] + 1j * w0[1]) * np.exp(1j * rate * t)
    w = trajectory.omega_b_rad_s[0]
    assert np.max(np.abs(w[:, 0] - exact.real)) < RK4_RATE_TOLERANCE
    assert np.max(np.abs(w[:, 1] - exact.imag)) < RK4_RATE_TOLERANCE
    assert np.allclose(w[:, 2], w0[2], rtol=0, atol=RK4_RATE_TOLERANCE)


def test_inertial_angular_momentum_is_conserved_for_every_batch_member() -> None:
    spin = RigidSpinScenario(
        duration_s=10.0,
        dt_s=0.005,
        inertia_kg_m2=[[500.0, 200.0, 300.0], [35.0, 30.0, 25.0]],
        omega0_rad_s=[[0.5, -0.4, 0.7], [0.01, 0.2, -0.03]],
    )
    trajectory = simulate(spin)
    h_b = trajectory.inertia_kg_m2[:, None, :] * trajectory.omega_b_rad_s
    h_i = qt.rotate(trajectory.q_ib, h_b)
    drift = np.linalg.norm(h_i - h_i[:, :1], axis=-1) / np.linalg.norm(h_i[:, :1], axis=-1)
    assert drift.max() < INERTIAL_MOMENTUM_TOLERANCE


def test_progress_reaches_one_and_bad_shapes_name_the_field() -> None:
    seen: list[float] = []
    simulate(RigidSpinScenario(duration_s=1.0, dt_s=0.01), seen.append)
    assert seen[-1] == 1.0 and seen == sorted(seen)
    with pytest.raises(ValueError, match="omega0_rad_s"):
        RigidSpinScenario(inertia_kg_m2=[[1, 2, 3]], omega0_rad_s=[[1, 2]])
    with pytest.raises(ValueError, match="inertia_kg_m2"):
        RigidSpinScenario(inertia_kg_m2=[[1, -2, 3]], omega0_rad_s=[[1, 2, 3]])
