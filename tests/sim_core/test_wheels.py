"""Reaction-wheel cluster: seed 000 geometry by hand, seed 002/003 wheel dynamics vs analytic solutions."""

import itertools

import numpy as np
import pytest
from scipy import signal
from scipy.integrate import solve_ivp

from sim_core import wheels as wh
from sim_core.integrators import rk4_propagate
from sim_core.spacecraft import PlantParams, pack_state

EXACT = 1e-15  # hand-derived values, float64 round-off
SPIN_DOWN_RTOL = 1e-9  # RK4 at 1 ms on an exponential with time constant ≥ 10 s
ODE_RTOL = 1e-9  # solve_ivp at rtol 1e-12 vs closed form
VOLTAGE_DRIVE_RTOL = 5e-4  # one-step (1 ms) ZOH lag on a 2.2 s response, ≤ dt/τ_m; measured 7e-5
SQRT3_2, HALF, INV_SQRT2 = np.sqrt(3.0) / 2.0, 0.5, 1.0 / np.sqrt(2.0)


# --- geometry (seed 000 §2) -----------------------------------------------------------------------


def test_ge_device_matrix_matches_hand_values_at_30_degrees():
    expected = np.array([[SQRT3_2] * 4, [HALF, -HALF, 0.0, 0.0], [0.0, 0.0, HALF, -HALF]])
    assert np.allclose(wh.ge_device_axes(np.deg2rad(30.0)), expected, atol=EXACT, rtol=0.0)


def test_ge_body_axes_are_the_device_columns_turned_by_45_degrees_about_x():
    """A = [π/4]_1ᵗ A^d: (C, S, 0) → (C, S/√2, S/√2); (C, 0, S) → (C, −S/√2, S/√2)."""
    s = HALF * INV_SQRT2
    expected = np.array([[SQRT3_2] * 4, [s, -s, -s, s], [s, -s, s, -s]])
    assert np.allclose(wh.ge_scheme_axes(np.deg2rad(30.0)), expected, atol=EXACT, rtol=0.0)


@pytest.mark.parametrize("axes", [wh.ge_scheme_axes(0.5), wh.orthogonal_axes(), wh.skew_3plus1_axes()])
def test_cluster_axes_are_unit_and_every_three_wheels_span_space(axes):
    """Seed 000 §3: after any one failure the GE matrix stays square and non-singular (also 3+1 skew)."""
    assert np.allclose(np.linalg.norm(axes, axis=0), 1.0, atol=EXACT)
    for cols in itertools.combinations(range(axes.shape[1]), 3):
        assert abs(np.linalg.det(axes[:, cols])) > 0.1


def test_skew_wheel_sits_at_the_magic_angle_from_each_axis():
    angles = np.degrees(np.arccos(wh.skew_3plus1_axes()[:, 3]))
    assert np.allclose(angles, np.degrees(np.arccos(1.0 / np.sqrt(3.0))), atol=1e-12)  # 54.7356°


def test_normalized_momentum_of_seed_000_eq_4_by_hand():
    """h = (0.1, 0.2, 0.3, 0.4) N·m·s, h^m = 0.4, γ = 30°: h/h^m = (¼, ½, ¾, 1),
    x = C(¼ + ½) + C(¾ + 1) = 2.5 C = 2.1650635, y = S(¼ − ½) = −0.125, z = S(¾ − 1) = −0.125."""
    got = wh.ge_normalized_momentum([0.1, 0.2, 0.3, 0.4], 0.4, np.deg2rad(30.0))
    assert np.allclose(got, [2.5 * SQRT3_2, -0.125, -0.125], atol=EXACT, rtol=0.0)
    h = np.random.default_rng(7).uniform(-1, 1, (20, 4))
    assert np.allclose(wh.ge_normalized_momentum(h, 1.3, 0.6), h @ wh.ge_device_axes(0.6).T / 1.3, atol=EXACT)


# --- friction and torque components (seed 000 eq 1, seed 002 eq 1–5) -----------------------------


def _single_wheel_plant(wheels: wh.WheelParams, hub_z: float = 2.0) -> tuple[PlantParams, float]:
    j_r = float(wheels.inertia_kg_m2[0])
    params = PlantParams(np.diag([hub_z, hub_z, hub_z + j_r]), np.array([[0.0], [0.0], [1.0]]), wheels)
    return params, j_r * hub_z / (hub_z + j_r)  # effective inertia of the relative spin


def _spin_down(wheels: wh.WheelParams, speed0: float, duration: float) -> tuple[np.ndarray, np.ndarray, float]:
    params, j_eff = _single_wheel_plant(wheels)
    n = int(round(duration / 1e-3))
    x0 = pack_state(params, [1, 0, 0, 0], [0.0, 0.0, 0.01], [speed0])
    traj = rk4_propagate(x0, 1e-3, np.zeros((n, 1)), np.zeros((n, 3)), params, every=100)
    return np.arange(traj.shape[0]) * 0.1, traj[:, 7], j_eff


def test_coulomb_and_viscous_spin_down_matches_the_analytic_solution():
    """J Ω̇ = −c − kΩ: Ω(t) = (Ω0 + c/k) e^{−kt/J} − c/k until Ω = 0 at t* = (J/k) ln(1 + kΩ0/c).

    The wheel spins down inside the spacecraft, so J is the relative-spin inertia J_r J_hub/(J_hub + J_r).
    """
    c, k, speed0 = 2e-3, 2e-3, 300.0
    t, speed, j_eff = _spin_down(wh.WheelParams([0.05], coulomb_nm=c, viscous_nm_s=k), speed0, 150.0)
    stop = j_eff / k * np.log(1.0 + k * speed0 / c)
    before = t < 0.95 * stop
    exact = (speed0 + c / k) * np.exp(-k * t[before] / j_eff) - c / k
    assert stop < 150.0 and before.sum() > 1000  # the check covers the whole spin-down, not its start
    assert np.allclose(speed[before], exact, rtol=SPIN_DOWN_RTOL, atol=0.0)


def test_aerodynamic_drag_spin_down_matches_the_analytic_solution():
    """J Ω̇ = −K_a Ω^{3/2} (seed 002 eq 4): Ω(t) = (Ω0^{−1/2} + K_a t / (2J))^{−2}."""
    k_a, speed0 = 1e-5, 600.0
    t, speed, j_eff = _spin_down(wh.WheelParams([0.05], aero_drag_nm_s15=k_a), speed0, 20.0)
    exact = (speed0**-0.5 + k_a * t / (2.0 * j_eff)) ** -2.0
    assert np.allclose(speed, exact, rtol=SPIN_DOWN_RTOL, atol=0.0)


def test_saturated_dry_friction_of_seed_000_by_hand():
    """m^f = m_f Sat(Ω/Ω°): m_f = 0.01 N·m, Ω° = 2 rad/s → 0.005 at 1 rad/s, −0.01 at −5 rad/s, 0 at rest."""
    wheels = wh.WheelParams(np.full(3, 0.02), coulomb_nm=0.01, coulomb_sat_speed_rad_s=2.0)
    assert np.allclose(wh.friction_torque(wheels, [1.0, -5.0, 0.0]), [0.005, -0.01, 0.0], atol=EXACT)


def test_torque_and_momentum_limits_of_seed_000_eq_2():
    """m^m = 0.2 N·m, h^m = 1 N·m·s, J_r = 0.01 kg·m² (Ω^m = 100 rad/s)."""
    wheels = wh.WheelParams(np.full(4, 0.01), max_torque_nm=0.2, max_momentum_nms=1.0)
    got = wh.limited_motor_torque(wheels, [0.5, -0.5, 0.1, -0.1], [0.0, 0.0, 100.0, 100.0])
    assert np.allclose(got, [0.2, -0.2, 0.0, -0.1], atol=EXACT)
    assert np.allclose(wheels.max_speed_rad_s, 100.0)


def test_imbalance_noise_and_delivered_torque_of_seed_002_eq_1_and_4():
    """K_d Ω² sin φ = 1e-7 · 100² · sin(π/2) = 1e-3 N·m at Ω = 100 rad/s, rotor angle φ = π/2."""
    wheels = wh.WheelParams([0.02], noise_nm=1e-4, imbalance_nm_s2=1e-7)
    phase = np.array([np.pi / 2.0])
    assert wh.imbalance_torque(wheels, [100.0], phase) == pytest.approx([1e-3], rel=1e-12)
    total = wh.delivered_torque_1(
        np.array([0.05]), np.array([100.0]), phase, wheels.noise_nm, wheels.imbalance_nm_s2, np.array([-0.5])
    )
    assert total == pytest.approx([0.05 - 0.5e-4 + 1e-3], rel=1e-12)
    samples = np.concatenate([wh.noise_torque(wheels, np.random.default_rng(s)) for s in range(20_000)])
    assert np.max(np.abs(samples)) <= 1e-4
    five_sigma = 5.0 * 1e-4 / np.sqrt(3.0) / np.sqrt(samples.size)  # uniform W/|W_max| on [−1, 1]
    assert abs(np.mean(samples)) < five_sigma


def test_imbalance_turns_at_the_wheel_speed_during_a_speed_ramp():
    """Ω(t) = Ω_0 + α t: the imbalance torque's zero crossings are half a turn apart at the instantaneous speed,
    π/Ω(t_mid) (rotor angle ∫Ω dt = Ω_0 t + α t²/2 in closed form), not at the chirp Ω_0 + 2αt of sin(Ω(t) t)."""
    wheels = wh.WheelParams([0.02], imbalance_nm_s2=1e-7)
    omega0, alpha, dt = 50.0, 20.0, 1e-4
    t = np.arange(0.0, 10.0, dt)
    speed = omega0 + alpha * t
    phase, torque = np.zeros(1), np.empty(t.size)
    for k, w in enumerate(speed):
        torque[k] = wh.imbalance_torque(wheels, [w], phase)[0]
        wh.advance_rotor_phase_1(phase, np.array([w]), dt)
    np.testing.assert_allclose(
        phase[0], (omega0 * t[-1] + 0.5 * alpha * t[-1] ** 2 + omega0 * dt) % (2 * np.pi), atol=alpha * t[-1] * dt
    )
    crossing = np.nonzero(np.sign(torque[1:]) != np.sign(torque[:-1]))[0]
    t_cross = t[crossing] - torque[crossing] * dt / (torque[crossing + 1] - torque[crossing])
    half_period = np.diff(t_cross)
    speed_mid = omega0 + alpha * 0.5 * (t_cross[1:] + t_cross[:-1])
    np.testing.assert_allclose(half_period * speed_mid, np.pi, rtol=1e-3)
    chirp_mid = omega0 + 2.0 * alpha * 0.5 * (t_cross[1:] + t_cross[:-1])
    assert abs(half_period[-1] * chirp_mid[-1] - np.pi) > 1.0  # sin(Ω(t) t) would run 1.8× fast by t = 10 s


# --- motor electrics (seed 002 eq 2–3) and speed loop (seed 003 eq 35–37) --------------------------


MOTOR = wh.MotorParams(inductance_h=1e-3, resistance_ohm=1.0, torque_constant_nm_a=0.03, back_emf_v_s=0.03)


def test_armature_current_ode_matches_the_first_order_step_response():
    """L di/dt + R i + K_e Ω = u from i = 0: i(t) = (u − K_e Ω)/R (1 − e^{−Rt/L}); u = 5 V, Ω = 100 rad/s."""
    u, speed = 5.0, 100.0
    t = np.linspace(0.0, 5e-3, 26)
    sol = solve_ivp(
        lambda _t, i: wh.motor_current_derivative(MOTOR, i, [u], [speed]),
        (0.0, t[-1]),
        [0.0],
        method="DOP853",
        t_eval=t,
        rtol=1e-12,
        atol=1e-15,
    )
    exact = (u - 0.03 * speed) / 1.0 * (1.0 - np.exp(-t / 1e-3))
    assert np.allclose(sol.y[0], exact, rtol=ODE_RTOL, atol=1e-12)


def test_motor_torque_step_matches_scipy_transfer_function_of_seed_002_eq_3():
    """M = K_m V/(Ls + R): scipy.signal's step response vs 50 exact zero-order-hold current steps."""
    volts = 4.0
    t = np.linspace(0.0, 5e-3, 51)
    _, expected = signal.step(signal.lti([MOTOR.torque_constant_nm_a], [MOTOR.inductance_h, MOTOR.resistance_ohm]), T=t)
    current, got = np.zeros(1), [0.0]
    for _ in t[1:]:
        current = wh.motor_current_step(MOTOR, current, [volts], [0.0], t[1] - t[0])
        got.append(wh.motor_torque(MOTOR, current)[0])
    assert np.allclose(got, volts * expected, rtol=1e-9, atol=1e-12)


def test_speed_loop_is_the_first_order_lag_of_seed_003_eq_37():
    """J_r Ω̇ = −k_w(Ω − Ω_0) − k_T T_c: Ω → Ω_0 − k_T T_c/k_w with T_w = J_r/k_w (= 2 s here)."""
    j_r, k_w, set_speed, request = 0.02, 0.01, 200.0, 0.1
    t = np.linspace(0.0, 10.0, 41)

    def rhs(_t, w):
        return wh.speed_loop_torque(w, [set_speed], [request], k_w) / j_r

    sol = solve_ivp(rhs, (0.0, t[-1]), [100.0], method="DOP853", t_eval=t, rtol=1e-12, atol=1e-12)
    final = set_speed - request / k_w
    assert np.allclose(sol.y[0], final + (100.0 - final) * np.exp(-t * k_w / j_r), rtol=ODE_RTOL)


# --- validation -----------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"inertia_kg_m2": [0.0]}, "inertia_kg_m2"),
        ({"inertia_kg_m2": [0.01], "max_torque_nm": -1.0}, "max_torque_nm"),
        ({"inertia_kg_m2": [0.01], "coulomb_nm": np.nan}, "coulomb_nm"),
        ({"inertia_kg_m2": [0.01, 0.01], "viscous_nm_s": [1.0, 2.0, 3.0]}, "viscous_nm_s.*shape"),
    ],
)
def test_bad_wheel_parameters_are_rejected_naming_the_field(kwargs, match):
    with pytest.raises(ValueError, match=match):
        wh.WheelParams(**kwargs)


def test_bad_geometry_and_motor_inputs_are_rejected_naming_the_field():
    with pytest.raises(ValueError, match="gamma_rad"):
        wh.ge_scheme_axes(np.pi)
    with pytest.raises(ValueError, match="max_momentum_nms"):
        wh.ge_normalized_momentum([1, 2, 3, 4], 0.0, 0.5)
    with pytest.raises(ValueError, match="resistance_ohm"):
        wh.MotorParams(1e-3, -1.0, 0.03, 0.03)
    with pytest.raises(ValueError, match="speed_rad_s"):
        wh.friction_torque(wh.WheelParams([0.01]), [np.nan])
    with pytest.raises(ValueError, match="loop_gain_nm_s"):
        wh.speed_loop_torque([1.0], [0.0], [0.0], 0.0)


# --- the wheel model driving the plant -------------------------------------------------------------


def test_momentum_limit_stops_a_wheel_pushed_by_a_constant_command():
    """Seed 000 eq 2: commanding +m^m forever parks the wheel at h^m (within one step's increment)."""
    wheels = wh.WheelParams([0.01], max_torque_nm=0.05, max_momentum_nms=0.5)
    params, _ = _single_wheel_plant(wheels, hub_z=50.0)
    x = pack_state(params, [1, 0, 0, 0], [0.0, 0.0, 0.0], [0.0])
    for _ in range(200):  # 20 s at 0.1 s; unlimited, 0.05 N·m would reach 1 N·m·s
        torque = wh.limited_motor_torque(wheels, [1.0], x[7:8])
        x = rk4_propagate(x, 0.1, torque[None, :], np.zeros((1, 3)), params)[-1]
    h_final = 0.01 * x[7]
    assert 0.5 <= h_final <= 0.5 + 0.05 * 0.1 * 1.01


def test_voltage_driven_wheel_in_the_plant_follows_the_exact_linear_motor_solution():
    """Seed 002 eq 2 + seed 000 eq 1: [i, Ω]˙ = [[−R/L, −K_e/L], [K_m/J, 0]] [i, Ω] + [u/L, 0].

    The ZOH current kernel and RK4 plant, stepped at 1 ms, against scipy.linalg.expm of this
    linear system (J the relative-spin inertia). The plant sees the current sampled at each step
    start (zero-order hold), a one-step lag bounded by dt/τ_m relative to the response.
    """
    from scipy.linalg import expm

    wheels = wh.WheelParams([0.002])  # mechanical time constant J R/(K_m K_e) ≈ 2.2 s
    params, j_eff = _single_wheel_plant(wheels)
    volts, dt, n = 3.0, 1e-3, 3000
    x = pack_state(params, [1, 0, 0, 0], [0.0, 0.0, 0.0], [0.0])
    current = np.zeros(1)
    for _ in range(n):
        x = rk4_propagate(x, dt, MOTOR.torque_constant_nm_a * current[None, :], np.zeros((1, 3)), params)[-1]
        current = wh.motor_current_step(MOTOR, current, [volts], x[7:8], dt)
    a = np.array(
        [
            [-MOTOR.resistance_ohm / MOTOR.inductance_h, -MOTOR.back_emf_v_s / MOTOR.inductance_h],
            [MOTOR.torque_constant_nm_a / j_eff, 0.0],
        ]
    )
    aug = np.zeros((3, 3))
    aug[:2, :2], aug[0, 2] = a, volts / MOTOR.inductance_h
    exact_speed = (expm(aug * n * dt) @ np.array([0.0, 0.0, 1.0]))[1]
    assert x[7] == pytest.approx(exact_speed, rel=VOLTAGE_DRIVE_RTOL)
    assert exact_speed > 0.5 * volts / MOTOR.back_emf_v_s  # well into the response toward Ω = u/K_e
