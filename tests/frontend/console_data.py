"""Telemetry of a test satellite whose values broke the old dashboard: a temperature near -168.85 degC, a
wheel at -2,000 rpm, a GPS position of +/-6e6 m, a 2e-5 rad angle, an enumerated mode, a quaternion that
flips hemisphere, a wheel FDIR flag (red limit) and a description that tries to inject markup; sent as
ground CSV files through the real upload route."""

from __future__ import annotations

import time

import numpy as np

XSS = '<img src=x onerror="window.__xss=1">'
DICTIONARY_NAME = "console_test.yaml"
DICTIONARY = f"""
name: console test satellite
valid_time_utc: {{from: "2020-01-01T00:00:00Z"}}
packets:
  - name: CONSOLE_HK
    apid: 300
    period_s: 1.0
    packet_octets: 54
    time_code: {{format: CUC, coarse_octets: 4, fine_octets: 2, time_scale: UTC, epoch: "2000-01-01T00:00:00Z"}}
    parameters:
      - {{name: temp_probe_degc, type: float, bits: 32, units: degC, description: "probe temperature"}}
      - {{name: wheel_speed_rpm_1, type: float, bits: 32, units: rpm, description: "wheel 1 speed",
         limits: {{yellow_low: -1500.0, yellow_high: 1500.0, red_low: -1800.0, red_high: 1800.0}}}}
      - {{name: gps_pos_x_m, type: float, bits: 64, units: m, description: "GPS position, ECEF x"}}
      - {{name: attitude_error_rad, type: float, bits: 32, units: rad, description: '{XSS} attitude error'}}
      - {{name: mode, type: uint, bits: 8, description: "ACS mode", enumeration: {{0: STANDBY, 3: THREE_AXIS}}}}
      - {{name: q_ib_0, type: float, bits: 32, units: '1', description: "q_ib scalar"}}
      - {{name: q_ib_1, type: float, bits: 32, units: '1', description: "q_ib x"}}
      - {{name: q_ib_2, type: float, bits: 32, units: '1', description: "q_ib y"}}
      - {{name: q_ib_3, type: float, bits: 32, units: '1', description: "q_ib z"}}
      - {{name: fault_wheel_1, type: uint, bits: 8, description: "FDIR: wheel 1 isolated",
         enumeration: {{0: OK, 1: FAULT}}, limits: {{yellow_high: 0.5, red_high: 0.5}}}}
      - {{name: twin_attitude_residual_arcsec, type: float, bits: 32, units: arcsec,
         description: "actual vs twin attitude (named as the live twin archives it)"}}
"""
COLUMNS = [
    "temp_probe_degc",
    "wheel_speed_rpm_1",
    "gps_pos_x_m",
    "attitude_error_rad",
    "mode",
    "q_ib_0",
    "q_ib_1",
    "q_ib_2",
    "q_ib_3",
    "fault_wheel_1",
    "twin_attitude_residual_arcsec",
]
N = 600  # ten minutes at 1 Hz
FLIP_AT = 300  # the quaternion's sign flips here (same attitude, other hemisphere)


def history(end_unix_s: float, n: int = N) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """n samples at 1 Hz ending at end_unix_s: slow sweeps through the awkward values, no fault."""
    t = end_unix_s - np.arange(n)[::-1].astype(float)
    phase = np.linspace(0.0, 1.0, n)
    half = 0.5 * np.radians(10.0) * phase  # 10 deg about body z over the window
    q = np.stack([np.cos(half), np.zeros(n), np.zeros(n), np.sin(half)])
    q[:, FLIP_AT:] *= -1.0
    values = {
        "temp_probe_degc": -168.85 + 0.3 * np.sin(6 * phase),
        "wheel_speed_rpm_1": -2000.0 + 400.0 * phase,
        "gps_pos_x_m": 6.0e6 * np.cos(np.pi * phase),
        "attitude_error_rad": 2.0e-5 * (1 + phase),
        "mode": np.full(n, 3.0),
        "q_ib_0": q[0],
        "q_ib_1": q[1],
        "q_ib_2": q[2],
        "q_ib_3": q[3],
        "fault_wheel_1": np.zeros(n),
        "twin_attitude_residual_arcsec": 3.0 + np.sin(20 * phase),
    }
    return t, values


def csv_bytes(t: np.ndarray, values: dict[str, np.ndarray]) -> bytes:
    """Ground CSV: t_utc_ns then one column per parameter."""
    names = [c for c in COLUMNS if c in values]
    lines = ["t_utc_ns," + ",".join(names)]
    for i in range(t.size):
        lines.append(f"{int(round(t[i] * 1e9))}," + ",".join(repr(float(values[c][i])) for c in names))
    return ("\n".join(lines) + "\n").encode()


def upload(client, satellite: str, t: np.ndarray, values: dict[str, np.ndarray]) -> dict:
    """Send a ground CSV through POST /telemetry/uploads; the ingest report."""
    r = client.post(
        "/api/v1/telemetry/uploads",
        params={"satellite": satellite, "dictionary": DICTIONARY_NAME, "format": "csv"},
        content=csv_bytes(t, values),
    )
    r.raise_for_status()
    return r.json()


def one_row(t_unix_s: float, **overrides: float) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """A single sample at t_unix_s: nominal values, some overridden."""
    _, values = history(t_unix_s, 1)
    for name, value in overrides.items():
        values[name] = np.array([value])
    return np.array([t_unix_s]), values


def now_s() -> float:
    return time.time()
