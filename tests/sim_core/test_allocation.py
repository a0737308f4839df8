"""Wheel and magnetic-driver allocation (seed 000 §3, eqs 5–6) against Basilisk's truth, exact
derivatives and the defining equations A M = −M^r, f_ρ → 0, L × B."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sim_core import allocation as al

EXACT = 1e-10  # float64 round-off of 3×3 and 4×4 solves on O(1) matrices
FD_STEP = 1e-6  # central-difference step on normalised momenta: truncation ~1e-12, round-off ~1e-10
FD_TOL = 1e-7
BASILISK_DIGITS = 1e-7  # Basilisk's truth is printed with 7 decimals
M_MAX_NM = 0.2  # HR12 wheel torque limit, the feasible box of the property tests
B_EARTH_T = 3e-5  # typical field magnitude at 600 km

CONFIG = al.AllocationConfig()
AXES = al.ge_axes(CONFIG.gamma_rad)
PAIRS = [(p, q) for p in range(4) for q in range(p + 1, 4)]

unit = (
    st.tuples(*[st.floats(-1.0, 1.0)] * 3)
    .map(np.array)
    .filter(lambda v: np.linalg.norm(v) > 0.1)
    .map(lambda v: v / np.linalg.norm(v))
)
wheel_box = st.tuples(*[st.floats(-M_MAX_NM, M_MAX_NM)] * 4).map(np.array)
momentum_box = st.tuples(*[st.floats(-0.95, 0.95)] * 4).map(lambda h: np.array(h) * CONFIG.h_max_nms)


def test_min_norm_matches_basilisk_truth():
    gs = np.array([[1, 0, 0, 1 / np.sqrt(3)], [0, 1, 0, 1 / np.sqrt(3)], [0, 0, 1, 1 / np.sqrt(3)]])
    cfg = al.AllocationConfig(law4=al.LAW_PSEUDO_INVERSE)
    wheel, dipole, status = al.allocate([1.0, -0.5, 0.7], gs, [True] * 4, np.zeros(4), [B_EARTH_T, 0, 0], cfg)
    assert status == al.STATUS_OK
    assert np.allclose(wheel, [-0.8, 0.7, -0.5, -0.3464102], atol=BASILISK_DIGITS)
    assert np.all(dipole == 0.0)


def test_min_norm_and_three_wheel_laws_equal_basilisk_rw_motor_torque():
    """Random wheel layouts, availabilities and torques through Basilisk's rwMotorTorque C module
    (bsk, in the test extra: never skipped), which drops unavailable wheels and maps with the minimum-norm inverse."""
    from Basilisk.architecture import messaging
    from Basilisk.fswAlgorithms import rwMotorTorque
    from Basilisk.utilities import SimulationBaseClass, macros

    rng = np.random.default_rng(5)
    cfg = al.AllocationConfig(law4=al.LAW_PSEUDO_INVERSE)
    for case in range(12):
        gs = rng.normal(size=(3, 4))
        gs /= np.linalg.norm(gs, axis=0)
        avail = np.ones(4, dtype=bool)
        if case % 2:
            avail[rng.integers(4)] = False
        torque = rng.normal(size=3) * 0.05
        module = rwMotorTorque.rwMotorTorque()
        module.controlAxes_B = np.eye(3).ravel().tolist()
        cmd = messaging.CmdTorqueBodyMsgPayload()
        cmd.torqueRequestBody = torque.tolist()
        rw = messaging.RWArrayConfigMsgPayload()
        rw.GsMatrix_B, rw.JsList, rw.numRW = gs.T.ravel().tolist(), [0.1] * 4, 4
        av = messaging.RWAvailabilityMsgPayload()
        av.wheelAvailability = [0 if a else 1 for a in avail]
        msgs = [
            messaging.CmdTorqueBodyMsg().write(cmd),
            messaging.RWArrayConfigMsg().write(rw),
            messaging.RWAvailabilityMsg().write(av),
        ]
        for port, msg in zip((module.vehControlInMsg, module.rwParamsInMsg, module.rwAvailInMsg), msgs):
            port.subscribeTo(msg)
        sim = SimulationBaseClass.SimBaseClass()
        sim.CreateNewProcess("p").addTask(sim.CreateNewTask("t", macros.sec2nano(0.5)))
        sim.AddModelToTask("t", module)
        sim.InitializeSimulation()
        sim.ConfigureStopTime(0)
        sim.ExecuteSimulation()
        expected = np.array(module.rwMotorTorqueOutMsg.read().motorTorque)[:4]
        wheel, _, status = al.allocate(torque, gs, avail, np.zeros(4), [B_EARTH_T, 0, 0], cfg)
        assert status == al.STATUS_OK
        assert np.allclose(wheel, expected, atol=EXACT)


def test_min_norm_equals_numpy_pseudo_inverse():
    cfg = al.AllocationConfig(law4=al.LAW_PSEUDO_INVERSE)
    torque = np.random.default_rng(4).normal(size=(20, 3)) * 0.05
    wheel, _, _ = al.allocate(torque, AXES, [True] * 4, np.zeros(4), [B_EARTH_T, 0, 0], cfg)
    assert np.allclose(wheel, -(np.linalg.pinv(AXES) @ torque.T).T, atol=EXACT)


@settings(deadline=None)  # first call loads compiled numba kernels
@given(momentum_box)
def test_tuning_row_is_the_gradient_of_f_rho(h):
    grad = np.empty(4)
    for i in range(4):
        dh = np.zeros(4)
        dh[i] = FD_STEP * CONFIG.h_max_nms
        grad[i] = (al.tuning_function(h + dh) - al.tuning_function(h - dh)) / (2 * FD_STEP)
    assert np.allclose(al.tuning_gradient(h), grad, atol=FD_TOL)


@settings(deadline=None)  # first call loads compiled numba kernels
@given(st.tuples(*[st.floats(-1.2, 1.2)] * 3).map(np.array))
def test_momentum_distribution_reproduces_cluster_momentum_on_tuning_surface(h_norm_b):
    momentum = h_norm_b * CONFIG.h_max_nms
    h = al.distribute_momentum(momentum, AXES)
    assert np.allclose(AXES @ h, momentum, atol=EXACT * CONFIG.h_max_nms)
    assert abs(al.tuning_function(h)) < EXACT


@settings(max_examples=200, deadline=None)
@given(wheel_box, momentum_box, st.sampled_from([al.LAW_GE_DISTRIBUTION, al.LAW_PSEUDO_INVERSE]), st.integers(-1, 3))
def test_every_feasible_torque_is_reproduced_by_four_and_three_wheel_laws(m0, h, law, failed):
    mask = np.ones(4, dtype=bool)
    if failed >= 0:
        mask[failed] = False
    m0 = np.where(mask, m0, 0.0)
    torque_req = -AXES @ m0  # feasible by construction: some admissible wheel torques produce it
    wheel, dipole, status = al.allocate(torque_req, AXES, mask, h, [B_EARTH_T, 0, 0], al.AllocationConfig(law4=law))
    assert status == al.STATUS_OK
    assert np.all(wheel[~mask] == 0.0)
    assert np.allclose(AXES @ wheel, -torque_req, atol=EXACT)
    assert np.all(dipole == 0.0)


@settings(deadline=None)  # first call loads compiled numba kernels
@given(momentum_box)
def test_distribution_law_row_sets_the_tuning_rate(h):
    wheel, _, _ = al.allocate([0.01, -0.02, 0.005], AXES, [True] * 4, h, [B_EARTH_T, 0, 0])
    f = al.tuning_function(h)
    f_dot = al.tuning_gradient(h) @ wheel / CONFIG.h_max_nms  # ḣ_p = m_p
    expected = -np.clip(CONFIG.mu_rho_per_s * f, -CONFIG.phi_rho_per_s, CONFIG.phi_rho_per_s)
    assert f_dot == pytest.approx(expected, abs=EXACT)


def test_distribution_law_drives_f_rho_to_zero_while_delivering_torque():
    h = np.array([6.0, -3.0, 8.0, 2.0])  # far from the tuning surface
    torque_req = np.array([2e-3, -1e-3, 1.5e-3])
    dt, f_start = 0.5, al.tuning_function(h)
    for _ in range(2400):  # 1200 s ≈ 60 time constants 1/μ_ρ
        wheel, _, status = al.allocate(torque_req, AXES, [True] * 4, h, [B_EARTH_T, 0, 0])
        assert status == al.STATUS_OK and np.allclose(AXES @ wheel, -torque_req, atol=EXACT)
        h = h + wheel * dt
    assert abs(f_start) > 0.5
    assert abs(al.tuning_function(h)) < 1e-6


def test_ge_law_falls_back_to_min_norm_where_f_rho_is_undefined():
    h = np.array([2.5, -2.5, 0.0, 0.0]) * CONFIG.h_max_nms  # q_y² = 4C² − S²(h1 − h2)² < 0 at γ = 30°
    assert not np.isfinite(al.tuning_function(h))
    torque_req = np.array([1e-3, -2e-3, 5e-4])
    wheel, _, status = al.allocate(torque_req, AXES, [True] * 4, h, [B_EARTH_T, 0, 0])
    assert status == al.STATUS_OK
    assert np.allclose(wheel, -np.linalg.pinv(AXES) @ torque_req, atol=EXACT)


@settings(max_examples=300, deadline=None)
@given(st.sampled_from(PAIRS), unit, unit, st.floats(1e-5, 1e-3))
def test_two_wheels_and_md_reproduce_torque_where_kappa_allows(pair, b_dir, torque_dir, torque_nm):
    mask = np.zeros(4, dtype=bool)
    mask[list(pair)] = True
    b_field = B_EARTH_T * b_dir
    torque_req = torque_nm * torque_dir
    wheel, dipole, status = al.allocate(torque_req, AXES, mask, np.zeros(4), b_field)
    s = AXES[:, pair[0]] + AXES[:, pair[1]]
    kappa = s @ b_dir / np.linalg.norm(s)
    if abs(kappa) > al.KAPPA_MAX:
        assert status == al.STATUS_KAPPA_REFUSED and np.all(dipole == 0.0)
        return
    if status == al.STATUS_SINGULAR:  # e^m nearly in the pair plane: covered by the next test
        normal = np.cross(AXES[:, pair[0]], AXES[:, pair[1]])
        e_m = np.cross(b_dir, s)
        assert abs(e_m @ normal) / np.linalg.norm(e_m) / np.linalg.norm(normal) < al.MIN_MD_PLANE_COVER
        return
    achieved = -AXES @ wheel + np.cross(dipole, b_field)
    scale = np.max(np.abs(dipole)) or 1.0  # |L| as scale · |L/scale|: squares of a 1e-194 dipole underflow to 0
    assert abs(dipole @ b_field) <= EXACT * scale * np.linalg.norm(dipole / scale) * B_EARTH_T
    if status == al.STATUS_OK:
        assert np.allclose(achieved, torque_req, atol=EXACT * torque_nm)
        assert np.max(np.abs(dipole)) <= CONFIG.l_max_am2
    else:
        assert status == al.STATUS_MD_SATURATED
        assert np.max(np.abs(dipole)) == pytest.approx(CONFIG.l_max_am2)
        scale = achieved @ torque_req / torque_nm**2
        assert 0.0 < scale < 1.0 and np.allclose(achieved, scale * torque_req, atol=EXACT * torque_nm)


@settings(max_examples=300, deadline=None)
@given(st.sampled_from(PAIRS), unit, unit, st.floats(1e-5, 1e-2))
def test_least_dipole_md_gives_the_torque_across_the_pair_plane_up_to_the_rod_limit(pair, b_dir, torque_dir, torque_nm):
    """The least-dipole law: L ⟂ B and ⟂ n_pq's part along b, i.e. L ∥ B × n_pq, gives ⟨L × B, n_pq⟩ = ⟨M^r, n_pq⟩
    while the rods allow; the wheels give all of M^r across the rest, exactly; saturated rods leave a shortfall
    along n_pq only, with the largest |l_i| = l^m and the torque across the plane of M^r's sign."""
    mask = np.zeros(4, dtype=bool)
    mask[list(pair)] = True
    b_field = B_EARTH_T * b_dir
    torque_req = torque_nm * torque_dir
    cfg = al.AllocationConfig(md_law=al.MD_LAW_PAIR_NORMAL)
    wheel, dipole, status = al.allocate(torque_req, AXES, mask, np.zeros(4), b_field, cfg)
    normal = np.cross(AXES[:, pair[0]], AXES[:, pair[1]])
    normal /= np.linalg.norm(normal)
    sine = np.linalg.norm(np.cross(b_dir, normal))
    if sine < al.MIN_NORMAL_SINE:
        assert status == al.STATUS_KAPPA_REFUSED and np.all(dipole == 0.0)
        return
    achieved = -AXES @ wheel + np.cross(dipole, b_field)
    along_b_cross_n = np.cross(b_dir, normal) / sine
    assert np.allclose(dipole, (dipole @ along_b_cross_n) * along_b_cross_n, atol=EXACT * CONFIG.l_max_am2)
    shortfall = torque_req - achieved
    assert np.allclose(shortfall, (shortfall @ normal) * normal, atol=EXACT * torque_nm)
    if status == al.STATUS_OK:
        assert np.allclose(achieved, torque_req, atol=EXACT * torque_nm)
        assert np.max(np.abs(dipole)) <= CONFIG.l_max_am2
    else:
        assert status == al.STATUS_MD_SATURATED
        assert np.max(np.abs(dipole)) == pytest.approx(CONFIG.l_max_am2)
        across = achieved @ normal
        assert 0.0 < across / (torque_req @ normal) < 1.0


def test_md_refused_when_field_lies_along_pair_direction():
    mask = np.array([True, True, False, False])
    e_pq = (AXES[:, 0] + AXES[:, 1]) / np.linalg.norm(AXES[:, 0] + AXES[:, 1])
    wheel, dipole, status = al.allocate([1e-4, 2e-4, -1e-4], AXES, mask, np.zeros(4), B_EARTH_T * e_pq)
    assert status == al.STATUS_KAPPA_REFUSED and np.all(dipole == 0.0)
    plane = AXES[:, :2]
    achieved = -plane @ wheel[:2]
    residual = np.array([1e-4, 2e-4, -1e-4]) - achieved
    assert np.allclose(plane.T @ residual, 0.0, atol=EXACT)  # least squares: residual ⟂ pair plane


def test_md_refused_when_its_torque_cannot_leave_the_pair_plane():
    mask = np.array([True, True, False, False])
    a1, a2 = AXES[:, 0], AXES[:, 1]
    e_pq = (a1 + a2) / np.linalg.norm(a1 + a2)
    normal = np.cross(a1, a2) / np.linalg.norm(np.cross(a1, a2))
    b_dir = 0.3 * e_pq + np.sqrt(1 - 0.09) * normal  # |κ| = 0.3 ≤ 1/2 but b × e_pq lies in the plane
    _, dipole, status = al.allocate([1e-4, 2e-4, -1e-4], AXES, mask, np.zeros(4), B_EARTH_T * b_dir)
    assert status == al.STATUS_SINGULAR and np.all(dipole == 0.0)


@pytest.mark.parametrize("md_law", [al.MD_LAW_SEED, al.MD_LAW_PAIR_NORMAL])
def test_two_wheels_without_a_driver_give_the_least_squares_pair_torque(md_law):
    """l^m = 0 (no magnetic driver): the seed's A^m_pq solution scaled to the rods' limit would be zero, wheels
    too; the pair gives instead the in-plane part of M^r, the residual ⟂ the pair plane, with the field such
    that the MD's condition holds (b ⟂ e_pq, b × e_pq along the pair's normal)."""
    mask = np.array([True, True, False, False])
    a1, a2 = AXES[:, 0], AXES[:, 1]
    b_dir = np.cross(np.cross(a1, a2), a1 + a2)
    torque_req = np.array([1e-4, 2e-4, -1e-4])
    cfg = al.AllocationConfig(l_max_am2=0.0, md_law=md_law)
    wheel, dipole, status = al.allocate(
        torque_req, AXES, mask, np.zeros(4), B_EARTH_T * b_dir / np.linalg.norm(b_dir), cfg
    )
    assert status == al.STATUS_NO_DRIVER and np.all(dipole == 0.0)
    plane = AXES[:, :2]
    residual = torque_req - (-plane @ wheel[:2])
    assert np.allclose(plane.T @ residual, 0.0, atol=EXACT) and np.any(wheel[:2] != 0.0)


def test_fewer_than_two_wheels_gives_no_torque_and_a_status():
    wheel, dipole, status = al.allocate([1e-3, 0, 0], AXES, [False, False, True, False], np.zeros(4), [B_EARTH_T, 0, 0])
    assert status == al.STATUS_TOO_FEW_WHEELS and np.all(wheel == 0.0) and np.all(dipole == 0.0)


def test_batch_axis_matches_single_calls():
    rng = np.random.default_rng(7)
    torque = rng.normal(size=(5, 3)) * 1e-3
    masks = np.array([[1, 1, 1, 1], [1, 1, 1, 0], [0, 1, 1, 1], [1, 0, 0, 1], [0, 1, 0, 1]], dtype=bool)
    b_field = rng.normal(size=(5, 3)) * B_EARTH_T
    h = rng.uniform(-5, 5, size=(5, 4))
    wheel, dipole, status = al.allocate(torque, AXES, masks, h, b_field)
    for i in range(5):
        w1, d1, s1 = al.allocate(torque[i], AXES, masks[i], h[i], b_field[i])
        assert np.array_equal(w1, wheel[i]) and np.array_equal(d1, dipole[i]) and s1 == status[i]


def test_bad_inputs_name_the_field():
    with pytest.raises(ValueError, match="torque_req_b_nm"):
        al.allocate([1.0, 2.0], AXES, [True] * 4, np.zeros(4), [B_EARTH_T, 0, 0])
    with pytest.raises(ValueError, match="b_field_b_t"):
        al.allocate([1.0, 2.0, 3.0], AXES, [True] * 4, np.zeros(4), [np.nan, 0, 0])
    with pytest.raises(ValueError, match="axes_b"):
        al.allocate([1.0, 2.0, 3.0], np.eye(3, 4), [True] * 4, np.zeros(4), [B_EARTH_T, 0, 0])
    with pytest.raises(ValueError, match="momentum_b_nms"):
        al.distribute_momentum([0.0, 4.0 * CONFIG.h_max_nms, 0.0], AXES)
    with pytest.raises(ValueError, match="md_law"):
        al.AllocationConfig(md_law=7)
    with pytest.raises(ValueError, match="rho"):
        al.AllocationConfig(rho=1.5)
