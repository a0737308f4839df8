"""The peer scenario ``peer-basilisk-rw4`` built in Basilisk (``bsk`` from PyPI), for benchmarks.

DESIGN.md "Learned facts": one orbit (5,801 s, circular 600 km) of a rigid 300 kg spacecraft with hub
inertia diag(35, 30, 25) kg·m², 4 × Honeywell HR12 wheels (0.2 N·m, 6,000 rpm, J_s = 0.0191 kg·m²,
12 N·m·s) with spin axes 30° from body x spread 0/90/180/270° about it, start speeds
(+1000, −1000, +1000, −1000) rpm, RK4 dynamics at 0.1 s, MRP feedback + minimum-norm wheel mapping
at 0.5 s, point-mass gravity with gravity-gradient torque; the inertial reference is a 20° roll
(about x) from t = 0, then a further 20° pitch (about y) from t = 1000 s. A failed wheel gets a huge
``u_min`` (its torque is clipped to zero) and is marked unavailable to the controller.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

ORBIT_ALTITUDE_M = 600e3
ORBIT_INCLINATION_DEG = 97.8
DURATION_S = 5801.0
DYNAMICS_DT_S = 0.1
CONTROL_DT_S = 0.5
HUB_INERTIA_KGM2 = (35.0, 30.0, 25.0)
HUB_MASS_KG = 300.0 - 4 * 6.0  # HR12 rotor mass 6 kg each (Basilisk rwFactory)
WHEEL_CANT_DEG = 30.0
WHEEL_CLOCK_DEG = (0.0, 90.0, 180.0, 270.0)
WHEEL_START_RPM = (1000.0, -1000.0, 1000.0, -1000.0)
WHEEL_MAX_MOMENTUM_NMS = 12.0
MRP_K = 2.7  # N·m: ω_n = sqrt(K / 4I) ≈ 0.15 rad/s on the 30 kg·m² axis
MRP_P = 9.0  # N·m·s: ζ ≈ 1 on the same axis
FIRST_REFERENCE = ((1.0, 0.0, 0.0), 20.0)  # axis, angle_deg: a 20° roll from t = 0
SECOND_REFERENCE = ((0.0, 1.0, 0.0), 20.0)  # then a further 20° pitch
SECOND_SLEW_TIME_S = 1000.0


def wheel_axes_b() -> np.ndarray:
    """Spin axes (4, 3) in body axes: 30° from +x, clocked 0/90/180/270° about it."""
    cant = np.radians(WHEEL_CANT_DEG)
    clock = np.radians(WHEEL_CLOCK_DEG)
    return np.stack([np.full(4, np.cos(cant)), np.sin(cant) * np.cos(clock), np.sin(cant) * np.sin(clock)], axis=1)


def reference_mrps() -> tuple[np.ndarray, np.ndarray]:
    """MRP σ_RN of the first and the second inertial reference (second = first ∘ 20° pitch)."""
    from scipy.spatial.transform import Rotation

    first = Rotation.from_rotvec(np.radians(FIRST_REFERENCE[1]) * np.array(FIRST_REFERENCE[0]))
    second = first * Rotation.from_rotvec(np.radians(SECOND_REFERENCE[1]) * np.array(SECOND_REFERENCE[0]))
    return first.as_mrp(), second.as_mrp()


@dataclass
class PeerRun:
    """What one Basilisk run returns: timing (wall and CPU) and the attitude-error history at the control rate."""

    wall_time_s: float
    cpu_time_s: float
    t_s: np.ndarray
    sigma_br: np.ndarray
    omega_rw_rad_s: np.ndarray


@dataclass
class PeerSim:
    """The peer scenario assembled in Basilisk, ready to fly: the simulation and the modules a caller records."""

    sim: Any
    nav: Any
    ref: Any
    err: Any
    mapping: Any
    wheels: Any
    rotor_inertia_kg_m2: float
    messages: tuple[Any, ...]  # stand-alone messages the modules read: kept alive with the simulation

    def fly(self, duration_s: float) -> None:
        """Fly the reference profile after ``sim.InitializeSimulation()``: the first reference, then the second
        from SECOND_SLEW_TIME_S."""
        from Basilisk.utilities import macros

        switch = min(SECOND_SLEW_TIME_S, duration_s)
        # Stop just before the switch so that the FSW tick at t = switch already sees the new reference.
        self.sim.ConfigureStopTime(macros.sec2nano(switch - 0.5 * DYNAMICS_DT_S))
        self.sim.ExecuteSimulation()
        if duration_s > switch:
            self.ref.sigma_R0N = list(reference_mrps()[1])
            self.sim.ConfigureStopTime(macros.sec2nano(duration_s))
            self.sim.ExecuteSimulation()


def build(
    failed_wheels: tuple[int, ...] | None = (),
    wheel_torque_limit: bool = True,
    command_filter: Callable[[float], Any] | None = None,
) -> PeerSim:
    """Assemble the peer case (module docstring) in Basilisk.

    ``failed_wheels``: wheels the flight software is told are unavailable (None: no availability message at
    all); ``command_filter(J_s)``: a module placed between the torque mapping and the wheel effector (inputs
    ``cmdInMsg``, ``speedInMsg``, output ``torqueOutMsg``), e.g. a fault the flight software is never told of;
    ``wheel_torque_limit``: the effector clips the torque at the wheel's rating (off when a filter must act).
    """
    from Basilisk.architecture import messaging
    from Basilisk.fswAlgorithms import attTrackingError, inertial3D, mrpFeedback, rwMotorTorque
    from Basilisk.simulation import GravityGradientEffector, reactionWheelStateEffector, simpleNav, spacecraft
    from Basilisk.utilities import (
        SimulationBaseClass,
        macros,
        orbitalMotion,
        simIncludeGravBody,
        simIncludeRW,
    )

    sim = SimulationBaseClass.SimBaseClass()
    dyn = sim.CreateNewProcess("dyn")
    dyn.addTask(sim.CreateNewTask("dynTask", macros.sec2nano(DYNAMICS_DT_S)))
    fsw = sim.CreateNewProcess("fsw")
    fsw.addTask(sim.CreateNewTask("fswTask", macros.sec2nano(CONTROL_DT_S)))

    sc = spacecraft.Spacecraft()
    sc.ModelTag = "peer"
    inertia = np.diag(HUB_INERTIA_KGM2)
    sc.hub.mHub = HUB_MASS_KG
    sc.hub.IHubPntBc_B = inertia.tolist()
    sim.AddModelToTask("dynTask", sc, None, 1)

    grav = simIncludeGravBody.gravBodyFactory()
    earth = grav.createEarth()
    earth.isCentralBody = True
    sc.gravField.gravBodies = spacecraft.GravBodyVector(list(grav.gravBodies.values()))

    gg = GravityGradientEffector.GravityGradientEffector()
    gg.ModelTag = "gravityGradient"
    gg.addPlanetName(earth.planetName)
    sc.addDynamicEffector(gg)
    sim.AddModelToTask("dynTask", gg)

    factory = simIncludeRW.rwFactory()
    limit = {} if wheel_torque_limit else {"useMaxTorque": False}
    for axis, rpm in zip(wheel_axes_b(), WHEEL_START_RPM):
        factory.create("Honeywell_HR12", list(axis), maxMomentum=WHEEL_MAX_MOMENTUM_NMS, Omega=rpm, **limit)
    for index in failed_wheels or ():
        list(factory.rwList.values())[index].u_min = 1e9
    rw_effector = reactionWheelStateEffector.ReactionWheelStateEffector()
    factory.addToSpacecraft("wheels", rw_effector, sc)
    sim.AddModelToTask("dynTask", rw_effector, None, 2)
    js = float(next(iter(factory.rwList.values())).Js)
    between = None
    if command_filter is not None:
        between = command_filter(js)
        between.ModelTag = "commandFilter"
        sim.AddModelToTask("dynTask", between, None, 3)

    nav = simpleNav.SimpleNav()
    nav.ModelTag = "nav"
    sim.AddModelToTask("dynTask", nav)

    ref = inertial3D.inertial3D()
    ref.ModelTag = "reference"
    ref.sigma_R0N = list(reference_mrps()[0])
    sim.AddModelToTask("fswTask", ref)
    err = attTrackingError.attTrackingError()
    err.ModelTag = "attitudeError"
    sim.AddModelToTask("fswTask", err)
    ctrl = mrpFeedback.mrpFeedback()
    ctrl.ModelTag = "mrpFeedback"
    ctrl.K, ctrl.P, ctrl.Ki = MRP_K, MRP_P, -1.0
    ctrl.integralLimit = 0.0
    sim.AddModelToTask("fswTask", ctrl)
    mapping = rwMotorTorque.rwMotorTorque()
    mapping.ModelTag = "rwMotorTorque"
    mapping.controlAxes_B = [1, 0, 0, 0, 1, 0, 0, 0, 1]
    sim.AddModelToTask("fswTask", mapping)

    veh = messaging.VehicleConfigMsgPayload()
    veh.ISCPntB_B = inertia.flatten().tolist()
    veh_msg = messaging.VehicleConfigMsg().write(veh)
    rw_params = factory.getConfigMessage()

    oe = orbitalMotion.ClassicElements()
    oe.a = earth.radEquator + ORBIT_ALTITUDE_M  # radEquator is in metres
    oe.e = 0.0
    oe.i = np.radians(ORBIT_INCLINATION_DEG)
    oe.Omega = oe.omega = oe.f = 0.0
    r_n, v_n = orbitalMotion.elem2rv(earth.mu, oe)
    sc.hub.r_CN_NInit = r_n
    sc.hub.v_CN_NInit = v_n
    sc.hub.sigma_BNInit = [[0.0], [0.0], [0.0]]
    sc.hub.omega_BN_BInit = [[0.0], [0.0], [0.0]]

    nav.scStateInMsg.subscribeTo(sc.scStateOutMsg)
    err.attNavInMsg.subscribeTo(nav.attOutMsg)
    err.attRefInMsg.subscribeTo(ref.attRefOutMsg)
    ctrl.guidInMsg.subscribeTo(err.attGuidOutMsg)
    ctrl.vehConfigInMsg.subscribeTo(veh_msg)
    ctrl.rwParamsInMsg.subscribeTo(rw_params)
    ctrl.rwSpeedsInMsg.subscribeTo(rw_effector.rwSpeedOutMsg)
    mapping.rwParamsInMsg.subscribeTo(rw_params)
    mapping.vehControlInMsg.subscribeTo(ctrl.cmdTorqueOutMsg)
    if failed_wheels is not None:
        avail = messaging.RWAvailabilityMsgPayload()
        avail.wheelAvailability = [
            messaging.UNAVAILABLE if i in failed_wheels else messaging.AVAILABLE for i in range(4)
        ]
        avail_msg = messaging.RWAvailabilityMsg().write(avail)
        ctrl.rwAvailInMsg.subscribeTo(avail_msg)
        mapping.rwAvailInMsg.subscribeTo(avail_msg)
    if between is None:
        rw_effector.rwMotorCmdInMsg.subscribeTo(mapping.rwMotorTorqueOutMsg)
    else:
        between.cmdInMsg.subscribeTo(mapping.rwMotorTorqueOutMsg)
        between.speedInMsg.subscribeTo(rw_effector.rwSpeedOutMsg)
        rw_effector.rwMotorCmdInMsg.subscribeTo(between.torqueOutMsg)
    messages = (veh_msg, rw_params) + ((avail_msg,) if failed_wheels is not None else ())
    return PeerSim(sim, nav, ref, err, mapping, rw_effector, js, messages)


def run(duration_s: float = DURATION_S, failed_wheels: tuple[int, ...] = (), record: bool = True) -> PeerRun:
    """Build and run the peer scenario in Basilisk; wall and CPU time cover ExecuteSimulation only."""
    from Basilisk.utilities import macros

    peer = build(failed_wheels)
    err_log = speed_log = None
    if record:
        err_log = peer.err.attGuidOutMsg.recorder(macros.sec2nano(CONTROL_DT_S))
        speed_log = peer.wheels.rwSpeedOutMsg.recorder(macros.sec2nano(CONTROL_DT_S))
        peer.sim.AddModelToTask("fswTask", err_log)
        peer.sim.AddModelToTask("fswTask", speed_log)
    peer.sim.InitializeSimulation()
    start, start_cpu = time.perf_counter(), time.process_time()
    peer.fly(duration_s)
    wall, cpu = time.perf_counter() - start, time.process_time() - start_cpu
    if not record:
        return PeerRun(wall, cpu, np.empty(0), np.empty((0, 3)), np.empty((0, 4)))
    return PeerRun(
        wall_time_s=wall,
        cpu_time_s=cpu,
        t_s=err_log.times() * 1e-9,
        sigma_br=np.array(err_log.sigma_BR),
        omega_rw_rad_s=np.array(speed_log.wheelSpeeds)[:, :4],
    )
