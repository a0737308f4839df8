"""Real NOAA-20 (JPSS-1) spacecraft-diary data, 2021-04-09 00:00–02:00 UTC, 7,200 samples at 1 Hz:
our SGP4 + frames against its GPS fixes, and its measured attitude against our frames and ORF.

The decoded CSV (space-packet-parser's test data, see ../shared/data/README.md) carries the CCSDS
CDS times already as ISO-8601 UTC; GPS position/velocity are ECEF (m, m/s) at ``ephem_time``; the
quaternion (q1, q2, q3, q4) is scalar-LAST, body → GCRS, at ``att_time`` (0.1 s earlier); body +z
looks at nadir, +x along the flight direction. We convert at this edge: ours = (q4, q1, q2, q3).
"""

from __future__ import annotations

import csv
import datetime as dt

import numpy as np
import pytest

from sim_core import frames, orbit, quaternion

# Issue 2 requirement: both NOAA-20 TLEs are 34–108 days from the packets (README of the data).
SGP4_VS_GPS_TOL_M = 200e3
# Issue 2 requirement for the measured boresight (body +z) against nadir.
NADIR_POINTING_TOL_DEG = 0.5
# NOAA-20 steers to the geodetic (ellipsoid-normal) nadir; an order tighter than the requirement
# shows that the remaining offset from −r̂ is the geodetic/geocentric gap, not our frames.
GEODETIC_NADIR_TOL_DEG = 0.05
# Our ORF x^o is the geocentric nadir −r̂: the geodetic normal through the spacecraft departs from it
# by at most ½ e² a/(a + h) = 0.17° at h = 824 km; 0.03° of margin for the pointing itself.
ORF_VS_REAL_TOL_DEG = 0.2
# NOAA-20 body axes in our ORF (columns): body +x = y^o (flight), +y = z^o, +z = x^o (nadir).
NOAA20_BODY_IN_ORF = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])


def _unix_s(iso: str) -> float:
    return dt.datetime.fromisoformat(iso).replace(tzinfo=dt.UTC).timestamp()


@pytest.fixture(scope="module")
def diary(shared_data) -> dict[str, np.ndarray]:
    path = shared_data / "real" / "noaa20_jpss1_apid11" / "jpss1_apid11_decoded.csv"
    with path.open(newline="") as f:
        rows = list(csv.DictReader(f))

    def cols(*names: str) -> np.ndarray:
        return np.array([[float(r[n]) for n in names] for r in rows])

    return {
        "t_ephem_unix_s": np.array([_unix_s(r["ephem_time"]) for r in rows]),
        "t_att_unix_s": np.array([_unix_s(r["att_time"]) for r in rows]),
        "r_ecef_m": cols("pos_x_m", "pos_y_m", "pos_z_m"),
        "v_ecef_m_s": cols("vel_x_mps", "vel_y_mps", "vel_z_mps"),
        "q_ib": quaternion.normalize(cols("q4", "q1", "q2", "q3")),  # scalar-last → scalar-first
    }


def _state_at_attitude_time(diary: dict[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """GPS state turned into ECI by our frames and carried 0.1 s back to the attitude time."""
    r_eci, v_eci = frames.ecef_to_eci(diary["r_ecef_m"], diary["v_ecef_m_s"], diary["t_ephem_unix_s"])
    dt_s = (diary["t_att_unix_s"] - diary["t_ephem_unix_s"])[:, None]
    return r_eci + v_eci * dt_s, v_eci


def _angle_deg(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    cos = np.sum(a * b, axis=-1) / (np.linalg.norm(a, axis=-1) * np.linalg.norm(b, axis=-1))
    return np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))


def test_diary_covers_two_hours_at_one_hertz(diary):
    assert len(diary["t_ephem_unix_s"]) == 7200
    assert np.all(np.abs(np.diff(diary["t_ephem_unix_s"]) - 1.0) < 1e-3)


@pytest.mark.parametrize("tle_index", [0, 1])
def test_sgp4_of_noaa20_tle_lies_within_200_km_of_gps_fixes(shared_data, diary, tle_index):
    text = (shared_data / "tle" / "real_sso_smallsats.tle").read_text()
    noaa20 = [sat for _, sat in orbit.read_tle_file(text) if sat.satnum == 43013]
    assert len(noaa20) == 2
    t = diary["t_ephem_unix_s"]
    r_eci, v_eci = orbit.propagate_tle(noaa20[tle_index], t)
    r_ecef, _ = frames.eci_to_ecef(r_eci, v_eci, t)
    miss_m = np.linalg.norm(r_ecef - diary["r_ecef_m"], axis=1)
    assert np.max(miss_m) < SGP4_VS_GPS_TOL_M


def test_real_quaternion_points_body_z_at_nadir_through_our_frames(diary):
    r_eci, _ = _state_at_attitude_time(diary)
    z_body_eci = quaternion.rotate(diary["q_ib"], np.array([0.0, 0.0, 1.0]))
    assert np.max(_angle_deg(z_body_eci, -r_eci)) < NADIR_POINTING_TOL_DEG
    lat_deg, lon_deg, _ = frames.ecef_to_geodetic(diary["r_ecef_m"])
    up_ecef = frames.geodetic_to_ecef(lat_deg, lon_deg, 1.0) - frames.geodetic_to_ecef(lat_deg, lon_deg, 0.0)
    up_eci, _ = frames.ecef_to_eci(up_ecef, np.zeros_like(up_ecef), diary["t_ephem_unix_s"])
    assert np.max(_angle_deg(z_body_eci, -up_eci)) < GEODETIC_NADIR_TOL_DEG


def test_orf_quaternion_from_gps_state_agrees_with_real_attitude(diary):
    r_eci, v_eci = _state_at_attitude_time(diary)
    q_orf_body = quaternion.from_dcm(NOAA20_BODY_IN_ORF)
    q_predicted = quaternion.multiply(frames.orf_quaternion(r_eci, v_eci), q_orf_body)
    error = quaternion.multiply(quaternion.conjugate(q_predicted), diary["q_ib"])
    assert np.max(np.degrees(quaternion.angle(error))) < ORF_VS_REAL_TOL_DEG
