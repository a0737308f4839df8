"""Telemetry side of the twin session: actual track, GPS orbit fit, and a twin aligned to telemetry (seed 000 §7).

Truths: sim_core's exact circular orbit (noise-free fixes must give its elements back), the
emulated satellite's scenario elements under seed 003's GPS noise, the satellite's own programme
and telemetry (a twin flying the right fault hypothesis must reproduce them; the nominal twin must not).
"""

from __future__ import annotations

import numpy as np
import pytest

from sim_core import frames, orbit, quaternion, scenario_library
from sim_core.engine import orbit_state, simulate
from telemetry import emulator
from telemetry.actual_state import (
    TACHOMETER_COUNT_RAD_S,
    actual_track,
    aligned_scenario,
    aligned_wheel_available,
    fit_circular_orbit,
    rank_hypotheses,
)
from telemetry.decoding import decode_stream
from telemetry.dictionary import load_dictionary

ARCSEC = np.pi / 180.0 / 3600.0
NS = 10**9
FAILED_WHEEL, FAILURE_ONSET_S = 1, 350.0
ALIGN_S, TWIN_S = 300.0, 200.0  # start of the first scanning course; runs into the 20° turn (420–520 s)
RANKING_S = 300.0  # through the whole turn, where the wheels of the GE pair 1/3 part ways
EXACT_FIT_TOL_RAD = 1e-9  # noise-free fixes: only rounding of 7,000 km positions (~1e-9 m relative)
# 60 fixes with σ = 7.5 m (seed 003, 15 m 2σ) over a ±225 km arc: plane tilt σ√3/(225 km·√60) ≈ 7.5e-6 rad; 5σ.
NOISY_FIT_TOL_RAD = 4e-5
NOISY_ALTITUDE_TOL_M = 5.0  # σ/√60 ≈ 1 m; 5σ
GPS_2SIGMA_R_M, GPS_2SIGMA_V_M_S = 15.0, 1.5  # one fix's 2σ (seed 003); the local cubic averages 31 of them
# Three fixes 1 s apart: their velocities (σ_v = 0.75 m/s against |v| ≈ 7.56 km/s) hold the plane to ≈ 1e-4/√3 rad; 5σ.
THREE_FIX_PLANE_TOL_RAD = 5 * (GPS_2SIGMA_V_M_S / 2) / 7560.0 / np.sqrt(3)
EXTRAPOLATION_TOL_M = 100.0  # fitted plane tilt (5σ ≈ 4e-5 rad, above) over ±300 s of flight (2,300 km): < 100 m
EXTRAPOLATION_TOL_M_S = 0.1  # the same error turning at the orbit rate n ≈ 1.1e-3 rad/s
PROGRAMME_TOL_RAD = 3.0 * ARCSEC  # the fitted orbit plane turns the ORF by ≲ 1.5″ (tilt above)
TWIN_ATTITUDE_TOL_RAD = 30.0 * ARCSEC  # twin truth vs telemetered estimate: 10 × the 3″ star tracker σ
TWIN_WHEEL_TOL_RAD_S = 0.1  # ≈ 1 rpm over 200 s: different noise draws through the same control loop
DIVERGED_WHEEL_RAD_S = 1.0  # a twin flying the wrong hypothesis is off by more than this (≈ 10 rpm)


@pytest.fixture(scope="module")
def satellite():
    dictionary = load_dictionary(emulator.REFERENCE_DICTIONARY)
    fault = emulator.parse_fault(f"wheel:{FAILED_WHEEL}:failure@{FAILURE_ONSET_S}")
    traj, _, stream = emulator.emulate(faults=[fault], dictionary=dictionary)
    return traj, stream, decode_stream(stream.data, dictionary).batches


def test_actual_track_from_shuffled_repeated_batches_restores_sim_core_layouts(satellite) -> None:
    traj, stream, batches = satellite
    dictionary = load_dictionary(emulator.REFERENCE_DICTIONARY)
    pieces = [
        stream.window(int(stream.t_utc_ns[0]) + k * 60 * NS, int(stream.t_utc_ns[0]) + (k + 1) * 60 * NS)
        for k in range(15)
    ]
    live = [b for p in pieces for b in decode_stream(p.data, dictionary).batches]
    shuffled = [live[k] for k in np.random.default_rng(3).permutation(len(live))] + live[:4]  # repeats too
    track = actual_track(shuffled)
    whole = actual_track(batches)
    np.testing.assert_array_equal(track.t_utc_ns, whole.t_utc_ns)
    assert track.series["q_est_ib"].shape == (3600, 4) and track.series["wheel_speed_rad_s"].shape == (3600, 4)
    assert track.gps["r_ecef_m"].shape == (900, 3)
    for name, values in whole.series.items():
        np.testing.assert_array_equal(track.series[name], values)
    half_count = np.pi / 240.0 + 1e-12  # half of 0.25 rpm
    np.testing.assert_allclose(track.series["wheel_speed_rad_s"], traj["wheel_speed_rad_s"][0], atol=half_count)


def test_noise_free_fixes_give_the_circular_orbit_back_exactly() -> None:
    elements = {"altitude_m": 523e3, "inclination_deg": 61.0, "raan_deg": 40.0, "arg_latitude_deg": 123.0}
    t0 = 1.77e9
    t = t0 + np.arange(-30.0, 31.0)
    r, v = orbit.circular_orbit(
        t - t0, elements["altitude_m"], elements["inclination_deg"], elements["raan_deg"], elements["arg_latitude_deg"]
    )
    r_ecef, v_ecef = frames.eci_to_ecef(r, v, t)
    fitted = fit_circular_orbit(t, r_ecef, v_ecef, t0)
    assert fitted["altitude_m"] == pytest.approx(elements["altitude_m"], abs=1e-6)
    for key in ("inclination_deg", "raan_deg", "arg_latitude_deg"):
        assert np.radians(fitted[key] - elements[key]) == pytest.approx(0.0, abs=EXACT_FIT_TOL_RAD), key


def test_gps_fixes_of_the_emulated_satellite_give_its_scenario_orbit(satellite) -> None:
    traj, _, batches = satellite
    track = actual_track(batches)
    t_align = int(track.t_utc_ns[0]) + int(ALIGN_S * NS)
    near = np.abs(track.gps_t_utc_ns - t_align) <= 30 * NS
    fitted = fit_circular_orbit(
        track.gps_t_utc_ns[near] / NS, track.gps["r_ecef_m"][near], track.gps["v_ecef_m_s"][near], t_align / NS
    )
    s = scenario_library.get("somov-ge4-scan")  # circular 600 km, Sun-synchronous, RAAN 0, u0 = 0
    a = orbit.R_EARTH_M + s.orbit.altitude_m
    u = np.degrees(np.sqrt(orbit.MU_EARTH_M3_S2 / a**3) * ALIGN_S)
    assert fitted["altitude_m"] == pytest.approx(s.orbit.altitude_m, abs=NOISY_ALTITUDE_TOL_M)
    expected = {
        "inclination_deg": float(orbit.sun_synchronous_inclination_deg(s.orbit.altitude_m)),
        "raan_deg": s.orbit.raan_deg,
        "arg_latitude_deg": u,
    }
    for key, value in expected.items():
        assert np.radians(fitted[key] - value) == pytest.approx(0.0, abs=NOISY_FIT_TOL_RAD), key


def test_three_gps_fixes_give_the_orbit_plane_from_their_velocities(satellite) -> None:
    """The live twin's first synchronisation (2 s after the first packets) fits three fixes: positions alone would
    leave the plane free to turn about the 15 km chord they span; the weighted velocities pin it."""
    traj, _, batches = satellite
    track = actual_track(batches)
    s = scenario_library.get("somov-ge4-scan")
    for k in (10, 300, 600):
        t = track.gps_t_utc_ns[k : k + 3] / NS
        fitted = fit_circular_orbit(t, track.gps["r_ecef_m"][k : k + 3], track.gps["v_ecef_m_s"][k : k + 3], t[0])
        inclination = float(orbit.sun_synchronous_inclination_deg(s.orbit.altitude_m))
        assert np.radians(fitted["inclination_deg"] - inclination) == pytest.approx(0.0, abs=THREE_FIX_PLANE_TOL_RAD)
        assert np.radians(fitted["raan_deg"] - s.orbit.raan_deg) == pytest.approx(0.0, abs=THREE_FIX_PLANE_TOL_RAD)


def test_orbit_from_gps_fixes_follows_the_flown_orbit_inside_and_beyond_the_pass(satellite) -> None:
    traj, _, batches = satellite
    track = actual_track(batches)
    s = emulator.satellite_scenario()
    inside = traj.extra["epoch_unix_s"] + traj.t_s  # every 0.25 s, between and at the 1 Hz fixes
    beyond = np.concatenate([inside[0] - np.array([300.0, 10.0]), inside[-1] + np.array([10.0, 300.0])])
    cases = ((inside, GPS_2SIGMA_R_M, GPS_2SIGMA_V_M_S), (beyond, EXTRAPOLATION_TOL_M, EXTRAPOLATION_TOL_M_S))
    for t, tol_r, tol_v in cases:
        r, v = track.orbit_eci(t)
        r_true, v_true, _ = orbit_state(s)(t)
        assert np.linalg.norm(r - r_true, axis=-1).max() < tol_r
        assert np.linalg.norm(v - v_true, axis=-1).max() < tol_v


def _twin_vs_telemetry(satellite, hypothesis: list) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per-sample wheel-speed gaps (n, 4), attitude gaps and programme gaps of a twin aligned at ALIGN_S."""
    _, _, batches = satellite
    track = actual_track(batches)
    t_align = int(track.t_utc_ns[0]) + int(ALIGN_S * NS)
    twin_scenario = aligned_scenario(scenario_library.get("somov-ge4-scan"), track, t_align, TWIN_S, hypothesis)
    twin = simulate(twin_scenario, wheel_available=aligned_wheel_available(track, t_align), fdir=True)
    rows = track.at(t_align) + np.arange(twin.t_s.shape[0])
    wheels = np.abs(twin["wheel_speed_rad_s"][0] - track.series["wheel_speed_rad_s"][rows])

    def gap(q_a, q_b):
        return quaternion.angle(quaternion.multiply(quaternion.conjugate(q_a), q_b))

    attitude = gap(twin["q_ib"][0], track.series["q_est_ib"][rows])
    return wheels, attitude, gap(twin["q_prog_ib"][0], track.series["q_prog_ib"][rows])


def _truth_allowance_rad_s(satellite) -> float:
    traj = satellite[0]
    return emulator.truth_wheel_allowance_rad_s(traj, scenario_library.get("somov-ge4-scan"), ALIGN_S, ALIGN_S + TWIN_S)


def test_twin_with_the_right_fault_hypothesis_reproduces_the_telemetry(satellite) -> None:
    hypothesis = [emulator.parse_fault(f"wheel:{FAILED_WHEEL}:failure@{FAILURE_ONSET_S - ALIGN_S}")]
    wheels, attitude, programme = _twin_vs_telemetry(satellite, hypothesis)
    assert programme.max() < PROGRAMME_TOL_RAD  # the shifted route is the satellite's own programme
    assert attitude.max() < TWIN_ATTITUDE_TOL_RAD
    assert wheels.max() < TWIN_WHEEL_TOL_RAD_S + _truth_allowance_rad_s(satellite)


def test_nominal_twin_departs_from_a_satellite_with_a_hidden_wheel_failure(satellite) -> None:
    wheels, _, programme = _twin_vs_telemetry(satellite, [])
    assert programme.max() < PROGRAMME_TOL_RAD
    before = int((FAILURE_ONSET_S - ALIGN_S) / 0.25)
    assert wheels[:before].max() < TWIN_WHEEL_TOL_RAD_S + _truth_allowance_rad_s(satellite)  # same until the failure
    assert wheels[before:].max() > DIVERGED_WHEEL_RAD_S


def test_batch_of_fault_hypotheses_ranks_the_hidden_failure_first(satellite) -> None:
    _, _, batches = satellite
    track = actual_track(batches)
    t_align = int(track.t_utc_ns[0]) + int(ALIGN_S * NS)
    onset = FAILURE_ONSET_S - ALIGN_S
    hypotheses = {"nominal": [], "gyro y bias": [emulator.parse_fault(f"gyro:1:bias@{onset},value=1e-4")]}
    hypotheses.update({f"wheel {k} failure": [emulator.parse_fault(f"wheel:{k}:failure@{onset}")] for k in range(4)})
    fits = rank_hypotheses(scenario_library.get("somov-ge4-scan"), track, t_align, RANKING_S, hypotheses)
    assert fits[0].name == f"wheel {FAILED_WHEEL} failure"  # the satellite's hidden schedule
    # one count of misfit from noise, about one more from the satellite's own truth (emulator.TruthTolerances)
    assert fits[0].wheel_speed_rms_rad_s < 2 * TACHOMETER_COUNT_RAD_S
    assert min(f.wheel_speed_rms_rad_s for f in fits[1:]) > max(
        2 * TACHOMETER_COUNT_RAD_S, 2 * fits[0].wheel_speed_rms_rad_s
    )
    with pytest.raises(ValueError, match="hypotheses"):
        rank_hypotheses(scenario_library.get("somov-ge4-scan"), track, t_align, RANKING_S, {})


def test_twin_starts_with_the_wheels_onboard_fdir_had_isolated(satellite) -> None:
    _, _, batches = satellite
    track = actual_track(batches)
    t0 = int(track.t_utc_ns[0])
    before, after = aligned_wheel_available(track, t0 + 300 * NS), aligned_wheel_available(track, t0 + 400 * NS)
    expected_after = np.ones((1, 4), dtype=bool)
    expected_after[0, FAILED_WHEEL] = False
    np.testing.assert_array_equal(before, np.ones((1, 4), dtype=bool))
    np.testing.assert_array_equal(after, expected_after)


def test_alignment_inside_a_turn_or_off_the_sample_grid_is_refused(satellite) -> None:
    _, _, batches = satellite
    track = actual_track(batches)
    base = scenario_library.get("somov-ge4-scan")
    t0 = int(track.t_utc_ns[0])
    with pytest.raises(ValueError, match="t_align_utc_ns: inside"):
        aligned_scenario(base, track, t0 + 450 * NS, 60.0)
    with pytest.raises(ValueError, match="t_utc_ns: no ACS_HK sample"):
        aligned_scenario(base, track, t0 + 450 * NS + 1, 60.0)
    late = aligned_scenario(base, track, t0 + 800 * NS, 60.0)  # last course: 20° roll hold continues
    assert late.guidance.route[0].roll_deg == 20.0 and late.guidance.route_start_s == 0.0
    with pytest.raises(ValueError, match="batches: no GPS_NAV"):
        actual_track([b for b in batches if b.packet == "ACS_HK"])
