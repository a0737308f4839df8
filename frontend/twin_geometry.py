"""Everything the twin scenes draw, in scene units (Earth radii), computed once per playback tick and
shared by all monitors: Earth orientation, Sun, spacecraft poses, line of sight, footprint, CCD line,
ground trace, survey zone, station circles and terminator (seed 000 §6 SURIUS-S map and animation).

Scene frame: ECI axes, unit = WGS84 equatorial radius. Ground geometry stays in ECEF and hangs under
the Earth node, whose orientation is the ECEF → ECI rotation of the displayed instant (frames.py
chain with C, W and DUT1 frozen at the start of the pass: < 1e-6 rad per day, invisible).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from frontend.feed import TwinFeed
from sim_core import attitude_spline, camera, environment, frames, quaternion

__all__ = ["CameraFov", "TwinFrame", "TwinGeometry", "SCENE_UNIT_M"]

SCENE_UNIT_M = frames.WGS84_A_M
TRACE_STEP_S = 20.0  # ground trace and orbit polyline sampling (≈ 150 km of track)
TRACE_HALF_SPAN_S = 3000.0  # past and future shown: about half an orbit each way
TERMINATOR_STEP_RAD = np.radians(0.05)  # redraw the day/night boundary once the Sun moved this much (ECEF)
RATE_STEP_S = 0.05  # body rate of the displayed attitude by a central difference over this step
SURVEY_MAX_ROLL_RAD = np.radians(30.0)  # survey zone: boresight rolled up to ±30° (seed 000 §5 uses 20°)


@dataclass(frozen=True)
class CameraFov:
    """Rectangular field of view of the survey camera about body +x (half angles, rad)."""

    half_across_rad: float = np.radians(2.0)
    half_along_rad: float = np.radians(1.0)


@dataclass(frozen=True)
class TwinFrame:
    """One instant of the twin view, scene units; ground geometry in ECEF, the rest in ECI."""

    t_unix_s: float
    earth_wxyz: np.ndarray  # ECEF → ECI quaternion
    sun_dir_eci: np.ndarray  # unit vector toward the Sun
    sat_eci: np.ndarray  # spacecraft position
    q_actual: np.ndarray  # q_ib
    q_simulated: np.ndarray
    los_actual_ecef: np.ndarray  # boresight ground point (NaN if it misses)
    los_simulated_ecef: np.ndarray
    footprint_actual_ecef: np.ndarray  # (n, 3) polygon
    footprint_simulated_ecef: np.ndarray
    ccd_actual_ecef: np.ndarray  # (m, 3) projected CCD line
    ccd_simulated_ecef: np.ndarray
    observing: bool
    trace_split: int  # index of the first future trace sample
    terminator_ecef: np.ndarray  # (k, 3)


class TwinGeometry:
    """Precomputed tracks of a feed and the per-instant frame for the scenes."""

    def __init__(self, feed: TwinFeed, fov: CameraFov = CameraFov()) -> None:
        self.feed, self.fov = feed, fov
        t0, t1 = feed.span_unix_s()
        self._c_pn, self._w_pm, self._dut1 = frames.earth_orientation_frozen(t0)
        self.track_t = np.arange(t0 - TRACE_HALF_SPAN_S, t1 + TRACE_HALF_SPAN_S + TRACE_STEP_S, TRACE_STEP_S)
        r, v = feed.orbit_eci(self.track_t)
        m = self.eci_to_ecef(self.track_t)
        r_e = np.einsum("nij,nj->ni", m, r)
        v_e = np.einsum("nij,nj->ni", m, v) - np.cross([0.0, 0.0, frames.EARTH_ROTATION_RATE_RAD_S], r_e)
        self.orbit_eci = r / SCENE_UNIT_M
        self.trace_ecef = camera.ground_trace_ecef_m(r_e) / SCENE_UNIT_M
        left, right = camera.survey_zone_bounds_ecef_m(r_e, v_e, SURVEY_MAX_ROLL_RAD)
        self.survey_left_ecef, self.survey_right_ecef = left / SCENE_UNIT_M, right / SCENE_UNIT_M
        self._terminator = (np.zeros(3), np.zeros((0, 3)))
        altitude = float(np.median(np.linalg.norm(r, axis=-1))) - frames.WGS84_A_M
        self.stations = feed.ground_stations()
        self.station_ecef = [frames.geodetic_to_ecef(s.lat_deg, s.lon_deg, 0.0) / SCENE_UNIT_M for s in self.stations]
        self.station_circles_ecef = [
            camera.station_visibility_circle_ecef_m(s.lat_deg, s.lon_deg, altitude, s.min_elevation_deg) / SCENE_UNIT_M
            for s in self.stations
        ]

    def eci_to_ecef(self, t_unix_s: np.ndarray) -> np.ndarray:
        """ECI → ECEF rotation W · R3(ERA(UT1)) · C with C, W, DUT1 frozen at the pass start, (N, 3, 3)."""
        era = frames.earth_rotation_angle_rad(np.asarray(t_unix_s, dtype=float) + self._dut1)
        c, s = np.cos(era), np.sin(era)
        r3 = np.zeros(np.shape(era) + (3, 3))
        r3[..., 0, 0], r3[..., 0, 1], r3[..., 1, 0], r3[..., 1, 1], r3[..., 2, 2] = c, s, -s, c, 1.0
        return self._w_pm @ r3 @ self._c_pn

    def _terminator_at(self, sun_ecef: np.ndarray) -> np.ndarray:
        """Day/night boundary (scene units), recomputed only when the Sun moved by TERMINATOR_STEP_RAD."""
        last_sun, points = self._terminator
        if np.dot(last_sun, sun_ecef) < np.cos(TERMINATOR_STEP_RAD):
            points = camera.terminator_ecef_m(sun_ecef, n_points=181) / SCENE_UNIT_M
            self._terminator = (sun_ecef, points)
        return points

    def image_motion_rad_s(self, t_unix_s: float) -> np.ndarray:
        """Focal-plane rate (2,) of the actual boresight's ground point (seed 000 §6), NaN when it misses the Earth.

        The body rate is the central difference of the displayed attitude spline over RATE_STEP_S.
        """
        t = float(t_unix_s)
        m = self.eci_to_ecef(np.array([t]))[0]
        r, v = self.feed.orbit_eci(np.array([t]))
        q0, q, q1 = self.feed.attitude_actual(np.array([t - RATE_STEP_S / 2, t, t + RATE_STEP_S / 2]))
        p = m.T @ camera.line_of_sight_ecef_m(m @ r[0], camera.body_to_ecef_dcm(q, m))
        if not np.all(np.isfinite(p)):
            return np.full(2, np.nan)
        omega = attitude_spline.log_rotation(quaternion.multiply(quaternion.conjugate(q0), q1)) / RATE_STEP_S
        return camera.image_motion_rad_s(r[0], v[0], q, omega, p, camera.ground_point_velocity_eci_m_s(p))

    def frame(self, t_unix_s: float) -> TwinFrame:
        """Everything the scenes need at one instant (seed 000 §6 trace point, LOS point, CCD line)."""
        t = np.array([float(t_unix_s)])
        m = self.eci_to_ecef(t)[0]
        r, _ = self.feed.orbit_eci(t)
        r_e = m @ r[0]
        q_a, q_s = self.feed.attitude_actual(t)[0], self.feed.attitude_simulated(t)[0]
        c_a, c_s = camera.body_to_ecef_dcm(q_a, m), camera.body_to_ecef_dcm(q_s, m)
        sun = environment.sun_position_1(float(t_unix_s))
        sun /= np.linalg.norm(sun)
        win = self.feed.window(float(t_unix_s) - 1.0, float(t_unix_s))
        fov = self.fov
        return TwinFrame(
            t_unix_s=float(t_unix_s),
            earth_wxyz=quaternion.from_dcm(m.T),
            sun_dir_eci=sun,
            sat_eci=r[0] / SCENE_UNIT_M,
            q_actual=q_a,
            q_simulated=q_s,
            los_actual_ecef=camera.line_of_sight_ecef_m(r_e, c_a) / SCENE_UNIT_M,
            los_simulated_ecef=camera.line_of_sight_ecef_m(r_e, c_s) / SCENE_UNIT_M,
            footprint_actual_ecef=camera.footprint_ecef_m(r_e, c_a, fov.half_across_rad, fov.half_along_rad)
            / SCENE_UNIT_M,
            footprint_simulated_ecef=camera.footprint_ecef_m(r_e, c_s, fov.half_across_rad, fov.half_along_rad)
            / SCENE_UNIT_M,
            ccd_actual_ecef=camera.ccd_line_ecef_m(r_e, c_a, fov.half_across_rad) / SCENE_UNIT_M,
            ccd_simulated_ecef=camera.ccd_line_ecef_m(r_e, c_s, fov.half_across_rad) / SCENE_UNIT_M,
            observing=bool(win.observing[-1]) if win.observing.size else False,
            trace_split=int(np.searchsorted(self.track_t, float(t_unix_s))),
            terminator_ecef=self._terminator_at(m @ sun),
        )
