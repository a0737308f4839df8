"""Per-viewer playback in real browsers (Debian chromium through Playwright): two browsers on one monitor, one
leaves live follow and replays, or loads a past window of the archive, while the other stays live."""

from __future__ import annotations

import numpy as np
import pytest

from frontend.feed import TrajectoryFeed
from frontend.monitors import serve_monitors
from frontend.twin_panels import format_utc, parse_utc
from sim_core.trajectory import Trajectory
from tests.frontend.conftest import PANEL_VIEWPORT, synthetic_trajectory
from tests.frontend.test_browser import PAINT_TIMEOUT_S, _displayed_utc, _wait_for
from tests.ports import free_port

pytestmark = [pytest.mark.browser, pytest.mark.slow]  # a chromium and servers per file: scheduled first

HISTORY_BEFORE_S = 86_400.0  # the archive's past window lies a day before the live feed
HISTORY_S = 1800.0
WINDOW_MIN = 10
# The bound of every wait for a viewer to show a state: a hang bound, each wait ending as soon as the page or the
# server shows it. A panel change crosses viser's event loop, its thread pool, the render thread (30 Hz, panels at
# 2 Hz) and two pages rendering WebGL in software; at load 5-9 one was seen more than 2 s late (189f033), and some
# of these waits had 10 s
SHOWN_S = 30.0


def _window(traj: Trajectory, t0_unix_s: float, t1_unix_s: float) -> Trajectory:
    """The samples of a trajectory inside [t0, t1] (UTC s)."""
    t = traj.t_s + traj.extra["epoch_unix_s"]
    keep = (t >= t0_unix_s) & (t <= t1_unix_s)
    series = {name: values[:, keep] for name, values in traj.series.items()}
    return Trajectory(
        traj.scenario_name,
        traj.variant_names,
        traj.t_s[keep],
        series,
        traj.events,
        traj.wheel_inertia_kg_m2,
        extra=dict(traj.extra),
    )


class HistoryWindows:
    """frontend.feed.WindowSource over a synthetic past (a rolled twin a day before the live feed)."""

    def __init__(self, epoch_unix_s: float) -> None:
        self.history = synthetic_trajectory(duration_s=HISTORY_S, offset_deg=2.0)
        self.history.extra["epoch_unix_s"] = epoch_unix_s - HISTORY_BEFORE_S
        self.asked: list[tuple[float, float]] = []

    def archive_span_unix_s(self) -> tuple[float, float]:
        t = self.history.t_s + self.history.extra["epoch_unix_s"]
        return float(t[0]), float(t[-1])

    def window_feed(self, t0_unix_s: float, t1_unix_s: float) -> TrajectoryFeed:
        self.asked.append((t0_unix_s, t1_unix_s))
        window = _window(self.history, t0_unix_s, t1_unix_s)
        if window.t_s.size < 2:
            raise ValueError("from: no telemetry archived in that window")
        return TrajectoryFeed(window, actual_variant=0, simulated_variant=1)


@pytest.fixture
def live_monitor(twin_feed):
    windows = HistoryWindows(twin_feed.span_unix_s()[0])
    handles = serve_monitors(twin_feed, ports={"overlay": free_port()}, roles=("overlay",), live=True, windows=windows)
    yield handles, windows
    handles.stop()


def _open(browser, url: str):
    page = browser.new_page(viewport=PANEL_VIEWPORT)
    page.goto(url)
    _wait_for(lambda: _displayed_utc(page) is not None, PAINT_TIMEOUT_S, "the monitor's panel")
    return page


def _input_showing(page, value: str):
    """The panel's text input that currently shows value (viser's labels are not tied to their inputs)."""
    index = page.evaluate("(v) => Array.from(document.querySelectorAll('input')).findIndex(i => i.value === v)", value)
    assert index >= 0, f"no input shows {value!r}"
    return page.locator("input").nth(index)


def _live_clocks(handles) -> int:
    return [v.clock.live for v in handles.all_viewers()].count(True)


def _utc_s(page) -> float:
    return parse_utc(_displayed_utc(page))


def test_one_viewer_replaying_leaves_the_other_live(browser, live_monitor):
    handles, _ = live_monitor
    live_end = format_utc(handles.geometry.feed.span_unix_s()[1])
    pages = [_open(browser, handles.urls()["overlay"]) for _ in range(2)]
    mover, watcher = pages
    try:
        for page in pages:
            _wait_for(lambda p=page: _displayed_utc(p) == live_end, SHOWN_S, "both viewers live at the newest instant")
        mover.get_by_text("Live follow").click()  # leave live follow …
        # … and, once its callback has moved the mover's clock, replay from the start of the data: viser runs each
        # callback on a thread of its pool, so a play clicked sooner could run first and the live-follow callback
        # then stopped the replay (follow_live(False) pauses)
        _wait_for(lambda: _live_clocks(handles) == 1, SHOWN_S, "the mover's clock out of live follow")
        mover.get_by_role("button", name="play").click()
        _wait_for(lambda: _displayed_utc(mover) != live_end, SHOWN_S, "the replaying viewer to move")
        first = _utc_s(mover)
        _wait_for(lambda: _utc_s(mover) > first, SHOWN_S, "the replay to advance")  # replay advances …
        assert _displayed_utc(watcher) == live_end  # … and the other viewer never left live follow
        assert _live_clocks(handles) == 1
    finally:
        for page in pages:
            page.close()


def test_a_viewer_replays_a_past_window_of_the_archive_while_another_stays_live(browser, live_monitor):
    handles, windows = live_monitor
    live_end = format_utc(handles.geometry.feed.span_unix_s()[1])
    a0, a1 = windows.archive_span_unix_s()
    start = a0 + 300.0
    pages = [_open(browser, handles.urls()["overlay"]) for _ in range(2)]
    replayer, watcher = pages
    try:
        assert format_utc(a0) in replayer.inner_text("body")  # the panel says what the archive holds
        field = _input_showing(replayer, format_utc(a0))  # From (UTC): the archive's first instant by default
        field.fill(format_utc(start))
        field.press("Enter")
        replayer.get_by_role("button", name="Load window").click()
        _wait_for(lambda: "replaying" in replayer.inner_text("body"), SHOWN_S, "the window to load")
        assert windows.asked[-1] == (pytest.approx(start, abs=1e-3), pytest.approx(start + 60 * WINDOW_MIN, abs=1e-3))
        _wait_for(lambda: _displayed_utc(replayer) == format_utc(start), SHOWN_S, "the viewer at the window's start")
        (viewer,) = [v for v in handles.all_viewers() if v.replaying_window]
        f = viewer.geometry.frame(start)  # the archived pair: the twin rolled 2° off the telemetry
        assert np.degrees(np.arccos(min(1.0, abs(float(np.dot(f.q_actual, f.q_simulated)))))) * 2 == pytest.approx(
            2.0, abs=1e-3
        )
        assert _displayed_utc(watcher) == live_end
        # the click toggles the box the browser shows: wait until it shows replay (off), or the click turns it off
        _wait_for(lambda: not replayer.get_by_label("Live follow").is_checked(), SHOWN_S, "live follow shown off")
        replayer.get_by_text("Live follow").click()  # back to live
        _wait_for(lambda: replayer.get_by_label("Live follow").is_checked(), SHOWN_S, "live follow shown on")
        _wait_for(lambda: _displayed_utc(replayer) == live_end, SHOWN_S, "the viewer back on the live feed")
        assert not any(v.replaying_window for v in handles.all_viewers())
        field.fill("yesterday")
        field.press("Enter")
        replayer.get_by_role("button", name="Load window").click()
        _wait_for(lambda: "not loaded: from:" in replayer.inner_text("body"), SHOWN_S, "the refusal naming the field")
    finally:
        for page in pages:
            page.close()
