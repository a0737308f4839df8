"""The twin monitors: one viser server per role (``actual``, ``simulated``, ``overlay``) so that two
browser windows can sit on two screens (seed 000 §7), and one render loop for all of them.

Every browser client is a viewer of its own (frontend.viewer.Viewer: clock, scene, panel): one viewer's
playback never moves another viewer's view. The loop computes each frame's geometry once per distinct
(geometry, instant) and sends it to every viewer at that instant, so viewers in live follow share it.

Entry point for the backend's ``acs-twin serve``: :func:`serve_monitors`.
"""

from __future__ import annotations

import logging
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from frontend.feed import NOMINAL_LABEL, TwinFeed, WindowSource
from frontend.twin_geometry import TwinFrame, TwinGeometry
from frontend.twin_panels import PLOT_WINDOW_S
from frontend.twin_scene import ROLES, Role
from frontend.viewer import Viewer, ViewerLink
from frontend.viser_events import loop_safe_message_events
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
WINDOW_LOADERS = 1  # archived windows load one at a time, off the render loop (live viewers never wait)

log = logging.getLogger(__name__)


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
    """Running monitors: servers and real ports by role, the live geometry, every connected viewer, the loop."""

    servers: dict[str, viser.ViserServer]
    geometry: TwinGeometry
    n_wheels: int
    host: str
    live: bool = False
    windows: WindowSource | None = None
    viewers: dict[str, dict[int, Viewer]] = field(default_factory=dict)
    link: ViewerLink = field(default_factory=ViewerLink)  # viewers that chose to move together (any monitor)
    label: str = NOMINAL_LABEL  # what the simulated side flies, named on every viewer's panel
    frames_sent: int = 0  # frames sent to a client (a frame it already shows is not sent again)
    frames_computed: int = 0
    _lock: threading.RLock = field(default_factory=threading.RLock)
    _stop: threading.Event = field(default_factory=threading.Event)
    _thread: threading.Thread | None = None
    _loader: ThreadPoolExecutor = field(
        default_factory=lambda: ThreadPoolExecutor(WINDOW_LOADERS, thread_name_prefix="monitor-window")
    )

    @property
    def ports(self) -> dict[str, int]:
        """The port each monitor really listens on (viser moves to the next free port when busy)."""
        return {role: s.get_port() for role, s in self.servers.items()}

    def urls(self, host: str | None = None) -> dict[str, str]:
        """Browser URL of each monitor."""
        h = host or self.host
        return {role: f"http://{h}:{port}/" for role, port in self.ports.items()}

    def all_viewers(self) -> list[Viewer]:
        """Every connected viewer of every monitor."""
        with self._lock:
            return [v for per_role in self.viewers.values() for v in per_role.values()]

    def _open_viewers(self) -> list[Viewer]:
        """Every viewer whose browser is still there (under the lock): one whose connection viser has closed is
        dropped now, before anything more is pushed to it, as its disconnect callback would (that comes later,
        from viser's thread pool)."""
        viewers = []
        for viewer in self.all_viewers():
            if viewer.closed:
                self._drop(viewer.role, viewer.client_id)
            else:
                viewers.append(viewer)
        return viewers

    def _connect(self, role: Role, client: viser.ClientHandle) -> None:
        """A browser connected: give it a viewer of its own (clock, scene, panel)."""
        with self._lock:
            geometry = self.geometry
        viewer = Viewer(client, role, geometry, self.n_wheels, self.live, self.windows, self._loader, self.link)
        with self._lock, viewer.sending():  # its first frame sent before it is listed: a listed viewer has been shown
            viewer.panels.show_simulated(self.label)
            self._render_one(viewer, {})
            self.viewers.setdefault(role, {})[viewer.client_id] = viewer  # gone already: the next render drops it

    def _disconnect(self, role: Role, client: viser.ClientHandle) -> None:
        self._drop(role, int(client.client_id))

    def _drop(self, role: Role, client_id: int) -> None:
        with self._lock:
            viewer = self.viewers.get(role, {}).pop(client_id, None)
        if viewer is not None:
            self.link.leave(viewer)

    def _frame(self, geometry: TwinGeometry, t: float, cache: dict) -> TwinFrame:
        key = (id(geometry), t)
        if key not in cache:
            cache[key] = geometry.frame(t)
            self.frames_computed += 1
        return cache[key]

    def _render_one(self, viewer: Viewer, cache: dict, wall_dt_s: float = 0.0) -> TwinFrame:
        viewer.apply_pending()
        clocks = cache.setdefault("clocks", {})  # a clock shared by linked viewers advances once per render
        if id(viewer.clock) not in clocks:
            clocks[id(viewer.clock)] = viewer.clock.advance(wall_dt_s)
        t = clocks[id(viewer.clock)]
        f = self._frame(viewer.geometry, t, cache)
        if viewer.scene.show(f):  # a frame the client already shows is not sent again
            self.frames_sent += 1
        viewer.panels.show_time(f)
        self._apply_preset(viewer, f)
        return f

    def render(self, wall_dt_s: float = 0.0) -> dict[int, TwinFrame]:
        """Advance every viewer's clock by wall_dt and push its frame (the loop does this at FRAME_RATE_HZ);
        the frame shown by each client id."""
        cache: dict = {}
        shown = {}
        with self._lock:
            for viewer in self._open_viewers():
                try:
                    with viewer.sending():
                        shown[viewer.client_id] = self._render_one(viewer, cache, wall_dt_s)
                except Exception:  # a client that went away mid-frame must not stop the others
                    log.debug("monitor viewer %s: frame not sent", viewer.client_id, exc_info=True)
        return shown

    def set_feed(self, feed: TwinFeed) -> None:
        """Show another feed (e.g. a newly finished twin session) on the running monitors, paused at its start.

        Viewers replaying an archived window keep it; the panels keep the wheel count of the first feed.
        """
        if not isinstance(feed, TwinFeed):
            raise ValueError("feed: does not implement frontend.feed.TwinFeed")
        geometry = TwinGeometry(feed)
        with self._lock:
            self.geometry = geometry
            for viewer in self._open_viewers():
                if not viewer.replaying_window:
                    viewer.clock.set_span(feed.span_unix_s)
                with viewer.sending():
                    viewer.set_live_geometry(geometry)

    def show_feed(self, feed: TwinFeed, label: str, live: bool = False) -> None:
        """Put a feed the operator chose on every viewer (a viewer replaying an archived window leaves it), paused
        at its start or in live follow, its simulated side named ``label`` on every panel (a flown hypothesis, or
        the nominal twin again)."""
        if not isinstance(feed, TwinFeed):
            raise ValueError("feed: does not implement frontend.feed.TwinFeed")
        geometry = TwinGeometry(feed)
        with self._lock:
            self.geometry, self.label = geometry, label
            for viewer in self._open_viewers():
                with viewer.sending():
                    viewer.show_on_live(geometry, live)
                    viewer.panels.show_simulated(label)

    def _apply_preset(self, viewer: Viewer, f: TwinFrame) -> None:
        preset = viewer.panels.take_preset()
        if preset is None:
            return
        _, v = viewer.geometry.feed.orbit_eci(np.array([f.t_unix_s]))
        position, look_at, up = camera_pose(preset, f, v[0])
        with viewer.client.atomic():
            viewer.client.camera.up_direction = tuple(up)
            viewer.client.camera.position = tuple(position)
            viewer.client.camera.look_at = tuple(look_at)
        if preset != "whole Earth":
            viewer.panels.camera_preset = preset  # chase and line of sight move on with the spacecraft

    def extend_tracks(self) -> bool:
        """Recompute orbit, trace and survey zone once live data nears the end of the drawn tracks."""
        _, t1 = self.geometry.feed.span_unix_s()
        if t1 < self.geometry.track_t[-1] - TRACK_RENEW_MARGIN_S:
            return False
        geometry = TwinGeometry(self.geometry.feed)
        with self._lock:
            self.geometry = geometry
            for viewer in self._open_viewers():
                with viewer.sending():
                    viewer.set_live_geometry(geometry)
        return True

    def update_panels(self) -> None:
        """Plots, flags and alarms of the last PLOT_WINDOW_S at each viewer's instant."""
        cache: dict = {}
        with self._lock:
            for viewer in self._open_viewers():
                t, feed = viewer.clock.t_unix_s, viewer.geometry.feed
                key = (id(viewer.geometry), t)
                if key not in cache:
                    cache[key] = (
                        feed.window(t - PLOT_WINDOW_S, t),
                        feed.active_alarms(t),
                        viewer.geometry.image_motion_rad_s(t),
                    )
                try:
                    with viewer.sending():
                        viewer.panels.show_window(t, *cache[key])
                except Exception:
                    log.debug("monitor viewer %s: panels not sent", viewer.client_id, exc_info=True)

    def _loop(self, rate_hz: float) -> None:
        period = 1.0 / rate_hz
        last = time.perf_counter()
        next_panels = last
        while not self._stop.is_set():
            now = time.perf_counter()
            self.render(now - last)
            last = now
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
        """Stop the loop, the window loader and the servers."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=5.0)
        self._loader.shutdown(wait=False, cancel_futures=True)
        for s in self.servers.values():
            s.stop()


def _initial_camera(server, f: TwinFrame) -> None:
    """Whole-Earth view from above the spacecraft for every new browser."""
    position, look_at, up = camera_pose("whole Earth", f, np.zeros(3))
    server.initial_camera.position = tuple(position)
    server.initial_camera.look_at = tuple(look_at)
    server.initial_camera.up = tuple(up)
    server.initial_camera.fov = INITIAL_FOV_RAD


def _watch_clients(handles: MonitorHandles, role: Role, server: viser.ViserServer) -> None:
    """Give every browser that connects to ``server`` a viewer of its own; drop it when the browser leaves."""

    def connect(client: viser.ClientHandle) -> None:
        handles._connect(role, client)

    def disconnect(client: viser.ClientHandle) -> None:
        handles._disconnect(role, client)

    server.on_client_connect(connect)
    server.on_client_disconnect(disconnect)


def serve_monitors(
    feed: TwinFeed,
    host: str = "127.0.0.1",
    ports: dict[str, int] | None = None,
    roles: tuple[Role, ...] = ROLES,
    rate_hz: float = FRAME_RATE_HZ,
    start: bool = True,
    live: bool = False,
    windows: WindowSource | None = None,
) -> MonitorHandles:
    """Start one viser server per role on host:port (real ports in ``handles.ports``) and the render loop.

    Each browser that connects gets a viewer of its own, in live follow if ``live`` (else paused at the start of
    the feed); ``windows`` lets viewers replay any past window of the archive.
    """
    import viser

    if not isinstance(feed, TwinFeed):
        raise ValueError("feed: does not implement frontend.feed.TwinFeed")
    ports = dict(DEFAULT_PORTS if ports is None else ports)
    missing = [r for r in roles if r not in ports]
    if missing:
        raise ValueError(f"ports: no port for role(s) {missing}")
    if not rate_hz > 0:
        raise ValueError("rate_hz: must be positive")
    if windows is not None and not isinstance(windows, WindowSource):
        raise ValueError("windows: does not implement frontend.feed.WindowSource")
    geometry = TwinGeometry(feed)
    t0, t1 = feed.span_unix_s()
    n_wheels = feed.window(t0, t1).wheel_speed_rad_s.shape[1]
    first = geometry.frame(t1 if live else t0)
    loop_safe_message_events()  # before the servers make their message buffers (frontend.viser_events)
    servers: dict[str, viser.ViserServer] = {
        role: viser.ViserServer(host=host, port=ports[role], verbose=False) for role in roles
    }
    handles = MonitorHandles(
        servers=servers, geometry=geometry, n_wheels=n_wheels, host=host, live=live, windows=windows
    )
    for role in roles:
        _initial_camera(servers[role], first)
        _watch_clients(handles, role, servers[role])
    if start:
        handles.start(rate_hz)
    return handles
