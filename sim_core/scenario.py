"""The ``Scenario`` schema: everything one simulation (or one batch of fault variants) needs.

Seed 000 §7: the twin runs "with the same values of parameters, initial conditions and variants of
possible faults" as the spacecraft, so every parameter of the plant, sensors, estimator, guidance,
controller, allocation and faults is a field here, validated at the edge (``ValueError`` /
pydantic ``ValidationError`` naming the field). Units are in the field names.
"""

from __future__ import annotations

import math
from typing import Annotated, Any, Literal

from pydantic import BaseModel, ConfigDict, Field, ValidationInfo, field_validator, model_validator

__all__ = [
    "WheelSpec",
    "ClusterSpec",
    "MotorSpec",
    "SurfaceSpec",
    "FlexModeSpec",
    "SpacecraftSpec",
    "OrbitSpec",
    "SensorsSpec",
    "EstimatorSpec",
    "RouteSegmentSpec",
    "GuidanceSpec",
    "ControllerSpec",
    "AllocationSpec",
    "FaultSpec",
    "TruthSpec",
    "VariantSpec",
    "Scenario",
    "apply_overrides",
    "shifted_guidance",
]

Finite = Annotated[float, Field(allow_inf_nan=False)]
NonNegative = Annotated[float, Field(ge=0.0, allow_inf_nan=False)]
Positive = Annotated[float, Field(gt=0.0, allow_inf_nan=False)]
Vector3 = Annotated[list[Finite], Field(min_length=3, max_length=3)]
Quaternion = Annotated[list[Finite], Field(min_length=4, max_length=4)]


class _Spec(BaseModel):
    model_config = ConfigDict(extra="forbid", validate_assignment=True)


class WheelSpec(_Spec):
    """One reaction wheel (seed 000 eq 1–2, seed 002 eq 1–4)."""

    inertia_kg_m2: Positive = 0.0191
    max_torque_nm: Positive = 0.2
    max_momentum_nms: Positive = 12.0
    torque_quantum_nm: NonNegative = 0.0
    coulomb_nm: NonNegative = 0.0
    coulomb_sat_speed_rad_s: NonNegative = 0.0
    viscous_nm_s: NonNegative = 0.0
    aero_drag_nm_s15: NonNegative = 0.0  # seed 002 eq 4 M_a = K_a Ω √|Ω|
    noise_nm: NonNegative = 0.0  # seed 002 eq 4 M_x = K_x W/|W_max|, W uniform white
    imbalance_nm_s2: NonNegative = 0.0  # seed 002 eq 4 M_d = K_d Ω² sin(Ω t)
    initial_speed_rpm: Finite = 0.0


class MotorSpec(_Spec):
    """Armature of the wheel motors (seed 002 eq 2–3) behind a voltage-limited driver: L di/dt + R i + K_e Ω = u,
    M = K_m i, with u = R M_c/K_m + K_e Ω (current feed-forward) clipped to ±max_voltage_v."""

    inductance_h: Positive = 1e-3
    resistance_ohm: Positive = 1.0
    torque_constant_nm_a: Positive = 0.053  # seed 002 Table 1 K_m
    back_emf_v_s: Positive = 0.053  # = K_m in SI for an ideal DC motor
    max_voltage_v: Positive = 28.0


class ClusterSpec(_Spec):
    """Wheel geometry: seed 000's GE scheme (angle γ), three orthogonal, 3+1 skew, or explicit axes."""

    geometry: Literal["ge", "orthogonal3", "skew4", "custom"] = "ge"
    gamma_deg: Annotated[float, Field(gt=0.0, lt=45.0)] = 30.0  # GE half-angle; < 45° keeps eq (6) real
    axes_b: list[Vector3] | None = None
    wheels: list[WheelSpec] = Field(default_factory=lambda: [WheelSpec() for _ in range(4)])
    motor: MotorSpec | None = None  # None: the motors deliver the commanded torque (no electrics)

    @model_validator(mode="after")
    def _axes_match_wheels(self) -> ClusterSpec:
        expected = {"ge": 4, "orthogonal3": 3, "skew4": 4}.get(self.geometry)
        if self.geometry == "custom":
            if not self.axes_b:
                raise ValueError("spacecraft.cluster.axes_b: required when geometry is 'custom'")
            expected = len(self.axes_b)
            if any(math.fsum(c * c for c in a) == 0.0 for a in self.axes_b):
                raise ValueError("spacecraft.cluster.axes_b: a zero vector has no direction")
        if len(self.wheels) != expected:
            raise ValueError(
                f"spacecraft.cluster.wheels: geometry {self.geometry!r} needs {expected} wheels, got {len(self.wheels)}"
            )
        return self


class FlexModeSpec(_Spec):
    """One flexible mode of seed 000 eq (1): coupling D_q column, modal mass a^q, Ω^q, δ^q."""

    coupling_b: Vector3
    modal_mass: Positive = 1.0
    freq_hz: Positive = 1.0
    log_decrement: NonNegative = 0.02


class SurfaceSpec(_Spec):
    """One flat outer plate for aerodynamic and solar-pressure torques (normal, area, centroid from the CoM,
    specular and diffuse reflectivity)."""

    normal_b: Vector3
    area_m2: Positive
    centroid_b_m: Vector3
    specular: Annotated[float, Field(ge=0.0, le=1.0)] = 0.1
    diffuse: Annotated[float, Field(ge=0.0, le=1.0)] = 0.2

    @model_validator(mode="after")
    def _unit_normal(self) -> SurfaceSpec:
        if abs(math.sqrt(math.fsum(c * c for c in self.normal_b)) - 1.0) > 1e-6:
            raise ValueError("spacecraft.surfaces.normal_b: must be a unit vector")
        if self.specular + self.diffuse > 1.0:
            raise ValueError("spacecraft.surfaces: specular + diffuse must not exceed 1")
        return self


class SpacecraftSpec(_Spec):
    """Mass properties, wheels, flexible modes and the magnetic driver of the spacecraft."""

    inertia_kg_m2: Annotated[list[Vector3], Field(min_length=3, max_length=3)] = Field(
        default_factory=lambda: [[35.0, 0.0, 0.0], [0.0, 30.0, 0.0], [0.0, 0.0, 25.0]]
    )
    inertia_includes_wheels: bool = True
    cluster: ClusterSpec = Field(default_factory=ClusterSpec)
    flex_modes: list[FlexModeSpec] = Field(default_factory=list)
    md_max_dipole_am2: NonNegative = 25.0
    residual_dipole_am2: Vector3 = Field(default_factory=lambda: [0.0, 0.0, 0.0])
    surfaces: list[SurfaceSpec] = Field(default_factory=list)  # outer plates (aero and SRP torques)
    drag_coefficient: Positive = 2.2  # free-molecular flat plate


class OrbitSpec(_Spec):
    """Orbit: circular elements, full Keplerian elements with J2, or a TLE through SGP4."""

    kind: Literal["circular", "j2", "tle"] = "circular"
    epoch_utc: str = "2026-03-20T00:00:00Z"
    altitude_m: Positive = 600e3
    inclination_deg: Annotated[float, Field(ge=0.0, le=180.0)] | None = None  # None: Sun-synchronous
    raan_deg: Finite = 0.0
    arg_latitude_deg: Finite = 0.0
    tle_line1: str | None = None
    tle_line2: str | None = None

    @model_validator(mode="after")
    def _tle_given(self) -> OrbitSpec:
        if self.kind == "tle" and not (self.tle_line1 and self.tle_line2):
            raise ValueError("orbit.tle_line1/tle_line2: both lines are required when kind is 'tle'")
        return self


class SensorsSpec(_Spec):
    """Sensor noise and periods (seed 000 §4, seed 002 eq 13–14, seed 003 §3.2.3.1)."""

    star_tracker_sigma_arcsec: NonNegative = 3.0
    gyro_drift_density_rad_s_sqrt_s: NonNegative = 1e-9  # bias random walk the MEKF assumes (σ_u)
    gyro_noise_rad_s: NonNegative = 1e-6
    gyro_bias_rad_s: Vector3 = Field(default_factory=lambda: [0.0, 0.0, 0.0])
    gyro_markov_sigma_rad_s: NonNegative = 0.0
    gyro_markov_tau_s: Positive = 300.0
    sun_sensor_sigma_rad: NonNegative = 0.0087  # coarse Sun sensor, 0.5° (seed 003 SS)
    magnetometer_noise_t: NonNegative = 50e-9
    tachometer_quantum_rad_s: NonNegative = 0.0
    star_tracker_boresight_b: Vector3 = Field(default_factory=lambda: [-1.0, 0.0, 0.0])  # zenith at nadir pointing
    star_tracker_sun_exclusion_deg: Annotated[float, Field(ge=0.0, lt=90.0)] = 0.0  # 0: never blinded
    star_tracker_max_rate_rad_s: Positive | None = None  # None: valid at any rate
    earth_sensor_sigma_rad: NonNegative = math.radians(0.05)  # seed 002 eq 14 φ_n, θ_n (static infrared class)
    earth_sensor_bias_rad: Annotated[list[Finite], Field(min_length=2, max_length=2)] = Field(
        default_factory=lambda: [0.0, 0.0]
    )  # seed 002 eq 14 constant deviations (φ_b, θ_b)


class EstimatorSpec(_Spec):
    """Attitude determination feeding the control law: the true state, the raw star tracker + gyro, the MEKF,
    seed 000 §4's mismatch filter (gyro + star tracker), seed 003's gyro-less body-rate estimator (eqs 15–19) or
    seed 003's TRIAD of the Sun sensor, earth sensor and magnetometer with gyro rates (§3.2.1.2.1), or seed 002's
    gyro + earth-sensor observer of roll, pitch and yaw about the orbit frame (eq 15; Earth-pointing flights only)."""

    kind: Literal["truth", "star_tracker", "mekf", "seed000_filter", "seed003_rate", "triad", "earth_observer"] = (
        "truth"
    )
    disturbance_density_rad2_s3: Positive = 1e-9  # q of the per-axis filters (white angular acceleration)
    observer_gains_1_s: Annotated[list[Positive], Field(min_length=3, max_length=3)] = Field(
        default_factory=lambda: [0.012, 0.01, 0.008]
    )  # seed 002 eq 15 K_φ, K_θ, K_ψ (its Table 1 K_x, K_y, K_z)
    observer_initial_rad: Vector3 | None = None  # (φ̂, θ̂, ψ̂) at t = 0; None: first earth-sensor sample, ψ̂ = 0


class RouteSegmentSpec(_Spec):
    """One segment of a trace-scanning route: hold an ORF attitude, or a seed 001 turn to the next hold."""

    kind: Literal["hold", "turn"] = "hold"
    duration_s: Positive
    yaw_deg: Finite = 0.0
    roll_deg: Finite = 0.0
    pitch_deg: Finite = 0.0
    observing: bool = False


class GuidanceSpec(_Spec):
    """Programmed motion Λ^p(t): inertial hold with timed steps, ORF hold, or a scanning route."""

    kind: Literal["inertial", "orf", "route"] = "orf"
    inertial_steps: list[tuple[NonNegative, Quaternion]] = Field(default_factory=list)
    route_start_s: NonNegative = 0.0
    route: list[RouteSegmentSpec] = Field(default_factory=list)

    @model_validator(mode="after")
    def _has_program(self) -> GuidanceSpec:
        if self.kind == "inertial" and not self.inertial_steps:
            raise ValueError("guidance.inertial_steps: at least one (time_s, q_ib) step is required")
        if self.kind == "route":
            if not self.route:
                raise ValueError("guidance.route: at least one segment is required")
            kinds = [s.kind for s in self.route]
            if kinds[0] == "turn" or kinds[-1] == "turn" or any(a == b == "turn" for a, b in zip(kinds, kinds[1:])):
                raise ValueError("guidance.route: a turn must sit between two hold segments")
        for q_step in self.inertial_steps:
            if abs(math.sqrt(math.fsum(c * c for c in q_step[1])) - 1.0) > 1e-6:
                raise ValueError("guidance.inertial_steps: every quaternion must be unit")
        return self


class ControllerSpec(_Spec):
    """Control law: seed 000 digital law (7)–(8), MRP feedback (peer), or quaternion PD (seed 002)."""

    kind: Literal["seed000", "mrp_feedback", "quaternion_pd"] = "seed000"
    gain_k_per_s2: Positive = 0.01  # control.DigitalLawGains: crossover ≈ 0.2 rad/s at T_u = 2 s, 13 dB / 50°
    tau1_s: Positive = 20.0
    tau2_s: Positive = 1.25
    gyroscopic_compensation: bool = False  # add ω × (Jω + A h) to eq (7), which prints no such term
    mrp_k_nm: Positive = 2.7
    mrp_p_nms: Positive = 9.0
    pd_kp_nm: Positive = 1.0
    pd_kd_nms: Positive = 10.0


class AllocationSpec(_Spec):
    """Wheel torque distribution: seed 000 eq (6) explicit law, or the minimum-norm pseudo-inverse; with two
    wheels left, the magnetic driver by seed 000 §3's e^m = b × e_pq where |κ| ≤ 1/2 (``md_law="seed"``) or by
    the least dipole across the pair plane (``"least_dipole"``, sim_core.allocation.MD_LAW_PAIR_NORMAL)."""

    kind: Literal["ge_explicit", "pseudo_inverse"] = "ge_explicit"
    md_law: Literal["seed", "least_dipole"] = "seed"
    rho: Annotated[float, Field(gt=0.0, lt=1.0)] = 0.5
    mu_rho_per_s: Positive = 0.05
    phi_rho_per_s: Positive = 0.002


FAULT_TARGETS = (
    "wheel",
    "gyro",
    "star_tracker",
    "earth_sensor",
    "magnetometer",
    "sun_sensor",
    "controller",
    "md_rod",
    "tachometer",
)
TACHOMETER_FAULT_TYPES = ("bias", "gain", "drift")  # sim_core.faults.tachometer_faults_1
FAULT_TYPES = (
    "failure",
    "stuck",
    "gain",
    "bias",
    "drift",
    "intermittent",
    "noise",
    "friction",
    "frozen",
)


class TruthSpec(_Spec):
    """Where the flown spacecraft differs from the model its onboard software (and the twin) holds:
    the plant flies these, the control law, allocation and FDIR keep the spacecraft's nominal values."""

    inertia_kg_m2: Annotated[list[Vector3], Field(min_length=3, max_length=3)] | None = None
    wheel_axes_b: list[Vector3] | None = None  # one per wheel, as mounted


class FaultSpec(_Spec):
    """One injected fault: target (and index), type, onset, duration and parameters."""

    target: Literal[FAULT_TARGETS]  # type: ignore[valid-type]
    index: Annotated[int, Field(ge=0)] = 0
    type: Literal[FAULT_TYPES]  # type: ignore[valid-type]
    onset_s: NonNegative = 0.0
    duration_s: Positive | None = None
    gain: Annotated[float, Field(ge=0.0, le=2.0)] = 1.0
    value: Finite = 0.0
    period_s: Positive | None = None
    duty: Annotated[float, Field(gt=0.0, le=1.0)] = 0.5

    @model_validator(mode="after")
    def _tachometer_types(self) -> FaultSpec:
        if self.target == "tachometer" and self.type not in TACHOMETER_FAULT_TYPES:
            raise ValueError(f"type: a tachometer fault is one of {', '.join(TACHOMETER_FAULT_TYPES)}")
        return self


class VariantSpec(_Spec):
    """One batch variant: a name, its fault set and its random-seed offset."""

    name: str
    faults: list[FaultSpec] = Field(default_factory=list)
    seed_offset: Annotated[int, Field(ge=0)] = 0


class Scenario(_Spec):
    """A complete simulation case; ``variants`` run as one batch (default: one nominal variant)."""

    name: str = "custom"
    description: str = ""
    spacecraft: SpacecraftSpec = Field(default_factory=SpacecraftSpec)
    orbit: OrbitSpec = Field(default_factory=OrbitSpec)
    initial_q_ib: Quaternion | None = None  # None: aligned with the program at t = 0 (turned by initial_q_pb)
    initial_q_pb: Quaternion | None = None  # start relative to the program, Λ(0) = Λ^p(0) ∘ Λ_pb (initial_q_ib None)
    initial_omega_b_rad_s: Vector3 | None = None
    sensors: SensorsSpec = Field(default_factory=SensorsSpec)
    estimator: EstimatorSpec = Field(default_factory=EstimatorSpec)
    guidance: GuidanceSpec = Field(default_factory=GuidanceSpec)
    controller: ControllerSpec = Field(default_factory=ControllerSpec)
    allocation: AllocationSpec = Field(default_factory=AllocationSpec)
    gravity_gradient: bool = True
    aerodynamic_torque: bool = False  # on spacecraft.surfaces (environment.aerodynamic_torque_1)
    solar_pressure_torque: bool = False  # on spacecraft.surfaces (environment.solar_pressure_torque_1)
    initial_mode: Literal["rate_damping", "sun_safe", "orf", "route"] | None = None  # None: no mode machine
    fdir: bool = False  # onboard wheel and sensor FDIR (sim_core.fdir); off flies the faults unmitigated
    magnetic_model: Literal["igrf", "dipole"] = "igrf"
    duration_s: Positive = 5801.0
    dynamics_dt_s: Positive = 0.05
    measurement_dt_s: Positive = 0.25
    control_dt_s: Positive = 2.0
    output_dt_s: Positive = 1.0
    seed: Annotated[int, Field(ge=0)] = 0
    variants: list[VariantSpec] = Field(default_factory=lambda: [VariantSpec(name="nominal")])
    truth: TruthSpec | None = None  # None: the flown spacecraft is the modelled one

    @model_validator(mode="after")
    def _truth_matches(self) -> Scenario:
        t = self.truth
        if t is not None and t.wheel_axes_b is not None:
            n = len(self.spacecraft.cluster.wheels)
            if len(t.wheel_axes_b) != n or any(math.fsum(c * c for c in a) == 0.0 for a in t.wheel_axes_b):
                raise ValueError(f"truth.wheel_axes_b: expected {n} non-zero axes (one per wheel)")
        if t is not None and t.inertia_kg_m2 is not None:
            j = t.inertia_kg_m2
            if any(abs(j[i][k] - j[k][i]) > 1e-9 * abs(j[i][i]) for i in range(3) for k in range(3)):
                raise ValueError("truth.inertia_kg_m2: not symmetric")
        return self

    @field_validator("initial_q_ib", "initial_q_pb")
    @classmethod
    def _unit(cls, q: list[float] | None, info: ValidationInfo) -> list[float] | None:
        if q is not None and abs(math.sqrt(math.fsum(c * c for c in q)) - 1.0) > 1e-6:
            raise ValueError(f"{info.field_name}: not a unit quaternion")
        return q

    @model_validator(mode="after")
    def _rates_nest(self) -> Scenario:
        for name in ("measurement_dt_s", "control_dt_s", "output_dt_s"):
            ratio = getattr(self, name) / self.dynamics_dt_s
            if not math.isfinite(ratio) or abs(ratio - round(ratio)) > 1e-9 or round(ratio) < 1:  # denormal dt: inf
                raise ValueError(f"{name}: must be a whole multiple of dynamics_dt_s ({self.dynamics_dt_s} s)")
        if not self.variants:
            raise ValueError("variants: at least one variant is required")
        n_wheels = len(self.spacecraft.cluster.wheels)
        for v in self.variants:
            for f in v.faults:
                if f.target in ("wheel", "tachometer") and f.index >= n_wheels:
                    raise ValueError(
                        f"variants[{v.name}].faults.index: wheel {f.index} does not exist (n = {n_wheels})"
                    )
        return self


def apply_overrides(scenario: Scenario, assignments: list[str]) -> Scenario:
    """Return a copy with ``path.to.field=value`` assignments applied (values parsed as JSON, else text)."""
    import json

    data: dict[str, Any] = scenario.model_dump()
    for item in assignments:
        path, sep, raw = item.partition("=")
        if not sep or not path:
            raise ValueError(f"--set {item!r}: expected path.to.field=value")
        try:
            value = json.loads(raw)
        except json.JSONDecodeError:
            value = raw
        node: Any = data
        keys = path.split(".")
        for depth, key in enumerate(keys):
            last = depth == len(keys) - 1
            if isinstance(node, list):
                if not key.isdigit() or int(key) >= len(node):
                    raise ValueError(
                        f"--set {path}: {'.'.join(keys[: depth + 1])} is not an index of a list of {len(node)}"
                    )
                key = int(key)  # type: ignore[assignment]
            elif not isinstance(node, dict) or key not in node:
                raise ValueError(f"--set {path}: unknown field {'.'.join(keys[: depth + 1])!r}")
            if last:
                node[key] = value
            else:
                node = node[key]
    return Scenario.model_validate(data)


def shifted_guidance(guidance: dict[str, Any], elapsed_s: float) -> dict[str, Any]:
    """The guidance programme as seen from elapsed_s after its epoch (seed 001 route segments trimmed)."""
    g = dict(guidance)
    if g["kind"] == "inertial":
        steps = sorted(g["inertial_steps"], key=lambda step: step[0])
        current = [q for t, q in steps if t <= elapsed_s][-1:] or [steps[0][1]]
        g["inertial_steps"] = [(0.0, current[0])] + [(t - elapsed_s, q) for t, q in steps if t > elapsed_s]
        return g
    if g["kind"] != "route" or g["route_start_s"] >= elapsed_s:
        g["route_start_s"] = max(g["route_start_s"] - elapsed_s, 0.0) if g["kind"] == "route" else 0.0
        return g
    into = elapsed_s - g["route_start_s"]
    route: list[dict[str, Any]] = []
    for seg in g["route"]:
        if route:
            route.append(seg)
        elif into >= seg["duration_s"]:
            into -= seg["duration_s"]
        elif seg["kind"] == "turn":
            raise ValueError("inside or at the start of a scheduled turn; align during a hold")
        else:
            route.append({**seg, "duration_s": seg["duration_s"] - into})
    if not route:  # past the end of the route: its final hold goes on
        route = [{**g["route"][-1], "duration_s": 1.0}]
    g["route"], g["route_start_s"] = route, 0.0
    return g
