"""The trajectory records the sensors' readings as the onboard software took them (closed_loop.Sensed.readings):

- the magnetometer's field minus the true field (the scenario's field model at the recorded position, turned into
  body axes by the recorded true attitude) is its noise, σ per axis about a zero mean; a bias fault shifts the
  reading on its axis by the bias from the onset (against the nominal flight's), and not the true field;
- the star tracker reads the true attitude to its noise while it works and zeros once it has failed;
- the tachometers read the true wheel speeds quantised to their quantum (at control ticks, when they sample);
- the gyro reads the true rate plus the scenario's bias, to its noise.
"""

import numpy as np
import pytest

from sim_core import engine, quaternion, scenario_library
from sim_core.scenario import FaultSpec, Scenario, VariantSpec

BIAS_T = 2e-6  # 40 σ of the magnetometer's 50 nT
MAG_ONSET_S, STAR_ONSET_S = 200.0, 300.0
TACH_QUANTUM_RAD_S = 0.25 * np.pi / 30.0  # 0.25 rpm, the telemetry's resolution
MEAN_SIGMAS = 5.0  # a mean within 5 standard errors of its expectation
# The loop reads the field from a table interpolated linearly every engine.FIELD_TABLE_STEP_S; program_along evaluates
# the model: 21.6 nT apart at most on this flight (measured with the noise off), against the 50 nT noise and the
# 2000 nT bias; the same in every variant, so it cancels between two of them.
FIELD_TABLE_T = 25e-9
STAR_ARCSEC = np.radians(1.0 / 3600.0)


@pytest.fixture(scope="module")
def flight():
    base = scenario_library.get("somov-ge4-scan")
    data = base.model_dump()
    data.update(duration_s=600.0, output_dt_s=2.0)  # output ticks on the control ticks (T_u = 2 s)
    data["sensors"]["tachometer_quantum_rad_s"] = TACH_QUANTUM_RAD_S
    mag_bias = FaultSpec(target="magnetometer", index=0, type="bias", onset_s=MAG_ONSET_S, value=BIAS_T)
    star_out = FaultSpec(target="star_tracker", type="failure", onset_s=STAR_ONSET_S)
    data["variants"] = [
        VariantSpec(name="nominal").model_dump(),
        VariantSpec(name="magnetometer bias", faults=[mag_bias]).model_dump(),
        VariantSpec(name="star tracker failed", faults=[star_out]).model_dump(),
    ]
    s = Scenario.model_validate(data)
    traj = engine.simulate(s)
    b_eci = engine.program_along(s, traj.t_s).b_eci_t
    true_field = np.stack([quaternion.rotate(quaternion.conjugate(q), b_eci) for q in traj["q_ib"]])
    return s, traj, true_field


def _mean_within(residual: np.ndarray, expected: np.ndarray, sigma: float, model_error: float = 0.0) -> None:
    tol = MEAN_SIGMAS * sigma / np.sqrt(residual.shape[0]) + model_error
    np.testing.assert_allclose(residual.mean(axis=0), expected, rtol=0.0, atol=tol)


def test_magnetometer_reading_is_the_true_field_plus_noise_and_a_bias_fault_shifts_only_the_reading(flight):
    s, traj, true_field = flight
    sigma = s.sensors.magnetometer_noise_t
    residual = traj["b_mag_b_t"] - true_field
    _mean_within(residual[0], np.zeros(3), sigma, FIELD_TABLE_T)
    np.testing.assert_allclose(residual[0].std(axis=0), sigma, rtol=0.2)  # 300 samples: ±4 % standard error
    after = traj.t_s >= MAG_ONSET_S
    shift = residual[1] - residual[0]  # two independent noises: σ√2
    _mean_within(shift[~after], np.zeros(3), sigma * np.sqrt(2.0))
    _mean_within(shift[after], np.array([BIAS_T, 0.0, 0.0]), sigma * np.sqrt(2.0))
    # the truth does not see the bias: the biased flight's true field is the nominal one's to far below the bias
    assert np.abs(true_field[1] - true_field[0]).max() < 0.01 * BIAS_T


def test_star_tracker_reading_follows_the_attitude_and_is_zeros_once_failed(flight):
    s, traj, _ = flight
    q_st, q_ib = traj["q_st_ib"][2], traj["q_ib"][2]
    after = traj.t_s >= STAR_ONSET_S
    assert np.all(q_st[after] == 0.0)
    sigma = s.sensors.star_tracker_sigma_arcsec * STAR_ARCSEC
    error = quaternion.angle(quaternion.multiply(quaternion.conjugate(q_ib[~after]), q_st[~after]))
    assert np.all(error < 6.0 * sigma)  # 3 axes of noise: |e| beyond 6σ has probability < 1e-6 per sample


def test_tachometers_read_the_wheel_speeds_quantised(flight):
    _, traj, _ = flight
    truth = traj["wheel_speed_rad_s"]
    np.testing.assert_array_equal(
        traj["wheel_tachometer_rad_s"], np.round(truth / TACH_QUANTUM_RAD_S) * TACH_QUANTUM_RAD_S
    )
    assert np.any(traj["wheel_tachometer_rad_s"] != truth)


def test_gyro_reading_is_the_rate_plus_its_bias(flight):
    s, traj, _ = flight
    residual = traj["omega_gyro_b_rad_s"][0] - traj["omega_b_rad_s"][0]
    _mean_within(residual, np.asarray(s.sensors.gyro_bias_rad_s), s.sensors.gyro_noise_rad_s)
