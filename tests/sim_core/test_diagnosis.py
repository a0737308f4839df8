"""The diagnosis's wheel momentum balance (seed 000 eq 1 row 3) against a wheel integrated exactly: what the
telemetered commands leave unexplained must be what the balance's process noise says."""

from __future__ import annotations

import numpy as np

from sim_core import fault_detection as fd
from sim_core.diagnosis import Observations, _wheel_channels, wheel_model

ROTOR_KG_M2 = 0.0191
CONTROL_DT_S = 2.0  # seed 000: T_u = 2 s, telemetry at 1 Hz (each command in two samples)
TORQUE_QUANTUM_NM = 1e-5  # the reference dictionary's wheel_torque_cmd_nm step
WINDOW = 50  # samples per window the unexplained speed is compared over
WINDOWS = 400  # independent windows: the variance's relative standard error is sqrt(2 / 400) = 7 %
VARIANCE_TOLERANCE = 4.0 * np.sqrt(2.0 / WINDOWS)  # 4 standard errors


def _flown_wheel(seed: int) -> Observations:
    """One wheel on a still body: a random command every T_u, telemetered rounded to its quantum each second, the
    speed integrated exactly and read by a tachometer too fine to matter."""
    rng = np.random.default_rng(seed)
    n = WINDOW * WINDOWS + 1
    command = np.repeat(rng.normal(0.0, 3.0 * TORQUE_QUANTUM_NM, n // 2 + 1), 2)[:n]  # held for T_u
    speed = np.concatenate([[10.0], 10.0 + np.cumsum(command[:-1]) / ROTOR_KG_M2])
    fine = 1e-9
    return Observations(
        t_s=np.arange(n, dtype=float),
        epoch_unix_s=0.0,
        q_est_ib=np.tile([1.0, 0.0, 0.0, 0.0], (n, 1)),
        omega_b_rad_s=np.zeros((n, 3)),
        wheel_speed_rad_s=(np.round(speed / fine) * fine)[:, None],
        wheel_torque_cmd_nm=(np.round(command / TORQUE_QUANTUM_NM) * TORQUE_QUANTUM_NM)[:, None],
        speed_quantum_rad_s=fine,
        torque_quantum_nm=TORQUE_QUANTUM_NM,
    )


def test_a_held_command_s_rounding_explains_the_speed_it_leaves_unexplained() -> None:
    """The telemetered command's rounding error is the same for both samples a command is held: over any window it
    drives the speed twice as far (in variance) as the same error drawn afresh every second would, and the
    balance's process noise must say so (it said half)."""
    obs = _flown_wheel(14)
    wm = wheel_model(np.array([[1.0], [0.0], [0.0]]), np.array([ROTOR_KG_M2]), np.array([0.2]), np.zeros(1), 2.0)
    (channel,) = _wheel_channels(obs, wm, sigma_torque_nm=0.0)
    unexplained = fd.open_loop_residual(channel.y, channel.drift)[::WINDOW]
    cumulative_q = np.concatenate([[0.0], np.cumsum(channel.q_var)])[::WINDOW]
    measured = np.mean(np.diff(unexplained) ** 2)
    stated = np.mean(np.diff(cumulative_q))
    assert abs(measured / stated - 1.0) <= VARIANCE_TOLERANCE
