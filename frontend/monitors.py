"""The twin monitors: one viser server per role (``actual``, ``simulated``, ``overlay``) so that two
browser windows can sit on two screens (seed 000 §7), driven by one playback clock and one render
loop that computes each frame's geometry once and sends it to every monitor.

Entry point for the backend's ``acs-twin serve``: :func:`serve_monitors`.
"""

from __future__ import annotations

import threading
import time
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from frontend.feed import TwinFeed
from frontend.playback import PlaybackClock
from frontend.twin_geometry import TwinFrame, TwinGeometry
from frontend.twin_panels import PLOT_WINDOW_S, TwinPanels
from frontend.twin_scene import ROLES, Role, TwinScene
from sim_core import quaternion

if TYPE_CHECKING:
    import viser

__all__ = ["DEFAULT_PORTS", "MonitorHandles", "serve_monitors", "camera_pose"]

DEFAULT_PORTS: dict[str, int] = {"actual": 8081, "simulated": 8082, "overlay": 8083}
FRAME_RATE_HZ = 30.0
TRACK_RENEW_MARGIN_S = 1500.0  # live: redraw the tracks when the data comes this close to their end
PANEL_RATE_HZ = 2.0
WHOLE_EARTH_DISTANCE = 3.2  # Earth radii from the centre, behind the spacecraft
CHASE_BACK, CHASE_UP = 0.12, 0.05  # Earth radii behind and above the spacecraft
LOS_AHEAD = 0.045  # Earth radii in front of the telescope (past the displayed model) along the boresight
INITIAL_FOV_RAD = float(np.radians(45.0))


def camera_pose(preset: str, f: TwinFrame, v_eci: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Camera position, look-at point and up vector (scene units, ECI) of a preset at a frame."""
    r = f.sat_eci
    up_r = r / np.linalg.norm(r)
    if preset == "chase":
        back = -v_eci / np.linalg.norm(v_eci)
        return r + CHASE_BACK * back + CHASE_UP * up_r, r, up_r
    if preset == "line of sight":
        boresight = quaternion.rotate(f.q_actual, np.array([1.0, 0.0, 0.0]))
        ground = quaternion.rotate(f.earth_wxyz, f.los_actual_ecef)
        target = ground if np.all(np.isfinite(ground)) else r + boresight * 0.1
        along = quaternion.rotate(f.q_actual, np.array([0.0, 1.0, 0.0]))
        return r + LOS_AHEAD * boresight, target, along
    if preset == "whole Earth":
        return up_r * WHOLE_EARTH_DISTANCE, np.zeros(3), np.array([0.0, 0.0, 1.0])
    raise ValueError(f"preset: unknown camera preset {preset!r}")


@dataclass
class MonitorHandles:
    """Running monitors: servers and real ports by role, the shared clock, and the render loop."""

    servers: dict[str, viser.ViserServer]
    clock: PlaybackClock
    geometry: TwinGeometry
    scenes: dict[str, TwinScene]
    panels: dict[str, TwinPanels]
    host: str
    frames_sent: int = 0
    _lock: threading.Lock = field(default_factory=threading.Lock)
    _stop: threading.Event = field(default_factory=threading.Event)
    _thread: threading.Thread | None = None

    @property
    def ports(self) -> dict[str, int]:
        """The port each monitor really listens on (viser moves to the next free port when busy)."""
        return {role: s.get_port() for role, s in self.servers.items()}

    def urls(self, host: str | None = None) -> dict[str, str]:
        """Browser URL of each monitor."""
        h = host or self.host
        return {role: f"http://{h}:{port}/" for role, port in self.ports.items()}

    def render(self, t_unix_s: float | None = None) -> TwinFrame:
        """Compute one frame and push it to every monitor (the loop does this at FRAME_RATE_HZ)."""
        with self._lock:
            t = self.clock.t_unix_s if t_unix_s is None else t_unix_s
            f = self.geometry.frame(t)
            for role, scene in self.scenes.items():
                scene.show(f)
                self.panels[role].show_time(f)
                self._apply_presets(role, f)
            self.frames_sent += 1
            return f

    def set_feed(self, feed: TwinFeed) -> None:
        """Show another feed (e.g. a newly finished twin session) on the running monitors, paused at its start.

        The panels keep the wheel count of the first feed.
        """
        if not isinstance(feed, TwinFeed):
            raise ValueError("feed: does not implement frontend.feed.TwinFeed")
        geometry = TwinGeometry(feed)
        with self._lock:
            self.geometry = geometry
            self.clock.set_span(feed.span_unix_s)
            for scene in self.scenes.values():
                scene.rebuild(geometry)

    def _apply_presets(self, role: str, f: TwinFrame) -> None:
        presets = self.panels[role].presets()
        if not presets:
            return
        clients = self.servers[role].get_clients()
        _, v = self.geometry.feed.orbit_eci(np.array([f.t_unix_s]))
        for cid, preset in presets.items():
            client = clients.get(cid)
            if client is None:
                continue
            position, look_at, up = camera_pose(preset, f, v[0])
            with client.atomic():
                client.camera.up_direction = tuple(up)
                client.camera.position = tuple(position)
                client.camera.look_at = tuple(look_at)
            if preset == "whole Earth":
                with self.panels[role]._lock:
                    self.panels[role].camera_preset.pop(cid, None)

    def extend_tracks(self) -> bool:
        """Recompute orbit, trace and survey zone once live data nears the end of the drawn tracks."""
        _, t1 = self.geometry.feed.span_unix_s()
        if t1 < self.geometry.track_t[-1] - TRACK_RENEW_MARGIN_S:
            return False
        geometry = TwinGeometry(self.geometry.feed)
        with self._lock:
            self.geometry = geometry
            for scene in self.scenes.values():
                scene.rebuild(geometry)
        return True

    def update_panels(self) -> None:
        """Plots, flags and alarms of the last PLOT_WINDOW_S on every monitor."""
        with self._lock:
            t = self.clock.t_unix_s
            w = self.geometry.feed.window(t - PLOT_WINDOW_S, t)
            alarms = self.geometry.feed.active_alarms(t)
            motion = self.geometry.image_motion_rad_s(t)
            for p in self.panels.values():
                p.show_window(t, w, alarms, motion)

    def _loop(self, rate_hz: float) -> None:
        period = 1.0 / rate_hz
        last = time.perf_counter()
        next_panels = last
        while not self._stop.is_set():
            now = time.perf_counter()
            self.clock.advance(now - last)
            last = now
            self.render()
            if now >= next_panels:
                self.extend_tracks()
                self.update_panels()
                next_panels = now + 1.0 / PANEL_RATE_HZ
            self._stop.wait(max(0.0, period - (time.perf_counter() - now)))

    def start(self, rate_hz: float = FRAME_RATE_HZ) -> None:
        """Start the render loop thread."""
        if self._thread is None:
            self._thread = threading.Thread(target=self._loop, args=(rate_hz,), name="twin-render", daemon=True)
            self._thread.start()

    def stop(self) -> None:
        """Stop the loop and the servers."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=5.0)
        for s in self.servers.values():
            s.stop()


def _initial_camera(server, f: TwinFrame) -> None:
    """Whole-Earth view from above the spacecraft for every new browser."""
    position, look_at, up = camera_pose("whole Earth", f, np.zeros(3))
    server.initial_camera.position = tuple(position)
    server.initial_camera.look_at = tuple(look_at)
    server.initial_camera.up = tuple(up)
    server.initial_camera.fov = INITIAL_FOV_RAD


def serve_monitors(
    feed: TwinFeed,
    host: str = "127.0.0.1",
    ports: dict[str, int] | None = None,
    roles: tuple[Role, ...] = ROLES,
    rate_hz: float = FRAME_RATE_HZ,
    start: bool = True,
) -> MonitorHandles:
    """Start one viser server per role on host:port (real ports in ``handles.ports``) and the render loop."""
    import viser

    if not isinstance(feed, TwinFeed):
        raise ValueError("feed: does not implement frontend.feed.TwinFeed")
    ports = dict(DEFAULT_PORTS if ports is None else ports)
    missing = [r for r in roles if r not in ports]
    if missing:
        raise ValueError(f"ports: no port for role(s) {missing}")
    if not rate_hz > 0:
        raise ValueError("rate_hz: must be positive")
    geometry = TwinGeometry(feed)
    clock = PlaybackClock(feed.span_unix_s)
    n_wheels = feed.window(*feed.span_unix_s()).wheel_speed_rad_s.shape[1]
    servers, scenes, panels = {}, {}, {}
    for role in roles:
        server = viser.ViserServer(host=host, port=ports[role], verbose=False)
        servers[role] = server
        scenes[role] = TwinScene(server, role, geometry)
        _initial_camera(server, geometry.frame(clock.t_unix_s))
        panels[role] = TwinPanels(server, role, clock, n_wheels)
    handles = MonitorHandles(servers=servers, clock=clock, geometry=geometry, scenes=scenes, panels=panels, host=host)
    handles.render()
    handles.update_panels()
    if start:
        handles.start(rate_hz)
    return handles
