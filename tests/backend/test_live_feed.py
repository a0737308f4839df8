"""Past windows of the archive for the 3D monitors (backend.twin.live_feed.ArchiveWindows): the emulated reference
satellite uploaded through the app, its window read back as the telemetry and the twin said it, bounded."""

from __future__ import annotations

import contextlib
from collections.abc import Iterator

import numpy as np
import pytest
from fastapi.testclient import TestClient

from backend.app import create_app
from backend.core.auth import Role
from backend.twin import live_feed
from backend.twin.live_feed import MAX_WINDOW_S, ArchiveWindows
from tests.backend.conftest import make_settings, postgres_schema_url
from tests.backend.test_satellites_api import _upload, reference_pass  # noqa: F401 (the fixture)

SAME_ATTITUDE = 1e-9  # |<q_a, q_b>| of one attitude read twice: float round-off only
NS_PER_S = 1e9


def _same_attitude(q_a: np.ndarray, q_b: np.ndarray) -> bool:
    return bool(np.all(np.abs(np.abs(np.einsum("ij,ij->i", q_a, q_b)) - 1.0) < SAME_ATTITUDE))


@pytest.fixture(scope="module", params=["sqlite", pytest.param("postgres", marks=pytest.mark.postgres)])
def client(
    request: pytest.FixtureRequest,
    tmp_path_factory: pytest.TempPathFactory,
    reference_pass: bytes,  # noqa: F811
) -> Iterator[TestClient]:
    """One started app per database for this module, the reference pass uploaded through it once (its live twin
    drained): every test only reads the archive and the twin's samples, none changes them."""
    data = tmp_path_factory.mktemp("live_feed")
    with contextlib.ExitStack() as stack:
        if request.param == "sqlite":
            url = f"sqlite:///{data / 'api.sqlite'}"
        else:
            url = stack.enter_context(
                contextlib.contextmanager(postgres_schema_url)(request.getfixturevalue("postgres_url"))
            )
        client = stack.enter_context(TestClient(create_app(make_settings(data, url))))
        operator = client.app.state.services.auth.issue("test-operator", Role.operator)[1]
        _upload(client, operator, "REFSAT", "reference_satellite.yaml", reference_pass)
        yield client


@pytest.fixture
def windows(client: TestClient) -> ArchiveWindows:
    """A new ArchiveWindows (its own span cache) over the module's app."""
    services = client.app.state.services
    return ArchiveWindows(services.telemetry.opened_archive, services.twins, "REFSAT")


def test_a_past_window_replays_the_archived_telemetry_and_the_archived_twin(
    client: TestClient, windows: ArchiveWindows
) -> None:
    t0, t1 = windows.archive_span_unix_s()
    feed = windows.window_feed(t0 + 60.0, t0 + 180.0)
    start, end = feed.span_unix_s()
    assert t0 + 60.0 <= start < start + 100.0 < end <= t0 + 180.0
    recent = client.app.state.services.twins.recent("REFSAT")  # what the live twin held when it compared
    inside = (recent["t_ns"] >= start * NS_PER_S) & (recent["t_ns"] <= end * NS_PER_S)
    assert _same_attitude(feed.attitude_actual(recent["t_ns"][inside] / NS_PER_S), recent["q_ib"][inside])
    flown = (recent["twin_t_ns"] >= start * NS_PER_S) & (recent["twin_t_ns"] <= end * NS_PER_S)
    assert flown.sum() > 100
    assert _same_attitude(feed.attitude_simulated(recent["twin_t_ns"][flown] / NS_PER_S), recent["twin_q_ib"][flown])
    window = feed.window(start, end)
    assert np.nanmax(window.error_angle_rad) > 0.0 and window.wheel_speed_rad_s.shape[1] == 4
    assert not any("no twin attitude" in a for a in feed.active_alarms(end))


def test_a_window_without_an_archived_twin_says_so(windows: ArchiveWindows, monkeypatch) -> None:
    from backend.twin import live

    monkeypatch.setattr(live, "TWIN_ATTITUDE_PARAMETERS", ("not_archived_0", "a", "b", "c"))  # an older archive
    t0, t1 = windows.archive_span_unix_s()
    feed = windows.window_feed(t0, t1)
    assert "no twin attitude archived in this window" in feed.active_alarms(t1)[0]
    t = np.linspace(t0, t1, 7)
    assert _same_attitude(feed.attitude_simulated(t), feed.attitude_actual(t))


def test_loading_is_bounded_by_the_one_downsampler(windows: ArchiveWindows, monkeypatch) -> None:
    t0, t1 = windows.archive_span_unix_s()
    monkeypatch.setattr(live_feed, "MAX_WINDOW_SAMPLES", 200)
    feed = windows.window_feed(t0, t1)
    assert feed.window(t0, t1).t_unix_s.size <= 200  # 4 Hz over 4 minutes would be 960
    assert feed.span_unix_s() == pytest.approx((t0, t1), abs=0.3)  # min/max buckets keep the ends of the span


def test_windows_outside_the_archive_or_too_long_are_refused_naming_the_field(windows: ArchiveWindows) -> None:
    t0, t1 = windows.archive_span_unix_s()
    with pytest.raises(ValueError, match="^from: no telemetry"):
        windows.window_feed(t1 + 3600.0, t1 + 4200.0)
    with pytest.raises(ValueError, match="^length: at most"):
        windows.window_feed(t0, t0 + MAX_WINDOW_S + 1.0)
    with pytest.raises(ValueError, match="^window: need finite"):
        windows.window_feed(t1, t0)


def test_the_feed_orbit_goes_through_the_gps_fixes_within_their_noise(windows: ArchiveWindows) -> None:
    from sim_core import frames
    from telemetry.emulator import GPS_SIGMA_R_M

    t0, t1 = windows.archive_span_unix_s()
    feed = windows.window_feed(t0, t1)
    recent = feed._snapshot()  # the window's GPS fixes as read from the archive
    m, gps, t_fix = recent["mapping"], recent["gps"], recent["gps_t_ns"] / NS_PER_S
    r_fix, _ = frames.ecef_to_eci(
        np.stack([gps[n] for n in m.r_ecef_m], -1), np.stack([gps[n] for n in m.v_ecef_m_s], -1), t_fix
    )
    r, _ = feed.orbit_eci(t_fix + 0.25)  # between the table's rows, off the fixes' instants
    r_at_fix, _ = feed.orbit_eci(t_fix)
    assert np.max(np.linalg.norm(r_at_fix - r_fix, axis=-1)) < 5 * GPS_SIGMA_R_M  # smoothed through the noise
    assert np.all(np.linalg.norm(r - r_at_fix, axis=-1) < 8_000.0 * 0.25 + 5 * GPS_SIGMA_R_M)  # LEO ~7.6 km/s
