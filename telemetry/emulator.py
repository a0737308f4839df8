"""Spacecraft emulator (issue 5): sim_core flies "the real satellite" and its telemetry goes out as CCSDS packets.

Pipeline: scenario + hidden fault schedule → :func:`sim_core.engine.simulate` (one variant, output at
the ACS_HK period T_q) → per-sample engineering values of every dictionary parameter
(:func:`packet_series`) → fixed-length packets with primary headers, per-APID sequence counts and
CUC secondary-header times (:func:`telemetry.encoding.encode_packets`, CCSDS 133.0-B-2 §4.1) merged
in time order (:func:`encode_stream`) → a file (:func:`demo_pass_bytes`) or a paced TCP link with
reconnect (:func:`send_stream`).

Where the values come from (reference dictionary ``reference_satellite.yaml``):

* straight from the trajectory: estimated and program quaternions, estimated rates, wheel speeds,
  wheel torque commands, magnetic-driver moments, engine events;
* drawn from truth with sim_core's sensor models, because the engine does not record raw sensor
  samples: star tracker Λ^m = Λ ∘ Λ^n (seed 000 §4), gyro ω + b + d + n (seed 002 eq 13),
  magnetometer Λ̃ ∘ B_I ∘ Λ + n (seed 003 MAG), GPS fix with noise (seed 003 §3.2.1.1), all with
  the scenario's noise figures and a random stream of their own; the hidden schedule's sensor
  faults act on them as in the engine (gain, bias, drift, noise, frozen; a failed sensor sends zeros);
* wheel motor current i = M / K_m (seed 002 eq 2) from the torque the wheel delivers;
* mode from the guidance programme (PROGRAM_TURN inside a scheduled turn, THREE_AXIS otherwise)
  and FAULT after the onboard FDIR's ``mode_change`` to the fault mode;
* FDIR flags from the onboard FDIR's ``fault_isolated`` events (:mod:`sim_core.fdir` arguments).

A hidden fault stays hidden: the engine's fault onset/cleared events (ground truth of the
injection, not something the satellite knows) are never sent; the fault shows through its effects
(a failed wheel stops accelerating and draws no current) and through what onboard FDIR reports.
"""

from __future__ import annotations

import asyncio
import contextlib
import math
import time
from collections import deque
from collections.abc import AsyncGenerator, AsyncIterator, Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np
import numpy.typing as npt
from pydantic import ValidationError

from sim_core import environment, frames, modes, quaternion, scenario_library, sensors
from sim_core import faults as fault_kernels
from sim_core import fdir as onboard_fdir
from sim_core.engine import Flight, cluster_axes, orbit_state, plant_params
from sim_core.faults import (  # parse_fault: the grammar's home is sim_core.faults
    TARGET_CODES,
    parse_fault,
)
from sim_core.scenario import FaultSpec, Scenario, VariantSpec
from sim_core.trajectory import EVENT_NAMES, Trajectory
from telemetry.ccsds import NS_PER_S, SEQUENCE_COUNT_MODULUS
from telemetry.dictionary import (
    Dictionary,
    PacketDefinition,
    load_dictionary,
    parse_utc_ns,
)
from telemetry.encoding import encode_packets

__all__ = [
    "DEFAULT_SCENARIO",
    "REFERENCE_DICTIONARY",
    "PacketSeries",
    "PacketStream",
    "Clock",
    "SYSTEM_CLOCK",
    "SendOptions",
    "SendReport",
    "Satellite",
    "TelemetryCarry",
    "flight_streams",
    "send_streams",
    "parse_fault",
    "satellite_scenario",
    "TruthTolerances",
    "truth_scenario",
    "truth_wheel_allowance_rad_s",
    "packet_series",
    "encode_stream",
    "emulate",
    "demo_pass_bytes",
    "gps_week_seconds",
    "hk_period_s",
    "send_stream",
]

DEFAULT_SCENARIO = "somov-ge4-scan"
REFERENCE_DICTIONARY = "reference_satellite.yaml"
HK_PACKET, GPS_PACKET = "ACS_HK", "GPS_NAV"
EMULATOR_STREAM = 5  # spawn key of the emulator's sensor noise, apart from the engine's own streams
TRUTH_STREAM = 6  # spawn key of the draw of the satellite's truth parameters

# GPS receiver: seed 003 §3.2.1.1 (SRG-10): position 15 m (2σ), velocity 1.5 m/s (2σ).
GPS_SIGMA_R_M = 7.5
GPS_SIGMA_V_M_S = 0.75
GPS_SATELLITES_TRACKED = 8  # a healthy LEO receiver's typical count (≥ 4 needed for a 3-D fix, seed 003 eq 1)
GPS_EPOCH_UTC_NS = parse_utc_ns("1980-01-06T00:00:00Z")
TAI_MINUS_GPS_S = 19  # fixed since the GPS epoch (IS-GPS-200 §3.3.4)
SECONDS_PER_WEEK = 604_800
GYRO_RANGE_RAD_S = math.radians(20.0)  # measuring range of the emulated rate sensor (well above any turn)
WHEEL_TORQUE_CONSTANT_NM_A = 0.1  # K_m: the HR12-class 0.2 N·m maximum draws 2 A, inside the 2.5 A yellow limit
STAR_TRACKER_TRACKING_RATE_RAD_S = math.radians(2.0)  # validity is not telemetered; a typical tracking limit
SEGMENT_S = 600.0  # an endless flight is flown and packetised this much at a time (well under a second of CPU)
REWIND_S = 1.0  # on reconnect, re-send what went out in the last second (socket buffers lost with the link)
RETRY_S = 0.5
MODE_LABELS = {
    modes.MODE_RATE_DAMPING: "RATE_DAMPING",
    modes.MODE_SUN_SAFE: "ONE_AXIS",
    modes.MODE_ORF: "THREE_AXIS",
    modes.MODE_ROUTE: "THREE_AXIS",
    modes.MODE_FAULT: "FAULT",
}  # sim_core.modes → dictionary labels
HIDDEN_EVENTS = {EVENT_NAMES[2], EVENT_NAMES[3]}  # fault onset/cleared: ground truth of the injection
SENSOR_FLAGS = {
    "star_tracker": "fault_star_tracker",
    "gyro": "fault_gyro",
    "magnetometer": "fault_magnetometer",
    "md_rod": "fault_md",
}  # sim_core fault target → dictionary FDIR flag


@dataclass(frozen=True)
class PacketSeries:
    """Engineering values of one packet type at its sample times (the satellite's truth before encoding)."""

    definition: PacketDefinition
    t_utc_ns: np.ndarray
    values: dict[str, np.ndarray]


@dataclass(frozen=True)
class PacketStream:
    """Packets of all APIDs in time order: bytes, each packet's end offset, time and APID."""

    data: bytes
    ends: np.ndarray
    t_utc_ns: np.ndarray
    apid: np.ndarray

    def __len__(self) -> int:
        return int(self.ends.shape[0])

    def window(self, t_start_utc_ns: int, t_stop_utc_ns: int) -> PacketStream:
        """The packets stamped in [t_start, t_stop), counts and bytes unchanged."""
        keep = np.flatnonzero((self.t_utc_ns >= t_start_utc_ns) & (self.t_utc_ns < t_stop_utc_ns))
        if keep.size == 0:
            return PacketStream(b"", np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0, np.int64))
        lo, hi = int(keep[0]), int(keep[-1]) + 1
        starts = np.concatenate([[0], self.ends])
        base = int(starts[lo])
        return PacketStream(
            self.data[base : int(self.ends[hi - 1])], self.ends[lo:hi] - base, self.t_utc_ns[lo:hi], self.apid[lo:hi]
        )


@dataclass
class TelemetryCarry:
    """What the emulated telemetry carries from one segment of a flight to the next: the sensors' noise stream,
    the gyro's Markov drift at the next sample (None: drawn from its stationary distribution), each sensor's
    last output (time, value: what a frozen sensor holds), the onboard events the telemetry still shows (the last
    one, the last mode change, every isolation) and the next sequence count per packet."""

    rng: np.random.Generator
    gyro_drift: np.ndarray | None = None
    held: dict[str, tuple[float, np.ndarray]] = field(default_factory=dict)
    events: list[tuple[float, str, int]] = field(default_factory=list)
    counts: dict[str, int] = field(default_factory=dict)


@dataclass
class SendReport:
    """What a TCP send delivered: packets and octets written, connections opened, re-sent packets."""

    packets_sent: int = 0
    octets_sent: int = 0
    connections: int = 0
    packets_resent: int = 0


@dataclass(frozen=True)
class TruthTolerances:
    """How far the emulated satellite's truth may lie from the twin's nominal (drawn uniformly inside):
    principal moments ±2 % and products ±0.5 % of the mean moment (mass properties measured before
    launch, then propellant-free but cabled), wheel spin axes tilted ≤ 0.1° (mounting alignment),
    gyro bias ±5e-6 rad/s (≈ 1 °/h, a tactical-grade turn-on bias) per axis, and noise streams of its own."""

    inertia_rel: float = 0.02
    product_rel: float = 0.005
    wheel_axis_rad: float = math.radians(0.1)
    gyro_bias_rad_s: float = 5e-6


def _tilted(axis: np.ndarray, angle: float, rng: np.random.Generator) -> list[float]:
    """``axis`` turned by ``angle`` about a random direction perpendicular to it."""
    u = axis / np.linalg.norm(axis)
    perp = np.cross(u, rng.standard_normal(3))
    perp /= np.linalg.norm(perp)
    tilted: list[float] = (np.cos(angle) * u + np.sin(angle) * perp).tolist()
    return tilted


def truth_scenario(s: Scenario, seed: int = 0, tolerances: TruthTolerances = TruthTolerances()) -> Scenario:
    """The same spacecraft as flown: ``s`` with truth inertia, wheel axes, gyro bias and noise seed drawn
    within ``tolerances`` (onboard software keeps the nominal model, see :class:`sim_core.scenario.TruthSpec`)."""
    rng = np.random.default_rng(np.random.SeedSequence([TRUTH_STREAM, seed]))
    tol = tolerances
    j = np.array(s.spacecraft.inertia_kg_m2, dtype=float)
    j_true = j + np.diag(np.diag(j) * tol.inertia_rel * rng.uniform(-1.0, 1.0, 3))
    off = np.triu(rng.uniform(-1.0, 1.0, (3, 3)), 1) * tol.product_rel * np.trace(j) / 3.0
    j_true += off + off.T
    axes = [_tilted(a, rng.uniform(0.0, tol.wheel_axis_rad), rng) for a in cluster_axes(s).T]
    bias = np.array(s.sensors.gyro_bias_rad_s) + rng.uniform(-tol.gyro_bias_rad_s, tol.gyro_bias_rad_s, 3)
    data = s.model_dump()
    data["truth"] = {"inertia_kg_m2": j_true.tolist(), "wheel_axes_b": axes}
    data["sensors"]["gyro_bias_rad_s"] = bias.tolist()
    data["seed"] = s.seed + 1 + seed  # never the twin's own noise streams
    return Scenario.model_validate(data)


def truth_wheel_allowance_rad_s(
    traj: Trajectory, model: Scenario, t_from_s: float, t_to_s: float, tolerances: TruthTolerances = TruthTolerances()
) -> float:
    """Wheel-speed gap between the satellite (``traj``) and a twin synchronised at ``t_from_s`` that its truth may
    cause by ``t_to_s``: the inertia error times the body momentum the wheels took over (spread by the cluster's
    pseudo-inverse), plus the mounting tilt times the wheels' own speed (rad/s, a bound, not a fit)."""
    p = plant_params(model)
    window = (traj.t_s >= t_from_s) & (traj.t_s <= t_to_s)
    h = traj["omega_b_rad_s"][0, window] @ p.inertia_kg_m2.T
    dh = float(np.max(np.linalg.norm(h - h[0], axis=1)))
    spread = np.linalg.norm(np.linalg.pinv(p.wheel_axes_b), 2) / np.min(p.wheels.inertia_kg_m2)
    tilt = tolerances.wheel_axis_rad * float(np.max(np.abs(traj["wheel_speed_rad_s"][0, window])))
    return float((tolerances.inertia_rel + 3.0 * tolerances.product_rel) * dh * spread + tilt)


def satellite_scenario(
    scenario: str | Scenario = DEFAULT_SCENARIO,
    faults: Sequence[FaultSpec] = (),
    duration_s: float | None = None,
    start_utc: str | None = None,
    output_dt_s: float = 0.25,
    truth_seed: int | None = 0,
) -> Scenario:
    """The scenario the emulated satellite flies: one variant with the hidden faults, output at T_q (seed 000 §5),
    and, unless ``truth_seed`` is None, its own truth parameters (:func:`truth_scenario`)."""
    base = scenario_library.get(scenario) if isinstance(scenario, str) else scenario
    if truth_seed is not None:
        base = truth_scenario(base, truth_seed)
    data = base.model_dump()
    data["variants"] = [VariantSpec(name="satellite", faults=list(faults)).model_dump()]
    data["output_dt_s"] = output_dt_s
    if duration_s is not None:
        data["duration_s"] = duration_s
    if start_utc is not None:
        data["orbit"]["epoch_utc"] = start_utc
    try:
        return Scenario.model_validate(data)
    except ValidationError as exc:
        err = exc.errors()[0]
        where = ".".join(["scenario", *(str(x) for x in err["loc"])])
        message = err["msg"].removeprefix("Value error, ")
        raise ValueError(f"{where}: {message} (telemetry sampled every {output_dt_s} s)") from None


def _stride(definition: PacketDefinition, output_dt_s: float) -> int:
    """Output samples per packet period; ValueError if the period is not a whole multiple."""
    period = definition.period_s or output_dt_s
    ratio = period / output_dt_s
    if abs(ratio - round(ratio)) > 1e-9 or round(ratio) < 1:
        raise ValueError(
            f"{definition.name}.period_s: {period} s is not a whole multiple of the output step {output_dt_s} s"
        )
    return int(round(ratio))


def _codes(definition: PacketDefinition, name: str) -> dict[str, int]:
    """Label → code of an enumerated parameter."""
    for p in definition.parameters:
        if p.name == name:
            return {label: code for code, label in p.enumeration.items()}
    raise ValueError(f"{definition.name}: dictionary has no parameter {name!r}")


def _turn_windows(s: Scenario) -> list[tuple[float, float]]:
    """[start, end) of every scheduled turn of the guidance route, s from the epoch (seed 001)."""
    if s.guidance.kind != "route":
        return []
    windows, t = [], s.guidance.route_start_s
    for seg in s.guidance.route:
        if seg.kind == "turn":
            windows.append((t, t + seg.duration_s))
        t += seg.duration_s
    return windows


def _mode(
    events: list[tuple[float, str, int]], s: Scenario, definition: PacketDefinition, t_s: np.ndarray
) -> np.ndarray:
    """Onboard mode code per sample: PROGRAM_TURN inside a scheduled turn, THREE_AXIS otherwise, and the mode
    the onboard logic announces by ``mode_change`` events from then on (seed 001 modes)."""
    codes = _codes(definition, "mode")
    programme = np.full(t_s.shape, codes["THREE_AXIS"], dtype=np.int64)
    for start, end in _turn_windows(s):
        programme[(t_s >= start) & (t_s < end)] = codes["PROGRAM_TURN"]
    mode = programme.copy()
    for t, name, arg in events:
        if name == "mode_change":
            label = MODE_LABELS.get(arg, "THREE_AXIS")
            mode[t_s >= t] = programme[t_s >= t] if label == "THREE_AXIS" else codes[label]
    return mode


def _fdir_flags(
    events: list[tuple[float, str, int]], definition: PacketDefinition, t_s: np.ndarray
) -> dict[str, np.ndarray]:
    """FDIR isolation flags per sample from the onboard FDIR's ``fault_isolated`` events (sim_core.fdir arguments)."""
    names = [p.name for p in definition.parameters if p.name.startswith("fault_")]
    flags = {name: np.zeros(t_s.shape, dtype=np.int64) for name in names}
    target_names = {code: name for name, code in TARGET_CODES.items()}
    for t, event, arg in events:
        if event != "fault_isolated":
            continue
        if arg < onboard_fdir.SENSOR_ARG:
            flag = f"fault_wheel_{arg + 1}"
        else:
            flag = SENSOR_FLAGS.get(target_names.get((arg - onboard_fdir.SENSOR_ARG) // 10, ""), "")
        if flag in flags:
            flags[flag][t_s >= t] = 1
    return flags


def _last_events(
    events: list[tuple[float, str, int]], definition: PacketDefinition, t_s: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Code and argument of the last onboard-known engine event at or before each sample (truth-only events left out;
    a mode change carries the dictionary's mode code)."""
    codes, mode_codes = _codes(definition, "fdir_event"), _codes(definition, "mode")
    known = [
        (t, codes[name.upper()], mode_codes[MODE_LABELS.get(arg, "THREE_AXIS")] if name == "mode_change" else arg)
        for t, name, arg in events
        if name not in HIDDEN_EVENTS
    ]
    event = np.full(t_s.shape, codes["NONE"], dtype=np.int64)
    argument = np.zeros(t_s.shape, dtype=np.int64)
    if known:
        ev_t = np.array([k[0] for k in known])
        at = np.searchsorted(ev_t, t_s, side="right") - 1
        seen = at >= 0
        event[seen] = np.array([k[1] for k in known])[at[seen]]
        argument[seen] = np.clip(np.array([k[2] for k in known])[at[seen]], 0, 255)
    return event, argument


def _split(prefix: str, columns: np.ndarray, suffixes: Sequence[str]) -> dict[str, np.ndarray]:
    """Named columns ``prefix_suffix`` of an (n, k) array."""
    return {f"{prefix}_{sfx}": columns[:, k] for k, sfx in enumerate(suffixes)}


def _faulted(
    carry: TelemetryCarry,
    sensor: str,
    t_s: np.ndarray,
    samples: np.ndarray,
    noise: np.ndarray,
    series: Callable[[np.ndarray, np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]],
) -> tuple[np.ndarray, np.ndarray]:
    """``series(t, samples, noise)`` (a sim_core.faults series) run on from the sensor's last output of the previous
    segment, so that a frozen sensor holds it across the seam; keeps this segment's last output."""
    held = carry.held.get(sensor)
    if held is not None:
        t_s = np.concatenate([[held[0]], t_s])
        samples = np.vstack([held[1], samples])
        noise = np.vstack([np.zeros(noise.shape[1]), noise])
    out, failed = series(np.ascontiguousarray(t_s), np.ascontiguousarray(samples), np.ascontiguousarray(noise))
    if held is not None:
        out, failed = out[1:], failed[1:]
    carry.held[sensor] = (float(t_s[-1]), out[-1].copy())
    return out, failed


def _star_tracker(sr: dict[str, np.ndarray], s: Scenario, t_s: np.ndarray, carry: TelemetryCarry) -> np.ndarray:
    """Star-tracker quaternions Λ^m = Λ ∘ Λ^n ∘ Λ^f (seed 000 §4), Λ^f the hidden faults' rotation; zeros if failed."""
    q_m, _ = sensors.star_tracker(
        sr["q_ib"],
        sr["omega_b_rad_s"],
        s.sensors.star_tracker_sigma_arcsec * sensors.ARCSEC,
        STAR_TRACKER_TRACKING_RATE_RAD_S,
        carry.rng,
    )
    e = quaternion.multiply(quaternion.conjugate(sr["q_ib"]), q_m)
    theta = 2.0 * np.arctan2(np.linalg.norm(e[:, 1:], axis=-1), e[:, 0])[:, None]
    noise = theta * e[:, 1:] / np.maximum(np.linalg.norm(e[:, 1:], axis=-1, keepdims=True), 1e-300)
    table, _ = fault_kernels.fault_table(s.variants[:1])
    q_m, failed = _faulted(
        carry,
        "star_tracker",
        t_s,
        q_m,
        noise,
        lambda t, q, n: fault_kernels.star_tracker_fault_series(table[0], t, q, n),
    )
    q_m = quaternion.normalize(q_m)
    q_m[failed] = 0.0
    return q_m


def _gyro(sr: dict[str, np.ndarray], s: Scenario, t_s: np.ndarray, carry: TelemetryCarry) -> np.ndarray:
    """Gyro rates ω + b + d + n_g (seed 002 eq 13) under the hidden gyro faults; zeros if failed. The Markov
    drift goes on from ``carry.gyro_drift`` and leaves there its value at the next sample."""
    sn, rng = s.sensors, carry.rng
    bias = np.array(sn.gyro_bias_rad_s)
    density = sn.gyro_markov_sigma_rad_s * math.sqrt(2.0 / sn.gyro_markov_tau_s)  # stationary σ as in the loop
    drift = sensors.GaussMarkovDrift(sn.gyro_markov_tau_s, density, s.measurement_dt_s)
    w_g, d, _ = sensors.gyro(
        sr["omega_b_rad_s"], bias, drift, sn.gyro_noise_rad_s, GYRO_RANGE_RAD_S, rng, carry.gyro_drift
    )
    carry.gyro_drift = drift.decay * d[-1] + drift.step_std * rng.standard_normal(3)
    table, _ = fault_kernels.fault_table(s.variants[:1])
    w_g, failed = _faulted(
        carry,
        "gyro",
        t_s,
        w_g,
        w_g - sr["omega_b_rad_s"] - bias - d,
        lambda t, w, n: fault_kernels.sensor_fault_series(table[0], fault_kernels.T_GYRO, t, w, n),
    )
    w_g[failed] = 0.0
    return w_g


def _magnetometer(
    sr: dict[str, np.ndarray], s: Scenario, t_s: np.ndarray, range_t: float, carry: TelemetryCarry
) -> np.ndarray:
    """Magnetometer field Λ̃ ∘ B_I ∘ Λ + n (seed 003 MAG, field model as flown) under the hidden faults; 0 if failed."""
    b_i = environment.magnetic_field_eci_t(sr["r_eci_m"], _unix_s(s, t_s), s.magnetic_model)
    b_b, _ = sensors.magnetometer(sr["q_ib"], b_i, np.zeros(3), s.sensors.magnetometer_noise_t, range_t, carry.rng)
    b_true = quaternion.rotate(quaternion.conjugate(sr["q_ib"]), b_i)
    table, _ = fault_kernels.fault_table(s.variants[:1])
    b_b, failed = _faulted(
        carry,
        "magnetometer",
        t_s,
        b_b,
        b_b - b_true,
        lambda t, b, n: fault_kernels.sensor_fault_series(table[0], fault_kernels.T_MAG, t, b, n),
    )
    clipped: npt.NDArray[np.float64] = np.clip(b_b, -range_t, range_t)
    clipped[failed] = 0.0
    return clipped


def _unix_s(s: Scenario, t_s: np.ndarray) -> np.ndarray:
    """Unix seconds of times since the scenario epoch."""
    return parse_utc_ns(s.orbit.epoch_utc) / NS_PER_S + t_s


def _tachometer(sr: dict[str, np.ndarray], s: Scenario, t_s: np.ndarray) -> np.ndarray:
    """Wheel speeds as the satellite's tachometers read them: the rotors' under the hidden tachometer faults (the
    loop's kernel, faults.tachometer_faults_1); the dictionary's 0.25 rpm counts quantise them on encoding."""
    table, _ = fault_kernels.fault_table(s.variants[:1])
    speeds = np.array(sr["wheel_speed_rad_s"], dtype=float, order="C")
    for k in range(t_s.shape[0]):
        fault_kernels.tachometer_faults_1(table[0], float(t_s[k]), speeds[k])
    return speeds


def _hk_values(
    traj: Trajectory,
    s: Scenario,
    definition: PacketDefinition,
    rows: np.ndarray,
    carry: TelemetryCarry,
    events: list[tuple[float, str, int]],
) -> dict[str, np.ndarray]:
    """ACS_HK engineering values at the trajectory rows (estimates, programme, actuators, sensor samples), the
    onboard ``events`` so far."""
    sr = {name: series[0, rows] for name, series in traj.series.items()}
    t_s = traj.t_s[rows]
    wheels = [str(k + 1) for k in range(sr["wheel_speed_rad_s"].shape[-1])]
    event, argument = _last_events(events, definition, t_s)
    values = {
        **_split("q_st_ib", _star_tracker(sr, s, t_s, carry), "0123"),
        **_split("omega_gyro_b_rad_s", _gyro(sr, s, t_s, carry), "xyz"),
        **_split("b_mag_b_t", _magnetometer(sr, s, t_s, _representable(definition, "b_mag_b_t_x"), carry), "xyz"),
        **_split("q_est_ib", sr["q_est_ib"], "0123"),
        **_split("q_prog_ib", sr["q_prog_ib"], "0123"),
        **_split("omega_est_b_rad_s", sr["omega_est_b_rad_s"], "xyz"),
        **_split("wheel_speed_rad_s", _tachometer(sr, s, t_s), wheels),
        **_split("wheel_torque_cmd_nm", sr["wheel_torque_cmd_nm"], wheels),
        **_split("wheel_current_a", sr["wheel_torque_nm"] / WHEEL_TORQUE_CONSTANT_NM_A, wheels),
        **_split("md_dipole_am2", sr["md_dipole_am2"], "xyz"),
        "mode": _mode(events, s, definition, t_s),
        "fdir_event": event,
        "fdir_event_argument": argument,
        **_fdir_flags(events, definition, t_s),
    }
    return values


def _representable(definition: PacketDefinition, name: str) -> float:
    """Largest magnitude a signed, linearly calibrated field can carry (engineering units)."""
    p = next(p for p in definition.parameters if p.name == name)
    return ((1 << (p.bit_length - 1)) - 1) * abs(p.polynomial[1])


def gps_week_seconds(t_utc_ns: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """GPS week (not rolled over) and seconds of week of UTC times: GPS = UTC + (TAI−UTC) − 19 s (IS-GPS-200 §3.3.4)."""
    from skyfield.api import load

    t = np.asarray(t_utc_ns, dtype=np.int64)
    if np.any(t < GPS_EPOCH_UTC_NS):
        raise ValueError("t_utc_ns: times before the GPS epoch 1980-01-06 have no GPS week")
    ts = load.timescale(builtin=True)
    jd_utc = 2440587.5 + t / (86_400.0 * NS_PER_S)
    tai_minus_utc = ts.leap_offsets[np.searchsorted(ts.leap_dates, jd_utc, side="right") - 1]
    gps_ns = t - GPS_EPOCH_UTC_NS + (tai_minus_utc.astype(np.int64) - TAI_MINUS_GPS_S) * NS_PER_S
    week, ns = np.divmod(gps_ns, SECONDS_PER_WEEK * NS_PER_S)
    return week, ns / NS_PER_S


def _gps_values(
    traj: Trajectory,
    s: Scenario,
    definition: PacketDefinition,
    rows: np.ndarray,
    t_utc_ns: np.ndarray,
    carry: TelemetryCarry,
) -> dict[str, np.ndarray]:
    """GPS_NAV engineering values: ECEF fix of the flown orbit with seed 003's receiver noise, GPS time."""
    t_unix = traj.extra["epoch_unix_s"] + traj.t_s[rows]
    r_eci = traj.series["r_eci_m"][0, rows]
    _, v_eci, _ = orbit_state(s)(t_unix)
    r_ecef, v_ecef = frames.eci_to_ecef(r_eci, v_eci, t_unix)
    r_fix, v_fix, _ = sensors.gps_receiver(r_ecef, v_ecef, GPS_SIGMA_R_M, GPS_SIGMA_V_M_S, 0.0, carry.rng)
    week, seconds = gps_week_seconds(t_utc_ns)
    n = rows.shape[0]
    return {
        **_split("r_ecef_m", r_fix, "xyz"),
        **_split("v_ecef_m_s", v_fix, "xyz"),
        "gps_week": week,
        "gps_seconds_of_week": seconds,
        "n_satellites": np.full(n, GPS_SATELLITES_TRACKED, dtype=np.int64),
        "fix_type": np.full(n, _codes(definition, "fix_type")["FIX_3D"], dtype=np.int64),
    }


def packet_series(
    traj: Trajectory, s: Scenario, dictionary: Dictionary, seed: int = 0, carry: TelemetryCarry | None = None
) -> dict[str, PacketSeries]:
    """Engineering values of ACS_HK (every T_q) and GPS_NAV (every 1 s) from a flown trajectory (variant 0).

    ``carry``: a segment of a longer flight (its sample times since the epoch), the sensors going on from the
    previous segment's carry and leaving theirs in it; without it, sensors start afresh from ``seed``."""
    packets = _check_packets(dictionary, traj.series["wheel_speed_rad_s"].shape[-1])
    output_dt = float(traj.t_s[1] - traj.t_s[0]) if traj.t_s.shape[0] > 1 else s.output_dt_s
    epoch_ns = int(round(traj.extra["epoch_unix_s"] * NS_PER_S))
    carry = carry or TelemetryCarry(np.random.default_rng(np.random.SeedSequence([s.seed, seed, EMULATOR_STREAM])))
    events = carry.events + traj.events[0]
    out = {}
    for name in (HK_PACKET, GPS_PACKET):
        definition = packets[name]
        rows = np.flatnonzero(np.rint(traj.t_s / output_dt).astype(np.int64) % _stride(definition, output_dt) == 0)
        t_ns = epoch_ns + np.rint(traj.t_s[rows] * NS_PER_S).astype(np.int64)
        if name == HK_PACKET:
            values = _hk_values(traj, s, definition, rows, carry, events)
        else:
            values = _gps_values(traj, s, definition, rows, t_ns, carry)
        out[name] = PacketSeries(definition, t_ns, values)
    carry.events = _kept_events(events)
    return out


def _check_packets(dictionary: Dictionary, n_wheels: int) -> dict[str, PacketDefinition]:
    """The dictionary's packets by name; ValueError unless it has the reference satellite's ACS_HK (with a period
    and ``n_wheels`` wheels) and GPS_NAV."""
    packets = {p.name: p for p in dictionary.packets.values()}
    missing = {HK_PACKET, GPS_PACKET} - set(packets)
    if missing:
        raise ValueError(f"dictionary: the emulator needs packets {sorted(missing)} of the reference satellite")
    carried = sum(1 for p in packets[HK_PACKET].parameters if p.name.startswith("wheel_speed_rad_s_"))
    if carried != n_wheels:
        raise ValueError(
            f"scenario.spacecraft.cluster.wheels: the dictionary carries {carried} wheels, "
            f"the scenario flies {n_wheels}"
        )
    return packets


def _kept_events(events: list[tuple[float, str, int]]) -> list[tuple[float, str, int]]:
    """The events later telemetry still shows: the last onboard-known one, the last mode change, every isolation."""
    known = [i for i, e in enumerate(events) if e[1] not in HIDDEN_EVENTS]
    changes = [i for i, e in enumerate(events) if e[1] == "mode_change"]
    kept = {i for i, e in enumerate(events) if e[1] == "fault_isolated"} | set(known[-1:]) | set(changes[-1:])
    return [events[i] for i in sorted(kept)]  # in their order: the last of equal times is the one shown


def encode_stream(series: dict[str, PacketSeries], first_count: int | Mapping[str, int] = 0) -> PacketStream:
    """Packets of every series merged in time order, per-APID sequence counts mod 2^14 (CCSDS 133.0-B-2 §4.1.3.4)
    from ``first_count`` (one for all, or per packet name: a segment going on from the previous one's counts)."""
    blocks, times, apids, lengths = [], [], [], []
    for name, item in series.items():
        n = item.t_utc_ns.shape[0]
        first = first_count if isinstance(first_count, int) else first_count.get(name, 0)
        counts = (first + np.arange(n)) % SEQUENCE_COUNT_MODULUS
        blocks.append(encode_packets(item.definition, item.t_utc_ns, counts, item.values))
        times.append(item.t_utc_ns)
        apids.append(np.full(n, item.definition.apid, dtype=np.int64))
        lengths.append(np.full(n, item.definition.packet_octets, dtype=np.int64))
    t, apid, size = np.concatenate(times), np.concatenate(apids), np.concatenate(lengths)
    order = np.lexsort((apid, t))
    starts = np.concatenate([[0], np.cumsum(size)[:-1]])
    flat = np.concatenate([b.reshape(-1) for b in blocks])
    pieces = [flat[a : a + n] for a, n in zip(starts[order], size[order])]
    data = np.concatenate(pieces).tobytes() if pieces else b""
    return PacketStream(data, np.cumsum(size[order]), t[order], apid[order])


class Satellite:
    """The emulated satellite flying without end: :meth:`fly` flies and packetises the next segment, the flight's
    whole state handed over (sim_core.engine.Flight) and the sensors' noise, drift, onboard events and sequence
    counts going on (:class:`TelemetryCarry`), so that the segments' packets are one continuous stream."""

    def __init__(self, s: Scenario, dictionary: Dictionary | None = None, seed: int = 0, fdir: bool = True) -> None:
        """``s``: the scenario as flown (:func:`satellite_scenario`); ``seed``: of the sensor noise."""
        self.scenario, self.dictionary = s, dictionary or load_dictionary(REFERENCE_DICTIONARY)
        _check_packets(self.dictionary, len(s.spacecraft.cluster.wheels))
        self.flight = Flight(s, fdir=fdir)
        self.telemetry = TelemetryCarry(np.random.default_rng(np.random.SeedSequence([s.seed, seed, EMULATOR_STREAM])))

    def fly(self, duration_s: float) -> tuple[Trajectory, dict[str, PacketSeries], PacketStream]:
        """The next ``duration_s`` of the flight: trajectory, values, packets."""
        traj = self.flight.fly(duration_s)
        series = packet_series(traj, self.scenario, self.dictionary, carry=self.telemetry)
        stream = encode_stream(series, self.telemetry.counts)
        for name, item in series.items():
            self.telemetry.counts[name] = (
                self.telemetry.counts.get(name, 0) + len(item.t_utc_ns)
            ) % SEQUENCE_COUNT_MODULUS
        return traj, series, stream


def hk_period_s(dictionary: Dictionary) -> float:
    """Period of the dictionary's ACS_HK packet (the emulator's output step); ValueError if it has none."""
    hk = next((p for p in dictionary.packets.values() if p.name == HK_PACKET), None)
    if hk is None or hk.period_s is None:
        raise ValueError(f"dictionary: needs packet {HK_PACKET} with a period_s")
    return float(hk.period_s)


def emulate(
    scenario: str | Scenario = DEFAULT_SCENARIO,
    faults: Sequence[FaultSpec] = (),
    duration_s: float | None = None,
    start_utc: str | None = None,
    dictionary: Dictionary | None = None,
    seed: int = 0,
    fdir: bool = True,
    truth_seed: int | None = 0,
) -> tuple[Trajectory, dict[str, PacketSeries], PacketStream]:
    """Fly the satellite (hidden faults, onboard FDIR on, its own truth parameters unless ``truth_seed`` is
    None) for ``duration_s`` (default: the scenario's) and packetise its telemetry: trajectory, values, packets."""
    dictionary = dictionary or load_dictionary(REFERENCE_DICTIONARY)
    s = satellite_scenario(scenario, faults, duration_s, start_utc, hk_period_s(dictionary), truth_seed)
    return Satellite(s, dictionary, seed, fdir).fly(s.duration_s)


async def flight_streams(
    satellite: Satellite, segment_s: float = SEGMENT_S, duration_s: float | None = None
) -> AsyncGenerator[PacketStream, None]:
    """The satellite's packets segment after segment (``segment_s`` each) for ``duration_s`` (None: without end);
    the next segment is flown in a worker thread while the caller sends this one, so the stream never waits."""
    if not segment_s > 0.0:
        raise ValueError(f"segment_s: must be > 0, got {segment_s}")
    loop, flown = asyncio.get_running_loop(), 0.0

    def next_length() -> float:
        return segment_s if duration_s is None else min(segment_s, duration_s - flown)

    pending = loop.run_in_executor(None, satellite.fly, next_length())
    while True:
        flown += next_length()
        _, _, stream = await pending
        more = duration_s is None or flown < duration_s - 1e-9
        if more:
            pending = loop.run_in_executor(None, satellite.fly, next_length())
        yield stream
        if not more:
            return


def demo_pass_bytes(
    scenario: str | Scenario = DEFAULT_SCENARIO,
    t_start_s: float = 0.0,
    t_stop_s: float | None = None,
    faults: Sequence[FaultSpec] = (),
    start_utc: str | None = None,
    seed: int = 0,
) -> bytes:
    """Packet file of a demo pass: the satellite's packets stamped in [t_start_s, t_stop_s) after the scenario epoch."""
    if t_start_s < 0.0 or (t_stop_s is not None and t_stop_s <= t_start_s):
        raise ValueError(f"t_start_s/t_stop_s: need 0 <= start < stop, got {t_start_s}, {t_stop_s}")
    traj, _, stream = emulate(scenario, faults, t_stop_s, start_utc, seed=seed)
    epoch_ns = int(round(traj.extra["epoch_unix_s"] * NS_PER_S))
    stop_ns = epoch_ns + int(round((t_stop_s if t_stop_s is not None else traj.t_s[-1] + 1.0) * NS_PER_S))
    return stream.window(epoch_ns + int(round(t_start_s * NS_PER_S)), stop_ns).data


class Clock(Protocol):
    """What the sender's pace reads and waits on: a monotonic clock (s), the UTC clock (Unix s) and a wait."""

    def monotonic(self) -> float: ...

    def time(self) -> float: ...

    async def sleep(self, delay_s: float) -> None: ...


class _SystemClock:
    """The machine's clocks (time.monotonic, time.time) and asyncio.sleep."""

    def monotonic(self) -> float:
        return time.monotonic()

    def time(self) -> float:
        return time.time()

    async def sleep(self, delay_s: float) -> None:
        await asyncio.sleep(delay_s)


SYSTEM_CLOCK: Clock = _SystemClock()


@dataclass(frozen=True)
class SendOptions:
    """Where and how :func:`send_stream` / :func:`send_streams` send: the listener's ``host``:``port``, the pace
    ``rate`` × the packets' time stamps (inf: as fast as possible), a reconnect every ``retry_s`` (``attempts``
    None: keep trying), real-time release on the UTC clock (``on_wall_clock``), the hello line's
    ``satellite`` and ``dictionary`` (telemetry.live.hello), and the ``clock`` the pace follows (the machine's;
    a test passes one it steps itself). Checked when made (ValueError naming the field)."""

    host: str = "127.0.0.1"
    port: int = 10025
    rate: float = 1.0
    retry_s: float = RETRY_S
    attempts: int | None = None
    on_wall_clock: bool = False
    satellite: str | None = None
    dictionary: str | None = None
    clock: Clock = SYSTEM_CLOCK

    def __post_init__(self) -> None:
        if not self.rate > 0.0:
            raise ValueError(f"rate: must be > 0 (inf = unpaced), got {self.rate}")
        if self.on_wall_clock and self.rate != 1.0:
            raise ValueError(
                f"on_wall_clock: packets can follow the UTC clock only in real time (rate 1), got rate {self.rate}"
            )
        if self.port <= 0 or self.port > 65535:
            raise ValueError(f"port: expected 1..65535, got {self.port}")
        if self.attempts is not None and self.attempts < 1:
            raise ValueError(f"attempts: expected at least 1 (None = keep trying), got {self.attempts}")
        if self.dictionary is not None and self.satellite is None:
            raise ValueError("dictionary: a hello line names the dictionary of a named satellite (give satellite)")

    def greeting(self) -> bytes:
        """The line each connection opens with: the hello naming the satellite, empty without one."""
        from telemetry.live import hello

        return b"" if self.satellite is None else hello(self.satellite, self.dictionary)


async def _connect(options: SendOptions, greeting: bytes) -> tuple[asyncio.StreamReader, asyncio.StreamWriter]:
    """Open a TCP connection that starts with ``greeting``, retrying every retry_s (attempts None = forever)."""
    tried = 0
    while True:
        try:
            reader, writer = await asyncio.open_connection(options.host, options.port)
            writer.write(greeting)
            await writer.drain()
            return reader, writer
        except OSError:
            tried += 1
            if options.attempts is not None and tried >= options.attempts:
                raise
            await asyncio.sleep(options.retry_s)


async def send_stream(stream: PacketStream, options: SendOptions) -> SendReport:
    """Send packets over TCP as ``options`` say, reconnecting (:func:`send_streams` of this one stream)."""

    async def once() -> AsyncIterator[PacketStream]:
        yield stream

    return await send_streams(once(), options)


@dataclass
class _Link:
    """An open connection with its greeting, and the pace: wall clock (monotonic s) of the first packet's time."""

    reader: asyncio.StreamReader
    writer: asyncio.StreamWriter
    greeting: bytes
    wall0: float
    t0_ns: int


async def send_streams(streams: AsyncIterator[PacketStream], options: SendOptions) -> SendReport:
    """Send the packets of each stream in turn over one TCP link, paced at ``options.rate`` × their time stamps from
    the first packet's (inf: as fast as possible), reconnecting.

    ``options.satellite``: each connection opens with telemetry.live.hello(satellite, dictionary), so that a listener
    serving a fleet files the packets under that name (without it, under the listener's own satellite) and, for a
    mixed fleet, decodes them with the ``dictionary`` it knows by that id (without it, with its own).

    ``options.on_wall_clock`` (real time only): each packet leaves when the UTC clock reaches its time stamp
    (those already due leave at once). TCP gives no application acknowledgement, so after a lost link
    the packets of the current stream written in the last ``REWIND_S`` are sent again; the archive drops
    duplicates (same APID, count and time).
    """
    greeting = options.greeting()
    report, link = SendReport(), None
    try:
        async for stream in streams:
            if len(stream) == 0:
                continue
            if link is None:
                reader, writer = await _connect(options, greeting)
                report.connections += 1
                wall0 = options.clock.monotonic()
                if options.on_wall_clock:
                    wall0 -= options.clock.time() - int(stream.t_utc_ns[0]) / NS_PER_S
                link = _Link(reader, writer, greeting, wall0, int(stream.t_utc_ns[0]))
            await _send_one(stream, link, options, report)
    finally:
        if link is not None:
            link.writer.close()
            with contextlib.suppress(ConnectionError, OSError):
                await link.writer.wait_closed()
    return report


async def _send_one(stream: PacketStream, link: _Link, options: SendOptions, report: SendReport) -> None:
    """Write one stream's packets on ``link`` at their pace, reconnecting it (and re-sending) when it drops."""
    n = len(stream)
    starts = np.concatenate([[0], stream.ends[:-1]])
    due_s = (stream.t_utc_ns - link.t0_ns) / NS_PER_S / options.rate
    i, clock = 0, options.clock
    recent: deque[tuple[float, int]] = deque()  # (monotonic s, packet index) written within REWIND_S
    while i < n:
        j = int(np.searchsorted(due_s, clock.monotonic() - link.wall0, side="right"))
        if j <= i:
            await clock.sleep(due_s[i] - (clock.monotonic() - link.wall0))
            continue
        try:
            if link.reader.at_eof():
                raise ConnectionResetError("listener closed the connection")
            link.writer.write(stream.data[int(starts[i]) : int(stream.ends[j - 1])])
            await link.writer.drain()
        except (ConnectionError, OSError):
            link.writer.close()
            resume = _rewind(recent, i)
            report.packets_resent += i - resume
            i = resume
            link.reader, link.writer = await _connect(options, link.greeting)
            report.connections += 1
            continue
        recent.append((clock.monotonic(), i))
        while recent and recent[0][0] < clock.monotonic() - REWIND_S:
            recent.popleft()
        report.packets_sent += j - i
        report.octets_sent += int(stream.ends[j - 1] - starts[i])
        i = j


def _rewind(recent: deque[tuple[float, int]], i: int) -> int:
    """First packet index written within the last REWIND_S (i if none)."""
    resume = recent[0][1] if recent else i
    recent.clear()
    return resume
