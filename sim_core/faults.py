"""The fault catalogue: named fault sets of the seed experiments and the wheel-failure configurations.

Everything here builds :class:`~sim_core.scenario.FaultSpec` / :class:`~sim_core.scenario.VariantSpec`
values (validated there) for batch runs of :func:`sim_core.engine.simulate`:

- :func:`wheel_configurations`: the 11 configurations of the GE cluster of seed 000 §3 (all four,
  each single failure, each failed pair leaving two wheels + the magnetic driver);
- :func:`seed002_fault_sets`: seed 002 §3.2's experiments on its three-orthogonal-wheel bus
  (controller intermittent 7–8 s and abrupt at 7 s; wheel 3 multiplicative and stuck; wheels
  {1,2}, {1,3}, {2,3}, {1,2,3}; gyro and attitude-sensor graded faults alone and together; 10σ and
  50σ measurement noise). The seed's Table 1 of magnitudes is garbled (DESIGN.md), so magnitudes are
  ours, chosen in proportion to the ``song-table1`` bus and stated in :data:`SEED002_MAGNITUDES`. The
  seed's earth sensor is the attitude sensor of that loop; the engine's attitude sensor is the star
  tracker, so its graded fault is applied there (the earth sensor is not yet in the loop);
- :func:`seed000_two_wheels` : seed 000 §5's wheels 2 and 4 with the MD.

Wheel numbers in names are the seeds' (1-based); indices in specs are 0-based.
"""

from __future__ import annotations

from itertools import combinations

import numpy as np

from sim_core.scenario import FaultSpec, VariantSpec

__all__ = [
    "SEED002_ONSET_S",
    "SEED002_MAGNITUDES",
    "wheel_failure",
    "wheel_configurations",
    "configuration_variants",
    "seed002_fault_sets",
    "seed000_two_wheels",
    "random_wheel_failures",
]

SEED002_ONSET_S = 7.0  # seed 002 §3.2.1: the controller faults start at 7 s; we start every fault there
SEED002_MAGNITUDES = {
    "controller_bias_nm": 0.02,  # 20 % of the bus's 0.1 N·m wheels: an abrupt offset the PD must fight
    "wheel_gain": 0.3,  # multiplicative fault: 70 % of the motor torque lost
    "gyro_drift_rad_s2": 2e-6,  # graded gyro fault: 0.4 mrad/s of extra bias after 200 s
    "attitude_drift_rad_s": 5e-5,  # graded attitude-sensor fault: 0.57° of cumulative offset after 200 s
    "noise_10": 10.0,  # seed 002 §3.2.4: 10σ
    "noise_50": 50.0,  # and 50σ
}


def wheel_failure(index: int, onset_s: float = 0.0, kind: str = "failure", **params: float) -> FaultSpec:
    """One wheel fault (seed 000 §3 failed wheel; seed 002 §3.2.2 multiplicative/stuck), validated."""
    return FaultSpec(target="wheel", index=index, type=kind, onset_s=onset_s, **params)


def wheel_configurations(n_wheels: int = 4) -> list[tuple[str, np.ndarray]]:
    """(name, availability mask) of all, each single failure and each failed pair (seed 000 §3)."""
    if n_wheels < 3:
        raise ValueError("n_wheels: the configurations need at least three wheels")
    out = [("all wheels", np.ones(n_wheels, dtype=bool))]
    for fail in range(n_wheels):
        mask = np.ones(n_wheels, dtype=bool)
        mask[fail] = False
        out.append((f"without wheel {fail + 1}", mask))
    for p, q in combinations(range(n_wheels), 2):
        mask = np.zeros(n_wheels, dtype=bool)
        mask[[p, q]] = True
        out.append((f"wheels {p + 1}+{q + 1} + MD", mask))
    return out


def configuration_variants(n_wheels: int = 4) -> tuple[list[VariantSpec], np.ndarray]:
    """Variants with the missing wheels failed from t = 0, and the matching availability masks."""
    variants, masks = [], []
    for name, mask in wheel_configurations(n_wheels):
        faults = [wheel_failure(int(p)) for p in np.nonzero(~mask)[0]]
        variants.append(VariantSpec(name=name, faults=faults))
        masks.append(mask)
    return variants, np.array(masks)


def _axes(target: str, kind: str, onset: float, **params: float) -> list[FaultSpec]:
    return [FaultSpec(target=target, index=i, type=kind, onset_s=onset, **params) for i in range(3)]


def _noise(k: float) -> list[FaultSpec]:
    """Gyro and star-tracker noise scaled to k·σ on every axis (seed 002 §3.2.4)."""
    return _axes("gyro", "noise", 0.0, value=k) + _axes("star_tracker", "noise", 0.0, value=k)


def seed002_fault_sets(onset_s: float = SEED002_ONSET_S) -> dict[str, list[FaultSpec]]:
    """Seed 002 §3.2 experiments as named fault sets for the three-wheel ``song-table1`` bus."""
    m = SEED002_MAGNITUDES
    gyro_drift = [FaultSpec(target="gyro", index=0, type="drift", onset_s=onset_s, value=m["gyro_drift_rad_s2"])]
    att_drift = [FaultSpec(target="star_tracker", index=0, type="drift", onset_s=onset_s,
                           value=m["attitude_drift_rad_s"])]
    return {
        "nominal": [],
        "controller intermittent 7-8 s": [FaultSpec(target="controller", type="intermittent", onset_s=onset_s,
                                                    duration_s=1.0)],
        "controller abrupt 7 s": [FaultSpec(target="controller", index=0, type="bias", onset_s=onset_s,
                                            value=m["controller_bias_nm"])],
        "wheel 3 multiplicative": [wheel_failure(2, onset_s, "gain", gain=m["wheel_gain"])],
        "wheel 3 stuck": [wheel_failure(2, onset_s, "stuck")],
        "wheels 1,2": [wheel_failure(0, onset_s), wheel_failure(1, onset_s)],
        "wheels 1,3": [wheel_failure(0, onset_s), wheel_failure(2, onset_s)],
        "wheels 2,3": [wheel_failure(1, onset_s), wheel_failure(2, onset_s)],
        "wheels 1,2,3": [wheel_failure(p, onset_s) for p in range(3)],
        "gyro graded": gyro_drift,
        "attitude sensor graded": att_drift,
        "gyro + attitude sensor graded": gyro_drift + att_drift,
        "noise 10 sigma": _noise(m["noise_10"]),
        "noise 50 sigma": _noise(m["noise_50"]),
    }


def seed000_two_wheels(onset_s: float = 0.0) -> tuple[list[FaultSpec], np.ndarray]:
    """Seed 000 §5: wheels 1 and 3 failed, so wheels 2 and 4 fly with the MD; faults and mask."""
    mask = np.array([False, True, False, True])
    return [wheel_failure(0, onset_s), wheel_failure(2, onset_s)], mask


def random_wheel_failures(n: int, onset_range_s: tuple[float, float], n_wheels: int = 4, seed: int = 0,
                          kind: str = "failure") -> list[VariantSpec]:
    """``n`` variants, each with one wheel (uniformly drawn) failing at a uniform onset time."""
    lo, hi = onset_range_s
    if n < 1:
        raise ValueError("n: at least one variant")
    if not 0.0 <= lo < hi:
        raise ValueError("onset_range_s: expected 0 ≤ start < end")
    rng = np.random.default_rng(seed)
    wheels = rng.integers(0, n_wheels, n)
    onsets = rng.uniform(lo, hi, n)
    return [VariantSpec(name=f"wheel {w + 1} {kind} at {t:.1f} s", faults=[wheel_failure(int(w), float(t), kind)])
            for w, t in zip(wheels, onsets)]
