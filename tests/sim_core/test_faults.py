"""The fault catalogue and the faults as the engine applies them, against the physics they stand
for: a dead motor leaves ḣ = 0 (no friction), a seized wheel hands its momentum to the body with the
total conserved, a gain fault scales the delivered momentum change, an intermittent controller
fault silences the output only inside its window."""

import numpy as np
import pytest

from sim_core import engine, faults, quaternion, scenario_library
from sim_core.scenario import FaultSpec, Scenario, VariantSpec

MOMENTUM_CONSERVED = 1e-9  # relative: RK4 at 0.05 s with no external torque, a few hundred steps
EXACT_TORQUE = 1e-12  # N·m, recorded commands vs delivered torques are the same floats scaled


def test_eleven_configurations_cover_all_failures_of_up_to_two_wheels():
    configs = faults.wheel_configurations(4)
    masks = {tuple(m) for _, m in configs}
    assert len(configs) == 11 and len(masks) == 11
    assert sorted(int(np.sum(m)) for m in masks) == [2] * 6 + [3] * 4 + [4]
    variants, mask_array = faults.configuration_variants(4)
    for v, mask in zip(variants, mask_array):
        assert sorted(f.index for f in v.faults) == list(np.nonzero(~mask)[0])
        assert all(f.type == "failure" and f.onset_s == 0.0 for f in v.faults)


def test_seed002_sets_are_valid_scenarios_on_the_song_bus():
    s = scenario_library.get("song-table1")
    sets = faults.seed002_fault_sets()
    assert {"wheel 3 stuck", "wheels 1,2,3", "noise 50 sigma", "controller intermittent 7-8 s"} <= set(sets)
    variants = [VariantSpec(name=n, faults=f) for n, f in sets.items()]
    Scenario.model_validate({**s.model_dump(), "variants": [v.model_dump() for v in variants]})


def test_seed000_two_wheels_leaves_wheels_2_and_4():
    fs, mask = faults.seed000_two_wheels()
    assert list(mask) == [False, True, False, True]
    assert sorted(f.index for f in fs) == [0, 2]


def test_random_failures_are_reproducible_and_in_range():
    a = faults.random_wheel_failures(50, (10.0, 20.0), seed=3)
    b = faults.random_wheel_failures(50, (10.0, 20.0), seed=3)
    assert [v.name for v in a] == [v.name for v in b]
    assert all(10.0 <= v.faults[0].onset_s < 20.0 and 0 <= v.faults[0].index < 4 for v in a)


@pytest.mark.parametrize(
    ("field", "spec"),
    [
        ("gain", {"target": "wheel", "type": "gain", "gain": 2.5}),
        ("onset_s", {"target": "wheel", "type": "failure", "onset_s": -1.0}),
        ("target", {"target": "reaction_wheel", "type": "failure"}),
        ("type", {"target": "wheel", "type": "explode"}),
    ],
)
def test_bad_fault_names_the_field(field, spec):
    with pytest.raises(ValueError, match=field):
        FaultSpec(**spec)


def test_bad_catalogue_arguments_name_the_field():
    with pytest.raises(ValueError, match="n_wheels"):
        faults.wheel_configurations(2)
    with pytest.raises(ValueError, match="onset_range_s"):
        faults.random_wheel_failures(3, (5.0, 1.0))


def _quiet(variants: list[VariantSpec], duration_s: float = 60.0) -> Scenario:
    """somov-ge4-scan, no gravity gradient, truth navigation: nothing external acts on the body."""
    s = scenario_library.get("somov-ge4-scan")
    data = s.model_dump()
    data.update(duration_s=duration_s, gravity_gradient=False, variants=[v.model_dump() for v in variants])
    data["estimator"]["kind"] = "truth"
    data["spacecraft"]["md_max_dipole_am2"] = 0.0
    for w, rpm in zip(data["spacecraft"]["cluster"]["wheels"], (800.0, -600.0, 400.0, -200.0)):
        w["initial_speed_rpm"] = rpm
    return Scenario.model_validate(data)


def _h_inertial(traj, s: Scenario, v: int) -> np.ndarray:
    p = engine.plant_params(s)
    wheels = (traj["wheel_speed_rad_s"][v] * p.wheels.inertia_kg_m2) @ p.wheel_axes_b.T
    h_body = traj["omega_b_rad_s"][v] @ p.inertia_kg_m2.T + wheels
    return quaternion.rotate(traj["q_ib"][v], h_body)


def test_dead_motor_keeps_its_momentum_and_a_seized_wheel_hands_it_to_the_body():
    onset = 20.0
    s = _quiet(
        [
            VariantSpec(name="dead", faults=[faults.wheel_failure(0, onset)]),
            VariantSpec(name="seized", faults=[faults.wheel_failure(0, onset, "stuck")]),
        ]
    )
    traj = engine.simulate(s)
    after = traj.t_s > onset + s.output_dt_s
    p = engine.plant_params(s)
    axial = traj["omega_b_rad_s"][0, after] @ p.wheel_axes_b[:, 0]
    spin = p.wheels.inertia_kg_m2[0] * (traj["wheel_speed_rad_s"][0, after, 0] + axial)
    assert np.ptp(spin) <= MOMENTUM_CONSERVED * abs(spin[0])  # no friction on this bus: d/dt J(Ω + aᵗω) = 0
    assert np.all(traj["wheel_torque_nm"][0, after, 0] == 0.0)
    assert np.all(traj["wheel_speed_rad_s"][1, after, 0] == 0.0)
    h = _h_inertial(traj, s, 1)
    assert np.max(np.linalg.norm(h - h[0], axis=1)) <= MOMENTUM_CONSERVED * np.linalg.norm(h[0])


def test_gain_fault_scales_the_delivered_torque():
    gain = 0.3
    s = _quiet([VariantSpec(name="gain", faults=[faults.wheel_failure(1, 10.0, "gain", gain=gain)])])
    traj = engine.simulate(s)
    between = np.abs(np.remainder(traj.t_s, s.control_dt_s)) > 1e-9  # delivered is recorded one step late
    after = (traj.t_s >= 10.0 + s.output_dt_s) & between
    cmd, delivered = traj["wheel_torque_cmd_nm"][0, after, 1], traj["wheel_torque_nm"][0, after, 1]
    assert np.max(np.abs(delivered - gain * cmd)) <= EXACT_TORQUE


def test_intermittent_controller_fault_silences_only_its_window():
    s = scenario_library.get("song-table1")
    fs = faults.seed002_fault_sets()["controller intermittent 7-8 s"]
    variant = {"name": "x", "faults": [f.model_dump() for f in fs]}
    s = Scenario.model_validate({**s.model_dump(), "duration_s": 12.0, "variants": [variant]})
    traj = engine.simulate(s)
    torque = np.linalg.norm(traj["control_torque_b_nm"][0], axis=1)
    inside = (traj.t_s >= 7.0 + s.control_dt_s) & (traj.t_s < 8.0)
    outside = (traj.t_s > 1.0) & (traj.t_s < 7.0)
    assert np.all(torque[inside] == 0.0) and np.all(torque[outside] > 0.0)
