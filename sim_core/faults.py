"""Faults: the one home of the fault grammar, the codes, the effect kernels and the catalogue.

- Grammar: :func:`parse_fault` / :func:`format_fault` (``target:index:type@onset_s[+duration_s][,key=value]``),
  the text form the command line, the API and the emulator accept; values are validated by
  :class:`~sim_core.scenario.FaultSpec`.
- Codes and table: :data:`TARGET_CODES`, :data:`TYPE_CODES` and :func:`fault_table` turn the specs of
  a batch into the float table (columns ``F_*``) the compiled loop reads.
- Effect kernels (compiled, one per place a fault acts): :func:`fault_active_1`,
  :func:`fault_transitions_1`, :func:`sensor_faults_1`, :func:`held_sensor_faults_1`, :func:`star_tracker_faults_1`,
  :func:`wheel_commands_1`, :func:`tachometer_faults_1`, :func:`lock_stuck_wheels_1`, :func:`extra_friction_1`,
  :func:`controller_faults_1`, :func:`rod_faults_1`; :func:`sensor_fault_series` and
  :func:`star_tracker_fault_series` run the same kernels over sample series (the emulator's sensors).
- Catalogue: the named fault sets of the seed experiments and the wheel-failure configurations:
The catalogue builds :class:`~sim_core.scenario.FaultSpec` / :class:`~sim_core.scenario.VariantSpec`
values (validated there) for batch runs of :func:`sim_core.engine.simulate`:

- :func:`wheel_configurations`: the 11 configurations of the GE cluster of seed 000 §3 (all four,
  each single failure, each failed pair leaving two wheels + the magnetic driver);
- :func:`seed002_fault_sets`: seed 002 §3.2's experiments on its three-orthogonal-wheel bus
  (controller intermittent 7–8 s and abrupt at 7 s; wheel 3 multiplicative and stuck; wheels
  {1,2}, {1,3}, {2,3}, {1,2,3}; gyro and attitude-sensor graded faults alone and together; 10σ and
  50σ measurement noise). The seed's Table 1 of magnitudes is garbled (DESIGN.md), so magnitudes are
  ours, chosen in proportion to the ``song-table1`` bus and stated in :data:`SEED002_MAGNITUDES`. The
  attitude sensors are the seed's own (§3.2.3): the gyros and the earth sensors its observer (eq 15) reads; the
  graded faults act on the pitch axis (the earth sensor's pitch, seed 002 Fig. 36, and the pitch gyro, whose
  channel of eq 15 is decoupled from roll and yaw);
- :func:`seed000_two_wheels` : seed 000 §5's wheels 2 and 4 with the MD.

Wheel numbers in names are the seeds' (1-based); indices in specs are 0-based.
"""

from __future__ import annotations

from collections.abc import Sequence
from itertools import combinations

import numpy as np
from numba import njit
from pydantic import ValidationError

from sim_core.scenario import FaultSpec, VariantSpec
from sim_core.spacecraft import PlantArrays

__all__ = [
    "TARGET_CODES",
    "TYPE_CODES",
    "FAULT_COLUMNS",
    "parse_fault",
    "format_fault",
    "fault_table",
    "fault_active_1",
    "fault_active_at",
    "fault_transitions_1",
    "sensor_faults_1",
    "held_sensor_faults_1",
    "star_tracker_faults_1",
    "fault_of_type_1",
    "wheel_commands_1",
    "tachometer_faults_1",
    "lock_stuck_wheels_1",
    "extra_friction_1",
    "controller_faults_1",
    "rod_faults_1",
    "sensor_fault_series",
    "star_tracker_fault_series",
    "SEED002_ONSET_S",
    "SEED002_MAGNITUDES",
    "wheel_failure",
    "wheel_configurations",
    "configuration_variants",
    "seed002_fault_sets",
    "seed000_two_wheels",
    "random_wheel_failures",
]

# Fault table columns and codes (fault_table builds the table from FaultSpec).
F_TARGET, F_INDEX, F_TYPE, F_ONSET, F_END, F_GAIN, F_VALUE, F_PERIOD, F_DUTY = range(9)
FAULT_COLUMNS = 9
TARGET_CODES = {
    "wheel": 0,
    "gyro": 1,
    "star_tracker": 2,
    "earth_sensor": 3,
    "magnetometer": 4,
    "sun_sensor": 5,
    "controller": 6,
    "md_rod": 7,
    "tachometer": 8,
}
TYPE_CODES = {
    "failure": 0,
    "stuck": 1,
    "gain": 2,
    "bias": 3,
    "drift": 4,
    "intermittent": 5,
    "noise": 6,
    "friction": 7,
    "frozen": 8,
}
T_WHEEL, T_GYRO, T_STAR, T_EARTH, T_MAG, T_SUN, T_CTRL, T_ROD, T_TACH = range(9)
Y_FAIL, Y_STUCK, Y_GAIN, Y_BIAS, Y_DRIFT, Y_INTERMITTENT, Y_NOISE, Y_FRICTION, Y_FROZEN = range(9)
EV_FAULT_ONSET, EV_FAULT_CLEARED = 2, 3  # sim_core.trajectory.EVENT_NAMES
OPTIONS = ("gain", "value", "period_s", "duty")

SEED002_ONSET_S = 7.0  # seed 002 §3.2.1: the controller faults start at 7 s; we start every fault there
SEED002_MAGNITUDES = {
    "controller_bias_nm": 0.02,  # 20 % of the bus's 0.1 N·m wheels: an abrupt offset the PD must fight
    "wheel_gain": 0.3,  # multiplicative fault: 70 % of the motor torque lost
    "gyro_drift_rad_s2": 1e-7,  # graded pitch-gyro fault: 0.1 mrad/s of extra bias after 1,000 s
    "attitude_drift_rad_s": 5e-5,  # graded earth-sensor pitch fault: 2.9° of cumulative offset after 1,000 s
    "noise_10": 10.0,  # seed 002 §3.2.4: 10σ
    "noise_50": 50.0,  # and 50σ
}


# --- grammar -------------------------------------------------------------------------------------


def parse_fault(text: str) -> FaultSpec:
    """A fault from ``target:index:type@onset_s[+duration_s][,gain=G][,value=V][,period_s=P][,duty=D]``.

    ``index`` is the 0-based index (wheel 0 is the dictionary's ``wheel_*_1``, axis 0 is x).
    >>> parse_fault("wheel:1:failure@600").model_dump(include={"target", "index", "type", "onset_s"})
    {'target': 'wheel', 'index': 1, 'type': 'failure', 'onset_s': 600.0}
    """
    head, *options = text.split(",")
    spec, _, timing = head.partition("@")
    parts = spec.split(":")
    if len(parts) != 3 or not timing:
        raise ValueError(f"fault: expected target:index:type@onset_s[+duration_s][,key=value], got {text!r}")
    onset, _, duration = timing.partition("+")
    fields: dict[str, str] = {"target": parts[0], "index": parts[1], "type": parts[2], "onset_s": onset}
    if duration:
        fields["duration_s"] = duration
    for option in options:
        key, sep, value = option.partition("=")
        if not sep or key not in OPTIONS:
            raise ValueError(f"fault: option {option!r} is not gain=, value=, period_s= or duty=")
        fields[key] = value
    try:
        return FaultSpec.model_validate(fields)
    except ValidationError as exc:
        err = exc.errors()[0]
        raise ValueError(f"fault.{'.'.join(str(x) for x in err['loc'])}: {err['msg']} in {text!r}") from None


def format_fault(f: FaultSpec) -> str:
    """The text form :func:`parse_fault` reads back to the same spec (defaults left out)."""
    text = f"{f.target}:{f.index}:{f.type}@{f.onset_s!r}"
    if f.duration_s is not None:
        text += f"+{f.duration_s!r}"
    defaults = FaultSpec(target=f.target, type=f.type)
    for key in OPTIONS:
        if getattr(f, key) != getattr(defaults, key):
            text += f",{key}={getattr(f, key)!r}"
    return text


def fault_table(variants: Sequence[VariantSpec]) -> tuple[np.ndarray, np.ndarray]:
    """Fault rows (variants × max faults × FAULT_COLUMNS) of a batch and the number of faults per variant."""
    n_max = max([1, *(len(v.faults) for v in variants)])
    table = np.zeros((len(variants), n_max, FAULT_COLUMNS))
    counts = np.zeros(len(variants), dtype=np.int64)
    for i, v in enumerate(variants):
        for j, f in enumerate(v.faults):
            end = np.inf if f.duration_s is None else f.onset_s + f.duration_s
            table[i, j] = [
                TARGET_CODES[f.target],
                f.index,
                TYPE_CODES[f.type],
                f.onset_s,
                end,
                f.gain,
                f.value,
                f.period_s or 0.0,
                f.duty,
            ]
        counts[i] = len(v.faults)
    return table, counts


# --- effect kernels (compiled; the loop and the emulator call these) -------------------------------


@njit(cache=True, inline="always")
def fault_active_at(t: float, onset: float, end: float, kind: int, period: float, duty: float) -> bool:
    """Whether a fault acts at t: inside [onset, end) and, if intermittent, in an on-window. Scalars only, for
    kernels the loop calls every step (a kernel handed a table row is reference-counted at each call)."""
    if t < onset or t >= end:
        return False
    if kind == Y_INTERMITTENT and period > 0.0:
        phase = (t - onset) % period
        return bool(phase < duty * period)
    return True


@njit(cache=True)
def fault_active_1(row: np.ndarray, t: float) -> bool:
    """Whether a fault row acts at t (:func:`fault_active_at` on the row's onset, end, type, period, duty)."""
    return fault_active_at(t, row[F_ONSET], row[F_END], int(row[F_TYPE]), row[F_PERIOD], row[F_DUTY])


@njit(cache=True)
def _emit(ev: np.ndarray, n_ev: np.ndarray, t: float, code: int, arg: int) -> None:
    if n_ev[0] < ev.shape[0]:
        ev[n_ev[0], 0], ev[n_ev[0], 1], ev[n_ev[0], 2] = t, code, arg
        n_ev[0] += 1


@njit(cache=True)
def fault_transitions_1(faults: np.ndarray, t: float, state: np.ndarray, ev: np.ndarray, n_ev: np.ndarray) -> int:
    """Active-fault bit flags at t, with onset/clear events; returns −flags−1 if a fault just began."""
    flags = 0
    began = False
    for f in range(faults.shape[0]):
        on = fault_active_1(faults[f], t)
        if on:
            flags |= 1 << min(f, 30)
        if on != state[f]:
            _emit(ev, n_ev, t, EV_FAULT_ONSET if on else EV_FAULT_CLEARED, f)
            began = began or on
            state[f] = on
    return -flags - 1 if began else flags


@njit(cache=True)
def sensor_faults_1(
    faults: np.ndarray, target: int, t: float, value: np.ndarray, frozen: np.ndarray, sigma: float, normals: np.ndarray
) -> bool:
    """A sensor's faults (seed 002 §3.2 catalogue) on its sample in place: gain, bias, intermittent bias,
    drift value·(t − onset), noise scaled to value·σ (``sigma·normals`` is the sample's noise) on axis
    ``index``, frozen (holds ``frozen``); returns False while the sensor has failed."""
    valid = True
    for f in range(faults.shape[0]):
        row = faults[f]
        if int(row[F_TARGET]) != target or not fault_active_1(row, t):
            continue
        kind, i = int(row[F_TYPE]), int(row[F_INDEX])
        axis = i if i < value.shape[0] else 0
        if kind == Y_FAIL:
            valid = False
        elif kind == Y_FROZEN:
            value[:] = frozen
        elif kind == Y_GAIN:
            value[axis] *= row[F_GAIN]
        elif kind in (Y_BIAS, Y_INTERMITTENT):
            value[axis] += row[F_VALUE]
        elif kind == Y_DRIFT:
            value[axis] += row[F_VALUE] * (t - row[F_ONSET])
        elif kind == Y_NOISE:
            value[axis] += (row[F_VALUE] - 1.0) * sigma * normals[axis]
    return valid


@njit(cache=True)
def held_sensor_faults_1(
    faults: np.ndarray, target: int, t: float, value: np.ndarray, held: np.ndarray, sigma: float, normals: np.ndarray
) -> bool:
    """:func:`sensor_faults_1` for a sensor that keeps its own held output: a frozen fault holds ``held``, the
    last output it gave before the freeze (``held`` NaN: it has given none, the freeze holds this sample);
    ``held`` follows the output while the sensor is not frozen. Returns False while the sensor has failed."""
    if np.isnan(held[0]):
        held[:] = value
    ok = sensor_faults_1(faults, target, t, value, held, sigma, normals)
    if not fault_of_type_1(faults, target, Y_FROZEN, t):
        held[:] = value
    return ok


@njit(cache=True)
def fault_of_type_1(faults: np.ndarray, target: int, kind: int, t: float) -> bool:
    """Whether a fault of this target and type acts at t."""
    for f in range(faults.shape[0]):
        if int(faults[f, F_TARGET]) == target and int(faults[f, F_TYPE]) == kind and fault_active_1(faults[f], t):
            return True
    return False


@njit(cache=True)
def _small_rotation_1(rot: np.ndarray) -> np.ndarray:
    """Quaternion of a rotation vector (rad)."""
    ang = np.sqrt(rot @ rot)
    dq = np.empty(4)
    dq[0] = np.cos(0.5 * ang)
    dq[1:] = np.sin(0.5 * ang) * rot / ang
    return dq


@njit(cache=True)
def star_tracker_faults_1(
    faults: np.ndarray, t: float, q_m: np.ndarray, frozen_q: np.ndarray, sigma: float, normals: np.ndarray
) -> bool:
    """Star-tracker faults on Λ^m in place: Λ^m ∘ Λ^f with Λ^f the rotation the faults' bias, drift,
    gain-free noise give (seed 000 §4); frozen holds ``frozen_q`` (updated while not frozen); False if failed."""
    rot = np.zeros(3)
    ok = sensor_faults_1(faults, T_STAR, t, rot, rot, sigma, normals)
    if rot[0] != 0.0 or rot[1] != 0.0 or rot[2] != 0.0:
        dq = _small_rotation_1(rot)
        q0, q1, q2, q3 = q_m[0], q_m[1], q_m[2], q_m[3]
        q_m[0] = q0 * dq[0] - q1 * dq[1] - q2 * dq[2] - q3 * dq[3]
        q_m[1] = q0 * dq[1] + q1 * dq[0] + q2 * dq[3] - q3 * dq[2]
        q_m[2] = q0 * dq[2] - q1 * dq[3] + q2 * dq[0] + q3 * dq[1]
        q_m[3] = q0 * dq[3] + q1 * dq[2] - q2 * dq[1] + q3 * dq[0]
    if fault_of_type_1(faults, T_STAR, Y_FROZEN, t):
        q_m[:] = frozen_q
    else:
        frozen_q[:] = q_m
    return ok


@njit(cache=True)
def wheel_commands_1(faults: np.ndarray, t: float, cmd: np.ndarray, frozen_cmd: np.ndarray, out: np.ndarray) -> None:
    """Torque the wheel motors deliver for the held command under the wheel faults (seed 002 §3.2.2:
    outage/stuck deliver 0, multiplicative gain, additive bias, frozen command). Called every dynamics step:
    element reads and writes only, no row views or slice copies (those keep numba from pruning the reference
    counts of the arguments: 60 -> 9 ns per call with two faults)."""
    for i in range(out.shape[0]):
        out[i] = cmd[i]
    for f in range(faults.shape[0]):
        kind, p = int(faults[f, F_TYPE]), int(faults[f, F_INDEX])
        if int(faults[f, F_TARGET]) != T_WHEEL or not fault_active_at(
            t, faults[f, F_ONSET], faults[f, F_END], kind, faults[f, F_PERIOD], faults[f, F_DUTY]
        ):
            continue
        if kind in (Y_FAIL, Y_INTERMITTENT, Y_STUCK):
            out[p] = 0.0
        elif kind == Y_GAIN:
            out[p] *= faults[f, F_GAIN]
        elif kind == Y_BIAS:
            out[p] += faults[f, F_VALUE]
        elif kind == Y_FROZEN:
            out[p] = frozen_cmd[p]


@njit(cache=True)
def tachometer_faults_1(faults: np.ndarray, t: float, speeds: np.ndarray) -> None:
    """Tachometer faults on the wheel speeds the onboard software reads, in place (the rotors are untouched):
    wheel ``index``'s reading Ω̃ + value (bias, rad/s), Ω̃ · gain (scale-factor error), Ω̃ + value · (t − onset)
    (drift, rad/s²); they act after the quantisation, as an offset of the sensor's output."""
    for f in range(faults.shape[0]):
        row = faults[f]
        if int(row[F_TARGET]) != T_TACH or not fault_active_1(row, t):
            continue
        kind, p = int(row[F_TYPE]), int(row[F_INDEX])
        if kind == Y_BIAS:
            speeds[p] += row[F_VALUE]
        elif kind == Y_GAIN:
            speeds[p] *= row[F_GAIN]
        elif kind == Y_DRIFT:
            speeds[p] += row[F_VALUE] * (t - row[F_ONSET])


@njit(cache=True)
def lock_stuck_wheels_1(faults: np.ndarray, t: float, x: np.ndarray, p: PlantArrays, j_inv: np.ndarray) -> None:
    """Seized wheels: Ω_p = 0 with the body taking the momentum (H conserved, seed 000 eq 1)."""
    nq = p.flex_mass.shape[0]
    for f in range(faults.shape[0]):
        row = faults[f]
        if int(row[F_TARGET]) != T_WHEEL or int(row[F_TYPE]) != Y_STUCK or not fault_active_1(row, t):
            continue
        w = int(row[F_INDEX])
        i = 7 + 2 * nq + w
        h = p.wheel_inertia[w] * x[i]
        for r in range(3):
            for c in range(3):
                x[4 + r] += j_inv[r, c] * p.wheel_axes[c, w] * h
        x[i] = 0.0


@njit(cache=True)
def extra_friction_1(faults: np.ndarray, t: float, friction: np.ndarray, base: np.ndarray) -> None:
    """Coulomb friction table with the 'increased friction' faults added (N·m, seed 002 eq 1)."""
    friction[:, :] = base
    for f in range(faults.shape[0]):
        row = faults[f]
        if int(row[F_TARGET]) == T_WHEEL and int(row[F_TYPE]) == Y_FRICTION and fault_active_1(row, t):
            friction[0, int(row[F_INDEX])] += row[F_VALUE]


@njit(cache=True)
def controller_faults_1(faults: np.ndarray, t: float, torque: np.ndarray, frozen: np.ndarray) -> None:
    """Controller-output faults (seed 002 §3.2.1: intermittent and abrupt) applied in place."""
    for f in range(faults.shape[0]):
        row = faults[f]
        if int(row[F_TARGET]) != T_CTRL or not fault_active_1(row, t):
            continue
        kind, axis = int(row[F_TYPE]), min(int(row[F_INDEX]), 2)
        if kind in (Y_FAIL, Y_INTERMITTENT):
            torque[:] = 0.0
        elif kind == Y_GAIN:
            torque *= row[F_GAIN]
        elif kind == Y_BIAS:
            torque[axis] += row[F_VALUE]
        elif kind == Y_FROZEN:
            torque[:] = frozen


@njit(cache=True)
def rod_faults_1(faults: np.ndarray, t: float, dipole: np.ndarray) -> None:
    """Magnetic-driver rod faults applied to the commanded dipole in place."""
    for f in range(faults.shape[0]):
        row = faults[f]
        if int(row[F_TARGET]) != T_ROD or not fault_active_1(row, t):
            continue
        kind, i = int(row[F_TYPE]), min(int(row[F_INDEX]), 2)
        if kind in (Y_FAIL, Y_STUCK):
            dipole[i] = 0.0
        elif kind == Y_GAIN:
            dipole[i] *= row[F_GAIN]
        elif kind == Y_BIAS:
            dipole[i] += row[F_VALUE]


@njit(cache=True)
def sensor_fault_series(
    faults: np.ndarray, target: int, t_s: np.ndarray, samples: np.ndarray, noise: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """:func:`sensor_faults_1` over (n, k) samples with their realised noise; frozen holds the previous
    output sample. Returns (samples under the faults, failed mask)."""
    out = samples.copy()
    failed = np.zeros(t_s.shape[0], dtype=np.bool_)
    for k in range(t_s.shape[0]):
        held = out[k - 1].copy() if k > 0 else samples[0].copy()
        failed[k] = not sensor_faults_1(faults, target, t_s[k], out[k], held, 1.0, noise[k])
    return out, failed


@njit(cache=True)
def star_tracker_fault_series(
    faults: np.ndarray, t_s: np.ndarray, q_m: np.ndarray, noise: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """:func:`star_tracker_faults_1` over (n, 4) quaternions with their realised noise rotation vectors."""
    out = q_m.copy()
    failed = np.zeros(t_s.shape[0], dtype=np.bool_)
    frozen = q_m[0].copy()
    for k in range(t_s.shape[0]):
        failed[k] = not star_tracker_faults_1(faults, t_s[k], out[k], frozen, 1.0, noise[k])
    return out, failed


# --- catalogue -----------------------------------------------------------------------------------


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
    """Gyro (three axes) and earth-sensor (roll, pitch) noise scaled to k·σ (seed 002 §3.2.4)."""
    earth = [FaultSpec(target="earth_sensor", index=i, type="noise", value=k) for i in range(2)]
    return _axes("gyro", "noise", 0.0, value=k) + earth


def seed002_fault_sets(onset_s: float = SEED002_ONSET_S) -> dict[str, list[FaultSpec]]:
    """Seed 002 §3.2 experiments as named fault sets for the three-wheel ``song-table1`` bus."""
    m = SEED002_MAGNITUDES
    gyro_drift = [FaultSpec(target="gyro", index=2, type="drift", onset_s=onset_s, value=m["gyro_drift_rad_s2"])]
    att_drift = [
        FaultSpec(target="earth_sensor", index=1, type="drift", onset_s=onset_s, value=m["attitude_drift_rad_s"])
    ]
    return {
        "nominal": [],
        "controller intermittent 7-8 s": [
            FaultSpec(target="controller", type="intermittent", onset_s=onset_s, duration_s=1.0)
        ],
        "controller abrupt 7 s": [
            FaultSpec(target="controller", index=0, type="bias", onset_s=onset_s, value=m["controller_bias_nm"])
        ],
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


def random_wheel_failures(
    n: int, onset_range_s: tuple[float, float], n_wheels: int = 4, seed: int = 0, kind: str = "failure"
) -> list[VariantSpec]:
    """``n`` variants, each with one wheel (uniformly drawn) failing at a uniform onset time."""
    lo, hi = onset_range_s
    if n < 1:
        raise ValueError("n: at least one variant")
    if not 0.0 <= lo < hi:
        raise ValueError("onset_range_s: expected 0 ≤ start < end")
    rng = np.random.default_rng(seed)
    wheels = rng.integers(0, n_wheels, n)
    onsets = rng.uniform(lo, hi, n)
    return [
        VariantSpec(name=f"wheel {w + 1} {kind} at {t:.1f} s", faults=[wheel_failure(int(w), float(t), kind)])
        for w, t in zip(wheels, onsets)
    ]
