"""Coupled plant of seed 000 eq (1) against exact solutions and conservation laws."""

import numpy as np
import pytest
from scipy.integrate import quad
from scipy.special import ellipj

from sim_core import quaternion as qt
from sim_core.integrators import reference_propagate, rk4_propagate
from sim_core.spacecraft import (
    PlantParams,
    angular_momentum_b,
    angular_momentum_i,
    kinetic_energy,
    mechanical_energy,
    pack_state,
    plant_derivative,
    wheel_momentum,
)
from sim_core.wheels import WheelParams, ge_scheme_axes

RPM = np.pi / 30.0
JACOBI_TOL_RAD = 1e-9  # issue 2: reference path must match the exact motion to 1e-9 rad over 1000 s
CONSERVATION_RTOL = 1e-10  # issue 2 (and Basilisk's own check) for |H| and energy
ROUNDOFF_RTOL = 1e-13  # float64 round-off on sums of a few dozen terms
FLEX_TOL = 1e-9  # RK4 at 1 ms on a 3 rad/s mode: local error (Ω dt)^5 / 120 ≈ 2e-15 per step
PRECESSION_RTOL = 0.02  # eq (38) is the nutation-averaged rate; ~50 nutation periods leave a partial one
DERIVATIVE_RTOL = 1e-12  # two float64 solves of the same 9 × 9 system

SPACECRAFT_J = np.array([[35.0, 0.5, -0.3], [0.5, 30.0, 0.2], [-0.3, 0.2, 25.0]])
FLEX_D = np.array([[1.0, 0.3], [0.2, 1.0], [0.0, 0.5]])


def _no_wheels() -> WheelParams:
    return WheelParams(inertia_kg_m2=np.zeros(0))


def _flexible_ge_plant(decrement: float = 0.0, coulomb_nm: float = 0.0, viscous: float = 0.0) -> PlantParams:
    wheels = WheelParams(np.full(4, 0.0191), coulomb_nm=coulomb_nm, coulomb_sat_speed_rad_s=1.0, viscous_nm_s=viscous)
    return PlantParams(
        SPACECRAFT_J,
        ge_scheme_axes(np.deg2rad(30.0)),
        wheels,
        flex_coupling=FLEX_D,
        flex_modal_mass=np.ones(2),
        flex_freq_rad_s=np.array([3.0, 7.0]),
        flex_log_decrement=np.full(2, decrement),
    )


def _spinning_state(params: PlantParams) -> np.ndarray:
    return pack_state(
        params,
        [1.0, 0.0, 0.0, 0.0],
        [0.02, -0.03, 0.05],
        np.array([1000.0, -1000.0, 1000.0, -1000.0]) * RPM,
        flex_q=[0.01, -0.005],
    )


def _history(params: PlantParams, x0: np.ndarray, dt: float, duration: float, samples: int = 400):
    n = int(round(duration / dt))
    traj = rk4_propagate(x0, dt, np.zeros((n, params.n_wheels)), np.zeros((n, 3)), params, every=n // samples)
    return angular_momentum_i(traj, params), mechanical_energy(traj, params)


# --- exact torque-free motion (Landau & Lifshitz, Mechanics §37) -----------------------------------


class _EulerPoinsot:
    """Exact torque-free motion of a triaxial body I1 < I2 < I3 with M² > 2 E I2, from ω(0) = (a, 0, c)."""

    def __init__(self, moments, a: float, c: float):
        self.i1, self.i2, self.i3 = moments
        i1, i2, i3 = moments
        self.m2 = (i1 * a) ** 2 + (i3 * c) ** 2
        self.e2 = i1 * a * a + i3 * c * c
        self.m = np.sqrt(self.m2)
        self.k2 = (i2 - i1) * (self.e2 * i3 - self.m2) / ((i3 - i2) * (self.m2 - self.e2 * i1))
        self.rate = np.sqrt((i3 - i2) * (self.m2 - self.e2 * i1) / (i1 * i2 * i3))
        self.amp = np.array(
            [
                np.sqrt((self.e2 * i3 - self.m2) / (i1 * (i3 - i1))),
                np.sqrt((self.e2 * i3 - self.m2) / (i2 * (i3 - i2))),
                np.sqrt((self.m2 - self.e2 * i1) / (i3 * (i3 - i1))),
            ]
        )

    def omega(self, t) -> np.ndarray:
        sn, cn, dn, _ = ellipj(self.rate * np.asarray(t, dtype=float), self.k2)
        return np.stack([cn, sn, dn], axis=-1) * self.amp

    def _phi_dot(self, t: float) -> float:
        w1, w2, _ = self.omega(t)
        return self.m * (self.i1 * w1 * w1 + self.i2 * w2 * w2) / ((self.i1 * w1) ** 2 + (self.i2 * w2) ** 2)

    def _r_sb(self, t: float, phi: float) -> np.ndarray:
        """Body → space (Z along M) as Z–X–Z Euler angles φ, θ, ψ: M_b = M (sinθ sinψ, sinθ cosψ, cosθ)."""
        w1, w2, w3 = self.omega(t)
        theta, psi = np.arccos(self.i3 * w3 / self.m), np.arctan2(self.i1 * w1, self.i2 * w2)
        return _rz(phi) @ _rx(theta) @ _rz(psi)

    def attitude_dcms(self, times: np.ndarray, chunk_s: float = 5.0) -> np.ndarray:
        """R_NB(t) with R_NB(0) = I; the precession angle φ is the quadrature of φ̇ (scipy.quad)."""
        r0 = self._r_sb(0.0, 0.0)
        edges = np.arange(0.0, times[-1] + chunk_s, chunk_s)
        cumulative = np.concatenate(
            [
                [0.0],
                np.cumsum(
                    [quad(self._phi_dot, a, b, epsabs=1e-14, epsrel=1e-13)[0] for a, b in zip(edges[:-1], edges[1:])]
                ),
            ]
        )
        out = []
        for t in times:
            k = int(np.searchsorted(edges, t, side="right") - 1)
            phi = cumulative[k] + quad(self._phi_dot, edges[k], t, epsabs=1e-14, epsrel=1e-13)[0]
            out.append(r0.T @ self._r_sb(t, phi))
        return np.array(out)


def _rx(a: float) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def _rz(a: float) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def test_reference_path_matches_jacobi_elliptic_torque_free_motion():
    """DOP853 rates and attitude vs the closed-form Euler–Poinsot motion over 1000 s (≈ 30 turns)."""
    moments, a, c = (100.0, 200.0, 250.0), 0.4, 0.5
    exact = _EulerPoinsot(moments, a, c)
    params = PlantParams(np.diag(moments), np.zeros((3, 0)), _no_wheels())
    times = np.linspace(0.0, 1000.0, 21)
    ref = reference_propagate(pack_state(params, [1.0, 0.0, 0.0, 0.0], [a, 0.0, c]), times, params)
    assert np.max(np.abs(ref[:, 4:7] - exact.omega(times))) < JACOBI_TOL_RAD
    error_rot = qt.from_dcm(np.einsum("nji,njk->nik", exact.attitude_dcms(times), qt.to_dcm(ref[:, :4])))
    assert np.max(qt.angle(error_rot)) < JACOBI_TOL_RAD


def test_rk4_matches_jacobi_elliptic_rates_at_one_millisecond():
    """The engine's RK4 path on the same exact motion over 100 s at 1 ms (global error ∝ dt⁴)."""
    moments, a, c = (100.0, 200.0, 250.0), 0.4, 0.5
    params = PlantParams(np.diag(moments), np.zeros((3, 0)), _no_wheels())
    n = 100_000
    traj = rk4_propagate(
        pack_state(params, [1, 0, 0, 0], [a, 0.0, c]), 1e-3, np.zeros((n, 0)), np.zeros((n, 3)), params, every=10_000
    )
    assert np.max(np.abs(traj[:, 4:7] - _EulerPoinsot(moments, a, c).omega(np.linspace(0, 100, 11)))) < JACOBI_TOL_RAD


# --- conservation laws ---------------------------------------------------------------------------


def test_momentum_and_energy_conserved_with_spinning_wheels_and_undamped_flex_modes():
    """No friction, no damping, no external torque: inertial H and mechanical energy are invariants."""
    params = _flexible_ge_plant()
    h, e = _history(params, _spinning_state(params), dt=0.005, duration=200.0)
    assert np.max(np.linalg.norm(h - h[0], axis=1)) / np.linalg.norm(h[0]) < CONSERVATION_RTOL
    assert np.max(np.abs(e / e[0] - 1.0)) < CONSERVATION_RTOL


def test_wheel_friction_keeps_momentum_and_dissipates_energy_monotonically():
    """Friction is internal: H stays; dE/dt = −Σ Ω_p m^f_p ≤ 0 (seed 000 eq 1 with m^f = m_f Sat(Ω/Ω°))."""
    params = _flexible_ge_plant(coulomb_nm=0.02, viscous=2e-5)
    h, e = _history(params, _spinning_state(params), dt=0.005, duration=200.0)
    assert np.max(np.linalg.norm(h - h[0], axis=1)) / np.linalg.norm(h[0]) < CONSERVATION_RTOL
    assert np.all(np.diff(e) <= ROUNDOFF_RTOL * e[0])
    assert e[-1] < 0.01 * e[0]  # the wheels have spun down to the Sat(Ω/Ω°) band


def test_flex_damping_dissipates_energy_and_keeps_momentum():
    params = _flexible_ge_plant(decrement=0.05)
    h, e = _history(params, _spinning_state(params), dt=0.005, duration=100.0)
    assert np.max(np.linalg.norm(h - h[0], axis=1)) / np.linalg.norm(h[0]) < CONSERVATION_RTOL
    assert np.all(np.diff(e) <= ROUNDOFF_RTOL * e[0])
    assert e[-1] < e[0]


def test_single_axis_flex_mode_matches_the_damped_oscillator_solution():
    """One mode coupled about z: J ω̇ + d q̈ = 0, d ω̇ + a q̈ = −a(δΩ/π q̇ + Ω² q).

    Eliminating ω̇ gives (a − d²/J) q̈ + (aδΩ/π) q̇ + aΩ² q = 0, an exactly solvable damped
    oscillator; the body rate follows from the conserved J ω + d q̇.
    """
    j, d, a, om, dec = 10.0, 2.0, 1.0, 3.0, 0.1
    params = PlantParams(
        np.diag([12.0, 11.0, j]),
        np.zeros((3, 0)),
        _no_wheels(),
        flex_coupling=[[0.0], [0.0], [d]],
        flex_modal_mass=[a],
        flex_freq_rad_s=[om],
        flex_log_decrement=[dec],
    )
    q0, w0 = 0.02, 0.1
    x0 = pack_state(params, [1, 0, 0, 0], [0.0, 0.0, w0], flex_q=[q0])
    n = 10_000
    traj = rk4_propagate(x0, 1e-3, np.zeros((n, 0)), np.zeros((n, 3)), params, every=100)
    t = np.arange(traj.shape[0]) * 0.1
    m_eff, c_eff, k_eff = a - d * d / j, a * dec * om / np.pi, a * om * om
    beta = c_eff / (2.0 * m_eff)
    wd = np.sqrt(k_eff / m_eff - beta * beta)
    q = np.exp(-beta * t) * (q0 * np.cos(wd * t) + beta * q0 / wd * np.sin(wd * t))
    qdot = np.exp(-beta * t) * (-(wd + beta * beta / wd) * q0 * np.sin(wd * t))
    assert np.max(np.abs(traj[:, 7] - q)) < FLEX_TOL
    assert np.max(np.abs(traj[:, 8] - qdot)) < FLEX_TOL
    assert np.max(np.abs(traj[:, 6] - (w0 - d * qdot / j))) < FLEX_TOL


def test_derivative_solves_the_mass_matrix_system_of_seed_000():
    """ẋ against an independent dense solve A^o v̇ = F written straight from seed 000 eq (1)."""
    params = _flexible_ge_plant(decrement=0.03, coulomb_nm=0.01, viscous=1e-5)
    x = _spinning_state(params)
    x[:4] = qt.normalize(np.array([0.9, 0.1, -0.3, 0.2]))
    x[9:11] = [0.004, -0.002]
    motor, ext = np.array([0.05, -0.02, 0.01, 0.03]), np.array([1e-3, -2e-3, 5e-4])
    w, q, qd, om = x[4:7], x[7:9], x[9:11], x[11:15]
    jr, axes = params.wheels.inertia_kg_m2, params.wheel_axes_b
    g = SPACECRAFT_J @ w + axes @ (jr * om) + FLEX_D @ qd
    friction = 0.01 * np.clip(om / 1.0, -1, 1) + 1e-5 * om
    f = np.concatenate(
        [
            -np.cross(w, g) + ext,
            -np.ones(2) * (0.03 / np.pi * np.array([3.0, 7.0]) * qd + np.array([9.0, 49.0]) * q),
            motor - friction,
        ]
    )
    a_o = np.block(
        [
            [SPACECRAFT_J, FLEX_D, axes * jr],
            [FLEX_D.T, np.eye(2), np.zeros((2, 4))],
            [(axes * jr).T, np.zeros((4, 2)), np.diag(jr)],
        ]
    )
    vdot = np.linalg.solve(a_o, f)
    xdot = plant_derivative(x, motor, ext, params)
    assert np.allclose(xdot[:4], qt.derivative(x[:4], w), rtol=DERIVATIVE_RTOL, atol=0.0)
    assert np.allclose(xdot[4:7], vdot[:3], rtol=DERIVATIVE_RTOL, atol=1e-15)
    assert np.allclose(xdot[7:9], qd, rtol=0.0, atol=0.0)
    assert np.allclose(xdot[9:11], vdot[3:5], rtol=DERIVATIVE_RTOL, atol=1e-15)
    assert np.allclose(xdot[11:], vdot[5:], rtol=DERIVATIVE_RTOL, atol=1e-12)


def test_momentum_and_energy_are_the_quadratic_forms_of_the_mass_matrix():
    params = _flexible_ge_plant()
    x = _spinning_state(params)
    v = np.concatenate([x[4:7], x[9:11], x[11:15]])
    a_o = params.mass_matrix()
    assert np.allclose(angular_momentum_b(x, params), (a_o @ v)[:3], rtol=ROUNDOFF_RTOL)
    assert kinetic_energy(x, params) == pytest.approx(0.5 * v @ a_o @ v, rel=ROUNDOFF_RTOL)
    assert np.allclose(
        params.wheel_axes_b @ wheel_momentum(x, params),
        angular_momentum_b(x, params) - SPACECRAFT_J @ x[4:7] - FLEX_D @ x[9:11],
        rtol=1e-12,
        atol=1e-15,
    )
    strain = 0.5 * np.sum((np.array([3.0, 7.0]) * x[7:9]) ** 2)
    assert mechanical_energy(x, params) == pytest.approx(kinetic_energy(x, params) + strain, rel=ROUNDOFF_RTOL)


def test_gyroscopic_stiffness_of_a_momentum_bias_wheel_matches_seed_003_eq_38():
    """A pitch wheel h_y under a constant roll torque T_x precesses at ω_z = −T_x / (H_y + h_y) on average."""
    j_r, speed, torque = 0.05, 600.0, 1e-3
    params = PlantParams(np.diag([20.0, 22.0, 18.0]), np.array([[0.0], [1.0], [0.0]]), WheelParams([j_r]))
    x0 = pack_state(params, [1, 0, 0, 0], [0.0, 0.0, 0.0], [speed])
    n = 200_000
    traj = rk4_propagate(x0, 1e-3, np.zeros((n, 1)), np.tile([torque, 0.0, 0.0], (n, 1)), params, every=10)
    h_total = j_r * speed
    assert np.mean(traj[:, 6]) == pytest.approx(-torque / h_total, rel=PRECESSION_RTOL)


# --- validation -----------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("inertia", "match"),
    [
        (np.diag([10.0, -1.0, 10.0]), "inertia_kg_m2"),
        (np.array([[10.0, 1.0, 0.0], [0.0, 10.0, 0.0], [0.0, 0.0, 10.0]]), "inertia_kg_m2.*symmetric"),
        (np.diag([1.0, 1.0, 5.0]), "inertia_kg_m2.*triangle"),
        (np.diag([np.nan, 1.0, 1.0]), "inertia_kg_m2.*NaN"),
        (np.eye(2), "inertia_kg_m2.*shape"),
    ],
)
def test_bad_inertia_is_rejected_naming_the_field(inertia, match):
    with pytest.raises(ValueError, match=match):
        PlantParams(inertia, np.zeros((3, 0)), _no_wheels())


def test_bad_wheels_and_modes_are_rejected_naming_the_field():
    with pytest.raises(ValueError, match="wheel_axes_b"):
        PlantParams(np.eye(3), np.ones((3, 1)), WheelParams([0.01]))
    with pytest.raises(ValueError, match="wheel_axes_b.*shape"):
        PlantParams(np.eye(3), np.eye(3), WheelParams([0.01]))
    with pytest.raises(ValueError, match="mass matrix"):
        PlantParams(np.eye(3), np.eye(3)[:, :1], WheelParams([1.5]))  # wheel heavier than the spacecraft
    with pytest.raises(ValueError, match="inertia_kg_m2"):
        WheelParams([-0.01])
    with pytest.raises(ValueError, match="wheels"):
        PlantParams(np.eye(3), np.zeros((3, 0)), None)
    with pytest.raises(ValueError, match="flex_freq_rad_s"):
        PlantParams(
            np.eye(3),
            np.zeros((3, 0)),
            _no_wheels(),
            flex_coupling=np.zeros((3, 1)),
            flex_modal_mass=[1.0],
            flex_freq_rad_s=[-1.0],
        )
    with pytest.raises(ValueError, match="flex_modal_mass.*required"):
        PlantParams(np.eye(3), np.zeros((3, 0)), _no_wheels(), flex_coupling=np.zeros((3, 1)))


def test_bad_state_and_torques_are_rejected_naming_the_field():
    params = _flexible_ge_plant()
    with pytest.raises(ValueError, match="q_ib.*unit"):
        pack_state(params, [1.0, 1.0, 0.0, 0.0], [0.0, 0.0, 0.0])
    with pytest.raises(ValueError, match="omega_b_rad_s"):
        pack_state(params, [1.0, 0.0, 0.0, 0.0], [0.0, np.nan, 0.0])
    with pytest.raises(ValueError, match="wheel_speed_rad_s"):
        pack_state(params, [1.0, 0.0, 0.0, 0.0], [0.0, 0.0, 0.0], [1.0, 2.0])
    x = _spinning_state(params)
    with pytest.raises(ValueError, match="wheel_motor_torque_nm"):
        plant_derivative(x, np.zeros(3), np.zeros(3), params)
    with pytest.raises(ValueError, match="^x"):
        plant_derivative(x[:-1], np.zeros(4), np.zeros(3), params)


def test_orthogonal_wheels_satisfy_seed_003_eq_32_and_33():
    """Seed 003: J ω̇ + ω × Jω = −ḣ − ω × h + T (32); eq (33) along each spin axis: I(ω̇_p + Ω̇_p) = M_w − M^f.

    Per wheel, ω × (h_p a_p) ⟂ a_p, so the spin-axis equation has no gyroscopic term; seed 003's
    vector ω̆ h_w mixes the wheels and is carried by the bearings into the body equation (32).
    """
    j_r = np.array([0.02, 0.03, 0.04])
    wheels = WheelParams(j_r, coulomb_nm=0.003, coulomb_sat_speed_rad_s=0.5, viscous_nm_s=1e-5)
    params = PlantParams(SPACECRAFT_J, np.eye(3), wheels)
    x = pack_state(params, qt.normalize([0.3, -0.2, 0.8, 0.1]), [0.05, -0.1, 0.2], [300.0, -150.0, 40.0])
    motor, ext = np.array([0.02, -0.01, 0.05]), np.array([1e-3, 2e-4, -5e-4])
    xdot = plant_derivative(x, motor, ext, params)
    w, wdot, speed, speed_dot = x[4:7], xdot[4:7], x[7:10], xdot[7:10]
    h, hdot = j_r * speed, j_r * speed_dot
    eq32 = SPACECRAFT_J @ wdot + np.cross(w, SPACECRAFT_J @ w) + hdot + np.cross(w, h) - ext
    friction = 0.003 * np.clip(speed / 0.5, -1.0, 1.0) + 1e-5 * speed
    eq33 = j_r * (wdot + speed_dot) - (motor - friction)
    assert np.allclose(eq32, 0.0, atol=1e-12)
    assert np.allclose(eq33, 0.0, atol=1e-12)
