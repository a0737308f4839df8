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


def test_every_hypothesis_maps_to_the_engine_faults_the_monitor_flies() -> None:
    """hypothesis_faults: wheel faults as the ranking's replay scores them, a speed bias as the tachometer's, a gyro
    bias on the axis the telemetry shows it on (the diagnosis reports its norm only), a star-tracker outage as the
    tracker failed; pairs both; onsets after the twin's start row; a fault outside the fault space refused."""
    import pytest

    from sim_core.diagnosis import hypothesis_faults
    from sim_core.twin_replay import fault_specs

    n, onset, first, bias = 200, 120.0, 50, 1e-4
    gyro = np.zeros((n, 3))
    gyro[int(onset) :, 1] = bias  # body y reads 1e-4 rad/s high from the onset on
    gyro += np.random.default_rng(3).normal(0.0, 1e-7, gyro.shape)
    obs = Observations(
        t_s=np.arange(n, dtype=float),
        epoch_unix_s=0.0,
        q_est_ib=np.tile([1.0, 0.0, 0.0, 0.0], (n, 1)),
        omega_b_rad_s=np.zeros((n, 3)),
        wheel_speed_rad_s=np.zeros((n, 4)),
        wheel_torque_cmd_nm=np.zeros((n, 4)),
        speed_quantum_rad_s=0.026,
        omega_gyro_b_rad_s=gyro,
    )

    def flown(fault, wheel, magnitude):
        specs = hypothesis_faults(obs, fault, wheel, onset, magnitude, first, n)
        assert all(s.onset_s == onset - first for s in specs)
        return [(s.target, s.index, s.type, s.gain, s.value) for s in specs]

    assert flown("gain_loss", 2, 0.3) == [
        (s.target, s.index, s.type, s.gain, s.value) for s in fault_specs("gain_loss", 2, onset - first, 0.3) or []
    ]
    assert flown("speed_bias", 3, -0.05) == [("tachometer", 2, "bias", 1.0, -0.05)]
    assert flown("failure+speed_bias", [1, 4], [None, 0.05]) == [
        ("wheel", 0, "failure", 1.0, 0.0),
        ("tachometer", 3, "bias", 1.0, 0.05),
    ]
    assert flown("star_tracker_outage", None, None) == [("star_tracker", 0, "failure", 1.0, 0.0)]
    gyro_faults = flown("gyro_bias", None, 2 * bias)  # the reported norm, on the estimated direction
    assert [f[:3] for f in gyro_faults] == [("gyro", a, "bias") for a in range(3)]
    values = np.array([f[4] for f in gyro_faults])
    assert np.linalg.norm(values) == pytest.approx(2 * bias)
    assert values[1] == pytest.approx(2 * bias, rel=1e-3) and np.abs(values[[0, 2]]).max() < 1e-3 * bias
    with pytest.raises(ValueError, match="magnetometer_bias cannot be flown: no magnetometer field"):
        hypothesis_faults(obs, "magnetometer_bias", None, onset, 1e-6, first, n)
    with pytest.raises(ValueError, match="'warp' is not a fault of the diagnosis' fault space"):
        hypothesis_faults(obs, "warp", None, onset, None, first, n)
