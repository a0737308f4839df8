"""The twin replay's orbit phase, against Basilisk: a file cut 1,700 s into the peer flight (tests/data/basilisk_faults,
its README) starts 1,700 s of circular-orbit motion after the argument of latitude 0 Basilisk began at."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from sim_core import orbit, scenario_library
from sim_core.twin_replay import orbit_phase_deg

FAILURE_W2 = Path(__file__).resolve().parents[1] / "data" / "basilisk_faults" / "failure_w2.csv"
FLIGHT_TIME_AT_FIRST_SAMPLE_S = 1700.0  # its --start (README)
ROWS_BEFORE_ONSET = 250  # the onset is 300 s after the first sample
PHASE_TOLERANCE_DEG = 0.2  # 0.05° fit grid; Basilisk's point-mass orbit vs our two-body circle over 250 s


def _rows() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    data = np.genfromtxt(str(FAILURE_W2), delimiter=",", names=True, dtype=None, encoding=None)
    t = np.arange(data.shape[0], dtype=float)[:ROWS_BEFORE_ONSET]  # 1 Hz from the first sample
    q = np.stack([data[f"q_est_ib_{i}"] for i in range(4)], axis=1)[:ROWS_BEFORE_ONSET]
    u = np.stack([data[f"wheel_torque_cmd_nm_{w}"] for w in range(1, 5)], axis=1)[:ROWS_BEFORE_ONSET]
    return t, q, u


def test_orbit_phase_of_a_cut_basilisk_file_matches_its_flight_time() -> None:
    scenario = scenario_library.get("peer-basilisk-rw4")
    n_rad_s = math.sqrt(orbit.MU_EARTH_M3_S2 / (orbit.R_EARTH_M + scenario.orbit.altitude_m) ** 3)
    expected = math.degrees(n_rad_s * FLIGHT_TIME_AT_FIRST_SAMPLE_S) % 180.0
    phase = orbit_phase_deg(scenario, *_rows())
    assert phase is not None
    assert phase == pytest.approx(expected, abs=PHASE_TOLERANCE_DEG)


def test_commands_the_gravity_gradient_does_not_explain_leave_the_phase_unknown() -> None:
    t, q, u = _rows()
    assert orbit_phase_deg(scenario_library.get("peer-basilisk-rw4"), t, q, 3.0 * u) is None


def test_effective_samples_of_white_ar1_and_constant_residuals() -> None:
    """AR(1) errors e_k = ρ e_{k−1} + w_k: the variance of their mean is that of n (1 − ρ)/(1 + ρ) independent
    samples (large n); white noise counts every row, a constant offset (a twin that drifts from the spacecraft by
    a fixed amount) counts once."""
    from sim_core.twin_replay import effective_samples

    rng = np.random.default_rng(7)
    n = 20_000
    assert effective_samples(rng.normal(size=(n, 3))) == pytest.approx(n, rel=0.05)
    for rho in (0.5, 0.9):
        e = np.zeros((n, 2))
        w = rng.normal(size=(n, 2))
        for k in range(1, n):
            e[k] = rho * e[k - 1] + w[k]
        assert effective_samples(e) == pytest.approx(n * (1.0 - rho) / (1.0 + rho), rel=0.1)
    assert effective_samples(np.full((500, 3), 2e-6)) == 1.0
