"""Fixtures of the frontend tests: a small twin trajectory, running monitors, headless Debian
chromium driven by Playwright (never a downloaded browser), and the real backend app in a uvicorn
thread on 127.0.0.1 with a temporary SQLite archive holding the NOAA-20 diary and a predicted pass."""

from __future__ import annotations

import io
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from frontend.feed import TrajectoryFeed
from sim_core.trajectory import Trajectory
from tests.ports import free_port

CHROMIUM = Path("/usr/bin/chromium")
CHROMIUM_FLAGS = [
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--use-gl=angle",
    "--use-angle=swiftshader",
    "--enable-unsafe-swiftshader",
]
# a monitor page whose panel is read but whose pixels are not: headless chromium renders the WebGL scene in software
# every frame the page is open (~0.5 core at 1280x900 against ~0.35 at 800x600, a live monitor, load 3-6)
PANEL_VIEWPORT = {"width": 800, "height": 600}
SCENE_FRACTION = 0.62  # left part of a 1280-wide monitor page: the control panel floats on the right
EARTH_CHROMA = 16  # a pixel of the globe is coloured (max - min channel above this), its night side too (navy, about
# (15, 16, 43)); the background, viser's toasts, the white lines and the labels are grey
EARTH_LINE_PX = 4  # coloured lines (orbit, traces, terminator, station circles) are <= 3 px: eroded away at this radius
NOAA20_PACKETS = Path("real/noaa20_jpss1_apid11/J01_G011_LZ_2021-04-09T00-00-00Z_V01.DAT1")
NOAA20_TLE = Path("tle/real_sso_smallsats.tle")
STATION = {"name": "Svalbard", "lat_deg": 78.23, "lon_deg": 15.39, "alt_m": 500.0, "min_elevation_deg": 5.0}
DIARY_START, DIARY_END = "2021-04-09T00:00:00Z", "2021-04-09T02:00:00Z"
ALARM_SATELLITE = "NOAA-20L"  # the same diary under a dictionary with a limit on the attitude scalar
LIMITED_DICTIONARY = """
name: NOAA-20 with a limit on the attitude scalar
packets:
  - name: JPSS_ATT_EPHEM
    apid: 11
    layout_from: {ccsdspy_csv: jpss1_geolocation_upload.csv}
    time_code: {format: CDS, day_octets: 2, submillisecond_octets: 2, epoch_utc: "1958-01-01T00:00:00Z"}
    derived:
      - {name: q0_watch, kind: alias, inputs: [ADCFAQ4], limits: {yellow_high: 0.9, red_high: 0.99}}
"""


def earth_share(png: bytes | Path) -> float:
    """Share of a monitor screenshot's scene covered by the globe: coloured pixels in areas wider than a line (an
    erosion by EARTH_LINE_PX drops the lines and labels drawn over an empty background; the disc stays, day and
    night side). About 0.35 for the whole-Earth preset at 1280x800; 0.000 with the globe hidden."""
    from PIL import Image
    from scipy import ndimage

    img = np.asarray(Image.open(io.BytesIO(png) if isinstance(png, bytes) else png).convert("RGB"), dtype=int)
    scene = img[:, : int(img.shape[1] * SCENE_FRACTION)]
    coloured = np.ptp(scene, axis=-1) > EARTH_CHROMA
    side = 2 * EARTH_LINE_PX + 1
    return float(np.mean(ndimage.binary_erosion(coloured, structure=np.ones((side, side), dtype=bool))))


def synthetic_trajectory(duration_s: float = 600.0, dt_s: float = 1.0, offset_deg: float = 0.0) -> Trajectory:
    """A nadir-pointing spacecraft on a 600 km polar circular orbit (exact ORF attitude), optionally
    rolled by offset_deg about body y, as a two-variant trajectory (variant 1 = the rolled twin)."""
    from sim_core import frames, orbit, quaternion

    t = np.arange(0.0, duration_s + dt_s / 2, dt_s)
    r, v = orbit.circular_orbit(t, 600e3, 97.8, 30.0)
    q_orf = frames.orf_quaternion(r, v)
    roll = quaternion.from_axis_angle(np.array([0.0, 1.0, 0.0]), np.radians(offset_deg))
    q = np.stack([q_orf, quaternion.multiply(q_orf, np.broadcast_to(roll, q_orf.shape))])
    w = np.broadcast_to(frames.orf_rate_rad_s(r, v)[None], (2, t.size, 3))
    w_b = np.stack([quaternion.rotate(quaternion.conjugate(q[k]), w[k]) for k in range(2)])
    n = t.size
    series = {
        "q_ib": q,
        "omega_b_rad_s": w_b,
        "r_eci_m": np.broadcast_to(r, (2, n, 3)).copy(),
        "wheel_speed_rad_s": np.stack([np.outer(np.ones(n), [100.0, -100.0, 50.0, -50.0])] * 2),
        "md_dipole_am2": np.zeros((2, n, 3)),
        "observing": np.ones((2, n)),
        "fault_flags": np.zeros((2, n)),
    }
    return Trajectory(
        "synthetic-nadir",
        ["nominal", "rolled"],
        t,
        series,
        [[], []],
        np.full(4, 0.0191),
        extra={"epoch_unix_s": 1_773_964_800.0},
    )


@pytest.fixture(scope="session")
def twin_feed() -> TrajectoryFeed:
    """Actual = exact nadir pointing; simulated = the twin rolled by 1°."""
    traj = synthetic_trajectory(offset_deg=1.0)
    return TrajectoryFeed(traj, actual_variant=0, simulated_variant=1)


@pytest.fixture(scope="module")
def monitors(twin_feed):
    """The three monitors on free ports, render loop running."""
    from frontend.monitors import serve_monitors

    handles = serve_monitors(twin_feed, ports={r: free_port() for r in ("actual", "simulated", "overlay")})
    yield handles
    handles.stop()


@pytest.fixture(scope="module")
def browser():
    """Headless Debian chromium through Playwright (skip cleanly if the package is not installed)."""
    if not CHROMIUM.exists():
        pytest.skip("Debian chromium not installed (apt-get install -y chromium)")
    playwright_api = pytest.importorskip("playwright.sync_api")
    with playwright_api.sync_playwright() as p:
        b = p.chromium.launch(executable_path=str(CHROMIUM), args=CHROMIUM_FLAGS)
        yield b
        b.close()


def _start_uvicorn(app, port: int) -> tuple[object, threading.Thread]:
    import uvicorn

    server = uvicorn.Server(uvicorn.Config(app, host="127.0.0.1", port=port, log_level="warning"))
    thread = threading.Thread(target=server.run, daemon=True)
    thread.start()
    deadline = time.monotonic() + 30.0
    while not server.started:
        if time.monotonic() > deadline or not thread.is_alive():
            raise RuntimeError("uvicorn did not start")
        time.sleep(0.05)
    return server, thread


@pytest.fixture(scope="module")
def backend_server(tmp_path_factory, shared_data: Path, shared_dask) -> Iterator[dict]:
    """The backend app (create_app) + dashboard on 127.0.0.1 over a temp SQLite, with the NOAA-20
    diary uploaded, a TLE, the Svalbard station and the passes of the diary's two hours; the same diary
    again as NOAA-20L under a dictionary whose limit on the attitude scalar raises an alarm."""
    from backend.app import create_app
    from backend.core.auth import Role
    from backend.core.settings import Settings
    from frontend.dashboard_site import dashboard_app

    tmp = tmp_path_factory.mktemp("backend")
    settings = Settings(
        data_dir=tmp / "data",
        database_url=f"sqlite:///{tmp / 'api.sqlite'}",
        job_workers=1,
        job_queue_size=2,
        telemetry_port=0,
        live_enabled=False,
        dask_scheduler=shared_dask.scheduler.address,  # what-ifs fly on the shared cluster (tests/conftest.py)
    )
    app = create_app(settings)
    if not any(getattr(route, "path", "") == "/dashboard" for route in app.routes):
        app.mount("/dashboard", dashboard_app({}))  # the backend mounts it itself once it ships that
    port = free_port()
    server, thread = _start_uvicorn(app, port)
    token = app.state.services.auth.issue("browser-test", Role.operator)[1]
    import httpx

    base = f"http://127.0.0.1:{port}"
    h = {"Authorization": f"Bearer {token}"}
    with httpx.Client(base_url=base, headers=h, timeout=120.0) as c:
        c.post(
            "/api/v1/telemetry/uploads?satellite=NOAA-20", content=(shared_data / NOAA20_PACKETS).read_bytes()
        ).raise_for_status()
        tle = "\n".join((shared_data / NOAA20_TLE).read_text().splitlines()[9:12])
        c.post("/api/v1/satellites/NOAA-20/tles", content=tle).raise_for_status()
        c.post("/api/v1/ground-stations", json=STATION).raise_for_status()
        c.post(
            "/api/v1/satellites/NOAA-20/passes/predict",
            params={"station": "Svalbard", "start": DIARY_START, "end": DIARY_END},
        ).raise_for_status()
        passes = c.post("/api/v1/satellites/NOAA-20/passes/reception").json()
        layout = (shared_data / NOAA20_PACKETS.parent / "ccsdspy_jpss1_geolocation.csv").read_bytes()
        # shipped dictionaries are read-only: an operator uploads the same layout under a name of their own
        c.post("/api/v1/dictionaries/jpss1_geolocation_upload.csv?apid=11", content=layout).raise_for_status()
        c.post("/api/v1/dictionaries/limited.yaml", content=LIMITED_DICTIONARY.encode()).raise_for_status()
        c.post(
            f"/api/v1/telemetry/uploads?satellite={ALARM_SATELLITE}&dictionary=limited.yaml",
            content=(shared_data / NOAA20_PACKETS).read_bytes(),
        ).raise_for_status()
    yield {"base": base, "token": token, "passes": passes, "services": app.state.services}
    server.should_exit = True
    thread.join(timeout=10.0)
