"""Frames against published reference values (Vallado AIAA 2006-6753 App. C, SOFA), skyfield's
WGS84, and kinematic identities (orthonormality, Λ̇ = ½ Λ ∘ ω, ECEF velocity = d/dt ECEF position)."""

from __future__ import annotations

import datetime as dt
import inspect

import numpy as np
import pytest

from sim_core import environment, frames, orbit, quaternion

# --- Vallado, "Revisiting Spacetrack Report #3", AIAA 2006-6753 Rev 2, Appendix C (and Vallado
# Fundamentals Example 3-15): one state at 2004-04-06 07:51:28.386009 UTC in TEME, GCRF and ITRF. ---
VALLADO_T_UNIX_S = dt.datetime(2004, 4, 6, 7, 51, 28, 386009, tzinfo=dt.UTC).timestamp()
VALLADO_R_TEME_KM = np.array([5094.18016210, 6127.64465950, 6380.34453270])
VALLADO_V_TEME_KM_S = np.array([-4.746131487, 0.785818041, 5.531931288])
VALLADO_R_GCRF_KM = np.array([5102.508958, 6123.011401, 6378.136928])
VALLADO_V_GCRF_KM_S = np.array([-4.743220157, 0.790536497, 5.533755727])
VALLADO_R_ITRF_KM = np.array([-1033.4793830, 7901.2952754, 6380.3565958])
VALLADO_V_ITRF_KM_S = np.array([-3.225636520, -2.872451450, 5.531924446])
# GCRF: Vallado applies the IERS δΔψ, δΔε pole corrections that skyfield's IAU 2000A omits (≤ 0.3
# mas ≈ 1 cm at 8,000 km); his GCRF is printed to 1 mm.
GCRF_POSITION_TOL_M = 0.02
GCRF_VELOCITY_TOL_M_S = 1e-5
# ITRF: the finals2000A DUT1 (−0.44043 s) differs from the example's −0.4399619 s by 0.47 ms, i.e.
# 0.27 m at the 580 m/s of Earth rotation at this radius; LOD is not modelled in v (≤ 1 mm/s).
ITRF_POSITION_TOL_M = 0.5
ITRF_VELOCITY_TOL_M_S = 2e-3


def test_teme_to_eci_matches_vallado_appendix_c_gcrf():
    r, v = frames.teme_to_eci(VALLADO_R_TEME_KM * 1e3, VALLADO_V_TEME_KM_S * 1e3, VALLADO_T_UNIX_S)
    np.testing.assert_allclose(r, VALLADO_R_GCRF_KM * 1e3, rtol=0, atol=GCRF_POSITION_TOL_M)
    np.testing.assert_allclose(v, VALLADO_V_GCRF_KM_S * 1e3, rtol=0, atol=GCRF_VELOCITY_TOL_M_S)


def test_eci_to_ecef_matches_vallado_appendix_c_itrf():
    r, v = frames.eci_to_ecef(VALLADO_R_GCRF_KM * 1e3, VALLADO_V_GCRF_KM_S * 1e3, VALLADO_T_UNIX_S)
    np.testing.assert_allclose(r, VALLADO_R_ITRF_KM * 1e3, rtol=0, atol=ITRF_POSITION_TOL_M)
    np.testing.assert_allclose(v, VALLADO_V_ITRF_KM_S * 1e3, rtol=0, atol=ITRF_VELOCITY_TOL_M_S)
    r_back, v_back = frames.ecef_to_eci(r, v, VALLADO_T_UNIX_S)
    np.testing.assert_allclose(r_back, VALLADO_R_GCRF_KM * 1e3, rtol=0, atol=1e-6)
    np.testing.assert_allclose(v_back, VALLADO_V_GCRF_KM_S * 1e3, rtol=0, atol=1e-9)


# Hourly interpolation of precession-nutation and polar motion: nutation's fastest terms curve by
# < 1e-10 rad within an hour; skyfield's GAST route and our ERA route agree to rounding.
INTERPOLATED_ORIENTATION_TOL_RAD = 1e-10


def test_interpolated_earth_orientation_matches_skyfield_itrs_rotation():
    from skyfield.framelib import itrs

    t = 1.7e9 + np.array([0.0, 1234.5, 1800.0, 3599.9, 3.0 * 86400.0 + 77.0])
    ours = frames.eci_to_ecef_matrix(t)
    theirs = np.moveaxis(itrs.rotation_at(frames.skyfield_time(t)), -1, 0)
    residual = ours @ np.swapaxes(theirs, -1, -2) - np.eye(3)
    assert np.max(np.abs(residual)) < INTERPOLATED_ORIENTATION_TOL_RAD
    np.testing.assert_allclose(frames.eci_to_ecef_matrix(t[1:2])[0], ours[1], rtol=0, atol=1e-15)  # batch-independent


def test_kept_hourly_nodes_give_what_one_fresh_evaluation_gives_and_stay_bounded(monkeypatch):
    """Hours evaluated by skyfield in earlier calls (kept) or in this one give the same matrices as all hours evaluated
    together in one call; no more than the bound is kept."""
    t = 1.7e9 + np.array([100.0, 5000.0, 9000.0, 20000.0])
    frames._nodes.clear()
    together = frames.eci_to_ecef_matrix(t), frames.teme_to_eci(np.ones((4, 3)), np.ones((4, 3)), t)
    frames._nodes.clear()
    frames.eci_to_ecef_matrix(t[:2])  # some hours kept before
    monkeypatch.setattr(frames, "_NODES_KEPT", 3)  # fewer than the six hours the call needs
    piecewise = frames.eci_to_ecef_matrix(t), frames.teme_to_eci(np.ones((4, 3)), np.ones((4, 3)), t)
    np.testing.assert_allclose(piecewise[0], together[0], rtol=0, atol=1e-15)
    np.testing.assert_allclose(piecewise[1], together[1], rtol=0, atol=1e-9)
    assert len(frames._nodes) == 3


# SOFA t_sofa_c.c, t_era00: eraEra00(2400000.5, 54388.0) = 0.4022837240028158102 rad, tol 1e-12.
SOFA_ERA_JD_UT1 = 2400000.5 + 54388.0
SOFA_ERA_RAD = 0.4022837240028158102
SOFA_ERA_TOL_RAD = 1e-12


def test_earth_rotation_angle_matches_sofa_era00():
    t_ut1_unix_s = (SOFA_ERA_JD_UT1 - 2440587.5) * 86400.0
    assert float(frames.earth_rotation_angle_rad(t_ut1_unix_s)) == pytest.approx(SOFA_ERA_RAD, abs=SOFA_ERA_TOL_RAD)
    assert frames.earth_rotation_angle_1(t_ut1_unix_s) == pytest.approx(SOFA_ERA_RAD, abs=SOFA_ERA_TOL_RAD)


def test_ecef_velocity_is_the_time_derivative_of_ecef_position():
    t0 = 1.7e9
    r, v = orbit.circular_orbit(np.array([0.0, 0.5, 1.0]), 600e3, 97.8, 10.0, 0.0)
    r_e, v_e = frames.eci_to_ecef(r, v, t0 + np.array([0.0, 0.5, 1.0]))
    # central difference over ±0.5 s: truncation |r⃛| h²/6 ≈ 8e-3·0.25/6 m/s ≈ 3e-4 m/s
    np.testing.assert_allclose((r_e[2] - r_e[0]) / 1.0, v_e[1], rtol=0, atol=1e-3)


# The frozen-orientation kernels drift with precession-nutation and polar motion: < 0.3″ per day.
FROZEN_KERNEL_DRIFT_RAD_PER_DAY = 1.5e-6


def test_frozen_orientation_kernels_match_full_rotation_over_a_day():
    t0 = 1.7e9
    c, w, dut1 = frames.earth_orientation_frozen(t0)
    t = t0 + np.linspace(0.0, 86400.0, 7)
    m = frames.eci_to_ecef_matrix(t)
    v = np.array([0.3, -0.5, 0.81])
    v /= np.linalg.norm(v)
    for k in range(t.size):
        era = frames.earth_rotation_angle_1(t[k] + dut1)
        got = frames.eci_to_ecef_1(v, c, w, era)
        assert np.linalg.norm(got - m[k] @ v) < FROZEN_KERNEL_DRIFT_RAD_PER_DAY
        np.testing.assert_allclose(frames.ecef_to_eci_1(got, c, w, era), v, rtol=0, atol=1e-15 * 10)


# --- WGS84 geodetic ↔ ECEF against skyfield's wgs84 (an independent implementation) -------------
GEODETIC_POSITION_TOL_M = 1e-6
GEODETIC_ANGLE_TOL_DEG = 1e-10


def test_geodetic_to_ecef_matches_skyfield_wgs84():
    from skyfield.api import wgs84

    lat = np.array([0.0, 45.0, -33.9, 89.999, -90.0, 51.4778])
    lon = np.array([0.0, 120.0, 18.4, -75.0, 0.0, -0.0015])
    alt = np.array([0.0, 600e3, -50.0, 824e3, 10.0, 45.0])
    ours = frames.geodetic_to_ecef(lat, lon, alt)
    theirs = np.array([wgs84.latlon(a, b, elevation_m=h).itrs_xyz.m for a, b, h in zip(lat, lon, alt)])
    np.testing.assert_allclose(ours, theirs, rtol=0, atol=GEODETIC_POSITION_TOL_M)
    lat2, lon2, alt2 = frames.ecef_to_geodetic(ours)
    np.testing.assert_allclose(lat2, lat, atol=GEODETIC_ANGLE_TOL_DEG)
    np.testing.assert_allclose(alt2, alt, atol=GEODETIC_POSITION_TOL_M)
    keep = np.abs(lat) < 89.0  # longitude is undefined at the poles
    np.testing.assert_allclose(lon2[keep], lon[keep], atol=GEODETIC_ANGLE_TOL_DEG)


# --- ORF ----------------------------------------------------------------------------------------
ORTHONORMAL_TOL = 1e-14


def _leo_states() -> tuple[np.ndarray, np.ndarray]:
    sat = orbit.parse_tle(
        "1 43013U 17073A   21065.76936730  .00000007  00000-0  24183-4 0  9993",
        "2 43013  98.7452   5.9775 0000941  71.3410 288.7868 14.19552110170870",
    )
    t = orbit.tle_epoch_unix_s(sat) + np.arange(0.0, 6000.0, 300.0)
    return orbit.propagate_tle(sat, t)


def test_orf_axes_are_right_handed_nadir_and_along_velocity():
    r, v = _leo_states()
    m = frames.orf_axes(r, v)
    np.testing.assert_allclose(np.swapaxes(m, -1, -2) @ m, np.broadcast_to(np.eye(3), m.shape), atol=ORTHONORMAL_TOL)
    np.testing.assert_allclose(np.linalg.det(m), 1.0, atol=ORTHONORMAL_TOL)
    np.testing.assert_allclose(m[..., 0], -r / np.linalg.norm(r, axis=1, keepdims=True), atol=ORTHONORMAL_TOL)
    assert np.all(np.sum(m[..., 1] * v, axis=1) > 0.999 * np.linalg.norm(v, axis=1))
    np.testing.assert_allclose(np.sum(m[..., 2] * np.cross(r, v), axis=1), -np.linalg.norm(np.cross(r, v), axis=1))


def test_orf_quaternion_rotates_orf_axes_into_eci_and_kernel_agrees():
    r, v = _leo_states()
    q = frames.orf_quaternion(r, v)
    m = frames.orf_axes(r, v)
    for k, e in enumerate(np.eye(3)):
        np.testing.assert_allclose(quaternion.rotate(q, np.broadcast_to(e, r.shape)), m[..., k], atol=1e-14)
    rng = np.random.default_rng(3)  # isotropic states reach all four branches of Shepperd's method
    r_any, v_any = rng.normal(size=(400, 3)) * 7e6, rng.normal(size=(400, 3)) * 7e3
    q_any = frames.orf_quaternion(r_any, v_any)
    assert len({int(np.argmax(np.abs(qk))) for qk in q_any}) == 4
    for k in range(len(r_any)):
        np.testing.assert_allclose(frames.orf_quaternion_1(r_any[k], v_any[k]), q_any[k], atol=1e-14)


# Kinematics Λ̇_o = ½ Λ_o ∘ ω_o(ORF axes): central difference over ±0.5 s on a Keplerian orbit,
# truncation (n h)² ≈ 1e-6 of the orbital rate.
ORF_RATE_REL_TOL = 1e-5


def test_orf_rate_satisfies_quaternion_kinematics():
    t = np.array([-0.5, 0.0, 0.5])
    r, v = orbit.circular_orbit(t, 600e3, 97.8, 10.0, 30.0)
    q = frames.orf_quaternion(r, v)
    q_dot = (q[2] - q[0]) / 1.0
    omega_eci = frames.orf_rate_rad_s(r[1], v[1])
    omega_orf = quaternion.rotate(quaternion.conjugate(q[1]), omega_eci)
    expected = quaternion.derivative(q[1], omega_orf)
    np.testing.assert_allclose(q_dot, expected, rtol=0, atol=ORF_RATE_REL_TOL * np.linalg.norm(omega_eci))


@pytest.mark.parametrize(
    ("call", "field"),
    [
        (lambda: frames.eci_to_ecef(np.array([np.nan, 0, 0]), np.zeros(3), 1.7e9), "r_eci_m"),
        (lambda: frames.ecef_to_eci(np.ones(3), np.ones(3), np.nan), "t_unix_s"),
        (lambda: frames.teme_to_eci(np.ones(3), np.array([0, np.inf, 0]), 1.7e9), "v_teme_m_s"),
        (lambda: frames.geodetic_to_ecef(91.0, 0.0, 0.0), "lat_deg"),
        (lambda: frames.geodetic_to_ecef(0.0, np.nan, 0.0), "lon_deg"),
        (lambda: frames.orf_quaternion(np.ones(3), np.ones(3)), "v_eci_m_s"),
        (lambda: frames.orf_axes(np.ones((2, 4)), np.ones((2, 4))), "r_eci_m"),
    ],
)
def test_bad_input_raises_value_error_naming_the_field(call, field):
    with pytest.raises(ValueError, match=field):
        call()


@pytest.mark.parametrize("module", [frames, orbit, environment])
def test_exported_members_exist_and_every_function_is_documented_and_typed(module):
    for name in module.__all__:
        member = getattr(module, name)
        func = getattr(member, "py_func", member)  # numba dispatchers keep the Python function
        if callable(func):
            assert inspect.getdoc(func), f"{module.__name__}.{name} has no docstring"
            params = inspect.signature(func).parameters.values()
            assert all(p.annotation is not inspect.Parameter.empty for p in params), f"{module.__name__}.{name}"
            assert inspect.signature(func).return_annotation is not inspect.Signature.empty, f"{module.__name__}.{name}"
