"""``acs-twin serve``: start the control centre (REST + WebSocket API) on the embedded default.

First start creates an admin token (stored hashed) and prints it once; later starts print none.
"""

from __future__ import annotations

import argparse
import subprocess
import threading
import sys
from pathlib import Path
from typing import Any


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``serve`` subcommand (flags override ACS_TWIN_* environment variables)."""
    p = sub.add_parser("serve", help="start the control-centre server (API, live stream, jobs)")
    p.add_argument("--host", help="interface to bind (default 127.0.0.1, env ACS_TWIN_HOST)")
    p.add_argument("--port", type=int, help="API port (default 8000, env ACS_TWIN_PORT)")
    p.add_argument("--data-dir", type=Path, help="data directory (default ./data, env ACS_TWIN_DATA_DIR)")
    p.add_argument("--database-url", help="SQLAlchemy URL (default SQLite in the data directory)")
    p.add_argument("--no-auth", action="store_true", help="disable tokens (local development only)")
    p.add_argument("--job-workers", type=int, help="simulation worker processes (default 1)")
    p.add_argument("--no-emulator", action="store_true", help="do not start the demo spacecraft emulator")
    p.add_argument("--emulator-scenario", default="somov-ge4-scan", help="scenario the demo satellite flies")
    p.set_defaults(handler=run)


def _overrides(args: argparse.Namespace) -> dict[str, Any]:
    values = {"host": args.host, "port": args.port, "data_dir": args.data_dir,
              "database_url": args.database_url, "job_workers": args.job_workers}
    out = {k: v for k, v in values.items() if v is not None}
    if args.no_auth:
        out["auth_enabled"] = False
    return out


def first_admin_token(services: Any) -> str | None:
    """Issue an admin token when none is active (first start); the plain token, else None."""
    from backend.core.auth import Role

    if not services.settings.auth_enabled or services.tokens.count_active_admins() > 0:
        return None
    token_id, token = services.auth.issue("admin (first start)", Role.admin)
    services.audit.record("acs-twin serve", "token.create", f"token/{token_id}", {"role": "admin"})
    return token


HIDDEN_FAULTS = ["wheel:2:failure@1500"]  # the demo satellite's secret: found from telemetry, not printed
DEMO_FLIGHT_S = 5801.0  # one orbit of the demo satellite, so that the hidden fault does happen


def start_emulator(settings: Any, scenario: str) -> subprocess.Popen | None:
    """The demo satellite (``acs-twin emulate``) streaming into the live listener, logging to data_dir."""
    if not settings.live_enabled or settings.telemetry_port == 0:
        return None
    log = (settings.data_dir / "emulator.log").open("ab")
    command = [sys.executable, "-m", "backend", "emulate", "--scenario", scenario, "--host", settings.host,
               "--port", str(settings.telemetry_port), "--rate", "1", "--start-utc", "now",
               "--duration", str(DEMO_FLIGHT_S)]
    for fault in HIDDEN_FAULTS:
        command += ["--fault", fault]
    return subprocess.Popen(command, stdout=log, stderr=subprocess.STDOUT)


def run(args: argparse.Namespace) -> int:
    """Build the app from Settings, print URLs (and a first admin token), serve until stopped."""
    import uvicorn

    from backend.app import create_app
    from backend.core.settings import Settings

    settings = Settings(**_overrides(args))
    app = create_app(settings)
    token = first_admin_token(app.state.services)
    base = f"http://{settings.host}:{settings.port}"
    print(f"acs-twin control centre, data in {settings.data_dir.resolve()}")
    print(f"  API       {base}/api/v1   (OpenAPI {base}/openapi.json, docs {base}/docs)")
    print(f"  live      ws://{settings.host}:{settings.port}/api/v1/ws")
    print(f"  dashboard {base}/dashboard/")
    if token:
        print(f"  admin token (shown once, stored hashed): {token}")
    elif not settings.auth_enabled:
        print("  auth DISABLED: every caller is admin")
    emulator = None if args.no_emulator else start_emulator(settings, args.emulator_scenario)
    stop, twin = threading.Event(), None
    if emulator is not None:
        print(f"  emulator  demo satellite {settings.live_satellite} ({args.emulator_scenario}) -> "
              f"tcp://{settings.host}:{settings.telemetry_port}, log {settings.data_dir / 'emulator.log'}")
        twin = start_demo_twin(app.state.services, settings, args.emulator_scenario, stop)
    print("", flush=True)
    try:
        uvicorn.run(app, host=settings.host, port=settings.port, log_level="warning")
    finally:
        stop.set()
        if emulator is not None:
            emulator.terminate()
            emulator.wait(10)
        if twin is not None:
            twin.join(5)
    return 0


def start_demo_twin(services: Any, settings: Any, scenario: str, stop: threading.Event) -> threading.Thread:
    """Thread: the demo twin session and its 3D monitors once telemetry has arrived (see backend.twin.demo_twin)."""
    from backend.app import monitor_urls
    from backend.twin.demo_twin import TWIN_S, WARMUP_S, run_demo_twin

    ports = {role: int(url.rsplit(":", 1)[1]) for role, url in monitor_urls(settings).items()}
    thread = threading.Thread(target=run_demo_twin, args=(services, ports, scenario, stop),
                              name="demo-twin", daemon=True)
    thread.start()
    urls = ", ".join(f"{role} {url}" for role, url in monitor_urls(settings).items())
    print(f"  monitors  {urls} (after ~{WARMUP_S + TWIN_S:.0f} s of telemetry; log {settings.data_dir / 'twin.log'})")
    return thread
