"""The three monitors as real viser servers: bound to loopback on the ports they report, one clock
moving all scenes together, camera presets, refused bad arguments."""

from __future__ import annotations

import socket

import numpy as np
import pytest

from frontend.monitors import camera_pose, serve_monitors
from frontend.twin_panels import format_utc
from frontend.twin_scene import TwinScene
from tests.frontend.conftest import free_port


def test_monitors_listen_on_loopback_on_the_ports_they_report(monitors):
    ports = monitors.ports
    assert set(ports) == {"actual", "simulated", "overlay"} and len(set(ports.values())) == 3
    for role, server in monitors.servers.items():
        assert server.get_host() == "127.0.0.1"
        with socket.create_connection(("127.0.0.1", ports[role]), timeout=5.0):
            pass
    assert monitors.urls()["overlay"] == f"http://127.0.0.1:{ports['overlay']}/"


def test_a_busy_port_is_reported_as_the_port_really_used(twin_feed):
    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        taken = busy.getsockname()[1]
        handles = serve_monitors(twin_feed, ports={"actual": taken}, roles=("actual",), start=False)
        try:
            assert handles.ports["actual"] != taken
        finally:
            handles.stop()


def test_one_clock_moves_every_scene_and_panel_to_the_same_instant(monitors):
    t0, t1 = monitors.clock.span_unix_s()
    target = t0 + 123.25
    monitors.clock.seek(target)
    f = monitors.render()
    assert f.t_unix_s == target
    wxyz = {role: np.asarray(s.earth.wxyz) for role, s in monitors.scenes.items()}
    for role in ("simulated", "overlay"):
        np.testing.assert_array_equal(wxyz[role], wxyz["actual"])
    assert {p.time_text.value for p in monitors.panels.values()} == {format_utc(target)}
    np.testing.assert_allclose(monitors.scenes["overlay"].sats["actual"].wxyz, f.q_actual)
    np.testing.assert_allclose(monitors.scenes["overlay"].sats["simulated"].wxyz, f.q_simulated)
    assert set(monitors.scenes["actual"].sats) == {"actual"} and set(monitors.scenes["simulated"].sats) == {"simulated"}


def test_camera_presets_look_at_the_earth_the_spacecraft_and_along_the_boresight(monitors):
    f = monitors.geometry.frame(monitors.clock.t_unix_s)
    _, v = monitors.geometry.feed.orbit_eci(np.array([f.t_unix_s]))
    pos, look, _ = camera_pose("whole Earth", f, v[0])
    assert np.linalg.norm(pos) > 2.0 and np.allclose(look, 0.0)
    pos, look, _ = camera_pose("chase", f, v[0])
    np.testing.assert_allclose(look, f.sat_eci)
    assert np.dot(pos - f.sat_eci, v[0]) < 0.0  # behind
    pos, look, _ = camera_pose("line of sight", f, v[0])
    view = (look - pos) / np.linalg.norm(look - pos)
    to_earth = -f.sat_eci / np.linalg.norm(f.sat_eci)
    assert np.dot(view, to_earth) > 0.95  # the nadir pointer's boresight looks down
    with pytest.raises(ValueError, match="preset"):
        camera_pose("sideways", f, v[0])


def test_bad_arguments_name_the_field(twin_feed, monitors):
    with pytest.raises(ValueError, match="ports"):
        serve_monitors(twin_feed, ports={"actual": free_port()}, roles=("actual", "overlay"), start=False)
    with pytest.raises(ValueError, match="feed"):
        serve_monitors(object(), start=False)
    with pytest.raises(ValueError, match="role"):
        TwinScene(monitors.servers["actual"], "sideways", monitors.geometry)


def test_set_feed_moves_running_monitors_to_the_new_feed(twin_feed):
    from frontend.feed import TrajectoryFeed
    from tests.frontend.conftest import synthetic_trajectory

    handles = serve_monitors(twin_feed, ports={"overlay": free_port()}, roles=("overlay",), start=False)
    try:
        later = synthetic_trajectory(duration_s=300.0)
        later.extra["epoch_unix_s"] += 86_400.0
        handles.set_feed(TrajectoryFeed(later))
        t0, t1 = handles.clock.span_unix_s()
        assert (t0, t1) == (later.extra["epoch_unix_s"], later.extra["epoch_unix_s"] + 300.0)
        f = handles.render()
        assert f.t_unix_s == t0 and handles.panels["overlay"].time_text.value == format_utc(t0)
        with pytest.raises(ValueError, match="feed"):
            handles.set_feed(object())
    finally:
        handles.stop()


class GrowingFeed:
    """A TrajectoryFeed whose data span grows like a live pass."""

    def __init__(self, feed) -> None:
        self._feed, self.end = feed, feed.span_unix_s()[0] + 100.0

    def span_unix_s(self) -> tuple[float, float]:
        return self._feed.span_unix_s()[0], self.end

    def __getattr__(self, name):
        return getattr(self._feed, name)


def test_live_data_nearing_the_end_of_the_drawn_tracks_extends_them(twin_feed):
    feed = GrowingFeed(twin_feed)
    handles = serve_monitors(feed, ports={"overlay": free_port()}, roles=("overlay",), start=False)
    try:
        assert not handles.extend_tracks()
        first_end = handles.geometry.track_t[-1]
        feed.end = first_end - 1000.0
        assert handles.extend_tracks()
        assert handles.geometry.track_t[-1] > first_end
        handles.clock.follow_live()
        assert handles.clock.advance(0.1) == feed.end and handles.render().t_unix_s == feed.end
    finally:
        handles.stop()
