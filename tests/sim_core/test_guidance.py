"""ORF stabilisation, ground-target pointing and routes against Kepler's orbit and exact kinematics."""

import numpy as np
import pytest

from sim_core import frames
from sim_core import guidance as gd
from sim_core import quaternion as qt

MU = 3.986004418e14  # m³/s², the truth orbit's own constant (independent of sim_core.orbit)
R_ORBIT = 6378137.0 + 600e3  # seed 000 §5: 600 km orbit
N_CIRC = np.sqrt(MU / R_ORBIT**3)
EARTH_RATE = 7.292115146706979e-5  # rad/s, IERS sidereal rate, the truth target's spin
ROUND_OFF = 1e-12  # float64 round-off on unit quaternions and unit vectors
ANGLE_ROUND_OFF_DEG = 1e-9  # Euler angles through two quaternion products and asin/atan2 near 0 and 20°
RATE_ROUND_OFF = 1e-15  # rad/s: round-off on ORF rates of order 1e-3 rad/s
KINEMATIC_CONSISTENCY = 1e-8  # issue 3: ω^p = 2 Λ̃∘Λ̇, ω̇^p = dω^p/dt (rad/s, rad/s²)
ANGLE_STENCIL_RELATIVE = 1e-9  # 5-point stencil in ERA with h = 1e-3 rad: h⁴ ~ 1e-12, round-off ~1e-13
FRAMES_INTERPOLATION_RAD = 1e-9  # frames interpolates C hourly (< 1e-10 rad) and DUT1: LOS direction error
FD_STEP_S = 0.05  # 5-point stencil: truncation h⁴|x⁽⁵⁾| < 1e-11 for LEO rates, round-off ~1e-15/h


def _five_point(f, t):
    h = FD_STEP_S
    return (f(t - 2 * h) - 8 * f(t - h) + 8 * f(t + h) - f(t + 2 * h)) / (12 * h)


def _aligned(q):
    """Quaternion samples with the sign made continuous along the first axis (q ≡ −q)."""
    q = np.array(q)
    for i in range(1, len(q)):
        if np.dot(q[i], q[i - 1]) < 0:
            q[i] = -q[i]
    return q


def _quaternion_rate(program, t):
    """2 Λ̃ ∘ Λ̇ with Λ̇ from a 5-point stencil on sign-aligned quaternions of program(t) → q."""
    stencil = np.stack([program(t + k * FD_STEP_S) for k in (-2, -1, 0, 1, 2)])  # (5, n, 4)
    stencil = np.stack([_aligned(stencil[:, i]) for i in range(stencil.shape[1])], axis=1)
    q_dot = (stencil[0] - 8 * stencil[1] + 8 * stencil[3] - stencil[4]) / (12 * FD_STEP_S)
    return 2.0 * qt.multiply(qt.conjugate(stencil[2]), q_dot)[:, 1:]


def kepler_state(t, a=R_ORBIT + 300e3, e=0.1, inc=1.2, raan=0.4, argp=0.9):
    """ECI r, v, a of a Keplerian ellipse by Newton on Kepler's equation (the truth orbit)."""
    t = np.atleast_1d(t)
    n = np.sqrt(MU / a**3)
    mean = n * t
    ecc = mean.copy()
    for _ in range(30):
        ecc = ecc - (ecc - e * np.sin(ecc) - mean) / (1 - e * np.cos(ecc))
    cos_e, sin_e = np.cos(ecc), np.sin(ecc)
    b = a * np.sqrt(1 - e * e)
    edot = n / (1 - e * cos_e)
    r_pf = np.stack([a * (cos_e - e), b * sin_e, 0 * t], -1)
    v_pf = np.stack([-a * sin_e * edot, b * cos_e * edot, 0 * t], -1)
    rot = qt.to_dcm(
        qt.multiply(
            qt.multiply(qt.from_axis_angle([0, 0, 1], raan), qt.from_axis_angle([1, 0, 0], inc)),
            qt.from_axis_angle([0, 0, 1], argp),
        )
    )
    r, v = r_pf @ rot.T, v_pf @ rot.T
    return r, v, -MU * r / np.linalg.norm(r, axis=1, keepdims=True) ** 3


def circular_state(t):
    return kepler_state(t, a=R_ORBIT, e=0.0)


def test_orf_quaternion_of_the_program_has_nadir_x_and_velocity_y():
    r, v, _ = kepler_state(np.linspace(0, 6000, 50))
    q, _, _ = gd.orf_hold_program(r, v)
    x, y = qt.rotate(q, [1.0, 0, 0]), qt.rotate(q, [0, 1.0, 0])
    assert np.max(np.abs(x + r / np.linalg.norm(r, axis=1, keepdims=True))) < ROUND_OFF
    assert np.max(np.abs(np.sum(y * r, axis=1))) < ROUND_OFF * R_ORBIT and np.all(np.sum(y * v, axis=1) > 0)


def test_circular_orbit_orf_rate_is_minus_mean_motion_about_z():
    r, v, _ = circular_state(np.linspace(0, 6000, 20))
    _, w, wd = gd.orf_hold_program(r, v)
    assert np.max(np.abs(w - [0.0, 0.0, -N_CIRC])) < RATE_ROUND_OFF and np.max(np.abs(wd)) < 1e-18


def test_orf_rate_matches_finite_differences_of_the_orf_quaternion_on_an_ellipse():
    t = np.linspace(0.0, 6500.0, 40)
    _, w, wd = gd.orf_hold_program(*kepler_state(t)[:2])
    w_fd = _quaternion_rate(lambda s: gd.orf_hold_program(*kepler_state(s)[:2])[0], t)
    wd_fd = _five_point(lambda s: gd.orf_hold_program(*kepler_state(s)[:2])[1], t)
    assert np.max(np.abs(w_fd - w)) < KINEMATIC_CONSISTENCY * 1e-3  # ORF rates are ~1e-3 rad/s
    assert np.max(np.abs(wd_fd - wd)) < KINEMATIC_CONSISTENCY * 1e-3


J2 = 1.08262668e-3  # EGM96 C20 (sign-flipped), the truth orbit's own constant
ODE_RATE_NOISE = 1e-10  # rad/s: DOP853 at rtol 1e-13 leaves ~µm in r; a 1-s stencil turns it into < 1e-12
J2_JERK_TERM = 2e-9  # rad/s²: d/dt of the x^o rate (needs the jerk) is left out, ≈ 2n·4e-7 ≈ 9e-10


def _j2_acceleration(r):
    r_norm = np.linalg.norm(r, axis=-1, keepdims=True)
    z2 = (r[..., 2:3] / r_norm) ** 2
    k = -1.5 * J2 * MU * 6378137.0**2 / r_norm**5
    return -MU * r / r_norm**3 + k * r * np.concatenate([1 - 5 * z2, 1 - 5 * z2, 3 - 5 * z2], axis=-1)


@pytest.fixture(scope="module")
def j2_orbit():
    """Dense J2 trajectory (scipy DOP853) of a slightly eccentric 600 km SSO-like orbit: t → r, v, a."""
    from scipy.integrate import solve_ivp

    r0, v0, _ = kepler_state(np.array([0.0]), a=R_ORBIT + 100e3, e=0.05, inc=np.radians(97.8))
    sol = solve_ivp(
        lambda t, y: np.concatenate([y[3:], _j2_acceleration(y[:3])]),
        (0.0, 7000.0),
        np.concatenate([r0[0], v0[0]]),
        method="DOP853",
        rtol=1e-13,
        atol=1e-7,
        dense_output=True,
    )

    def state(t):
        y = sol.sol(np.atleast_1d(t)).T
        return y[:, :3], y[:, 3:], _j2_acceleration(y[:, :3])

    return state


def test_orf_rate_includes_the_orbit_plane_turn_under_j2(j2_orbit):
    """Under J2 the ORF also turns about x^o (≈4e-7 rad/s): the program rate matches 2 Λ̃_o∘Λ̇_o."""
    t, h = np.linspace(100.0, 6500.0, 33), 1.0

    def orf_q(s):
        r, v, _ = j2_orbit(s)
        x = -r / np.linalg.norm(r, axis=1, keepdims=True)
        z = np.cross(x, v)
        z /= np.linalg.norm(z, axis=1, keepdims=True)
        return qt.from_dcm(np.stack([x, np.cross(z, x), z], axis=-1))

    stencil = np.stack([orf_q(t + k * h) for k in (-2, -1, 0, 1, 2)])
    stencil = np.stack([_aligned(stencil[:, i]) for i in range(t.size)], axis=1)
    q_dot = (stencil[0] - 8 * stencil[1] + 8 * stencil[3] - stencil[4]) / (12 * h)
    w_truth = 2.0 * qt.multiply(qt.conjugate(stencil[2]), q_dot)[:, 1:]
    r, v, a = j2_orbit(t)
    _, w, wd = gd.orf_hold_program(r, v, a_eci_m_s2=a)
    assert np.max(np.abs(w_truth[:, 0])) > 1e-7  # the x^o term (≈4e-7 rad/s) is really there
    assert np.max(np.abs(w - w_truth)) < ODE_RATE_NOISE
    w_of = lambda s: gd.orf_hold_program(*j2_orbit(s)[:2], a_eci_m_s2=j2_orbit(s)[2])[1]  # noqa: E731
    wd_truth = (w_of(t - 2 * h) - 8 * w_of(t - h) + 8 * w_of(t + h) - w_of(t + 2 * h)) / (12 * h)
    assert np.max(np.abs(wd[:, 2] - wd_truth[:, 2])) < ODE_RATE_NOISE / h
    assert np.max(np.abs(wd - wd_truth)) < J2_JERK_TERM


def test_orf_hold_with_offsets_is_kinematically_consistent():
    t = np.linspace(0.0, 6500.0, 25)
    program = lambda s: gd.orf_hold_program(*kepler_state(s)[:2], yaw_deg=5.0, roll_deg=20.0, pitch_deg=-7.0)  # noqa: E731
    _, w, wd = program(t)
    assert np.max(np.abs(_quaternion_rate(lambda s: program(s)[0], t) - w)) < KINEMATIC_CONSISTENCY * 1e-3
    assert np.max(np.abs(_five_point(lambda s: program(s)[1], t) - wd)) < KINEMATIC_CONSISTENCY * 1e-3


def test_roll_about_y_moves_the_boresight_across_track():
    r, v, _ = circular_state(np.linspace(0, 3000, 10))
    q, _, _ = gd.orf_hold_program(r, v, roll_deg=20.0)
    x_b = qt.rotate(q, [1.0, 0, 0])
    nadir = -r / np.linalg.norm(r, axis=1, keepdims=True)
    assert np.allclose(np.degrees(np.arccos(np.sum(x_b * nadir, axis=1))), 20.0, atol=ANGLE_ROUND_OFF_DEG)
    assert np.max(np.abs(np.sum(x_b * v, axis=1) / np.linalg.norm(v, axis=1))) < ROUND_OFF


T_PASS = 2000.0  # s: the target is 100 km across track from the sub-satellite point then


def _rotating_target(t):
    """A ground point spinning about ECI z at the Earth's rate, near the track at T_PASS: exact r, v, a."""
    r_pass, v_pass, _ = circular_state(np.array([T_PASS]))
    cross = np.cross(r_pass[0], v_pass[0])
    r_tc = 6378137.0 * r_pass[0] / R_ORBIT + 1e5 * cross / np.linalg.norm(cross)
    ang = EARTH_RATE * (np.atleast_1d(t) - T_PASS)
    c, s = np.cos(ang), np.sin(ang)
    r = np.stack([c * r_tc[0] - s * r_tc[1], s * r_tc[0] + c * r_tc[1], r_tc[2] + 0 * ang], -1)
    spin = np.array([0.0, 0.0, EARTH_RATE])
    v = np.cross(spin, r)
    return r, v, np.cross(spin, v)


_H_PASS = np.cross(*circular_state(np.array([T_PASS]))[:2])[0]
YAW_REF = -_H_PASS / np.linalg.norm(_H_PASS)  # z^o: the nadir case is the ORF


def _target_program(t):
    r, v, a = circular_state(t)
    return gd.target_pointing_program(r, v, a, *_rotating_target(t), YAW_REF)


PASS_TIMES = T_PASS + np.linspace(-400.0, 400.0, 81)  # a pass from ~30° elevation through overflight


def test_target_pointing_puts_boresight_on_target_and_respects_yaw_constraint():
    t = PASS_TIMES
    q, _, _ = _target_program(t)
    r = circular_state(t)[0]
    los = _rotating_target(t)[0] - r
    assert np.max(np.abs(qt.rotate(q, [1.0, 0, 0]) - los / np.linalg.norm(los, axis=1, keepdims=True))) < ROUND_OFF
    assert np.max(np.abs(qt.rotate(q, [0, 1.0, 0]) @ YAW_REF)) < ROUND_OFF  # +z in the plane of x and u
    assert np.all(qt.rotate(q, [0, 0, 1.0]) @ YAW_REF > 0)


def test_target_pointing_rate_and_acceleration_are_exact_derivatives():
    t = PASS_TIMES
    _, w, wd = _target_program(t)
    assert np.max(np.linalg.norm(w, axis=1)) > 0.01  # overflight rates ~ v/h, not a trivial case
    assert np.max(np.abs(_quaternion_rate(lambda s: _target_program(s)[0], t) - w)) < KINEMATIC_CONSISTENCY
    assert np.max(np.abs(_five_point(lambda s: _target_program(s)[1], t) - wd)) < KINEMATIC_CONSISTENCY


def test_pointing_at_the_earth_centre_with_orbit_normal_yaw_is_the_orf_hold():
    t = np.linspace(0.0, 6000.0, 30)
    r, v, a = kepler_state(t)
    z_o = np.cross(-r[0], v[0])
    zero = np.zeros_like(r)
    q, w, wd = gd.target_pointing_program(r, v, a, zero, zero, zero, z_o)
    q_o, w_o, wd_o = gd.orf_hold_program(r, v)
    assert np.max(np.abs(np.abs(np.sum(q * q_o, axis=1)) - 1)) < ROUND_OFF
    assert np.max(np.abs(w - w_o)) < RATE_ROUND_OFF * 10 and np.max(np.abs(wd - wd_o)) < 1e-17


T0 = 1.7e9  # route epoch, t_unix_s


def _orbit_from_epoch(t):
    return circular_state(np.asarray(t) - T0)


def _join_mismatch(route, t_join):
    """Largest quaternion (up to sign) and rate jump between the segments meeting at t_join."""
    k = int(np.searchsorted(route[:, gd.COL_T0], t_join))
    r, v, a = (x[0] for x in _orbit_from_epoch(np.array([t_join])))
    q0, w0, _ = gd.segment_program_1(route[k - 1], t_join, r, v, a, np.eye(3), 0.0)
    q1, w1, _ = gd.segment_program_1(route[k], t_join, r, v, a, np.eye(3), 0.0)
    return abs(abs(q0 @ q1) - 1.0), np.max(np.abs(w0 - w1))


def test_two_course_scan_is_continuous_at_joins_and_observes_only_on_courses():
    route = gd.compile_route(gd.two_course_scan(course_s=600.0, turn_s=120.0), T0, _orbit_from_epoch)
    for t_join in route[1:, gd.COL_T0]:
        dq, dw = _join_mismatch(route, t_join)
        assert dq < ROUND_OFF and dw < ROUND_OFF
    t = T0 + np.array([10.0, 599.0, 601.0, 719.0, 721.0, 1300.0])
    _, _, _, obs = gd.route_program(route, t, *_orbit_from_epoch(t))
    assert obs.tolist() == [True, True, False, False, True, True]


def test_turn_envelopes_report_the_roll_manoeuvre():
    """A 20° roll between ORF holds in 120 s: λ1 and λ3 both turn about the orbit normal and carry the
    ORF's own turn nτ exactly (nτ/2 each), so λ2 is the pure 20° roll; τ < 144 s: no plateau."""
    route = gd.compile_route(gd.two_course_scan(course_s=300.0, turn_s=120.0), T0, _orbit_from_epoch)
    [(index, env)] = gd.turn_envelopes(route)
    assert index == 1 and env.duration_s == 120.0
    assert abs(env.transition_angle_rad - np.radians(20.0)) < ROUND_OFF
    assert env.transition_rate_rad_s == pytest.approx(env.transition_angle_rad / 60.0, rel=1e-12)


def test_orf_angles_recover_the_hold_offsets():
    r, v, _ = kepler_state(np.linspace(0.0, 6000.0, 13))
    q, _, _ = gd.orf_hold_program(r, v, yaw_deg=3.0, roll_deg=-20.0, pitch_deg=7.5)
    yaw, roll, pitch = gd.orf_angles_deg(q, r, v)
    assert np.max(np.abs(yaw - 3.0)) < ANGLE_ROUND_OFF_DEG and np.max(np.abs(roll + 20.0)) < ANGLE_ROUND_OFF_DEG
    assert np.max(np.abs(pitch - 7.5)) < ANGLE_ROUND_OFF_DEG


def test_roll_manoeuvre_takes_the_orf_roll_from_0_to_20_degrees():
    route = gd.compile_route(gd.two_course_scan(course_s=300.0, turn_s=120.0), T0, _orbit_from_epoch)
    t = T0 + np.linspace(0.0, 720.0, 721)
    r, v, a = _orbit_from_epoch(t)
    q, _, _, _ = gd.route_program(route, t, r, v, a)
    yaw, roll, pitch = gd.orf_angles_deg(q, r, v)
    assert np.max(np.abs(roll[:301])) < ANGLE_ROUND_OFF_DEG and np.max(np.abs(roll[420:] - 20.0)) < ANGLE_ROUND_OFF_DEG
    assert np.all(np.diff(roll[300:421]) >= -ANGLE_ROUND_OFF_DEG)  # seed 000 Fig. 4: a monotone roll


def _ecef_of_eci(r_eci, t_unix_s):
    """ECEF = R3(ERA) · ECI with the precession-nutation matrix taken as identity (c_pn = I, DUT1 = 0)."""
    era = float(frames.earth_rotation_angle_rad(t_unix_s))
    c, s = np.cos(era), np.sin(era)
    return np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]]) @ r_eci


def test_ground_target_state_is_the_derivative_of_its_eci_position():
    """v = ω⊕ dr/dERA and a = ω⊕ dv/dERA by a 5-point stencil in the rotation angle itself."""
    c_pn = qt.to_dcm(qt.from_axis_angle([0.3, 0.1, 1.0], 1e-3))  # a small precession-nutation tilt
    w_pm = qt.to_dcm(qt.from_axis_angle([1.0, -0.5, 0.0], 2e-6))  # a polar-motion-sized tilt
    r_e = np.array([3.9e6, 1.2e6, 4.8e6])
    era = np.array([0.3, 2.0, 5.9])
    h = 1e-3  # rad
    state = lambda k, e: np.array([gd.ground_target_state_1(r_e, c_pn, w_pm, ei)[k] for ei in e])  # noqa: E731

    def d_dera(k):
        return (state(k, era - 2 * h) - 8 * state(k, era - h) + 8 * state(k, era + h) - state(k, era + 2 * h)) / (
            12 * h
        )  # noqa: E731

    w = frames.EARTH_ROTATION_RATE_RAD_S
    assert np.max(np.abs(w * d_dera(0) - state(1, era))) < ANGLE_STENCIL_RELATIVE * np.max(np.abs(state(1, era)))
    assert np.max(np.abs(w * d_dera(1) - state(2, era))) < ANGLE_STENCIL_RELATIVE * np.max(np.abs(state(2, era)))


def test_route_through_a_ground_target_is_continuous_and_points_at_it():
    t_mid = T0 + 420.0
    r_mid, v_mid, _ = _orbit_from_epoch(np.array([t_mid]))
    cross = np.cross(r_mid[0], v_mid[0])
    target_eci = 6378137.0 * r_mid[0] / np.linalg.norm(r_mid[0]) + 8e4 * cross / np.linalg.norm(cross)
    target = _ecef_of_eci(target_eci, t_mid)  # 80 km across track at mid-segment
    segments = [
        gd.OrfHold(300.0),
        gd.Turn(90.0),
        gd.GroundTarget(60.0, tuple(target)),
        gd.Turn(90.0),
        gd.OrfHold(300.0),
    ]
    route = gd.compile_route(segments, T0, _orbit_from_epoch, c_pn=np.eye(3), dut1_s=0.0)
    for t_join in route[1:, gd.COL_T0]:
        dq, dw = _join_mismatch(route, t_join)
        assert dq < ROUND_OFF and dw < ROUND_OFF
    q, _, _, obs = gd.route_program(route, np.array([t_mid]), *_orbit_from_epoch(np.array([t_mid])))
    los = target_eci - r_mid[0]
    assert obs[0] and np.max(np.abs(qt.rotate(q[0], [1.0, 0, 0]) - los / np.linalg.norm(los))) < ROUND_OFF


def test_ground_target_route_agrees_with_the_frames_earth_orientation():
    """Boresight at frames.eci_to_ecef_matrix(t)ᵗ r_ecef when C, W, DUT1 are frozen at that t (IERS chain)."""
    t_mid = T0 + 420.0
    c_pn, w_pm, dut1 = frames.earth_orientation_frozen(t_mid)
    r_mid = _orbit_from_epoch(np.array([t_mid]))[0][0]
    target_ecef = frames.eci_to_ecef_matrix(t_mid) @ (6378137.0 * r_mid / np.linalg.norm(r_mid))
    target_ecef = target_ecef + np.array([3e4, -2e4, 1e4])
    segments = [gd.OrfHold(300.0), gd.Turn(90.0), gd.GroundTarget(60.0, tuple(target_ecef))]
    route = gd.compile_route(segments, T0, _orbit_from_epoch, c_pn=c_pn, dut1_s=dut1, w_pm=w_pm)
    q, _, _, _ = gd.route_program(
        route, np.array([t_mid]), *_orbit_from_epoch(np.array([t_mid])), c_pn=c_pn, dut1_s=dut1
    )
    los = frames.eci_to_ecef_matrix(t_mid).T @ target_ecef - r_mid
    assert np.max(np.abs(qt.rotate(q[0], [1.0, 0, 0]) - los / np.linalg.norm(los))) < FRAMES_INTERPOLATION_RAD


@pytest.mark.parametrize(
    ("segments", "field"),
    [
        ([], "segments"),
        ([gd.Turn(10.0), gd.OrfHold(10.0)], r"segments\[0\]"),
        ([gd.OrfHold(10.0), gd.Turn(10.0), gd.Turn(10.0), gd.OrfHold(1.0)], r"segments\[1\]"),
        ([gd.OrfHold(-1.0)], r"segments\[0\].duration_s"),
        ([gd.OrfHold(1.0, roll_deg=np.nan)], r"segments\[0\].roll_deg"),
        ([gd.GroundTarget(10.0, (1.0, 2.0))], "target_ecef_m"),
    ],
)
def test_bad_routes_name_the_field(segments, field):
    with pytest.raises(ValueError, match=field):
        gd.compile_route(segments, T0, _orbit_from_epoch)


def test_bad_program_inputs_name_the_field():
    r, v, a = circular_state(np.array([0.0]))
    with pytest.raises(ValueError, match="v_eci_m_s"):
        gd.orf_hold_program(r, r)
    with pytest.raises(ValueError, match="yaw_ref_eci"):
        gd.target_pointing_program(r, v, a, 0 * r, 0 * r, 0 * r, -r[0])
    with pytest.raises(ValueError, match="route"):
        gd.route_program(np.zeros((2, 3)), np.array([0.0]), r, v, a)
