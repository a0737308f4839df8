"""One monitor's 3D scene on a viser server: textured rotating Earth lit by the Sun, the actual
spacecraft (opaque) and/or the simulated ghost, body axes, labels, orbit and ground trace (past
solid, future faded), line of sight, footprint and CCD line while scanning, survey-zone bounds,
ground stations with visibility circles and the day/night boundary (seed 000 §6–7 SURIUS-S).
"""

from __future__ import annotations

import dataclasses
from typing import TYPE_CHECKING, Literal

import numpy as np

from frontend import globe, spacecraft_model
from frontend.twin_geometry import TwinFrame, TwinGeometry
from sim_core import quaternion

if TYPE_CHECKING:
    import viser

__all__ = ["Role", "ROLES", "TwinScene", "polyline_segments", "same_frame"]

Role = Literal["actual", "simulated", "overlay"]
ROLES: tuple[Role, ...] = ("actual", "simulated", "overlay")

MODEL_SIZE_EARTH_RADII = 0.03  # displayed half-size of the spacecraft (animation scale, seed 000 §6)
AXES_LENGTH = 0.04  # body axes a little longer than the displayed model
LINE_PX = 2.0
SUN_LIGHT_DISTANCE = 20.0  # directional light placed along the Sun direction (scene units)
AMBIENT = 0.12  # dim ambient so that the night side stays readable
SUN_INTENSITY = 3.0
PAST = (255, 210, 60)
FUTURE = (120, 105, 60)  # the same hue, faded
ORBIT_PAST = (90, 200, 255)
ORBIT_FUTURE = (45, 90, 120)
ACTUAL_COLOUR = (255, 120, 40)
GHOST_COLOUR = (80, 255, 160)
SURVEY = (255, 255, 255)
STATION = (255, 80, 80)
TERMINATOR = (255, 140, 0)


def polyline_segments(points: np.ndarray) -> np.ndarray:
    """Segments (N-1, 2, 3) of a polyline, dropping segments with a NaN end (rays that miss the Earth)."""
    p = np.asarray(points, dtype=float)
    seg = np.stack([p[:-1], p[1:]], axis=1)
    return seg[np.all(np.isfinite(seg), axis=(1, 2))]


def _closed(points: np.ndarray) -> np.ndarray:
    return np.concatenate([points, points[:1]])


class TwinScene:
    """The scene graph of one monitor role, built once, updated per playback frame."""

    def __init__(self, server: viser.ViserServer, role: Role, geometry: TwinGeometry) -> None:
        if role not in ROLES:
            raise ValueError(f"role: expected one of {ROLES}, got {role!r}")
        self.server, self.role, self.geometry = server, role, geometry
        self.sides = {"actual": ("actual",), "simulated": ("simulated",), "overlay": ("actual", "simulated")}[role]
        self._trace_split = -1
        self._shown: TwinFrame | None = None  # the frame the client holds (None: not shown since the last build)
        self._build()

    def _build(self) -> None:
        s = self.server.scene
        g = self.geometry
        s.set_up_direction("+z")
        s.configure_default_lights(enabled=False)
        s.configure_environment_map(None)
        self.ambient = s.add_light_ambient("/ambient", intensity=AMBIENT)
        self.sun = s.add_light_directional("/sun", intensity=SUN_INTENSITY)
        self.earth = s.add_frame("/earth", show_axes=False)
        self.globe = s.add_glb("/earth/globe", globe.earth_glb(), cast_shadow=False, receive_shadow=False)
        for k, (name, pos, circle) in enumerate(
            zip([st.name for st in g.stations], g.station_ecef, g.station_circles_ecef)
        ):
            s.add_icosphere(f"/earth/stations/{k}", radius=0.006, color=STATION, position=tuple(pos * 1.001))
            s.add_label(f"/earth/stations/{k}/label", name, font_screen_scale=0.7, depth_test=True)
            s.add_line_segments(
                f"/earth/station_circles/{k}",
                polyline_segments(_closed(circle) * 1.001),
                STATION,
                thickness=LINE_PX,
                thickness_units="screen",
            )
        for side, pts in (("left", g.survey_left_ecef), ("right", g.survey_right_ecef)):
            s.add_line_segments(
                f"/earth/survey_{side}",
                polyline_segments(pts * 1.0005),
                SURVEY,
                thickness=1.0,
                thickness_units="screen",
            )
        self.trace_past = s.add_line_segments(
            "/earth/trace_past", np.zeros((1, 2, 3)), PAST, thickness=LINE_PX, thickness_units="screen"
        )
        self.trace_future = s.add_line_segments(
            "/earth/trace_future", np.zeros((1, 2, 3)), FUTURE, thickness=LINE_PX, thickness_units="screen"
        )
        self.orbit_past = s.add_line_segments(
            "/orbit_past", np.zeros((1, 2, 3)), ORBIT_PAST, thickness=LINE_PX, thickness_units="screen"
        )
        self.orbit_future = s.add_line_segments(
            "/orbit_future", np.zeros((1, 2, 3)), ORBIT_FUTURE, thickness=LINE_PX, thickness_units="screen"
        )
        self.terminator = s.add_line_segments(
            "/earth/terminator", np.zeros((1, 2, 3)), TERMINATOR, thickness=LINE_PX, thickness_units="screen"
        )
        self.sats, self.los, self.footprints, self.ccd = {}, {}, {}, {}
        scale = MODEL_SIZE_EARTH_RADII / spacecraft_model.MODEL_EXTENT_M
        for side in self.sides:
            ghost = side == "simulated"
            colour = GHOST_COLOUR if ghost else ACTUAL_COLOUR
            node = s.add_frame(f"/sat_{side}", show_axes=False)
            s.add_glb(f"/sat_{side}/model", spacecraft_model.spacecraft_glb(ghost), scale=scale)
            s.add_frame(f"/sat_{side}/axes", axes_length=AXES_LENGTH, axes_radius=AXES_LENGTH / 80)
            s.add_label(
                f"/sat_{side}/label", side, font_screen_scale=0.8, anchor="bottom-left" if ghost else "top-left"
            )
            self.sats[side] = node
            self.los[side] = s.add_line_segments(
                f"/earth/los_{side}", np.zeros((1, 2, 3)), colour, thickness=1.5, thickness_units="screen"
            )
            self.footprints[side] = s.add_line_segments(
                f"/earth/footprint_{side}", np.zeros((1, 2, 3)), colour, thickness=LINE_PX, thickness_units="screen"
            )
            self.ccd[side] = s.add_line_segments(
                f"/earth/ccd_{side}", np.zeros((1, 2, 3)), (255, 255, 255), thickness=LINE_PX, thickness_units="screen"
            )

    def rebuild(self, geometry: TwinGeometry) -> None:
        """Redraw every node for another feed's geometry (viser replaces nodes of the same name)."""
        self.geometry = geometry
        self._trace_split = -1
        self._shown = None
        self._build()

    def show(self, f: TwinFrame) -> bool:
        """Move everything to the frame's instant (one batched websocket update); False, and nothing done, when the
        client already shows this very frame (a paused view, or live follow between two samples)."""
        if self._shown is not None and same_frame(self._shown, f):
            return False
        self._shown = f
        g = self.geometry
        with self.server.atomic():
            self.earth.wxyz = f.earth_wxyz
            self.sun.position = tuple(f.sun_dir_eci * SUN_LIGHT_DISTANCE)
            if f.trace_split != self._trace_split:
                self._trace_split = f.trace_split
                k = int(np.clip(f.trace_split, 1, len(g.track_t) - 1))
                _set_segments(self.trace_past, polyline_segments(g.trace_ecef[: k + 1] * 1.0005))
                _set_segments(self.trace_future, polyline_segments(g.trace_ecef[k:] * 1.0005))
                _set_segments(self.orbit_past, polyline_segments(g.orbit_eci[: k + 1]))
                _set_segments(self.orbit_future, polyline_segments(g.orbit_eci[k:]))
                _set_segments(self.terminator, polyline_segments(f.terminator_ecef * 1.001))
            m = _ecef_of(f)
            sat_ecef = m @ f.sat_eci
            for side in self.sides:
                q = f.q_actual if side == "actual" else f.q_simulated
                self.sats[side].position = tuple(f.sat_eci)
                self.sats[side].wxyz = tuple(q)
                los = f.los_actual_ecef if side == "actual" else f.los_simulated_ecef
                _set_segments(self.los[side], polyline_segments(np.stack([sat_ecef, los])))
                foot = f.footprint_actual_ecef if side == "actual" else f.footprint_simulated_ecef
                ccd = f.ccd_actual_ecef if side == "actual" else f.ccd_simulated_ecef
                _set_segments(self.footprints[side], polyline_segments(_closed(foot) * 1.0002), f.observing)
                _set_segments(self.ccd[side], polyline_segments(ccd * 1.0002), f.observing)
        return True


def same_frame(a: TwinFrame, b: TwinFrame) -> bool:
    """True when two frames hold the same values (NaN equal to NaN: a line of sight that misses the Earth)."""
    for field in dataclasses.fields(a):
        x, y = getattr(a, field.name), getattr(b, field.name)
        if isinstance(x, np.ndarray) or isinstance(y, np.ndarray):
            if not np.array_equal(x, y, equal_nan=True):
                return False
        elif x != y:
            return False
    return True


def _ecef_of(f: TwinFrame) -> np.ndarray:
    """ECI → ECEF matrix of the frame (transpose of the Earth node's rotation)."""
    return quaternion.to_dcm(f.earth_wxyz).T


def _set_segments(handle: viser.LineSegmentsHandle, segments: np.ndarray, visible: bool = True) -> None:
    """Replace a line set's segments; hide it when there is nothing (or nothing wanted) to draw."""
    if segments.shape[0]:
        handle.points = segments
    handle.visible = visible and bool(segments.shape[0])
