"""The 3D monitors on a live twin (backend.twin.live_feed) in a real browser: in live follow the displayed instant
moves on with the telemetry without a reload, a STALE warning shows at the top of the panel once it stops, and
while a monitor starts its port shows progress (backend.twin.monitor_gate) and then turns into the monitor."""

from __future__ import annotations

import dataclasses
import threading
import time

import numpy as np
import pytest

from backend.twin.live import LiveTwins
from backend.twin.live_feed import LiveFeed
from frontend.monitors import serve_monitors
from telemetry.decoding import decode_stream
from telemetry.dictionary import load_dictionary
from telemetry.emulator import demo_pass_bytes
from tests.frontend.conftest import PANEL_VIEWPORT
from tests.frontend.test_browser import PAINT_TIMEOUT_S, _displayed_utc, _wait_for
from tests.ports import free_port

pytestmark = [pytest.mark.browser, pytest.mark.slow]

FLIGHT_S = 120
FIRST_S = 40  # telemetry present before the monitors start (the orbit needs GPS fixes)
# The twins' stale threshold here (STALE_S = 10 s in service): the follow phase cannot reach it however long a loaded
# machine takes to bring the page to the newest sample (up to FOLLOW_TOLERANCE_S + 10 s of waiting, beyond 10 s);
# the test then moves the clock past it
STALE_AFTER_S = 3600.0
FOLLOW_TOLERANCE_S = 3.0  # live follow shows the newest sample within the feed's snapshot and panel periods
STREAM_PERIOD_S = 0.02  # wall time between two seconds of streamed telemetry (faster than real time: the monitor
# must follow whatever the pace; 80 streamed seconds take 1.6 s of the test, not 80)


class _Clock:
    """Wall clock that a test can move forward (to make the stream stale without waiting)."""

    def __init__(self) -> None:
        self.offset_s = 0.0

    def __call__(self) -> float:
        return time.time() + self.offset_s


def _seconds() -> list[list]:
    data = demo_pass_bytes("somov-ge4-scan", 0.0, float(FLIGHT_S), [], start_utc="2026-03-20T00:00:00Z")
    batches = decode_stream(data, load_dictionary("reference_satellite.yaml"), source="test").batches
    t0 = min(int(b.t_utc_ns[0]) for b in batches)
    out = []
    for k in range(FLIGHT_S):
        lo, hi = t0 + k * 10**9, t0 + (k + 1) * 10**9
        out.append(
            [
                dataclasses.replace(
                    b,
                    t_utc_ns=b.t_utc_ns[s],
                    sequence_count=b.sequence_count[s],
                    packets=None,
                    values={n: np.asarray(v)[s] for n, v in b.values.items()},
                )
                for b in batches
                if (s := (b.t_utc_ns >= lo) & (b.t_utc_ns < hi)).any()
            ]
        )
    return out


def _utc_across_reloads(page) -> str | None:
    """The displayed UTC, None while the page is (re)loading (the starting page reloads itself)."""
    from playwright.sync_api import Error

    try:
        return _displayed_utc(page)
    except Error:
        return None


def _page_text(page) -> str:
    return page.evaluate("() => document.body.innerText")


def test_monitors_follow_the_live_twin_and_warn_when_it_goes_stale(browser):
    clock = _Clock()
    twins = LiveTwins(
        lambda: None,
        type("Hub", (), {"publish": lambda *a: None, "wants_any": lambda *a: False})(),
        load_dictionary,
        clock=clock,
        stale_after_s=STALE_AFTER_S,
    )
    twins.register_model("REFSAT", "somov-ge4-scan", None, from_run=True)
    twins.start(recover=False)
    seconds = _seconds()
    for second in seconds[:FIRST_S]:
        twins.submit("REFSAT", "reference_satellite.yaml", second)
    twins.drain()
    handles = serve_monitors(
        LiveFeed(twins, "REFSAT", clock=clock),
        ports={r: free_port() for r in ("actual", "simulated", "overlay")},
        live=True,
    )
    stop = threading.Event()

    def stream() -> None:  # one second of telemetry every STREAM_PERIOD_S of wall time
        for second in seconds[FIRST_S:]:
            if stop.wait(STREAM_PERIOD_S):
                return
            twins.submit("REFSAT", "reference_satellite.yaml", second)

    page = browser.new_page(viewport=PANEL_VIEWPORT)
    feeder = threading.Thread(target=stream, daemon=True)
    try:
        page.goto(handles.urls()["overlay"])
        _wait_for(lambda: _displayed_utc(page) is not None, PAINT_TIMEOUT_S, "the monitor's panel")
        first = _displayed_utc(page)
        feeder.start()
        feeder.join()
        twins.drain()
        newest = twins.state("REFSAT")["telemetry_utc"]
        _wait_for(
            lambda: _displayed_utc(page) == newest,
            FOLLOW_TOLERANCE_S + 10.0,
            f"the monitor at the newest sample {newest} (was {first})",
        )
        assert _displayed_utc(page) > first  # moved on by itself: no reload
        assert "STALE" not in _page_text(page)
        clock.offset_s = STALE_AFTER_S + 5.0
        _wait_for(lambda: "STALE" in _page_text(page), 15.0, "the stale warning")
        text = _page_text(page)
        assert text.index("STALE") < text.index("Playback")  # at the top of the panel, above every folder
        assert "the view is not live" in text
    finally:
        stop.set()
        page.close()
        handles.stop()
        twins.stop()


def test_a_starting_monitor_shows_progress_then_turns_into_the_monitor(browser, twin_feed, tmp_path):
    from playwright.sync_api import expect

    from backend.core.auth import Role
    from backend.core.settings import Settings
    from backend.services import build_services
    from backend.twin.monitor_gate import MonitorGate

    services = build_services(Settings(data_dir=tmp_path))
    _, token = services.auth.issue("monitor viewer", Role.viewer)
    gate = MonitorGate(services.auth, "127.0.0.1", 0, None, role="overlay", progress=lambda: "waiting for REFSAT")
    gate.start()
    handles = None
    page = browser.new_page(viewport=PANEL_VIEWPORT)
    try:
        page.goto(f"http://127.0.0.1:{gate.port}/")
        assert "?token=" in _page_text(page)  # refused, and told how to open it
        page.goto(f"http://127.0.0.1:{gate.port}/?token={token}")
        # the starting page reloads itself every STARTING_REFRESH_S (2 s): read through Playwright's retrying
        # assertions, which find the page again after a reload (a single read that met one failed: no context, or
        # no element yet in the reloading document)
        expect(page.locator("body")).to_contain_text("starting: waiting for REFSAT")
        expect(page.locator("progress")).to_have_count(1)
        assert "token=" not in page.url  # kept in a cookie, out of the address bar
        handles = serve_monitors(twin_feed, ports={"overlay": free_port()}, roles=("overlay",))
        gate.attach(handles.ports["overlay"])
        _wait_for(lambda: _utc_across_reloads(page) is not None, PAINT_TIMEOUT_S, "the page to become the monitor")
    finally:
        page.close()
        if handles is not None:
            handles.stop()
        gate.stop()
        services.close()
