"""Quaternion algebra against scipy's independent Rotation implementation and exact identities."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from sim_core import quaternion as qt

EXACT = 1e-12  # float64 round-off on unit quaternions


def _random_quats(n: int, seed: int = 1) -> np.ndarray:
    q = np.random.default_rng(seed).normal(size=(n, 4))
    return qt.normalize(q)


def _scipy(q: np.ndarray) -> Rotation:
    return Rotation.from_quat(q, scalar_first=True)


def test_product_matches_scipy_composition():
    p, q = _random_quats(50, 1), _random_quats(50, 2)
    expected = (_scipy(p) * _scipy(q)).as_quat(scalar_first=True)
    got = qt.multiply(p, q)
    assert np.allclose(np.abs(np.sum(got * expected, axis=-1)), 1.0, atol=EXACT)


def test_rotate_and_dcm_match_scipy():
    q = _random_quats(50)
    v = np.random.default_rng(3).normal(size=(50, 3))
    assert np.allclose(qt.rotate(q, v), _scipy(q).apply(v), atol=EXACT)
    assert np.allclose(qt.to_dcm(q), _scipy(q).as_matrix(), atol=EXACT)


def test_dcm_round_trip_covers_every_shepperd_branch():
    q = np.concatenate([_random_quats(200), np.eye(4), [[0.0, 0.6, 0.8, 0.0]]])
    back = qt.from_dcm(qt.to_dcm(q))
    assert np.allclose(np.abs(np.sum(back * q, axis=-1)), 1.0, atol=EXACT)


def test_mrp_round_trip_and_scipy():
    q = _random_quats(50)
    assert np.allclose(qt.to_mrp(q), _scipy(q).as_mrp(), atol=EXACT)
    assert np.allclose(qt.from_mrp(qt.to_mrp(q)), q, atol=EXACT)


def test_euler_132_matches_passive_matrix_product():
    yaw, roll, pitch = 0.3, -0.2, 0.1

    def turn(i, a):  # passive simple-turn matrix [a]_i of seed 000
        c, s = np.cos(a), np.sin(a)
        m = {
            1: [[1, 0, 0], [0, c, s], [0, -s, c]],
            2: [[c, 0, -s], [0, 1, 0], [s, 0, c]],
            3: [[c, s, 0], [-s, c, 0], [0, 0, 1]],
        }
        return np.array(m[i])

    c_o = turn(2, roll) @ turn(3, pitch) @ turn(1, yaw)
    q = qt.from_euler_132(yaw, roll, pitch)
    assert np.allclose(qt.to_dcm(q).T, c_o, atol=EXACT)
    assert np.allclose(qt.to_euler_132(q), (yaw, roll, pitch), atol=EXACT)


def test_slerp_ends_and_constant_rate():
    q0, q1 = _random_quats(2, 7)
    assert np.allclose(qt.slerp(q0, q1, 0.0), q0, atol=EXACT)
    half = qt.slerp(q0, q1, 0.5)
    a0 = qt.angle(qt.multiply(qt.conjugate(q0), half))
    a1 = qt.angle(qt.multiply(qt.conjugate(half), q1))
    assert a0 == pytest.approx(a1, abs=1e-12)


def test_compiled_kernels_match_vectorised():
    p, q = _random_quats(2, 4)
    v = np.array([0.3, -1.0, 2.0])
    assert np.allclose(qt.multiply_1(p, q), qt.multiply(p, q), atol=EXACT)
    assert np.allclose(qt.rotate_1(p, v), qt.rotate(p, v), atol=EXACT)
    assert np.allclose(qt.conjugate_rotate_1(p, qt.rotate_1(p, v)), v, atol=EXACT)


def test_kinematics_derivative_matches_finite_difference_of_rotation():
    q = _random_quats(1)[0]
    w = np.array([0.01, -0.02, 0.03])
    h = 1e-6
    q_next = qt.multiply(q, qt.from_axis_angle(w, np.linalg.norm(w) * h))
    assert np.allclose((q_next - q) / h, qt.derivative(q, w), atol=1e-8)


@pytest.mark.parametrize("bad", [np.array([np.nan, 0, 0, 1.0]), np.zeros(3), np.zeros(4)])
def test_bad_quaternions_are_rejected_with_a_clear_error(bad):
    with pytest.raises(ValueError, match="q"):
        qt.normalize(bad)


def _fma_chain_exact(a: np.ndarray, b: np.ndarray) -> float:
    """fma(a2, b2, fma(a1, b1, fma(a0, b0, 0))) in exact rational arithmetic, each step rounded once to the nearest
    double (Fraction → float rounds correctly): the truth of an FMA instruction."""
    from fractions import Fraction

    s = 0.0
    for x, y in zip(a.tolist(), b.tolist(), strict=True):
        s = float(Fraction(x) * Fraction(y) + Fraction(s))
    return s


def test_dot3_is_the_rounded_fma_chain_and_numpys_dot_to_an_ulp():
    """dot3_1 rounds as an FMA chain does, step by step (the sum OpenBLAS's ddot forms for three terms on an FMA CPU,
    so the loop's kernels keep the bits of ``a @ b`` there: tests/sim_core/test_engine_digests.py), on random,
    signed, zero and large/small-exponent vectors; it differs from numpy's dot by at most the rounding of two
    products and two sums."""
    rng = np.random.default_rng(7)
    a = rng.standard_normal((2000, 3)) * 10.0 ** rng.integers(-8, 8, (2000, 3))
    b = rng.standard_normal((2000, 3)) * 10.0 ** rng.integers(-8, 8, (2000, 3))
    a[::7, 1] = 0.0
    b[::11, 2] = -0.0
    for x, y in zip(a, b, strict=True):
        d = qt.dot3_1(x, y)
        assert d == _fma_chain_exact(x, y)
        assert abs(d - float(x @ y)) <= 4.0 * np.finfo(float).eps * float(np.abs(x) @ np.abs(y))
    assert qt.dot3_floats(1.0, 2.0, 3.0, 4.0, -5.0, 6.0) == 12.0
