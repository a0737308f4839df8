"""The loop's gyro, magnetometer and earth-sensor faults act as their physics says (sim_core.faults through the
loop's sensing stages, closed_loop._sense_stage and _earth_sensor_angles_1), against truths written here:

- a k·σ noise fault on a magnetometer axis makes the measured-minus-true field on that axis have variance k²σ²
  (true field: the inertial field turned into body axes by the true attitude, a rotation about z written out here),
  the other axes σ², and the fault's noise is the magnetometer's own: uncorrelated with the gyro's noise;
- a frozen magnetometer or earth sensor (roll, pitch of the nadir, written out here for a turn about z) reads, from
  the onset to the fault's end, the output it gave last before the onset while the truth turns by many σ, and
  follows the truth again after;
- a frozen gyro (held by the same kernel, faults.held_sensor_faults_1) reads the output it gave last before the
  onset, or its first output when frozen from t = 0 (the truth plus noise, not the zeros the loop starts from).
"""

import numpy as np
import pytest
from numba import njit

from sim_core import closed_loop, faults
from sim_core.scenario import FaultSpec, VariantSpec

SIGMA_MAG_T = 1e-7
SIGMA_GYRO_RAD_S = 1e-5
SIGMA_EARTH_RAD = 1e-3
B_ECI_T = np.array([2.0e-5, -1.0e-5, 3.0e-5])
N_SAMPLES = 20_000
T_Q_S = 1.0
RATE_RAD_S = 1e-3  # the truth turns about z: 0.2 rad over the frozen interval, ≫ σ
VARIANCE_RTOL = 5.0 * np.sqrt(2.0 / N_SAMPLES)  # 5 standard errors of a sample variance (7 %)
CORRELATION_MAX = 5.0 / np.sqrt(N_SAMPLES)  # 5 standard errors of a sample correlation of independent series


@njit
def _seed(seed: int) -> None:
    np.random.seed(seed)


def _faults(*specs: FaultSpec) -> np.ndarray:
    table, _ = faults.fault_table([VariantSpec(name="v", faults=list(specs))])
    return table[0]


def _sensors() -> closed_loop.SensorModels:
    return closed_loop.SensorModels(
        star_sigma_rad=1e-5,
        gyro_noise_rad_s=SIGMA_GYRO_RAD_S,
        gyro_bias_rad_s=np.zeros(3),
        gyro_markov_sigma_rad_s=0.0,
        gyro_markov_tau_s=1.0,
        magnetometer_noise_t=SIGMA_MAG_T,
        tachometer_quantum_rad_s=0.0,
        sun_sensor_sigma_rad=0.0,
        star_boresight_b=np.array([0.0, 0.0, 1.0]),
        star_cos_sun_exclusion=2.0,  # never blinded
        star_max_rate_rad_s=np.inf,
        earth_sigma_rad=SIGMA_EARTH_RAD,
        earth_bias_rad=np.zeros(2),
    )


def _sensed() -> closed_loop.Sensed:
    held = np.full(3, np.nan)
    z = np.zeros(3)
    return closed_loop.Sensed(z.copy(), z.copy(), z.copy(), held.copy(), np.array([1.0, 0, 0, 0]), z.copy(), z.copy(),
                              held.copy(), held.copy(), held.copy(), np.zeros(closed_loop.RD_TACH))  # fmt: skip


def _state(t: float) -> np.ndarray:
    """Truth at t: attitude turned by RATE_RAD_S·t about z (scalar-first quaternion), body rate (0, 0, rate)."""
    a = RATE_RAD_S * t
    return np.array([np.cos(a / 2), 0.0, 0.0, np.sin(a / 2), 0.0, 0.0, RATE_RAD_S])


def _true_field_b(t: float) -> np.ndarray:
    """The inertial field in body axes of a body turned by a about z: R_z(a)ᵀ B."""
    a = RATE_RAD_S * t
    c, s = np.cos(a), np.sin(a)
    bx, by, bz = B_ECI_T
    return np.array([c * bx + s * by, -s * bx + c * by, bz])


def _fly_sensing(fault_rows: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """n T_q samples of the sensing stage: times, magnetometer readings, gyro noise (reading − true rate)."""
    s, sensed = _sensors(), _sensed()
    pos = closed_loop.Position(*(np.zeros(3) for _ in range(7)))
    pos.b_eci[:] = B_ECI_T
    markov = closed_loop._markov_1(s, T_Q_S)  # the gyro drift off: decay and step σ of an unused drift
    _seed(7)
    t_s = np.arange(n) * T_Q_S
    mag, gyro = np.empty((n, 3)), np.empty((n, 3))
    for i, t in enumerate(t_s):
        x = _state(t)
        closed_loop._sense_stage(s, fault_rows, t, x, markov, pos, sensed)
        mag[i], gyro[i] = sensed.mag, sensed.omega - x[4:7]
    return t_s, mag, gyro


@pytest.mark.parametrize("k", [1.0, 4.0])
def test_magnetometer_noise_fault_has_variance_k2_sigma2_and_its_own_noise(k):
    axis = 1
    rows = _faults(FaultSpec(target="magnetometer", index=axis, type="noise", value=k))
    t_s, mag, gyro_noise = _fly_sensing(rows, N_SAMPLES)
    resid = mag - np.array([_true_field_b(t) for t in t_s])
    expected = np.full(3, SIGMA_MAG_T**2)
    expected[axis] *= k**2
    assert np.var(resid, axis=0) == pytest.approx(expected, rel=VARIANCE_RTOL)
    assert np.all(np.abs(resid.mean(axis=0)) < 5.0 * np.sqrt(expected / N_SAMPLES))
    for i in range(3):
        for j in range(3):
            assert abs(np.corrcoef(resid[:, i], gyro_noise[:, j])[0, 1]) < CORRELATION_MAX


def test_frozen_magnetometer_holds_its_last_output_while_the_field_turns():
    onset, duration, n = 100.0, 200.0, 400
    rows = _faults(FaultSpec(target="magnetometer", type="frozen", onset_s=onset, duration_s=duration))
    t_s, mag, _ = _fly_sensing(rows, n)
    truth = np.array([_true_field_b(t) for t in t_s])
    held = (t_s >= onset) & (t_s < onset + duration)
    last_free = mag[np.flatnonzero(t_s < onset)[-1]]
    assert np.all(mag[held] == last_free)
    assert np.ptp(truth[held], axis=0).max() > 30.0 * SIGMA_MAG_T  # the truth moved by ≫ σ meanwhile
    free = ~held
    assert np.abs(mag[free] - truth[free]).max() < 6.0 * SIGMA_MAG_T  # before and after: the field plus noise
    assert np.unique(mag[t_s < onset][:, 0]).size == np.count_nonzero(t_s < onset)  # noisy, not a dead stream


@pytest.mark.parametrize("onset", [100.0, 0.0])
def test_frozen_gyro_holds_its_last_output(onset):
    """The body turns at RATE_RAD_S = 100 σ about z; the gyro's reading minus the truth is its noise, so a held
    reading is one value repeated, and a held zero would sit 100 σ off."""
    duration, n = 200.0, 400
    rows = _faults(FaultSpec(target="gyro", type="frozen", onset_s=onset, duration_s=duration))
    t_s, _, gyro_noise = _fly_sensing(rows, n)
    held = (t_s >= onset) & (t_s < onset + duration)
    last_free = np.flatnonzero(t_s < onset)
    given = gyro_noise[last_free[-1]] if last_free.size else gyro_noise[0]  # frozen from t = 0: its first output
    assert np.all(gyro_noise[held] == given)
    assert np.abs(gyro_noise).max() < 6.0 * SIGMA_GYRO_RAD_S  # truth + noise throughout, never a held zero
    free = ~held
    assert np.unique(gyro_noise[free][:, 0]).size == np.count_nonzero(free)  # noisy again after the fault


def test_frozen_earth_sensor_holds_its_last_output_while_the_attitude_turns():
    onset, duration, n = 100.0, 200.0, 400
    rows = _faults(FaultSpec(target="earth_sensor", type="frozen", onset_s=onset, duration_s=duration))
    r = np.array([-7.0e6, 0.0, 0.0])  # nadir along inertial x
    held_state = np.full(3, np.nan)
    _seed(11)
    t_s = np.arange(n) * T_Q_S
    angles = np.empty((n, 2))
    truth = np.empty((n, 2))
    for i, t in enumerate(t_s):
        x = _state(t)
        # truth: nadir x seen in a body turned by a about z is (cos a, −sin a, 0): roll 0, pitch a (seed 002 eq 14)
        truth[i] = 0.0, RATE_RAD_S * t
        a, ok = closed_loop._earth_sensor_angles_1(SIGMA_EARTH_RAD, np.zeros(2), rows, t, x, r, held_state)
        assert ok
        angles[i] = a[0:2]
    held = (t_s >= onset) & (t_s < onset + duration)
    last_free = angles[np.flatnonzero(t_s < onset)[-1]]
    assert np.all(angles[held] == last_free)
    assert np.ptp(truth[held], axis=0).max() > 100.0 * SIGMA_EARTH_RAD  # the truth moved by ≫ σ meanwhile
    free = ~held
    assert np.abs(angles[free] - truth[free]).max() < 6.0 * SIGMA_EARTH_RAD
    assert np.unique(angles[t_s < onset][:, 0]).size == np.count_nonzero(t_s < onset)
