"""ACS housekeeping for the diagnosis: a telemetry file or decoded batches as :class:`sim_core.diagnosis.Observations`.

Reads a packet file (``decode_stream``) or a ground CSV/JSON Lines file (``read_ground_file``) with the
satellite's dictionary, finds the packet that carries the wheel speeds, and stacks the series the
diagnosis needs under sim_core's names: estimated attitude (``q_est_ib_0..3``, else the star tracker's
``q_st_ib_0..3``), rates (``omega_est_b_rad_s_*``, else ``omega_gyro_b_rad_s_*``), wheel speeds
``wheel_speed_rad_s_1..n`` and commands ``wheel_torque_cmd_nm_1..n``; optional star-tracker quaternion,
gyro rates and magnetometer field ``b_mag_b_t_*``. With the magnetometer and a GPS position (``r_ecef_m_*``,
any packet, interpolated to the housekeeping times) the field model (IGRF-14, or the scenario's model) at
that position is rotated into the body frame by the estimated attitude, the field the magnetometer should
read (:func:`model_field_body_t`). The tachometer quantum is the dictionary's calibration step of
``wheel_speed_rad_s_1`` (0.25 rpm on the reference satellite). Samples are thinned to at most one per
``MIN_SPACING_S`` (the diagnosis works at the housekeeping's 1 Hz ground rate). The epoch is the first sample.
"""

from __future__ import annotations

from collections.abc import Iterable
from pathlib import Path

import numpy as np

from sim_core.diagnosis import MIN_SAMPLES, Observations
from telemetry.ccsds import NS_PER_S
from telemetry.decoding import decode_stream
from telemetry.dictionary import Dictionary, Parameter
from telemetry.ground_files import read_ground_file
from telemetry.ingest_report import SampleBatch

__all__ = ["GROUND_SUFFIXES", "MIN_SPACING_S", "calibration_step", "model_field_body_t", "observations", "read_batches"]

MIN_SPACING_S = 1.0
MAX_POSITION_GAP_S = 30.0  # GPS fixes further apart than this are not interpolated (no field model there)
GROUND_SUFFIXES = (".csv", ".jsonl", ".ndjson")
ALTERNATIVES = {  # what the diagnosis reads → dictionary prefixes in order of preference
    "q_est_ib": ("q_est_ib", "q_st_ib"),
    "omega_b_rad_s": ("omega_est_b_rad_s", "omega_gyro_b_rad_s"),
}


def read_batches(path: str | Path, dictionary: Dictionary, now_utc_ns: int | None = None) -> list[SampleBatch]:
    """Decoded, validated batches of a packet file or a ground CSV/JSONL file (chosen by the suffix); ValueError
    naming the quarantine reasons when every sample in it was rejected. ``now_utc_ns``: the validation's clock (samples
    later than a day after it are corrupt stamps)."""
    path = Path(path)
    if not path.exists():
        raise ValueError(f"telemetry: no such file {path}")
    if path.suffix.lower() in GROUND_SUFFIXES:
        result = read_ground_file(path, dictionary, now_utc_ns)
    else:
        result = decode_stream(path.read_bytes(), dictionary, source=str(path), now_utc_ns=now_utc_ns)
    rejected = {r: n for r, n in result.report.reason_counts().items() if r != "unknown_parameter"}
    if result.report.samples_accepted == 0 and rejected:  # unknown columns alone: the caller names what is missing
        reasons = ", ".join(f"{n} {r}" for r, n in sorted(rejected.items()))
        raise ValueError(f"telemetry: no sample of {path.name} accepted (quarantined: {reasons})")
    return result.batches


def _merged(batches: list[SampleBatch]) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """One packet's batches in time order, repeated times dropped, all values as float64."""
    t = np.concatenate([b.t_utc_ns for b in batches])
    names = set.intersection(*(set(b.values) for b in batches))
    t_unique, first = np.unique(t, return_index=True)
    return t_unique, {n: np.concatenate([np.asarray(b.values[n], dtype=float) for b in batches])[first] for n in names}


def calibration_step(dictionary: Dictionary, name: str) -> float:
    """Calibration step (engineering units per count) of an integer parameter; 0 for floats or unknown."""
    try:
        _, p = dictionary.parameter(name)
    except (KeyError, ValueError):
        return 0.0
    if isinstance(p, Parameter) and p.data_type in ("int", "uint") and len(p.polynomial) >= 2:
        return abs(float(p.polynomial[1]))
    return 0.0


def _stack(values: dict[str, np.ndarray], prefix: str, suffixes: Iterable[str]) -> np.ndarray | None:
    names = [f"{prefix}_{s}" for s in suffixes]
    if not all(n in values for n in names):
        return None
    return np.stack([values[n] for n in names], axis=-1)


def _positions_ecef(batches: list[SampleBatch], t_ns: np.ndarray) -> np.ndarray | None:
    """GPS positions (ECEF, m) interpolated to ``t_ns`` (NaN rows away from fixes); None without any fix."""
    fixes = [b for b in batches if len(b.t_utc_ns) and "r_ecef_m_x" in b.values]
    if not fixes:
        return None
    t_fix, values = _merged(fixes)
    r = _stack(values, "r_ecef_m", "xyz")
    if r is None:
        return None
    ok = np.all(np.isfinite(r), axis=1)
    t_fix, r = t_fix[ok], r[ok]
    if t_fix.shape[0] < 2:
        return None
    out = np.stack([np.interp(t_ns, t_fix, r[:, i]) for i in range(3)], axis=1)
    k = np.clip(np.searchsorted(t_fix, t_ns), 1, t_fix.shape[0] - 1)
    bracket = t_fix[k] - t_fix[k - 1]
    outside = (t_ns < t_fix[0]) | (t_ns > t_fix[-1]) | (bracket > MAX_POSITION_GAP_S * NS_PER_S)
    out[outside] = np.nan
    return out


def model_field_body_t(r_ecef_m: np.ndarray, t_unix_s: np.ndarray, q_ib: np.ndarray, model: str = "igrf") -> np.ndarray:
    """The field model (T) at ECEF positions in the body frame of attitude ``q_ib``; NaN rows where either is NaN."""
    from sim_core import environment, frames

    out = np.full(r_ecef_m.shape, np.nan)
    ok = np.all(np.isfinite(r_ecef_m), axis=1) & np.all(np.isfinite(q_ib), axis=1)
    if ok.any():
        r_eci, _ = frames.ecef_to_eci(r_ecef_m[ok], np.zeros((int(ok.sum()), 3)), t_unix_s[ok])
        out[ok] = environment.magnetic_field_body_t(r_eci, t_unix_s[ok], q_ib[ok], model)
    return out


def observations(
    batches: list[SampleBatch],
    dictionary: Dictionary,
    satellite: str | None = None,
    n_wheels: int | None = None,
    field_model: str = "igrf",
) -> Observations:
    """The diagnosis's :class:`Observations` from decoded batches; ValueError naming what is missing.

    ``field_model``: the geomagnetic model the magnetometer is compared with (the scenario's)."""
    if satellite is not None and satellite != dictionary.satellite_name:
        raise ValueError(
            f"--satellite {satellite!r}: the dictionary describes {dictionary.satellite_name!r} "
            f"(telemetry from another spacecraft?)"
        )
    carrying = [b for b in batches if len(b.t_utc_ns) and "wheel_speed_rad_s_1" in b.values]
    if not carrying:
        got = sorted({n for b in batches for n in b.values})[:8]
        raise ValueError(
            "telemetry: no wheel speeds (wheel_speed_rad_s_1 …) in the file"
            + (f"; it holds {got} …" if got else "; no sample was accepted")
            + " (another spacecraft?)"
        )
    t_ns, values = _merged(carrying)
    wheels = sorted(int(n.rsplit("_", 1)[1]) for n in values if n.startswith("wheel_speed_rad_s_"))
    if n_wheels is not None and len(wheels) != n_wheels:
        raise ValueError(
            f"telemetry: {len(wheels)} wheel speeds telemetered, the scenario's spacecraft has "
            f"{n_wheels} wheels (telemetry from another spacecraft?)"
        )
    suffixes = [str(w) for w in wheels]
    missing = [f"wheel_torque_cmd_nm_{s}" for s in suffixes if f"wheel_torque_cmd_nm_{s}" not in values]
    picked: dict[str, np.ndarray] = {}
    for key, prefixes in ALTERNATIVES.items():
        comps = "0123" if key.startswith("q_") else "xyz"
        found = next((a for a in (_stack(values, p, comps) for p in prefixes) if a is not None), None)
        if found is None:
            missing.append(" or ".join(f"{p}_{comps[0]}..{comps[-1]}" for p in prefixes))
        else:
            picked[key] = found
    if missing:
        raise ValueError(f"telemetry: the diagnosis needs {', '.join(missing)}; the file lacks them")
    keep = _thinned(t_ns)
    if keep.shape[0] < MIN_SAMPLES:
        raise ValueError(
            f"telemetry: {keep.shape[0]} housekeeping samples ({(t_ns[-1] - t_ns[0]) / NS_PER_S:.0f} s); "
            f"the diagnosis needs at least {MIN_SAMPLES} at ≥ {MIN_SPACING_S:g} s spacing"
        )
    t_ns = t_ns[keep]
    quantum = calibration_step(dictionary, "wheel_speed_rad_s_1")
    if quantum <= 0.0:
        raise ValueError("dictionary: wheel_speed_rad_s_1 has no integer calibration step (the tachometer quantum)")

    def cut(a: np.ndarray | None) -> np.ndarray | None:
        return None if a is None else np.ascontiguousarray(a[keep])

    b_mag = cut(_stack(values, "b_mag_b_t", "xyz"))
    r_ecef = _positions_ecef(batches, t_ns) if b_mag is not None else None
    b_model = None
    if r_ecef is not None:
        b_model = model_field_body_t(r_ecef, t_ns / NS_PER_S, picked["q_est_ib"][keep], field_model)
    return Observations(
        t_s=(t_ns - t_ns[0]) / NS_PER_S,
        epoch_unix_s=float(t_ns[0]) / NS_PER_S,
        q_est_ib=cut(picked["q_est_ib"]),  # type: ignore[arg-type]
        omega_b_rad_s=cut(picked["omega_b_rad_s"]),  # type: ignore[arg-type]
        wheel_speed_rad_s=cut(_stack(values, "wheel_speed_rad_s", suffixes)),  # type: ignore[arg-type]
        wheel_torque_cmd_nm=cut(_stack(values, "wheel_torque_cmd_nm", suffixes)),  # type: ignore[arg-type]
        speed_quantum_rad_s=quantum,
        torque_quantum_nm=_resolution(
            values["wheel_torque_cmd_nm_1"][keep], calibration_step(dictionary, "wheel_torque_cmd_nm_1")
        ),
        q_st_ib=cut(_stack(values, "q_st_ib", "0123")),
        q_prog_ib=cut(_stack(values, "q_prog_ib", "0123")),
        wheel_isolated=cut(_stack(values, "fault_wheel", suffixes)),
        omega_gyro_b_rad_s=cut(_stack(values, "omega_gyro_b_rad_s", "xyz")),
        b_mag_b_t=b_mag if b_model is not None else None,
        b_model_b_t=b_model,
    )


def _resolution(values: np.ndarray, step: float) -> float:
    """The dictionary's step if the values sit on its grid (packets), else 0 (ground files of unrounded values)."""
    v = values[np.isfinite(values)]
    if step <= 0.0 or v.size == 0:
        return 0.0
    counts = v / step
    return step if np.allclose(counts, np.round(counts), rtol=0.0, atol=1e-3) else 0.0


def _thinned(t_ns: np.ndarray) -> np.ndarray:
    """Indices of samples at least MIN_SPACING_S apart, greedily from the first."""
    step = int(MIN_SPACING_S * NS_PER_S)
    if t_ns.shape[0] < 2 or np.min(np.diff(t_ns)) >= step:
        return np.arange(t_ns.shape[0])
    keep, last = [], None
    for i, t in enumerate(t_ns):
        if last is None or t - last >= step:
            keep.append(i)
            last = t
    return np.array(keep, dtype=int)
