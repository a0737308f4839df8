"""The operator console in a real browser (Debian chromium) at 1280x720 and 1920x1080, against the real
backend, with telemetry whose values broke the old dashboard (tests/frontend/console_data.py): tick labels
keep their sign and fit their axis, units/descriptions/enumerations/limits come from the dictionary,
quaternions stay in one hemisphere, the last sample is plotted, markup in names and descriptions stays text,
values update live, the stale indicator appears, alarms go through their whole lifecycle, the honest states
show (empty, unknown, unreachable, token revoked, monitors starting), / opens the dashboard, /docs works
offline, the pass summary exports PNG and PDF, and the archive forms upload with a report table."""

from __future__ import annotations

import http.server
import re
import threading
import time
from pathlib import Path
from urllib.parse import quote, urlsplit

import httpx
import numpy as np
import pytest

from backend.twin.live import STALE_S as STALE_AFTER_S  # the threshold the page reads from /constants
from tests.frontend import console_data as data
from tests.frontend.conftest import _start_uvicorn
from tests.ports import free_port

pytestmark = [pytest.mark.browser, pytest.mark.slow]  # a chromium and servers per file: scheduled first

SATELLITE = "CONSOLE-1"
OTHER = "CONSOLE-2"  # a second satellite with data, to switch to
EMPTY = "EMPTY-1"  # registered, never sent telemetry
VIEWPORTS = [{"width": 1280, "height": 720}, {"width": 1920, "height": 1080}]
# Every wait for the page: a hang bound, each wait ending as soon as the page shows what it waits for. The alarm
# lifecycle's waits (an upload or a POST, the 'alarms' event, a fetch and a redraw) had 5 s, a page sharing two cores
# with its servers and the other test worker's browser or flight
LOAD_MS = 20_000
TICK_MARGIN_PX = 4  # the label must fit inside the axis box with this much to spare
ISO_UTC = r"^\d{4}-\d\d-\d\dT\d\d:\d\d:\d\d(\.\d{3})?Z$"
# The page's clock is held (Playwright's clock.set_fixed_time; its timers run on) where the live sample is FRESH_AGE_S
# old, then STALE_AGE_S. On the wall clock a sample uploaded 7 s old turned stale 3 s later, whether or not a loaded
# machine had carried it to the page by then (the wait for it allowed 5 s)
FRESH_AGE_S, STALE_AGE_S = 1.0, STALE_AFTER_S + 1.0


@pytest.fixture(scope="module")
def console(tmp_path_factory):
    """Backend + dashboard on 127.0.0.1 (temp SQLite): CONSOLE-1 and CONSOLE-2 with ten minutes of awkward
    values ending now, an empty satellite, a satellite whose name is markup; an operator, a viewer and an
    admin token; monitors configured on ports where nothing listens yet."""
    from backend.app import create_app
    from backend.core.auth import Role
    from backend.core.settings import Settings

    tmp = tmp_path_factory.mktemp("console")
    viewer_port = free_port()
    settings = Settings(
        data_dir=tmp / "data",
        database_url=f"sqlite:///{tmp / 'api.sqlite'}",
        job_workers=1,
        job_queue_size=2,
        telemetry_port=0,
        live_enabled=False,
        viewer_port=viewer_port,
    )
    app = create_app(settings)
    port = free_port()
    server, thread = _start_uvicorn(app, port)
    auth = app.state.services.auth
    tokens = {role.name: auth.issue(f"console-{role.name}", role) for role in (Role.viewer, Role.operator, Role.admin)}
    base = f"http://127.0.0.1:{port}"
    with httpx.Client(base_url=base, headers={"Authorization": f"Bearer {tokens['operator'][1]}"}, timeout=60) as c:
        c.post(f"/api/v1/dictionaries/{data.DICTIONARY_NAME}", content=data.DICTIONARY.encode()).raise_for_status()
        end = data.now_s() - 60.0
        for satellite in (SATELLITE, OTHER, data.XSS):
            data.upload(c, satellite, *data.history(end))
        c.post("/api/v1/satellites", json={"name": EMPTY}).raise_for_status()
    yield {
        "base": base,
        "tokens": {k: v[1] for k, v in tokens.items()},
        "token_ids": {k: v[0] for k, v in tokens.items()},
        "end": end,
        "viewer_port": viewer_port,
        "auth": auth,
    }
    server.should_exit = True
    thread.join(timeout=10.0)


def _client(console, role="operator") -> httpx.Client:
    return httpx.Client(
        base_url=console["base"], timeout=60, headers={"Authorization": f"Bearer {console['tokens'][role]}"}
    )


def _open(browser, console, viewport, satellite=SATELLITE, role="operator"):
    page = browser.new_page(viewport=viewport)
    page.errors = []
    page.on("pageerror", lambda e: page.errors.append(str(e)))
    page.goto(f"{console['base']}/dashboard/#satellite={quote(satellite)}")
    page.fill("#token", console["tokens"][role])
    page.click("#login button[type=submit]")
    return page


def _wait_plots(page, n, where="#plots"):
    page.wait_for_function(f"document.querySelectorAll('{where} .uplot').length === {n}", timeout=LOAD_MS)


def _plot(page, names):
    page.wait_for_selector("#parameter-list option", state="attached", timeout=LOAD_MS)
    page.select_option("#parameter-list", names)
    page.click("#plot-btn")
    _wait_plots(page, len(names))


AXIS_JS = """(sel) => acsTwin.plotsIn(sel).map(u => {
  const axis = u.axes[1], ctx = document.createElement('canvas').getContext('2d');
  ctx.font = axis.font[0];
  return {title: u.root.querySelector('.u-title').textContent, label: axis.label, size: axis._size,
          splits: axis._splits, ticks: axis._values, widths: axis._values.map(v => ctx.measureText(v).width),
          xticks: u.axes[0]._values, t: Array.from(u.data[0]), y: Array.from(u.data[1]), limits: u.limits.length};
})"""


@pytest.mark.parametrize("viewport", VIEWPORTS, ids=["1280x720", "1920x1080"])
def test_tick_labels_keep_their_sign_and_fit_and_values_carry_units(browser, console, viewport):
    page = _open(browser, console, viewport)
    try:
        _plot(page, ["temp_probe_degc", "wheel_speed_rpm_1", "gps_pos_x_m", "mode", "q_ib_0"])
        axes = {a["title"].split(" ")[0]: a for a in page.evaluate(AXIS_JS, "#plots")}
        for name, axis in axes.items():
            assert axis["ticks"], name
            for split, tick, width in zip(axis["splits"], axis["ticks"], axis["widths"]):
                assert width + TICK_MARGIN_PX <= axis["size"], (name, tick, width, axis["size"])  # never clipped
                if split < 0 and name != "mode":
                    assert tick.startswith("-"), (name, tick)  # "-168.85" never reads "68.85"
            assert all(re.match(r"^\d\d:\d\d(:\d\d)?(\n\d{4}-\d\d-\d\d)?$", x) for x in axis["xticks"]), axis["xticks"]
        temp, wheel, gps = axes["temp_probe_degc"], axes["wheel_speed_rpm_1"], axes["gps_pos_x_m"]
        assert all(t.startswith("-168") or t.startswith("-169") for t in temp["ticks"]), temp["ticks"]
        assert temp["label"] == "degC" and "probe temperature" in temp["title"] and "[degC]" in temp["title"]
        assert "-2000" in wheel["ticks"] or any(t.startswith("-1") for t in wheel["ticks"]), wheel["ticks"]
        assert wheel["limits"] == 4 and "wheel 1 speed" in wheel["title"]
        assert gps["label"] == "Mm" and "-5" in gps["ticks"] and "5" in gps["ticks"], gps  # ±6e6 m never reads "0"
        assert "THREE_AXIS" in axes["mode"]["ticks"]
        q = np.array(axes["q_ib_0"]["y"])
        assert np.max(np.abs(np.diff(q))) < 0.01 and "hemisphere-continuous" in axes["q_ib_0"]["title"]
        # residuals (actual - twin) are plotted beside the telemetry without being asked for
        residual = page.evaluate(AXIS_JS, "#residual-plots")
        assert [a["title"].split(" ")[0] for a in residual] == ["twin_attitude_residual_arcsec"]
        assert residual[0]["label"] == "arcsec"
        # the whole window: the newest archived sample is the last one plotted
        assert abs(axes["temp_probe_degc"]["t"][-1] - console["end"]) < 1e-3

        latest = {
            r[0]: r[1:]
            for r in page.eval_on_selector_all(
                "#latest tbody tr",
                "rs => rs.map(r => [r.dataset.parameter, r.children[1].textContent, "
                "r.children[1].className, r.children[2].textContent])",
            )
        }
        assert latest["mode"][0] == "THREE_AXIS (3)"
        assert latest["attitude_error_rad"][0] == "40 µrad"  # 2e-5 rad would read "0"
        assert latest["wheel_speed_rpm_1"][0] == "-1600 rpm" and "yellow" in latest["wheel_speed_rpm_1"][1]
        assert latest["gps_pos_x_m"][0] == "-6 Mm"
        assert all(re.match(ISO_UTC, v[2]) for v in latest.values())
        # the legend reads the value under the cursor with its unit
        page.evaluate(
            "acsTwin.plotsIn('#plots').forEach(u => u.setCursor({left: u.bbox.width / devicePixelRatio / 2, top: 10}))"
        )
        legend = page.inner_text("#plots .plot[data-parameter='temp_probe_degc'] .u-legend")
        assert "degC" in legend and re.search(r"\d{4}-\d\d-\d\dT\d\d:\d\d:\d\d\.\d{3}Z", legend), legend
        assert page.errors == []
    finally:
        page.close()


def test_markup_in_a_satellite_name_and_a_description_stays_text(browser, console):
    page = _open(browser, console, VIEWPORTS[1], satellite=data.XSS)
    try:
        page.wait_for_selector("#latest tbody tr", timeout=LOAD_MS)
        _plot(page, ["attitude_error_rad"])
        assert page.evaluate("window.__xss") is None
        assert page.evaluate("document.querySelectorAll('img').length") == 0
        assert data.XSS in page.inner_text("#status")
        assert data.XSS in page.inner_text("#satellite-ages")
        assert data.XSS in page.inner_text("#plots .u-title")
        row = page.locator("#latest tbody tr[data-parameter='attitude_error_rad'] td").first
        assert data.XSS in row.get_attribute("title")
        assert page.errors == []
    finally:
        page.close()


def test_root_opens_the_dashboard_and_the_api_docs_work_offline(browser, console):
    page = browser.new_page(viewport=VIEWPORTS[0])
    outside: list[str] = []

    def only_loopback(route):
        if urlsplit(route.request.url).hostname == "127.0.0.1":
            route.continue_()
        else:
            outside.append(route.request.url)
            route.abort()

    page.route("**/*", only_loopback)
    try:
        page.goto(console["base"] + "/")
        assert page.url.endswith("/dashboard/") and page.title().startswith("acs-twin")
        page.goto(console["base"] + "/docs")
        page.wait_for_function("document.querySelectorAll('.swagger-ui .opblock').length > 20", timeout=LOAD_MS)
        assert "acs-twin" in page.inner_text(".swagger-ui .title")
        assert outside == []
    finally:
        page.close()


def test_live_values_change_without_reload_and_the_stale_indicator_appears(browser, console):
    page = _open(browser, console, VIEWPORTS[0])
    try:
        _plot(page, ["wheel_speed_rpm_1"])
        page.wait_for_selector("#live-link.ok", timeout=LOAD_MS)
        ages = f"#satellite-ages .age[data-satellite='{SATELLITE}']"
        stale = page.locator(ages)
        assert "stale" in stale.inner_text()  # its newest sample is a minute old
        t_new = data.now_s()
        page.clock.set_fixed_time(t_new + FRESH_AGE_S)  # however long the sample takes to reach the page
        with _client(console) as c:
            data.upload(c, SATELLITE, *data.one_row(t_new, wheel_speed_rpm_1=-1234.5))
        cell = "#latest tbody tr[data-parameter='wheel_speed_rpm_1'] td.value"
        page.wait_for_function(f"document.querySelector(\"{cell}\").textContent === '-1234.5 rpm'", timeout=LOAD_MS)
        assert "stale" not in stale.inner_text() and "last packet" in stale.inner_text()
        last_x = page.evaluate("(() => { const t = acsTwin.plotsIn('#plots')[0].data[0]; return t[t.length - 1]; })()")
        assert abs(last_x - t_new) < 1e-3  # the plot followed without a reload
        page.clock.set_fixed_time(t_new + STALE_AGE_S)  # no newer sample: the indicator's next 1-s tick says stale
        page.wait_for_function(f'document.querySelector("{ages}").innerText.includes("stale")', timeout=LOAD_MS)
        # switching satellites clears the previous one's plots and values
        page.fill("#satellite", OTHER)
        page.click("#satellite-form button[type=submit]")
        page.wait_for_function(f"acsTwin.state.satellite === '{OTHER}'")
        page.wait_for_selector("#latest tbody tr", timeout=LOAD_MS)
        assert page.evaluate(f'document.querySelector("{cell}").textContent') != "-1234.5 rpm"
        assert page.errors == []
    finally:
        page.close()


WHEEL_ALARM = "#alarms tbody tr[data-parameter='fault_wheel_1']"


def _alarm_row(page):
    return page.locator(WHEEL_ALARM).first


def test_alarm_lifecycle_end_to_end_at_1280x720(browser, console):
    page = _open(browser, console, VIEWPORTS[0], satellite=OTHER)
    try:
        page.wait_for_selector("#latest tbody tr", timeout=LOAD_MS)
        page.check("#alarm-sound")
        t0 = data.now_s() - 30.0
        with _client(console) as c:
            data.upload(c, OTHER, *data.one_row(t0, fault_wheel_1=1.0))
        page.wait_for_selector(f"{WHEEL_ALARM}.state-active", timeout=LOAD_MS)
        row = _alarm_row(page)
        assert row.locator("td.severity").inner_text() == "critical"  # a wheel failure is red
        banner = page.inner_text("#alarm-banner")
        assert "critical" in banner and "fault_wheel_1" in banner, banner
        page.wait_for_function("Number(document.querySelector('#alarm-banner').dataset.beeps || 0) >= 1")
        for button in row.locator("button, select").all():  # every action visible inside 1280 px
            box = button.bounding_box()
            assert box and box["x"] >= 0 and box["x"] + box["width"] <= VIEWPORTS[0]["width"], box

        row.locator("button:text('ack')").click()
        page.wait_for_selector("#alarms tbody tr.state-acknowledged", timeout=LOAD_MS)
        assert "fault_wheel_1" not in page.inner_text("#alarm-banner")
        with _client(console) as c:  # back in limits: an acknowledged alarm clears itself
            data.upload(c, OTHER, *data.one_row(t0 + 1, fault_wheel_1=0.0))
        page.wait_for_selector(WHEEL_ALARM, state="detached", timeout=LOAD_MS)

        with _client(console) as c:  # a second failure: shelve, unshelve, back to normal unacknowledged, ack
            data.upload(c, OTHER, *data.one_row(t0 + 2, fault_wheel_1=1.0))
        page.wait_for_selector(f"{WHEEL_ALARM}.state-active", timeout=LOAD_MS)
        row = _alarm_row(page)
        row.locator("select").select_option("900")
        page.eval_on_selector(WHEEL_ALARM, "tr => { tr.dataset.drawn = 'before'; }")
        page.check("#show-cleared")  # the table is redrawn (twice) while the operator chooses
        page.wait_for_selector(f"{WHEEL_ALARM}[data-drawn]", state="detached", timeout=LOAD_MS)
        page.wait_for_selector("#alarms tbody tr.state-cleared", timeout=LOAD_MS)
        page.uncheck("#show-cleared")
        page.wait_for_selector("#alarms tbody tr.state-cleared", state="detached", timeout=LOAD_MS)
        assert row.locator("select").input_value() == "900"  # a redraw keeps the operator's choice
        row.locator("button:text('shelve')").click()
        page.wait_for_selector(f"{WHEEL_ALARM}.state-shelved", timeout=LOAD_MS)
        text = _alarm_row(page).locator("td.lifecycle").inner_text()
        until = re.search(r"shelved until (\S+)", text).group(1)
        assert (
            re.match(ISO_UTC, until)
            and 850 < np.datetime64(until.rstrip("Z")).astype("datetime64[s]").astype(float) - time.time() < 950
        )
        _alarm_row(page).locator("button:text('unshelve')").click()
        page.wait_for_selector(f"{WHEEL_ALARM}.state-active", timeout=LOAD_MS)
        with _client(console) as c:
            data.upload(c, OTHER, *data.one_row(t0 + 3, fault_wheel_1=0.0))
        page.wait_for_function(
            f'document.querySelector("{WHEEL_ALARM} td.lifecycle")?.textContent === '
            "'returned to normal, unacknowledged'",
            timeout=LOAD_MS,
        )
        _alarm_row(page).locator("button:text('history')").click()
        page.wait_for_selector("#alarm-history table.history-events tbody tr")
        events = page.eval_on_selector_all(
            "#alarm-history table.history-events tbody tr", "rs => rs.map(r => r.children[1].textContent)"
        )
        # in time order: the samples are 30 s old, the operator's actions happened now
        assert events == ["enter", "leave", "shelve", "unshelve"], events
        every = page.eval_on_selector_all("#alarm-history table.history-parameter tbody tr", "rs => rs.length")
        assert every == 2  # the cleared first alarm and this one
        _alarm_row(page).locator("button:text('ack')").click()
        page.wait_for_selector(WHEEL_ALARM, state="detached", timeout=LOAD_MS)
        page.check("#show-cleared")
        page.wait_for_function(f'document.querySelectorAll("{WHEEL_ALARM}.state-cleared").length === 2')
        assert page.errors == []
    finally:
        page.close()


def test_empty_and_unknown_satellites_say_so(browser, console):
    page = _open(browser, console, VIEWPORTS[0], satellite=EMPTY)
    try:
        page.wait_for_selector("#notice[data-kind='empty']", timeout=LOAD_MS)
        assert f"No telemetry yet for {EMPTY}: upload" in page.inner_text("#notice")
        page.fill("#satellite", "NO-SUCH-SAT")
        page.click("#satellite-form button[type=submit]")
        page.wait_for_selector("#notice[data-kind='unknown']", timeout=LOAD_MS)
        assert 'Unknown satellite "NO-SUCH-SAT"' in page.inner_text("#notice")
        with _client(console) as c:
            listed = c.get("/api/v1/satellites").status_code == 200  # GET /satellites is issue 11's
        assert (SATELLITE in page.inner_text("#notice")) == listed  # names the satellites that exist
    finally:
        page.close()


def test_unreachable_server_offers_retry_and_recovers(browser, console):
    page = browser.new_page(viewport=VIEWPORTS[0])
    # the page's timers held: its automatic retry (RETRY_S = 5 s after the notice) cannot recover the page on its
    # own between the unroute and the click (a test slowed that long clicked a button already gone); the recovery
    # below can only be the button's. The installed clock runs on from t0 until paused, and a pause_at in its past
    # raises: paused well ahead, before the page and its timers exist.
    t0 = data.now_s()
    page.clock.install(time=t0)
    page.clock.pause_at(t0 + 3600.0)
    page.route("**/api/v1/**", lambda route: route.abort("connectionrefused"))
    try:
        page.goto(f"{console['base']}/dashboard/")
        page.wait_for_selector("#notice[data-kind='unreachable']", timeout=LOAD_MS)
        assert "Server unreachable" in page.inner_text("#notice") and "Retrying in" in page.inner_text("#notice")
        page.unroute("**/api/v1/**")
        page.click("#notice button:text('Retry now')")
        page.wait_for_selector("#login:not([hidden])", timeout=LOAD_MS)
        assert page.locator("#notice").is_hidden()
    finally:
        page.close()


def test_a_revoked_token_sends_the_operator_back_to_login(browser, console):
    with _client(console, "admin") as c:
        issued = c.post("/api/v1/tokens", json={"name": "short-lived", "role": "viewer"}).json()
    page = browser.new_page(viewport=VIEWPORTS[0])
    try:
        page.goto(f"{console['base']}/dashboard/#satellite={SATELLITE}")
        page.fill("#token", issued["token"])
        page.click("#login button[type=submit]")
        page.wait_for_selector("#latest tbody tr", timeout=LOAD_MS)
        assert "needs operator: your token is viewer" in page.inner_text("#upload-form .role")
        assert page.locator("#upload-form button").is_disabled()
        with _client(console, "admin") as c:
            c.delete(f"/api/v1/tokens/{issued['id']}").raise_for_status()
        # the server closes the token's WebSocket at once (4401); without a socket the next request would say it
        page.wait_for_selector("#notice[data-kind='unauthorized']", timeout=LOAD_MS)
        assert "Token expired or revoked" in page.inner_text("#notice")
        assert page.locator("#app").is_hidden() and page.locator("#login").is_visible()
    finally:
        page.close()


class _Quiet(http.server.SimpleHTTPRequestHandler):
    def log_message(self, *args):
        pass


def test_monitors_show_progress_until_they_answer(browser, console):
    page = _open(browser, console, VIEWPORTS[1])
    server = None
    try:
        page.wait_for_selector("#monitors figure[data-role='actual'] .starting progress", timeout=LOAD_MS)
        page.wait_for_function(
            "document.querySelector(\"#monitors figure[data-role='actual']\").innerText.includes('starting…')",
            timeout=LOAD_MS,
        )
        assert page.locator("#monitors iframe").count() == 0  # no broken frame while nothing answers
        server = http.server.ThreadingHTTPServer(("127.0.0.1", console["viewer_port"]), _Quiet)
        threading.Thread(target=server.serve_forever, daemon=True).start()
        page.wait_for_selector("#monitors figure[data-role='actual'] iframe", timeout=LOAD_MS)
        assert page.get_attribute("#monitors figure[data-role='actual']", "data-state") == "ready"
    finally:
        if server:
            server.shutdown()
            server.server_close()
        page.close()


def test_an_embedded_monitor_behind_the_token_gate_opens_with_the_dashboard_token(browser, console, twin_feed):
    from backend.twin.monitor_gate import MonitorGate
    from frontend.monitors import serve_monitors
    from tests.frontend.test_browser import PAINT_TIMEOUT_S, _wait_for

    handles = serve_monitors(twin_feed, ports={"actual": free_port()}, roles=("actual",))
    gate = MonitorGate(console["auth"], "127.0.0.1", console["viewer_port"], handles.ports["actual"], role="actual")
    gate.start()
    page = _open(browser, console, VIEWPORTS[1], role="viewer")
    try:
        element = page.wait_for_selector("#monitors figure[data-role='actual'] iframe", timeout=LOAD_MS)
        element.scroll_into_view_if_needed()  # chromium does not animate an off-screen cross-origin frame
        # the frame's viser WebSocket came through the gate (cookie from the dashboard's token): a viewer of its own
        _wait_for(lambda: len(handles.viewers.get("actual", {})) == 1, PAINT_TIMEOUT_S, "the embedded monitor")
        gate_url = f"http://127.0.0.1:{console['viewer_port']}/"  # the gate moved the token into a cookie
        # looked up now, not before the wait: the gate's redirect replaces the frame the element first held, and
        # the new frame may still be navigating (url '') when the viewer registers: poll, letting playwright
        # dispatch its frame events between looks
        deadline = time.monotonic() + PAINT_TIMEOUT_S
        while (frame := next((f for f in page.frames if f.url == gate_url), None)) is None:
            assert time.monotonic() < deadline, [f.url for f in page.frames]
            page.wait_for_timeout(200)
        assert "Software WebGL" in frame.evaluate("document.body.innerText")  # viser's own page, not a refusal
    finally:
        page.close()
        gate.stop()
        handles.stop()


def _pdf_is_well_formed(pdf: bytes) -> None:
    assert pdf.startswith(b"%PDF-1.4") and pdf.rstrip().endswith(b"%%EOF") and b"/DCTDecode" in pdf
    xref = int(pdf[pdf.rindex(b"startxref") + 9 :].split()[0])
    assert pdf[xref : xref + 4] == b"xref"
    rows = pdf[xref:].split(b"\n")[3:10]  # seven objects after the free entry
    for number, row in enumerate(rows, start=1):
        offset = int(row.split()[0])
        assert pdf[offset:].startswith(f"{number} 0 obj".encode()), (number, offset)


def test_pass_summary_exports_png_and_pdf(browser, console, tmp_path):
    page = _open(browser, console, VIEWPORTS[1])
    try:
        page.wait_for_selector("#latest tbody tr", timeout=LOAD_MS)
        page.click("#summary-btn")
        _wait_plots(page, 3, "#summary-plots")
        whats = page.eval_on_selector_all("#summary-plots .summary-chart", "cs => cs.map(c => c.dataset.what)")
        assert whats == ["attitude error", "wheel speeds", "alarms"]
        with page.expect_download() as png:
            page.click("#summary-png")
        assert Path(png.value.path()).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
        with page.expect_download() as pdf:
            page.click("#summary-pdf")
        _pdf_is_well_formed(Path(pdf.value.path()).read_bytes())
        assert page.errors == []
    finally:
        page.close()


def test_archive_upload_from_the_ui_shows_its_report_as_a_table(browser, console, tmp_path):
    page = _open(browser, console, VIEWPORTS[1])
    try:
        page.wait_for_selector("#latest tbody tr", timeout=LOAD_MS)
        t, values = data.history(data.now_s() - 3600.0, 20)
        path = tmp_path / "ground.csv"
        path.write_bytes(data.csv_bytes(t, values))
        page.select_option("#upload-format", "csv")
        page.select_option("#upload-dictionary", data.DICTIONARY_NAME)
        page.set_input_files("#upload-file", str(path))
        page.click("#upload-form button[type=submit]")
        page.wait_for_selector("#upload-form table.report-archive", timeout=LOAD_MS)
        report = dict(
            page.eval_on_selector_all(
                "#upload-form table.report-archive tbody tr",
                "rs => rs.map(r => [r.children[0].textContent, r.children[1].textContent])",
            )
        )
        assert report["packets_accepted"] == "20" and report["samples_accepted"] == str(20 * len(data.COLUMNS))
        assert page.errors == []
    finally:
        page.close()
