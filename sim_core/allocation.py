"""Distribution of the required body torque between reaction wheels and the magnetic driver (seed 000 §3).

Sign convention (seed 000 eq 5): ``A M = −M^r``. ``A`` (3 × n) holds the wheel spin axes in body
axes as columns, ``M`` the motor torques on the wheels (N·m, they change the wheel momenta,
ḣ_p = m_p) and ``M^r`` the torque required on the body; the wheels' reaction on the body is −A M.
The magnetic driver (MD) adds the torque L × B (seed 003 eq 26) of its dipole L (A·m²).

The availability mask selects the law: four wheels → the GE explicit distribution law (6) or the
minimum-norm pseudo-inverse; any three → the square inverse; any two → wheels + MD. Every law
exists as a numba kernel (``allocate_1``) for the engine and as a vectorised API (``allocate``).

Seed defects corrected here (DESIGN.md, and found while deriving):
- κ ≡ ⟨e^m, b⟩ is identically zero; we use κ = ⟨e_pq, b⟩ and allow the MD where |κ| ≤ 1/2.
- e^m = b × e_pq is a unit vector only when b ⊥ e_pq: we normalise it, so m^m is the MD torque.
- M^m = −L × B contradicts L = (m^m/B)(b × e^m) (that L gives L × B = +m^m e^m): we keep the
  physical torque L × B of seed 003 eq (26), which with seed 000's L yields M^m = e^m m^m.
- |κ| ≤ 1/2 does not guarantee that {a_p, a_q, −e^m} is invertible (its determinant is
  ∝ ⟨b, a_p − a_q⟩): a pair is also refused when e^m covers less than ``MIN_MD_PLANE_COVER``
  of the pair plane's normal.
- The row a_f printed in the seed is not the gradient of f_ρ (wrong power of q_s, h_2 for h_1 in
  a_f2, and the sign of a_f3,4, which makes {A, a_f} singular at h = 0). We use the exact gradient, so
  that df_ρ/dt = −Sat(μ_ρ f_ρ, φ_ρ) holds; ``Sat(φ_ρ, μ_ρ f_ρ)`` is read as μ_ρ f_ρ clipped at ±φ_ρ.

Beyond the seed (``md_law=MD_LAW_PAIR_NORMAL``, scenario ``allocation.md_law="least_dipole"``): the MD only
has to supply the torque τ_n across the pair plane (about n_pq = a_p × a_q), and the least dipole doing so is
L = τ_n (B × n_pq)/|B × n_pq|², whose torque lies along the part of n_pq across b; the wheels take the rest.
It is usable wherever b is not along n_pq (the rods' limit, not a fixed κ window, bounds it), where the
seed's e^m = b × e_pq with |κ| ≤ 1/2 leaves the MD usable within about ±16° of the magnetic equator for the
pair whose e_pq is the nadir axis (wheels 1–2 of GE). With saturated rods the torque across the plane falls
short and the wheels still give the in-plane torque in full.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from numba import njit

__all__ = [
    "STATUS_OK",
    "STATUS_MD_SATURATED",
    "STATUS_KAPPA_REFUSED",
    "STATUS_SINGULAR",
    "STATUS_TOO_FEW_WHEELS",
    "STATUS_NO_DRIVER",
    "STATUS_NO_FIELD",
    "LAW_GE_DISTRIBUTION",
    "LAW_PSEUDO_INVERSE",
    "MD_LAW_SEED",
    "MD_LAW_PAIR_NORMAL",
    "KAPPA_MAX",
    "MIN_NORMAL_SINE",
    "MIN_MD_PLANE_COVER",
    "P_LAW4",
    "P_GAMMA",
    "P_RHO",
    "P_MU_RHO",
    "P_PHI_RHO",
    "P_H_MAX",
    "P_L_MAX",
    "P_MD_LAW",
    "AllocationConfig",
    "ge_axes",
    "tuning_function",
    "tuning_gradient",
    "distribute_momentum",
    "allocate",
    "tuning_function_1",
    "tuning_gradient_1",
    "distribute_momentum_1",
    "allocate_1",
]

STATUS_OK = 0  # M^r reproduced exactly
STATUS_MD_SATURATED = 1  # rods at |l_i| = l^m: wheels and MD command scaled down together
STATUS_KAPPA_REFUSED = 2  # MD refused by its geometric condition: the two wheels give the in-plane part only
STATUS_SINGULAR = 3  # wheel (or wheel + MD) geometry singular: least-squares wheel torques only
STATUS_TOO_FEW_WHEELS = 4  # fewer than two wheels: no torque
STATUS_NO_DRIVER = 5  # two wheels and no magnetic driver (l^m = 0): least-squares pair torques, in-plane only
STATUS_NO_FIELD = 6  # two wheels and no field (B = 0: no valid magnetometer sample): no dipole, pair in-plane only

LAW_GE_DISTRIBUTION = 0
LAW_PSEUDO_INVERSE = 1
MD_LAW_SEED = 0  # e^m = b × e_pq, used where |κ| = |⟨e_pq, b⟩| ≤ 1/2 (seed 000 §3 as corrected)
MD_LAW_PAIR_NORMAL = 1  # least dipole: e^m = the unit part of the pair normal n_pq across b, saturating at l^m

KAPPA_MAX = 0.5  # seed 000 §3: cos(π/3)
MIN_NORMAL_SINE = 1e-3  # sin∠(b, n_pq) below which the least dipole would exceed any rod by ~1000×
MIN_MD_PLANE_COVER = 0.05  # |⟨e^m, n_pq⟩| below this needs an MD torque > 20× the out-of-plane demand
_SINGULAR_PIVOT = 1e-9  # relative pivot below which a small system is treated as singular

# Layout of the float64 parameter vector of the kernels (AllocationConfig.as_array).
P_LAW4, P_GAMMA, P_RHO, P_MU_RHO, P_PHI_RHO, P_H_MAX, P_L_MAX, P_MD_LAW = range(8)


@dataclass(frozen=True)
class AllocationConfig:
    """Parameters of the allocation laws (seed 000 eq 6 and §3, SI units).

    Defaults: γ = 30° as in the peer GE cluster of DESIGN.md (the seed gives no γ; γ < 45° keeps
    q_s real over the whole momentum box); ρ = 0.5 inside the seed's 0 < ρ < 1; μ_ρ = 0.05 s⁻¹
    tunes f_ρ in ~20 s, far slower than the 2 s control period; φ_ρ = 0.002 s⁻¹ caps the null-motion
    torque to h^m φ_ρ ≈ 0.024 N·m, 12 % of an HR12's 0.2 N·m; h^m = 12 N·m·s (HR12);
    l^m = 25 A·m² (seed 000 §5; 0: no magnetic driver, two wheels give the least-squares pair torque); the
    seed's MD direction (``md_law``).
    """

    law4: int = LAW_GE_DISTRIBUTION
    gamma_rad: float = np.deg2rad(30.0)
    rho: float = 0.5
    mu_rho_per_s: float = 0.05
    phi_rho_per_s: float = 0.002
    h_max_nms: float = 12.0
    l_max_am2: float = 25.0
    md_law: int = MD_LAW_SEED

    def __post_init__(self) -> None:
        if self.law4 not in (LAW_GE_DISTRIBUTION, LAW_PSEUDO_INVERSE):
            raise ValueError("law4: use LAW_GE_DISTRIBUTION (0) or LAW_PSEUDO_INVERSE (1)")
        if self.md_law not in (MD_LAW_SEED, MD_LAW_PAIR_NORMAL):
            raise ValueError("md_law: use MD_LAW_SEED (0) or MD_LAW_PAIR_NORMAL (1)")
        if not 0.0 < self.gamma_rad < np.pi / 4:
            raise ValueError("gamma_rad: GE half-angle must lie in (0, π/4) so that q_s stays real")
        if not 0.0 < self.rho < 1.0:
            raise ValueError("rho: seed 000 requires 0 < ρ < 1")
        for name in ("mu_rho_per_s", "phi_rho_per_s", "h_max_nms"):
            if not getattr(self, name) > 0.0:
                raise ValueError(f"{name}: must be positive")
        if not self.l_max_am2 >= 0.0:
            raise ValueError("l_max_am2: must be non-negative (0: no magnetic driver)")

    def as_array(self) -> np.ndarray:
        """Parameter vector for the kernels of seed 000 eq (6) and §3, indexed by the P_* constants."""
        return np.array(
            [
                self.law4,
                self.gamma_rad,
                self.rho,
                self.mu_rho_per_s,
                self.phi_rho_per_s,
                self.h_max_nms,
                self.l_max_am2,
                self.md_law,
            ],
            dtype=np.float64,
        )


def ge_axes(gamma_rad: float, drf_roll_rad: float = np.pi / 4) -> np.ndarray:
    """Spin axes A = [π/4]_1^t A^d of the GE cluster in body axes, 3 × 4 (seed 000 eq 1)."""
    if not 0.0 < gamma_rad < np.pi / 2:
        raise ValueError("gamma_rad: must lie in (0, π/2)")
    c, s = np.cos(gamma_rad), np.sin(gamma_rad)
    a_d = np.array([[c, c, c, c], [s, -s, 0.0, 0.0], [0.0, 0.0, s, -s]])
    cr, sr = np.cos(drf_roll_rad), np.sin(drf_roll_rad)
    turn_1 = np.array([[1.0, 0.0, 0.0], [0.0, cr, sr], [0.0, -sr, cr]])  # passive [φ]_1
    axes_b: npt.NDArray[np.float64] = turn_1.T @ a_d
    return axes_b


@njit(cache=True)
def _pair_terms(h1: float, h2: float, c: float, s: float) -> tuple[float, float, float]:
    """x̃ of one wheel pair and its partial derivatives ∂x̃/∂h_1, ∂x̃/∂h_2 (seed 000 eq 6)."""
    d = h1 - h2
    q2 = 4.0 * c * c - s * s * d * d
    q = np.sqrt(q2)
    xt = c * (h1 + h2) / q
    q3 = q2 * q
    return xt, 2.0 * c * (2.0 * c * c + s * s * h2 * d) / q3, 2.0 * c * (2.0 * c * c - s * s * h1 * d) / q3


@njit(cache=True)
def tuning_function_1(h_norm: np.ndarray, gamma: float, rho: float) -> float:
    """Cluster tuning function f_ρ(h) = x̃1 − x̃2 + ρ(x̃1 x̃2 − 1), h = h_p/h^m (seed 000 eq 6)."""
    c, s = np.cos(gamma), np.sin(gamma)
    x1t = _pair_terms(h_norm[0], h_norm[1], c, s)[0]
    x2t = _pair_terms(h_norm[2], h_norm[3], c, s)[0]
    return x1t - x2t + rho * (x1t * x2t - 1.0)


@njit(cache=True)
def tuning_gradient_1(h_norm: np.ndarray, gamma: float, rho: float) -> np.ndarray:
    """Row a_f = ∂f_ρ/∂h_p of the distribution law (seed 000 eq 6, exact gradient)."""
    c, s = np.cos(gamma), np.sin(gamma)
    x1t, d11, d12 = _pair_terms(h_norm[0], h_norm[1], c, s)
    x2t, d23, d24 = _pair_terms(h_norm[2], h_norm[3], c, s)
    a_f = np.empty(4)
    a_f[0] = d11 * (1.0 + rho * x2t)
    a_f[1] = d12 * (1.0 + rho * x2t)
    a_f[2] = -d23 * (1.0 - rho * x1t)
    a_f[3] = -d24 * (1.0 - rho * x1t)
    return a_f


@njit(cache=True)
def distribute_momentum_1(h_drf_norm: np.ndarray, gamma: float, rho: float) -> np.ndarray:
    """Wheel momenta h_p/h^m from the normed DRF cluster momentum (x, y, z) by seed 000 eq 6 (i)–(ii)."""
    c, s = np.cos(gamma), np.sin(gamma)
    x, y, z = h_drf_norm[0], h_drf_norm[1], h_drf_norm[2]
    qy = np.sqrt(4.0 * c * c - y * y)
    qz = np.sqrt(4.0 * c * c - z * z)
    q = qy + qz
    inner = (qy - qz) * (0.5 * x) + rho * (qy * qz - 0.25 * x * x)
    u = 4.0 * rho * inner / (q * q)
    delta = (q / rho) * u / (1.0 + np.sqrt(1.0 - u))  # = (q/ρ)(1 − √(1 − u)) without cancellation
    x1, x2 = 0.5 * (x + delta), 0.5 * (x - delta)
    h = np.empty(4)
    h[0] = 0.5 * (x1 / c + y / s)
    h[1] = 0.5 * (x1 / c - y / s)
    h[2] = 0.5 * (x2 / c + z / s)
    h[3] = 0.5 * (x2 / c - z / s)
    return h


@njit(cache=True)
def _solve(m: np.ndarray, rhs: np.ndarray) -> tuple[np.ndarray, bool]:
    """Solve the small square system m x = rhs by Gaussian elimination with partial pivoting."""
    n = rhs.shape[0]
    a = m.copy()
    x = rhs.copy()
    scale = 0.0
    for i in range(n):
        for j in range(n):
            scale = max(scale, abs(a[i, j]))
    for col in range(n):
        piv = col
        for r in range(col + 1, n):
            if abs(a[r, col]) > abs(a[piv, col]):
                piv = r
        if abs(a[piv, col]) <= _SINGULAR_PIVOT * scale:
            return x, False
        if piv != col:
            for j in range(n):
                a[col, j], a[piv, j] = a[piv, j], a[col, j]
            x[col], x[piv] = x[piv], x[col]
        for r in range(col + 1, n):
            f = a[r, col] / a[col, col]
            for j in range(col, n):
                a[r, j] -= f * a[col, j]
            x[r] -= f * x[col]
    for r in range(n - 1, -1, -1):
        acc = x[r]
        for j in range(r + 1, n):
            acc -= a[r, j] * x[j]
        x[r] = acc / a[r, r]
    return x, True


@njit(cache=True)
def _dot3(u: np.ndarray, v: np.ndarray) -> float:
    return float(u[0] * v[0] + u[1] * v[1] + u[2] * v[2])


@njit(cache=True)
def _solve3(m: np.ndarray, i0: int, i1: int, i2: int, rhs: np.ndarray) -> tuple[np.ndarray, bool]:
    """Solve [m_{i0} m_{i1} m_{i2}] x = rhs for three columns of m by Cramer's rule (no temporaries)."""
    c0 = (m[0, i0], m[1, i0], m[2, i0])
    c1 = (m[0, i1], m[1, i1], m[2, i1])
    c2 = (m[0, i2], m[1, i2], m[2, i2])
    r = (rhs[0], rhs[1], rhs[2])
    det = _triple(c0, c1, c2)
    x = np.zeros(3)
    norms = np.sqrt(
        (c0[0] ** 2 + c0[1] ** 2 + c0[2] ** 2)
        * (c1[0] ** 2 + c1[1] ** 2 + c1[2] ** 2)
        * (c2[0] ** 2 + c2[1] ** 2 + c2[2] ** 2)
    )
    if abs(det) <= _SINGULAR_PIVOT * norms:
        return x, False
    x[0] = _triple(r, c1, c2) / det
    x[1] = _triple(c0, r, c2) / det
    x[2] = _triple(c0, c1, r) / det
    return x, True


@njit(cache=True)
def _triple(u: tuple[float, float, float], v: tuple[float, float, float], w: tuple[float, float, float]) -> float:
    """Scalar triple product u · (v × w)."""
    return float(
        u[0] * (v[1] * w[2] - v[2] * w[1]) + u[1] * (v[2] * w[0] - v[0] * w[2]) + u[2] * (v[0] * w[1] - v[1] * w[0])
    )


@njit(cache=True)
def _min_norm(axes: np.ndarray, idx: np.ndarray, n_on: int, torque: np.ndarray, out: np.ndarray) -> bool:
    """Minimum-norm M = −A^t (A A^t)^{-1} M^r over the available columns (seed 000 §3, Basilisk rwMotorTorque)."""
    gram = np.zeros((3, 3))
    for k in range(n_on):
        p = idx[k]
        for i in range(3):
            for j in range(3):
                gram[i, j] += axes[i, p] * axes[j, p]
    y, ok = _solve3(gram, 0, 1, 2, torque)
    for k in range(n_on):
        p = idx[k]
        out[p] = -(axes[0, p] * y[0] + axes[1, p] * y[1] + axes[2, p] * y[2])
    return ok


@njit(cache=True)
def _ge_law(axes: np.ndarray, torque: np.ndarray, h_wheels: np.ndarray, params: np.ndarray) -> tuple[np.ndarray, bool]:
    """GE explicit law M = {A, a_f}^{-1}{−M^r, −h^m Sat(μ_ρ f_ρ, φ_ρ)} (seed 000 eq 6)."""
    h_max = params[P_H_MAX]
    h_norm = h_wheels / h_max
    gamma, rho = params[P_GAMMA], params[P_RHO]
    a_f = tuning_gradient_1(h_norm, gamma, rho)
    f_rho = tuning_function_1(h_norm, gamma, rho)
    if not np.isfinite(f_rho):  # momenta so far outside the box that q_s is imaginary
        return np.zeros(4), False
    m4 = np.empty((4, 4))
    rhs = np.empty(4)
    for j in range(4):
        m4[0, j], m4[1, j], m4[2, j], m4[3, j] = axes[0, j], axes[1, j], axes[2, j], a_f[j]
    rhs[0], rhs[1], rhs[2] = -torque[0], -torque[1], -torque[2]
    drive = params[P_MU_RHO] * f_rho
    cap = params[P_PHI_RHO]
    rhs[3] = -h_max * min(max(drive, -cap), cap)
    return _solve(m4, rhs)


@njit(cache=True)
def _pair_least_squares(ap: np.ndarray, aq: np.ndarray, torque: np.ndarray) -> tuple[float, float]:
    """Wheel torques of a pair minimising |a_p m_p + a_q m_q + M^r| (in-plane part of M^r)."""
    g00, g01, g11 = _dot3(ap, ap), _dot3(ap, aq), _dot3(aq, aq)
    det = g00 * g11 - g01 * g01
    if det <= _SINGULAR_PIVOT * g00 * g11:
        return 0.0, 0.0
    r0, r1 = -_dot3(ap, torque), -_dot3(aq, torque)
    return (g11 * r0 - g01 * r1) / det, (g00 * r1 - g01 * r0) / det


@njit(cache=True)
def _md_direction(ap: np.ndarray, aq: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, int]:
    """Unit MD torque direction e^m = b × e_pq (⟂ b) for a wheel pair, or a refusal status (seed 000 §3)."""
    normal = np.cross(ap, aq)
    normal /= np.sqrt(_dot3(normal, normal))
    s = ap + aq
    e_pq = s / np.sqrt(_dot3(s, s))
    if abs(_dot3(e_pq, b)) > KAPPA_MAX:
        return e_pq, STATUS_KAPPA_REFUSED
    e_m = np.cross(b, e_pq)
    e_m /= np.sqrt(_dot3(e_m, e_m))
    if abs(_dot3(e_m, normal)) < MIN_MD_PLANE_COVER:
        return e_m, STATUS_SINGULAR
    return e_m, STATUS_OK


@njit(cache=True)
def _two_wheels_min_dipole(
    ap: np.ndarray, aq: np.ndarray, torque: np.ndarray, b_field: np.ndarray, b_norm: float, l_max: float
) -> tuple[float, float, np.ndarray, int]:
    """Two wheels + MD by the least dipole: the MD gives the torque τ_n = ⟨n_pq, M^r⟩ across the pair plane with
    L = τ_n (B × n_pq)/|B × n_pq|² (the shortest L with ⟨L × B, n_pq⟩ = τ_n; its torque is along the part of n_pq
    across b), clipped to the rods' |l_i| ≤ l^m; the wheels give the rest, M^r − L × B, which then lies in
    their plane (exactly unless the rods saturate: least squares). Refused only where b is within
    ``MIN_NORMAL_SINE`` of n_pq, when no dipole turns the body across the plane."""
    normal = np.cross(ap, aq)
    normal /= np.sqrt(_dot3(normal, normal))
    b_cross_n = np.cross(b_field, normal)
    sin2 = _dot3(b_cross_n, b_cross_n) / (b_norm * b_norm)
    if sin2 < MIN_NORMAL_SINE * MIN_NORMAL_SINE:
        mp, mq = _pair_least_squares(ap, aq, torque)
        return mp, mq, np.zeros(3), STATUS_KAPPA_REFUSED
    dipole = (_dot3(normal, torque) / (sin2 * b_norm * b_norm)) * b_cross_n
    status = STATUS_OK
    peak = max(abs(dipole[0]), abs(dipole[1]), abs(dipole[2]))
    if peak > l_max:
        dipole *= l_max / peak
        status = STATUS_MD_SATURATED
    mp, mq = _pair_least_squares(ap, aq, torque - np.cross(dipole, b_field))
    return mp, mq, dipole, status


@njit(cache=True)
def _two_wheels_md(
    ap: np.ndarray, aq: np.ndarray, torque: np.ndarray, b_field: np.ndarray, l_max: float, md_law: int
) -> tuple[float, float, np.ndarray, int]:
    """Two wheels + MD: A^m_pq {m_p, m_q, m^m} = −M^r, L = (m^m/B)(b × e^m) (seed 000 §3), or the least dipole
    (``MD_LAW_PAIR_NORMAL``, :func:`_two_wheels_min_dipole`)."""
    b_norm = np.sqrt(_dot3(b_field, b_field))
    dipole = np.zeros(3)
    if l_max == 0.0:  # no driver: scaling the seed's solution to a zero dipole would zero the wheels too
        mp, mq = _pair_least_squares(ap, aq, torque)
        return mp, mq, dipole, STATUS_NO_DRIVER
    if b_norm == 0.0:  # L × B is zero for every L: the pair gives the in-plane part of M^r, as without a driver
        mp, mq = _pair_least_squares(ap, aq, torque)
        return mp, mq, dipole, STATUS_NO_FIELD
    if md_law == MD_LAW_PAIR_NORMAL:
        return _two_wheels_min_dipole(ap, aq, torque, b_field, b_norm, l_max)
    b = b_field / b_norm
    e_m, status = _md_direction(ap, aq, b)
    if status != STATUS_OK:
        mp, mq = _pair_least_squares(ap, aq, torque)
        return mp, mq, dipole, status
    a_m = np.empty((3, 3))
    for i in range(3):
        a_m[i, 0], a_m[i, 1], a_m[i, 2] = ap[i], aq[i], -e_m[i]
    sol, _ = _solve3(a_m, 0, 1, 2, -torque)
    dipole = (sol[2] / b_norm) * np.cross(b, e_m)
    peak = max(abs(dipole[0]), abs(dipole[1]), abs(dipole[2]))
    if peak > l_max:
        k = l_max / peak
        return sol[0] * k, sol[1] * k, dipole * k, STATUS_MD_SATURATED
    return sol[0], sol[1], dipole, STATUS_OK


@njit(cache=True)
def allocate_1(
    torque_req_b: np.ndarray,
    axes_b: np.ndarray,
    available: np.ndarray,
    h_wheels_nms: np.ndarray,
    b_field_b_t: np.ndarray,
    params: np.ndarray,
    wheel_torque_out: np.ndarray,
    dipole_out: np.ndarray,
) -> int:
    """Wheel torques and MD dipole for M^r by the law the mask selects (seed 000 eqs 5–6, §3); returns a status."""
    n = axes_b.shape[1]
    idx = np.empty(n, dtype=np.int64)
    n_on = 0
    for j in range(n):
        wheel_torque_out[j] = 0.0
        if available[j]:
            idx[n_on] = j
            n_on += 1
    dipole_out[:] = 0.0
    if n_on < 2:
        return STATUS_TOO_FEW_WHEELS
    if n_on == 2:
        mp, mq, dip, status = _two_wheels_md(
            axes_b[:, idx[0]].copy(),
            axes_b[:, idx[1]].copy(),
            torque_req_b,
            b_field_b_t,
            params[P_L_MAX],
            int(params[P_MD_LAW]),
        )
        wheel_torque_out[idx[0]], wheel_torque_out[idx[1]] = mp, mq
        dipole_out[:] = dip
        return status
    if n_on == 3:
        m, ok = _solve3(axes_b, idx[0], idx[1], idx[2], -torque_req_b)
        if ok:
            for k in range(3):
                wheel_torque_out[idx[k]] = m[k]
    elif n_on == 4 and n == 4 and int(params[P_LAW4]) == LAW_GE_DISTRIBUTION:
        m, ok = _ge_law(axes_b, torque_req_b, h_wheels_nms, params)
        if ok:
            wheel_torque_out[:] = m
        else:
            ok = _min_norm(axes_b, idx, n_on, torque_req_b, wheel_torque_out)
    else:
        ok = _min_norm(axes_b, idx, n_on, torque_req_b, wheel_torque_out)
    if not ok:
        wheel_torque_out[:] = 0.0
        return STATUS_SINGULAR
    return STATUS_OK


def _as_field(x: np.ndarray, name: str, last: int) -> np.ndarray:
    arr = np.asarray(x, dtype=np.float64)
    if arr.shape[-1:] != (last,):
        raise ValueError(f"{name}: expected shape (..., {last}), got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name}: contains NaN or infinite values")
    return arr


def _check_ge_axes(axes: np.ndarray, gamma_rad: float) -> None:
    """The GE law needs A = R A^d for a rotation R, i.e. the Gram matrix AᵗA of A^d."""
    gram_ge = ge_axes(gamma_rad).T @ ge_axes(gamma_rad)
    if axes.shape != (3, 4) or not np.allclose(axes.T @ axes, gram_ge, atol=1e-9):
        raise ValueError(
            "axes_b: the GE law needs four unit axes ordered as seed 000's A^d (pairs 1–2 and 3–4) with "
            "half-angle gamma_rad; build them with ge_axes() or use law4=LAW_PSEUDO_INVERSE"
        )


def tuning_function(h_wheels_nms: np.ndarray, config: AllocationConfig = AllocationConfig()) -> np.ndarray:
    """f_ρ of wheel momenta (..., 4) in N·m·s (seed 000 eq 6)."""
    h = _as_field(h_wheels_nms, "h_wheels_nms", 4) / config.h_max_nms
    flat = h.reshape(-1, 4)
    out = np.array([tuning_function_1(row, config.gamma_rad, config.rho) for row in flat])
    return out.reshape(h.shape[:-1])


def tuning_gradient(h_wheels_nms: np.ndarray, config: AllocationConfig = AllocationConfig()) -> np.ndarray:
    """Row a_f = ∂f_ρ/∂(h_p/h^m) for wheel momenta (..., 4) in N·m·s (seed 000 eq 6)."""
    h = _as_field(h_wheels_nms, "h_wheels_nms", 4) / config.h_max_nms
    flat = h.reshape(-1, 4)
    out = np.array([tuning_gradient_1(row, config.gamma_rad, config.rho) for row in flat])
    return out.reshape(h.shape)


def distribute_momentum(
    momentum_b_nms: np.ndarray, axes_b: np.ndarray, config: AllocationConfig = AllocationConfig()
) -> np.ndarray:
    """Wheel momenta (..., 4) in N·m·s with A h = H and f_ρ(h) = 0 (seed 000 eq 6 (i)–(ii))."""
    momentum = _as_field(momentum_b_nms, "momentum_b_nms", 3)
    axes = _as_field(axes_b, "axes_b", 4)
    _check_ge_axes(axes, config.gamma_rad)
    a_d = ge_axes(config.gamma_rad, 0.0)
    rot = axes @ np.linalg.pinv(a_d)  # A = R A^d
    drf = (momentum / config.h_max_nms) @ rot  # R^t H per row
    flat = drf.reshape(-1, 3)
    out = np.array([distribute_momentum_1(row, config.gamma_rad, config.rho) for row in flat])
    if not np.all(np.isfinite(out)):
        raise ValueError(
            "momentum_b_nms: outside the domain of the distribution law (|y|, |z| < 2 cos γ · h^m in DRF axes)"
        )
    return out.reshape(momentum.shape[:-1] + (4,)) * config.h_max_nms


def allocate(
    torque_req_b_nm: np.ndarray,
    axes_b: np.ndarray,
    available: np.ndarray,
    h_wheels_nms: np.ndarray,
    b_field_b_t: np.ndarray,
    config: AllocationConfig = AllocationConfig(),
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Vectorised allocation (seed 000 eqs 5–6, §3): wheel torques (..., n) N·m, dipole (..., 3) A·m², status (...)."""
    torque = _as_field(torque_req_b_nm, "torque_req_b_nm", 3)
    axes = np.asarray(axes_b, dtype=np.float64)
    if axes.ndim != 2 or axes.shape[0] != 3:
        raise ValueError(f"axes_b: expected shape (3, n_wheels), got {axes.shape}")
    n = axes.shape[1]
    mask = np.asarray(available, dtype=bool)
    h = _as_field(h_wheels_nms, "h_wheels_nms", n)
    b = _as_field(b_field_b_t, "b_field_b_t", 3)
    if mask.shape[-1:] != (n,):
        raise ValueError(f"available: expected shape (..., {n}), got {mask.shape}")
    if config.law4 == LAW_GE_DISTRIBUTION and n == 4:
        _check_ge_axes(axes, config.gamma_rad)
    shape = np.broadcast_shapes(torque.shape[:-1], mask.shape[:-1], h.shape[:-1], b.shape[:-1])
    torque, mask, h, b = (
        np.broadcast_to(v, shape + v.shape[-1:]).reshape(-1, v.shape[-1]) for v in (torque, mask, h, b)
    )
    params = config.as_array()
    wheel = np.zeros((torque.shape[0], n))
    dipole = np.zeros((torque.shape[0], 3))
    status = np.empty(torque.shape[0], dtype=np.int64)
    axes_c = np.ascontiguousarray(axes)
    for i in range(torque.shape[0]):
        status[i] = allocate_1(
            torque[i].copy(), axes_c, mask[i].copy(), h[i].copy(), b[i].copy(), params, wheel[i], dipole[i]
        )
    return wheel.reshape(shape + (n,)), dipole.reshape(shape + (3,)), status.reshape(shape)
