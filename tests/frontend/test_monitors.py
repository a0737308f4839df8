"""The three monitors as real viser servers: bound to loopback on the ports they report, a clock per
viewer (one client's playback never moves another's view), camera presets, refused bad arguments."""

from __future__ import annotations

import socket
import threading
import time
import warnings
from collections.abc import Callable, Iterator
from contextlib import contextmanager

import numpy as np
import pytest
import viser

from frontend.monitors import camera_pose, serve_monitors
from frontend.twin_panels import ClockMirror, format_utc
from frontend.twin_scene import TwinScene
from tests.frontend.viser_clients import viser_client, wait_for_viewers
from tests.ports import free_port


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


def test_each_viewer_has_its_own_clock_and_one_moving_leaves_the_other_where_it_was(twin_feed):
    handles = serve_monitors(twin_feed, ports={"overlay": free_port()}, roles=("overlay",), start=False, live=True)
    try:
        with viser_client(handles.ports["overlay"]), viser_client(handles.ports["overlay"]):
            moved, watching = wait_for_viewers(handles, "overlay", 2)
            t0, t1 = twin_feed.span_unix_s()
            target = t0 + 123.25
            moved.clock.seek(target)
            computed = handles.frames_computed
            shown = handles.render(wall_dt_s=0.5)
            assert shown[moved.client_id].t_unix_s == target and shown[watching.client_id].t_unix_s == t1
            assert moved.panels.time_text.value == format_utc(target)
            assert watching.panels.time_text.value == format_utc(t1) and watching.clock.live
            f = shown[moved.client_id]
            np.testing.assert_allclose(moved.scene.sats["actual"].wxyz, f.q_actual)
            np.testing.assert_allclose(moved.scene.sats["simulated"].wxyz, f.q_simulated)
            moved.clock.set_speed(100.0)
            moved.clock.play()
            shown = handles.render(wall_dt_s=1.0)
            assert shown[moved.client_id].t_unix_s == target + 100.0 and shown[watching.client_id].t_unix_s == t1
            assert watching.clock.speed != 100.0
            assert handles.frames_computed - computed == 4  # one frame per distinct instant and render, not per viewer
    finally:
        handles.stop()


def test_a_viewer_whose_browser_left_is_dropped_before_anything_more_is_sent_to_it(twin_feed):
    """viser closes a departed browser's connection first and calls the disconnect callback later (from its thread
    pool): a render in between drops that viewer instead of queueing its moved frame on the closed connection (viser's
    "Queued a ... on a closed connection" warning), and the viewer that stayed goes on."""
    handles = serve_monitors(twin_feed, ports={"overlay": free_port()}, roles=("overlay",), start=False, live=True)
    try:
        with viser_client(handles.ports["overlay"]), viser_client(handles.ports["overlay"]) as leaving:
            staying, gone = wait_for_viewers(handles, "overlay", 2)
            with handles._lock:  # the disconnect callback waits for the lock: the render below comes before it
                leaving.close()
                deadline = time.monotonic() + 30.0
                while not gone.closed:
                    assert time.monotonic() < deadline, "viser never closed the departed client's connection"
                    time.sleep(0.01)
                t0, _ = twin_feed.span_unix_s()
                gone.clock.seek(t0 + 50.0)  # a new frame for it, had it stayed listed
                staying.clock.seek(t0 + 60.0)
                with warnings.catch_warnings(record=True) as caught:
                    warnings.simplefilter("always")
                    shown = handles.render(wall_dt_s=0.1)
                    handles.update_panels()
            assert [str(w.message) for w in caught if "closed connection" in str(w.message)] == []
            assert set(shown) == {staying.client_id} and handles.all_viewers() == [staying]
            assert staying.panels.time_text.value == format_utc(t0 + 60.0)
    finally:
        handles.stop()


@contextmanager
def _one_viewer(twin_feed) -> Iterator:
    """A live overlay monitor (no render loop: the test renders) and the viewer of its one client."""
    handles = serve_monitors(twin_feed, ports={"overlay": free_port()}, roles=("overlay",), start=False, live=True)
    try:
        with viser_client(handles.ports["overlay"]):
            (viewer,) = wait_for_viewers(handles, "overlay", 1)
            yield handles, viewer
    finally:
        handles.stop()


def _operator_sets(viewer, handle, value) -> Callable[[], None]:
    """An operator's change as viser applies it: the value set on the handle now (viser's event loop: no message
    back, no callbacks), the handle's callbacks run by the returned function (later, on viser's thread pool)."""
    handle._impl.value = value

    def callbacks() -> None:
        for cb in handle._impl.update_cb:
            cb(viser.GuiEvent(viewer.client, viewer.client_id, handle))

    return callbacks


def test_a_dragged_timeline_is_not_moved_back_by_the_replay_before_its_callback_seeks(twin_feed):
    """The timeline moves with the replaying clock every frame, but a frame between the operator's drag and its
    callback leaves the drag alone (it used to put the clock's instant back, and the callback then sought there:
    the drag was lost); after the callback the timeline moves on from where it was dragged."""
    with _one_viewer(twin_feed) as (handles, viewer):
        t0, _ = twin_feed.span_unix_s()
        viewer.clock.seek(t0 + 200.0)
        viewer.clock.play()  # x10: 1 s of data per 0.1 s of wall time
        handles.render(wall_dt_s=0.1)
        assert viewer.panels.slider.value == 201.0
        callbacks = _operator_sets(viewer, viewer.panels.slider, 50.0)
        handles.render(wall_dt_s=0.1)
        assert viewer.panels.slider.value == 50.0 and viewer.clock.t_unix_s == t0 + 202.0
        callbacks()
        assert viewer.clock.t_unix_s == t0 + 50.0 and viewer.clock.playing
        for t in (51.0, 52.0):  # the clock's advance moves the timeline again
            handles.render(wall_dt_s=0.1)
            assert viewer.panels.slider.value == t


def test_a_chosen_speed_is_not_put_back_by_a_frame_before_its_callback_sets_it(twin_feed):
    """A frame between the operator's choice of speed and its callback leaves the choice shown (it used to put the
    clock's speed back, and the callback then set that: the choice was lost); a speed set otherwise still shows."""
    with _one_viewer(twin_feed) as (handles, viewer):
        assert viewer.panels.speed.value == "x10" and viewer.clock.speed == 10.0
        callbacks = _operator_sets(viewer, viewer.panels.speed, "x100")
        handles.render(wall_dt_s=0.1)
        assert viewer.panels.speed.value == "x100" and viewer.clock.speed == 10.0
        callbacks()
        handles.render(wall_dt_s=0.1)
        assert viewer.clock.speed == 100.0 and viewer.panels.speed.value == "x100"
        viewer.clock.set_speed(2.0)  # e.g. a linked viewer's choice on the shared clock
        handles.render(wall_dt_s=0.1)
        assert viewer.panels.speed.value == "x2"


def test_a_value_its_callback_refuses_leaves_the_control_following_the_clock() -> None:
    """An operator's value that ``apply`` refuses (it raises) does not freeze the control: it used to stay 'on its
    way to the clock' for ever, and no frame put the clock's state on it again."""
    server = viser.ViserServer(host="127.0.0.1", port=free_port(), verbose=False)
    try:
        slider = server.gui.add_slider("t", min=0.0, max=100.0, step=1.0, initial_value=10.0)

        def refuse(value: float) -> None:
            raise ValueError(f"t: {value} is outside the archive")

        mirror = ClockMirror(slider, refuse)
        slider._impl.value = 70.0  # the operator's value as viser sets it, then its callback:
        with pytest.raises(ValueError):
            for cb in slider._impl.update_cb:
                cb(viser.GuiEvent(client=object(), client_id=1, target=slider))  # type: ignore[arg-type]
        mirror.show(11.0)
        assert slider.value == 11.0
    finally:
        server.stop()


def test_a_ticked_live_follow_box_stays_ticked_until_its_callback_moves_the_clock(twin_feed):
    """An operator's click reaches the panel's Live follow box (viser sets its value) before the box's callback
    reaches the viewer's clock: a frame in between leaves the box ticked (it used to untick it from the clock, and
    the browser test's second click then turned live follow off), and the callback's live follow then shows."""
    with _one_viewer(twin_feed) as (handles, viewer):
        t0, t1 = twin_feed.span_unix_s()
        viewer.clock.seek(t0 + 100.0)  # out of live follow
        handles.render()
        assert not viewer.clock.live and not viewer.panels.live.value
        callbacks = _operator_sets(viewer, viewer.panels.live, True)
        handles.render(wall_dt_s=0.1)
        assert viewer.panels.live.value and not viewer.clock.live
        callbacks()
        shown = handles.render(wall_dt_s=0.1)
        assert viewer.clock.live and viewer.panels.live.value and shown[viewer.client_id].t_unix_s == t1
        viewer.clock.seek(t0 + 50.0)  # the clock leaving live follow unticks the box
        handles.render()
        assert not viewer.panels.live.value


def _quiet(received: list, quiet_s: float = 0.5, timeout_s: float = 30.0) -> None:
    """Wait until the server has sent nothing to the client for quiet_s (its first scene and panel delivered)."""
    deadline = time.monotonic() + timeout_s
    while not received or time.monotonic() - received[-1] < quiet_s:
        if time.monotonic() > deadline:
            raise AssertionError(f"the server kept sending for {timeout_s} s")
        time.sleep(0.05)


def test_an_idle_viewer_is_sent_nothing_until_its_view_moves(twin_feed):
    """Paused at one instant (its plots full), three seconds of 30 Hz frames and 2 Hz panel updates send the page no
    message at all (the browser then has nothing to redraw or re-plot); a seek sends the new frame."""
    handles = serve_monitors(twin_feed, ports={"overlay": free_port()}, roles=("overlay",), start=False)
    received: list[float] = []
    try:
        with viser_client(handles.ports["overlay"], received=received):
            (viewer,) = wait_for_viewers(handles, "overlay", 1)
            viewer.clock.seek(twin_feed.span_unix_s()[0] + 400.0)  # 300 s of samples in the plots
            handles.render()
            handles.update_panels()
            assert viewer.panels.error_plot.data[0].size > 2
            _quiet(received)
            before, sent = len(received), handles.frames_sent
            for k in range(90):
                handles.render(wall_dt_s=1.0 / 30.0)
                if k % 15 == 0:
                    handles.update_panels()
            handles.servers["overlay"].flush()
            _quiet(received)
            assert len(received) == before and handles.frames_sent == sent
            viewer.clock.seek(viewer.clock.t_unix_s + 10.0)
            handles.render()
            assert handles.frames_sent == sent + 1
            deadline = time.monotonic() + 30.0
            while len(received) == before:
                assert time.monotonic() < deadline, "the moved frame never reached the client"
                time.sleep(0.05)
    finally:
        handles.stop()


def test_a_role_shows_its_sides_only(monitors):
    with viser_client(monitors.ports["actual"]), viser_client(monitors.ports["simulated"]):
        (actual,) = wait_for_viewers(monitors, "actual", 1)
        (simulated,) = wait_for_viewers(monitors, "simulated", 1)
        assert set(actual.scene.sats) == {"actual"} and set(simulated.scene.sats) == {"simulated"}


def test_camera_presets_look_at_the_earth_the_spacecraft_and_along_the_boresight(monitors):
    f = monitors.geometry.frame(monitors.geometry.feed.span_unix_s()[0])
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
        with viser_client(handles.ports["overlay"]):
            (viewer,) = wait_for_viewers(handles, "overlay", 1)
            later = synthetic_trajectory(duration_s=300.0)
            later.extra["epoch_unix_s"] += 86_400.0
            handles.set_feed(TrajectoryFeed(later))
            t0, t1 = viewer.clock.span_unix_s()
            assert (t0, t1) == (later.extra["epoch_unix_s"], later.extra["epoch_unix_s"] + 300.0)
            f = handles.render()[viewer.client_id]
            assert f.t_unix_s == t0 and viewer.panels.time_text.value == format_utc(t0)
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
    handles = serve_monitors(feed, ports={"overlay": free_port()}, roles=("overlay",), start=False, live=True)
    try:
        with viser_client(handles.ports["overlay"]):
            (viewer,) = wait_for_viewers(handles, "overlay", 1)
            assert not handles.extend_tracks()
            first_end = handles.geometry.track_t[-1]
            feed.end = first_end - 1000.0
            assert handles.extend_tracks()
            assert handles.geometry.track_t[-1] > first_end and viewer.geometry is handles.geometry
            assert handles.render(wall_dt_s=0.1)[viewer.client_id].t_unix_s == feed.end
    finally:
        handles.stop()


class SlowWindows:
    """A WindowSource whose archive read takes as long as the test wants (it waits for ``release``)."""

    def __init__(self, feed) -> None:
        self.feed, self.release = feed, threading.Event()

    def archive_span_unix_s(self) -> tuple[float, float]:
        return self.feed.span_unix_s()

    def window_feed(self, t0_unix_s: float, t1_unix_s: float):
        assert self.release.wait(60.0)
        return self.feed


def test_a_window_loading_in_the_background_never_holds_up_the_live_viewers(twin_feed):
    feed, windows = GrowingFeed(twin_feed), SlowWindows(twin_feed)
    handles = serve_monitors(
        feed, ports={"overlay": free_port()}, roles=("overlay",), start=False, live=True, windows=windows
    )
    try:
        with viser_client(handles.ports["overlay"]), viser_client(handles.ports["overlay"]):
            loader, watcher = wait_for_viewers(handles, "overlay", 2)
            t0, _ = twin_feed.span_unix_s()
            loader.request_window(t0 + 60.0, t0 + 360.0)
            for _ in range(3):  # the archive read is still running: live goes on for everyone
                feed.end += 10.0
                shown = handles.render(wall_dt_s=0.1)
                assert shown[watcher.client_id].t_unix_s == shown[loader.client_id].t_unix_s == feed.end
                assert loader.loading and not loader.replaying_window
            windows.release.set()
            deadline = time.monotonic() + 30.0
            while not loader.replaying_window and time.monotonic() < deadline:
                shown = handles.render(wall_dt_s=0.1)  # swapped in by the render loop once loaded
                time.sleep(0.05)
            assert loader.replaying_window and not loader.clock.live
            assert shown[loader.client_id].t_unix_s == t0 and shown[watcher.client_id].t_unix_s == feed.end
            assert "replaying" in loader.panels.window_status.content
    finally:
        handles.stop()


def test_linked_viewers_of_two_monitors_move_together_and_unlinking_frees_one(twin_feed):
    """The actual monitor on one screen and the simulated on another, both ticking "Link viewers": a seek, a replay
    at ×50 (their one clock advances once per render, not once per viewer), a window load by either moves both; a
    third viewer that did not tick it stays live; unticking frees a viewer where the link was."""  # live span: 100 s
    feed, windows = GrowingFeed(twin_feed), SlowWindows(twin_feed)
    windows.release.set()
    handles = serve_monitors(
        feed,
        ports={"actual": free_port(), "simulated": free_port()},
        roles=("actual", "simulated"),
        start=False,
        live=True,
        windows=windows,
    )
    try:
        with (
            viser_client(handles.ports["actual"]),
            viser_client(handles.ports["actual"]),
            viser_client(handles.ports["simulated"]),
        ):
            actual, alone = wait_for_viewers(handles, "actual", 2)

            def at(viewer) -> str:  # what its panel shows (client ids repeat across the two monitors' servers)
                return viewer.panels.time_text.value

            (simulated,) = wait_for_viewers(handles, "simulated", 1)
            actual.set_linked(True)
            simulated.set_linked(True)
            assert actual.linked and simulated.linked and not alone.linked
            t0, _ = twin_feed.span_unix_s()
            simulated.clock.seek(t0 + 42.5)
            handles.render(wall_dt_s=0.5)
            assert at(actual) == at(simulated) == format_utc(t0 + 42.5)
            assert at(alone) == format_utc(feed.end) and alone.clock.live
            actual.clock.set_speed(50.0)
            actual.clock.play()
            handles.render(wall_dt_s=1.0)
            assert at(actual) == at(simulated) == format_utc(t0 + 92.5)
            actual.request_window(t0 + 60.0, t0 + 360.0)
            deadline = time.monotonic() + 30.0
            while not (actual.replaying_window and simulated.replaying_window) and time.monotonic() < deadline:
                handles.render(wall_dt_s=0.1)
                time.sleep(0.05)
            assert actual.replaying_window and simulated.replaying_window and not alone.replaying_window
            assert at(actual) == at(simulated) == format_utc(t0)
            simulated.set_linked(False)
            simulated.clock.seek(t0 + 7.0)
            handles.render(wall_dt_s=0.5)
            assert at(simulated) == format_utc(t0 + 7.0) and at(actual) == format_utc(t0)
            simulated.set_linked(True)  # rejoining takes the link's view and instant
            handles.render(wall_dt_s=0.5)
            assert at(simulated) == at(actual) == format_utc(t0)
    finally:
        handles.stop()
