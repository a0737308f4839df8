"""The spacecraft's actual state as its telemetry tells it, and a twin scenario aligned to it (seed 000 §7).

The twin session of seed 000 §7 runs the simulation "with the same values of parameters, initial
conditions and variants of possible faults" as the spacecraft. This module is its telemetry side:
decoded reference-satellite batches (ACS_HK, GPS_NAV; e.g. live messages or an archived pass) become
time series under sim_core's names and layouts (:func:`actual_track`), the GPS fixes become the
circular orbit the twin flies (:func:`fit_circular_orbit`, a least-squares plane and phase through
the fixes), and a library scenario is re-started at a telemetry instant with the telemetered attitude,
rates and wheel speeds, its programme shifted to that instant (:func:`aligned_scenario`), and fault
hypotheses flown as one batch from there are ranked by how closely they reproduce the telemetry
(:func:`rank_hypotheses`).
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass

import numpy as np

from sim_core import frames, orbit, quaternion, sensors
from sim_core.scenario import FaultSpec, Scenario, VariantSpec, shifted_guidance
from telemetry.ccsds import NS_PER_S
from telemetry.dictionary import parse_utc_ns
from telemetry.ingest_report import SampleBatch

__all__ = [
    "ActualTrack",
    "actual_track",
    "fit_circular_orbit",
    "aligned_scenario",
    "aligned_wheel_available",
    "HypothesisFit",
    "rank_hypotheses",
    "HK_SERIES",
    "WHEEL_SERIES",
    "GPS_SERIES",
]

# sim_core series name → (dictionary parameter prefix, component suffixes); None = a scalar parameter.
HK_SERIES = {
    "q_st_ib": ("q_st_ib", "0123"),
    "q_est_ib": ("q_est_ib", "0123"),
    "q_prog_ib": ("q_prog_ib", "0123"),
    "omega_est_b_rad_s": ("omega_est_b_rad_s", "xyz"),
    "omega_gyro_b_rad_s": ("omega_gyro_b_rad_s", "xyz"),
    "md_dipole_am2": ("md_dipole_am2", "xyz"),
    "b_mag_b_t": ("b_mag_b_t", "xyz"),
    "mode": ("mode", None),
    "attitude_error_rad": ("attitude_error_rad", None),
}
WHEEL_SERIES = ("wheel_speed_rad_s", "wheel_torque_cmd_nm", "wheel_current_a", "fault_wheel")  # suffixes _1 … _n
GPS_SERIES = {"r_ecef_m": ("r_ecef_m", "xyz"), "v_ecef_m_s": ("v_ecef_m_s", "xyz")}
MIN_GPS_FIXES = 3  # a plane and a phase need at least three non-collinear positions
GPS_SIGMA_RATIO_S = 15.0 / 1.5  # σ_r / σ_v of the receiver, seed 003 §3.2.1.1: 15 m and 1.5 m/s (2σ)
SMOOTHING_FIXES = 31  # ±15 fixes at 1 Hz: a cubic's truncation error there is (nτ)⁴a/24 ≈ 2 cm at LEO
SMOOTHING_DEGREE = 3
TACHOMETER_COUNT_RAD_S = 0.25 * np.pi / 30.0  # wheel-speed count of the reference dictionary (0.25 rpm)


@dataclass(frozen=True)
class ActualTrack:
    """Telemetered series in sim_core layouts: ACS_HK at ``t_utc_ns`` (n,), GPS at ``gps_t_utc_ns`` (m,)."""

    t_utc_ns: np.ndarray
    series: dict[str, np.ndarray]
    gps_t_utc_ns: np.ndarray
    gps: dict[str, np.ndarray]

    def orbit_eci(self, t_unix_s: np.ndarray, fit_window_s: float = 60.0) -> tuple[np.ndarray, np.ndarray]:
        """ECI position (m) and velocity (m/s) at t from the GPS fixes: a local least-squares cubic through the fixes
        inside their span, the circular orbit fitted to the nearest ``fit_window_s`` of them beyond (seed 003
        §3.2.3.2.1 Keplerian OP)."""
        t = np.atleast_1d(np.asarray(t_unix_s, dtype=float))
        t_fix = self.gps_t_utc_ns / NS_PER_S
        if t_fix.shape[0] < MIN_GPS_FIXES:
            raise ValueError(f"gps_t_utc_ns: need at least {MIN_GPS_FIXES} GPS fixes, got {t_fix.shape[0]}")
        r_fix, v_fix = frames.ecef_to_eci(self.gps["r_ecef_m"], self.gps["v_ecef_m_s"], t_fix)
        r, v = _smoothed_fixes(t_fix, r_fix, v_fix, np.clip(t, t_fix[0], t_fix[-1]))
        for outside, edge in ((t < t_fix[0], t_fix[0]), (t > t_fix[-1], t_fix[-1])):
            if outside.any():
                near = np.abs(t_fix - edge) <= fit_window_s
                el = fit_circular_orbit(t_fix[near], self.gps["r_ecef_m"][near], self.gps["v_ecef_m_s"][near], edge)
                r[outside], v[outside] = orbit.circular_orbit(
                    t[outside] - edge, el["altitude_m"], el["inclination_deg"], el["raan_deg"], el["arg_latitude_deg"]
                )
        return r, v

    def at(self, t_utc_ns: int) -> int:
        """Index of the ACS_HK sample stamped exactly t_utc_ns; ValueError if there is none."""
        k = int(np.searchsorted(self.t_utc_ns, t_utc_ns))
        if k >= self.t_utc_ns.shape[0] or self.t_utc_ns[k] != t_utc_ns:
            raise ValueError(f"t_utc_ns: no ACS_HK sample at {np.datetime64(int(t_utc_ns), 'ns')}Z")
        return k


def _merged(batches: Sequence[SampleBatch]) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """Times and values of several batches of one packet, time-ordered, repeated times dropped."""
    t = np.concatenate([b.t_utc_ns for b in batches])
    names = set(batches[0].values)
    values = {n: np.concatenate([np.asarray(b.values[n]) for b in batches]) for n in names}
    t_unique, first = np.unique(t, return_index=True)
    return t_unique, {n: v[first] for n, v in values.items()}


def _stack(values: dict[str, np.ndarray], prefix: str, suffixes: str | None) -> np.ndarray:
    """(n, k) array of parameters prefix_suffix, or (n,) for a scalar; ValueError naming a missing one."""
    names = [prefix] if suffixes is None else [f"{prefix}_{s}" for s in suffixes]
    missing = [n for n in names if n not in values]
    if missing:
        raise ValueError(f"batches: telemetry lacks parameters {missing}")
    return values[prefix] if suffixes is None else np.stack([values[n] for n in names], axis=-1).astype(np.float64)


def actual_track(batches: Iterable[SampleBatch], hk_packet: str = "ACS_HK", gps_packet: str = "GPS_NAV") -> ActualTrack:
    """Decoded reference-satellite batches (any order, repeats allowed) as time series under sim_core's names."""
    by_packet: dict[str, list[SampleBatch]] = {}
    for b in batches:
        if len(b.t_utc_ns):
            by_packet.setdefault(b.packet, []).append(b)
    for name in (hk_packet, gps_packet):
        if name not in by_packet:
            raise ValueError(f"batches: no {name} samples")
    t, hk = _merged(by_packet[hk_packet])
    series = {name: _stack(hk, prefix, sfx) for name, (prefix, sfx) in HK_SERIES.items()}
    n_wheels = sum(1 for n in hk if n.startswith(f"{WHEEL_SERIES[0]}_"))
    wheels = "".join(str(k + 1) for k in range(n_wheels))
    series.update({name: _stack(hk, name, wheels) for name in WHEEL_SERIES})
    gps_t, gps = _merged(by_packet[gps_packet])
    return ActualTrack(t, series, gps_t, {name: _stack(gps, p, sfx) for name, (p, sfx) in GPS_SERIES.items()})


def _smoothed_fixes(t_fix: np.ndarray, r_fix: np.ndarray, v_fix: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, ...]:
    """r, v at t by a weighted least-squares cubic in time through the nearest SMOOTHING_FIXES fixes (r and v)."""
    m = min(SMOOTHING_FIXES, t_fix.shape[0])
    start = np.clip(np.searchsorted(t_fix, t) - m // 2, 0, t_fix.shape[0] - m)
    idx = start[:, None] + np.arange(m)
    tau = t_fix[idx] - t[:, None]  # (Q, m) s
    powers = np.arange(SMOOTHING_DEGREE + 1)
    a_r = tau[..., None] ** powers  # position rows: Σ c_k τ^k
    a_v = GPS_SIGMA_RATIO_S * powers * tau[..., None] ** np.maximum(powers - 1, 0)  # velocity rows, weighted
    design = np.concatenate([a_r, a_v], axis=1)  # (Q, 2m, d+1)
    observed = np.concatenate([r_fix[idx], GPS_SIGMA_RATIO_S * v_fix[idx]], axis=1)  # (Q, 2m, 3)
    scale = np.maximum(np.abs(tau).max(axis=1), 1.0)[:, None, None] ** powers  # conditioning: τ in units of the window
    normal = np.einsum("qik,qil->qkl", design / scale, design / scale)
    coeff = np.linalg.solve(normal, np.einsum("qik,qij->qkj", design / scale, observed)) / np.swapaxes(scale, 1, 2)
    return coeff[:, 0], coeff[:, 1]


def fit_circular_orbit(
    t_unix_s: np.ndarray, r_ecef_m: np.ndarray, v_ecef_m_s: np.ndarray, t0_unix_s: float
) -> dict[str, float]:
    """Circular-orbit elements at t0 fitted to GPS fixes: plane by least squares, radius and phase u = u0 + n (t − t0).

    The plane's normal n is the one that best satisfies n·r = 0 and n·v = 0 for every fix, each row weighted by
    its receiver noise (velocities scaled by σ_r/σ_v): positions alone fix the plane only once the fixes span an
    arc (five fixes 1 s apart tilt it by ~40″), while the velocities fix it to a few arcseconds from three fixes.
    Returns ``altitude_m``, ``inclination_deg``, ``raan_deg``, ``arg_latitude_deg`` as
    :func:`sim_core.orbit.circular_orbit` takes them (seed 003 §3.2.3.2.1 Keplerian OP).
    """
    t = np.asarray(t_unix_s, dtype=float)
    if t.shape[0] < MIN_GPS_FIXES:
        raise ValueError(f"t_unix_s: need at least {MIN_GPS_FIXES} GPS fixes, got {t.shape[0]}")
    r, v = frames.ecef_to_eci(r_ecef_m, v_ecef_m_s, t)
    rows = np.concatenate([r, GPS_SIGMA_RATIO_S * v])
    normal = np.linalg.svd(rows, full_matrices=False)[2][-1]  # plane nearest the fixes (above); not the (2n, 2n) U
    if np.dot(normal, np.cross(r, v).sum(axis=0)) < 0.0:
        normal = -normal
    node = np.cross([0.0, 0.0, 1.0], normal)
    node /= np.linalg.norm(node)
    a = float(np.linalg.norm(r, axis=-1).mean())
    n = np.sqrt(orbit.MU_EARTH_M3_S2 / a**3)
    u = np.arctan2(r @ np.cross(normal, node), r @ node)
    u0 = np.angle(np.mean(np.exp(1j * (u - n * (t - t0_unix_s)))))
    return {
        "altitude_m": a - orbit.R_EARTH_M,
        "inclination_deg": float(np.degrees(np.arccos(np.clip(normal[2], -1.0, 1.0)))),
        "raan_deg": float(np.degrees(np.arctan2(node[1], node[0]))),
        "arg_latitude_deg": float(np.degrees(u0)),
    }


def aligned_scenario(
    base: Scenario,
    track: ActualTrack,
    t_align_utc_ns: int,
    duration_s: float,
    faults: Sequence[FaultSpec] = (),
    gps_window_s: float = 60.0,
) -> Scenario:
    """The twin of ``base`` started at a telemetry instant: epoch, orbit, attitude, rates, wheel speeds from telemetry.

    Hypothesised faults (``faults``, times from the new epoch) make the twin's one variant.
    """
    k = track.at(t_align_utc_ns)
    elapsed_s = (t_align_utc_ns - parse_utc_ns(base.orbit.epoch_utc)) / NS_PER_S
    if elapsed_s < 0.0:
        raise ValueError("t_align_utc_ns: before the scenario's epoch")
    near = np.abs(track.gps_t_utc_ns - t_align_utc_ns) <= gps_window_s * 0.5 * NS_PER_S
    data = base.model_dump()
    data["orbit"]["epoch_utc"] = f"{np.datetime64(int(t_align_utc_ns), 'ns')}Z"
    if base.orbit.kind != "tle":
        t_gps = track.gps_t_utc_ns[near] / NS_PER_S
        data["orbit"].update(
            fit_circular_orbit(
                t_gps, track.gps["r_ecef_m"][near], track.gps["v_ecef_m_s"][near], t_align_utc_ns / NS_PER_S
            )
        )
    data["initial_q_ib"] = quaternion.normalize(track.series["q_est_ib"][k]).tolist()
    data["initial_omega_b_rad_s"] = track.series["omega_est_b_rad_s"][k].tolist()
    for wheel, speed in zip(data["spacecraft"]["cluster"]["wheels"], track.series["wheel_speed_rad_s"][k]):
        wheel["initial_speed_rpm"] = float(speed) * 30.0 / np.pi
    try:
        data["guidance"] = shifted_guidance(data["guidance"], elapsed_s)
    except ValueError as exc:
        raise ValueError(f"t_align_utc_ns: {exc}") from None
    data["duration_s"] = duration_s
    data["variants"] = [VariantSpec(name="twin", faults=list(faults)).model_dump()]
    return Scenario.model_validate(data)


def aligned_wheel_available(track: ActualTrack, t_align_utc_ns: int) -> np.ndarray:
    """(1, n_wheels) wheels onboard FDIR had not isolated at the telemetry instant (``simulate(wheel_available=)``)."""
    available: np.ndarray = track.series["fault_wheel"][track.at(t_align_utc_ns)][None, :] == 0.0
    return available


@dataclass(frozen=True)
class HypothesisFit:
    """How far a twin flying one fault hypothesis stays from the telemetry (RMS over the compared samples)."""

    name: str
    wheel_speed_rms_rad_s: float
    attitude_rms_rad: float
    score: float  # both mismatches in units of the telemetry's own resolution, summed


def rank_hypotheses(
    base: Scenario,
    track: ActualTrack,
    t_align_utc_ns: int,
    duration_s: float,
    hypotheses: dict[str, Sequence[FaultSpec]],
) -> list[HypothesisFit]:
    """Fly every fault hypothesis as one variant of a twin batch aligned to telemetry; best fit first (seed 000 §7).

    The mismatch unit of wheel speeds is the tachometer count of the dictionary (0.25 rpm); of the attitude,
    the star tracker's σ: the twin's true attitude against the telemetered estimate.
    """
    from sim_core.engine import simulate  # the engine's kernels: loaded by a fit, not by an import

    if not hypotheses:
        raise ValueError("hypotheses: give at least one (name -> fault list), e.g. {'nominal': []}")
    twin = aligned_scenario(base, track, t_align_utc_ns, duration_s)
    batch = twin.model_copy(update={"variants": [VariantSpec(name=n, faults=list(f)) for n, f in hypotheses.items()]})
    available = np.repeat(aligned_wheel_available(track, t_align_utc_ns), len(hypotheses), axis=0)
    flown = simulate(Scenario.model_validate(batch.model_dump()), wheel_available=available, fdir=True)
    first = track.at(t_align_utc_ns)
    n = min(flown.t_s.shape[0], track.t_utc_ns.shape[0] - first)
    rows = first + np.arange(n)
    sigma_att = max(base.sensors.star_tracker_sigma_arcsec * sensors.ARCSEC, np.finfo(float).eps)
    fits = []
    for v, name in enumerate(flown.variant_names):
        speed_gap = flown["wheel_speed_rad_s"][v, :n] - track.series["wheel_speed_rad_s"][rows]
        wheel = float(np.sqrt(np.mean(speed_gap**2)))
        twin_q = quaternion.conjugate(flown["q_ib"][v, :n])
        gap = quaternion.angle(quaternion.multiply(twin_q, track.series["q_est_ib"][rows]))
        attitude = float(np.sqrt(np.mean(gap**2)))
        fits.append(HypothesisFit(name, wheel, attitude, wheel / TACHOMETER_COUNT_RAD_S + attitude / sigma_att))
    return sorted(fits, key=lambda f: f.score)
