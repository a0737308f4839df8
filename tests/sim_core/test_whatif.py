"""What-if: the feasibility replay against conservation of angular momentum, monotonicity of the
fastest feasible turn in the number of wheels, MD windows against κ computed directly from the
field model, and sweeps reporting FDIR events per variant."""

import numpy as np
import pytest

from sim_core import allocation, engine, environment, faults, quaternion, scenario_library, whatif
from sim_core.scenario import Scenario, VariantSpec

MOMENTUM_REPLAY_TOL = 2e-3  # relative: the replay integrates m·T_u (rectangles) at 0.25 s along a smooth program


def _aist_without_gravity_gradient() -> Scenario:
    s = scenario_library.get("aist-scheduled-turn")
    return Scenario.model_validate({**s.model_dump(), "gravity_gradient": False})


def test_momentum_margin_equals_the_one_conservation_of_momentum_gives():
    """No external torque: A h = R_biᵀ H_i(0) − J ω^p with H_i(0) fixed, for three orthogonal wheels."""
    s = _aist_without_gravity_gradient()
    verdict = whatif.feasibility(s)
    p = engine.plant_params(s)
    t = np.arange(0.0, s.duration_s + 1e-9, s.control_dt_s)
    prog = engine.program_along(s, t)
    h_body0 = p.inertia_kg_m2 @ prog.omega_b[0]
    h_i0 = quaternion.rotate(prog.q_ib[0], h_body0)
    h_body = quaternion.rotate(quaternion.conjugate(prog.q_ib), np.broadcast_to(h_i0, (t.size, 3)))
    cluster = h_body - prog.omega_b @ p.inertia_kg_m2.T
    wheels = np.linalg.solve(p.wheel_axes_b, cluster.T).T
    expected = 1.0 - np.max(np.abs(wheels) / p.wheels.max_momentum_nms)
    assert verdict.feasible
    assert verdict.momentum_margin == pytest.approx(expected, abs=MOMENTUM_REPLAY_TOL)


def test_fewer_wheels_never_turn_faster():
    s = scenario_library.get("somov-ge4-scan")
    configs = dict(faults.wheel_configurations(4))
    all4 = whatif.max_feasible_turn_rate(s, configs["all wheels"])
    three = whatif.max_feasible_turn_rate(s, configs["without wheel 2"])
    pair = whatif.max_feasible_turn_rate(s, configs["wheels 3+4 + MD"])
    assert all4.rate_rad_s >= three.rate_rad_s > 0.0
    assert np.isnan(pair.rate_rad_s) or pair.rate_rad_s <= three.rate_rad_s


def test_md_windows_match_kappa_from_the_field_model():
    s = scenario_library.get("somov-ge4-scan")
    mask = np.array([False, True, False, True])
    verdict = whatif.feasibility(s, mask, window_s=(0.0, 300.0))
    t = np.arange(0.0, 300.0 + 1e-9, s.control_dt_s)
    prog = engine.program_along(s, t)
    b_eci = environment.magnetic_field_eci_t(prog.r_eci_m, t + prog_epoch(s), s.magnetic_model)
    b_body = quaternion.rotate(quaternion.conjugate(prog.q_ib), b_eci)
    axes = engine.plant_params(s).wheel_axes_b
    e_pq = (axes[:, 1] + axes[:, 3]) / np.linalg.norm(axes[:, 1] + axes[:, 3])
    kappa = b_body @ e_pq / np.linalg.norm(b_body, axis=1)
    assert verdict.md_windows_s == whatif.md_windows(t, kappa)
    inside = sum(b - a for a, b in verdict.md_windows_s)
    expected = np.sum(np.abs(kappa[:-1]) <= allocation.KAPPA_MAX) * s.control_dt_s
    assert inside == pytest.approx(expected, abs=2 * s.control_dt_s)


def prog_epoch(s: Scenario) -> float:
    from datetime import datetime

    return datetime.fromisoformat(s.orbit.epoch_utc.replace("Z", "+00:00")).timestamp()


def test_pair_outside_its_md_window_is_infeasible_with_the_reason():
    s = scenario_library.get("somov-ge4-scan")
    verdict = whatif.feasibility(s, np.array([True, True, False, False]))
    assert not verdict.feasible
    assert "κ" in verdict.reason and verdict.first_violation_s is not None


def test_sweep_reports_isolation_and_margins_per_variant():
    s = scenario_library.get("somov-ge4-scan")
    s = Scenario.model_validate({**s.model_dump(), "duration_s": 400.0})
    variants = [VariantSpec(name="nominal"), VariantSpec(name="wheel 3 dead", faults=[faults.wheel_failure(2, 330.0)])]
    rows = whatif.sweep(s, variants, initial={"wheel_speed_rpm": [300.0, -300.0, 300.0, -300.0]})
    assert [r["variant"] for r in rows] == ["nominal", "wheel 3 dead"]
    assert rows[0]["events"] == []
    isolated = [e for e in rows[1]["events"] if e["event"] == "fault_isolated"]
    assert isolated and isolated[0]["subject"] == "wheel 3"
    assert all(0.0 < r["wheel_momentum_margin"] < 1.0 and r["fault_mode_time_s"] == 0.0 for r in rows)


def test_bad_inputs_name_the_field():
    s = scenario_library.get("somov-ge4-scan")
    with pytest.raises(ValueError, match="window_s"):
        whatif.feasibility(s, window_s=(500.0, 100.0))
    with pytest.raises(ValueError, match="wheel_available"):
        whatif.feasibility(s, np.ones(3, dtype=bool))
    with pytest.raises(ValueError, match="initial.wheel_speed_rpm"):
        whatif.sweep(s, [VariantSpec(name="x")], initial={"wheel_speed_rpm": [0.0]})
    with pytest.raises(ValueError, match="variants"):
        whatif.sweep(s, [])
