"""One browser client of a monitor: its own playback clock, scene, panel and, in replay, its own archived window.

One viewer's playback never moves another viewer's view: every viser client gets a Viewer when it connects
(``MonitorHandles._connect``), with a clock of its own and a scene and GUI built on the client's handle (viser
sends client-scoped nodes to that browser only). Viewers on the live feed share its geometry, and the render
loop computes one frame per distinct (geometry, instant), so a hundred viewers in live follow cost one frame.

A replay window is loaded off the render loop (a worker thread reads the archive and builds the geometry), and
swapped in by the render loop at its next tick, so live viewers never wait for it.

Linked viewers (the panel's "Link viewers" box; seed 000 §7's two screens, actual on one and simulated on the
other, kept at one instant): every viewer that ticks it shares one clock and one view (live, or the same
replayed window) through the monitors' :class:`ViewerLink`: a seek, play, speed, live follow or window load by
one moves them all; unticking gives the viewer a clock of its own again, where it was. Viewers that never tick it
stay independent.
"""

from __future__ import annotations

import threading
import time
from concurrent.futures import Executor
from contextlib import AbstractContextManager
from typing import TYPE_CHECKING

from frontend.feed import WindowSource
from frontend.playback import PlaybackClock
from frontend.twin_geometry import TwinGeometry
from frontend.twin_panels import TwinPanels, format_utc
from frontend.twin_scene import Role, TwinScene

if TYPE_CHECKING:
    import viser

__all__ = ["Viewer", "ViewerLink"]


class ViewerLink:
    """The viewers that chose to move together, and their one clock (the first member's)."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._members: list[Viewer] = []

    def members(self) -> list[Viewer]:
        """The linked viewers, first joined first."""
        with self._lock:
            return list(self._members)

    def join(self, viewer: Viewer) -> None:
        """Link a viewer: it takes the link's clock and view (the first member's, at its instant)."""
        with self._lock:
            if viewer in self._members:
                return
            leader = self._members[0] if self._members else None
            self._members.append(viewer)
        if leader is not None:
            viewer.follow(leader)

    def leave(self, viewer: Viewer) -> None:
        """Unlink a viewer: it keeps its view with a clock of its own, where the link was."""
        with self._lock:
            if viewer not in self._members:
                return
            self._members.remove(viewer)
        viewer.clock = viewer.panels.clock = viewer.clock.copy()


class Viewer:
    """A client's clock, geometry (live or a replayed window), scene and panel; geometry swaps happen in the
    render thread (:meth:`apply_pending`)."""

    def __init__(
        self,
        client: viser.ClientHandle,
        role: Role,
        live_geometry: TwinGeometry,
        n_wheels: int,
        live: bool,
        windows: WindowSource | None = None,
        loader: Executor | None = None,
        link: ViewerLink | None = None,
    ) -> None:
        self.client, self.role, self.live_geometry, self._link = client, role, live_geometry, link
        self._outbox = client._websock_connection.get_message_buffer()  # what viser sends this browser
        self.geometry = live_geometry
        self.clock = PlaybackClock(live_geometry.feed.span_unix_s)
        if live:
            self.clock.follow_live(True)
        self._windows, self._loader = windows, loader
        self._lock = threading.Lock()
        self._pending: TwinGeometry | None = None
        self._want_live = False
        self._keep_clock = False  # the pending swap keeps the (link's) clock where it is
        self.loading = False
        self.window_load_s: float | None = None  # wall time of the last window load (request → swapped in)
        self._requested_at = 0.0
        with self.sending():  # the browser may leave while its scene is built
            self.scene = TwinScene(client, role, live_geometry)
            self.panels = TwinPanels(
                client,
                role,
                self.clock,
                n_wheels,
                archive_span=windows.archive_span_unix_s if windows is not None else None,
                on_live=self.request_live,
                on_window=self.request_window if windows is not None else None,
                on_link=self.set_linked if link is not None else None,
            )

    @property
    def client_id(self) -> int:
        return int(self.client.client_id)

    @property
    def closed(self) -> bool:
        """True once the browser has gone: viser closes the client's connection first and calls the disconnect
        callback (which drops the viewer) later, on its thread pool."""
        return bool(self._outbox.done)

    def sending(self) -> AbstractContextManager[None]:
        """Scope of the monitors' pushes to this browser, made while it was not :attr:`closed`: a push that races
        its departure is discarded by viser without its dead-connection warning (the viewer is dropped at the next
        look, so nothing is pushed to it after that)."""
        return self._outbox.sanctioned_dead_writes()

    @property
    def replaying_window(self) -> bool:
        """True while the viewer shows an archived window instead of the live feed."""
        return self.geometry is not self.live_geometry

    @property
    def linked(self) -> bool:
        """True while the viewer moves with the other linked viewers."""
        return self._link is not None and self in self._link.members()

    def set_linked(self, on: bool) -> None:
        """Join (on) or leave the monitors' link (the panel's "Link viewers" box)."""
        if self._link is None:
            raise ValueError("link: these monitors have no viewer link")
        if on:
            self._link.join(self)
        else:
            self._link.leave(self)

    def _together(self) -> list[Viewer]:
        """The viewers an action of this one moves: the linked ones, or itself alone."""
        return self._link.members() if self.linked and self._link is not None else [self]

    def follow(self, leader: Viewer) -> None:
        """Take ``leader``'s clock and view (on joining a link; applied by the render thread)."""
        self.clock = self.panels.clock = leader.clock
        with self._lock:
            if leader.replaying_window:
                self._pending, self._want_live, self._keep_clock = leader.geometry, False, True
            elif self.replaying_window:
                self._want_live, self._pending, self._keep_clock = True, None, True

    def request_live(self, on: bool) -> None:
        """Live follow on: back to the live feed (at its newest instant); off: stay where we are (every linked
        viewer with it)."""
        if not on:
            self.clock.follow_live(False)
            return
        for viewer in self._together():
            with viewer._lock:
                viewer._want_live, viewer._pending = True, None
        if not self.replaying_window:
            self.clock.follow_live(True)

    def request_window(self, t0_unix_s: float, t1_unix_s: float) -> None:
        """Load the archived window [t0, t1] in the background; it replaces the view once loaded (of every linked
        viewer with it)."""
        if self._windows is None or self._loader is None:
            raise ValueError("window: this monitor has no archive to replay from")
        viewers = self._together()
        for viewer in viewers:
            viewer.loading, viewer._requested_at = True, time.perf_counter()
            viewer.panels.show_window_status(f"loading {format_utc(t0_unix_s)} + {t1_unix_s - t0_unix_s:.0f} s …")
        self._loader.submit(self._load, t0_unix_s, t1_unix_s, viewers)

    def _load(self, t0_unix_s: float, t1_unix_s: float, viewers: list[Viewer]) -> None:
        assert self._windows is not None
        try:
            geometry = TwinGeometry(self._windows.window_feed(t0_unix_s, t1_unix_s))
        except ValueError as exc:
            for viewer in viewers:
                viewer.loading = False
                if not viewer.closed:
                    with viewer.sending():
                        viewer.panels.show_window_status(f"not loaded: {exc}")
            return
        for viewer in viewers:
            with viewer._lock:
                viewer._pending, viewer._want_live = geometry, False

    def set_live_geometry(self, geometry: TwinGeometry) -> None:
        """The live feed's geometry changed (tracks extended, another feed): follow it if showing live (render
        thread)."""
        on_live = not self.replaying_window
        self.live_geometry = geometry
        if on_live:
            self.geometry = geometry
            self.scene.rebuild(geometry)

    def show_on_live(self, geometry: TwinGeometry, live: bool) -> None:
        """Leave any replayed window for the live feed's (new) geometry, paused at its start or in live follow
        (render thread or under the monitors' lock): a feed the operator put on the monitors reaches every viewer."""
        with self._lock:
            self._pending, self._want_live, self._keep_clock = None, False, False
        self.loading = False
        self.live_geometry = self.geometry = geometry
        self.scene.rebuild(geometry)
        self.clock.set_span(geometry.feed.span_unix_s)
        self.clock.follow_live(live)
        self.panels.show_window_status("live" if live else "—")

    def apply_pending(self) -> None:
        """Swap in a loaded window or go back to live (render thread)."""
        with self._lock:
            pending, want_live, keep_clock = self._pending, self._want_live, self._keep_clock
            self._pending, self._want_live, self._keep_clock = None, False, False
        if pending is not None:
            self.geometry = pending
            self.scene.rebuild(pending)
            if not keep_clock:  # linked viewers swap their one clock each, in one tick: paused at the start
                self.clock.set_span(pending.feed.span_unix_s)
            t0, t1 = pending.feed.span_unix_s()
            self.loading = False
            self.window_load_s = time.perf_counter() - self._requested_at
            self.panels.show_window_status(
                f"replaying {format_utc(t0)} … {format_utc(t1)} (archive; loaded in {self.window_load_s:.1f} s)"
            )
        elif want_live:
            if self.replaying_window:
                self.geometry = self.live_geometry
                self.scene.rebuild(self.live_geometry)
                if not keep_clock:
                    self.clock.set_span(self.live_geometry.feed.span_unix_s)
                self.panels.show_window_status("live")
            if not keep_clock:
                self.clock.follow_live(True)
