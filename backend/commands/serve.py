"""``acs-twin serve``: start the control centre (REST + WebSocket API) on the embedded default.

First start creates an admin token (stored hashed) and prints it once; later starts print none.
"""

from __future__ import annotations

import argparse
import contextlib
import gc
import signal
import socket
import subprocess
import sys
import threading
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:  # imported where used: `serve` binds its ports before the server's heavy imports
    import uvicorn

    from backend.core.settings import Settings
    from backend.ingest.live_link import LiveChild
    from backend.services import Services


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``serve`` subcommand (flags override ACS_TWIN_* environment variables)."""
    p = sub.add_parser("serve", help="start the control-centre server (API, live stream, jobs)")
    p.add_argument("--host", help="interface to bind (default 127.0.0.1, env ACS_TWIN_HOST)")
    p.add_argument("--port", type=int, help="API port (default 8000, env ACS_TWIN_PORT)")
    p.add_argument("--data-dir", type=Path, help="data directory (default ./data, env ACS_TWIN_DATA_DIR)")
    p.add_argument("--database-url", help="SQLAlchemy URL (default SQLite in the data directory)")
    p.add_argument("--no-auth", action="store_true", help="disable tokens (local development only)")
    p.add_argument("--job-workers", type=int, help="jobs at once, Dask LocalCluster workers (default 2)")
    p.add_argument(
        "--scheduler",
        help="Dask scheduler of an existing cluster (tcp://host:port, env ACS_TWIN_DASK_SCHEDULER; "
        "default a LocalCluster the server owns)",
    )
    p.add_argument("--no-emulator", action="store_true", help="do not start the demo spacecraft emulator")
    p.add_argument("--emulator-scenario", default="somov-ge4-scan", help="scenario the demo satellite flies")
    p.set_defaults(handler=run)


def _overrides(args: argparse.Namespace) -> dict[str, Any]:
    values = {
        "host": args.host,
        "port": args.port,
        "data_dir": args.data_dir,
        "database_url": args.database_url,
        "job_workers": args.job_workers,
        "dask_scheduler": args.scheduler,
    }
    out = {k: v for k, v in values.items() if v is not None}
    if args.no_auth:
        out["auth_enabled"] = False
    return out


def first_admin_token(services: Services) -> str | None:
    """Issue an admin token when none is active (first start); the plain token, else None."""
    from backend.core.auth import Role

    if not services.settings.auth_enabled or services.tokens.count_active_admins() > 0:
        return None
    token_id, token = services.auth.issue("admin (first start)", Role.admin)
    services.audit.record("acs-twin serve", "token.create", f"token/{token_id}", {"role": "admin"})
    return token


HIDDEN_FAULTS = ["wheel:2:failure@1500"]  # the demo satellite's secret: found from telemetry, not printed


def start_emulator(settings: Settings, scenario: str, telemetry_port: int | None) -> subprocess.Popen[bytes] | None:
    """The demo satellite (``acs-twin emulate --forever``) streaming into the live listener without end, logging to
    data_dir."""
    from backend.core.processes import spawn_owned

    if not settings.live_enabled or not settings.telemetry_port or not telemetry_port:
        return None  # an ephemeral telemetry port (0) means no demo satellite
    settings.data_dir.mkdir(parents=True, exist_ok=True)  # before the app made it: the emulator starts first
    log = (settings.data_dir / "emulator.log").open("ab")
    command = [
        sys.executable,
        "-m",
        "backend",
        "emulate",
        "--scenario",
        scenario,
        "--host",
        settings.host,
        "--port",
        str(telemetry_port),
        "--rate",
        "1",
        "--start-utc",
        "now",
        "--forever",
    ]
    for fault in HIDDEN_FAULTS:
        command += ["--fault", fault]
    return spawn_owned(command, log)


def _bind_api_socket(host: str, port: int) -> socket.socket:
    """The API's listening socket, bound before anything starts (SystemExit naming the holder if taken)."""
    sock = socket.socket(socket.AF_INET6 if ":" in host else socket.AF_INET)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    try:
        sock.bind((host, port))
    except OSError as exc:
        sock.close()
        raise SystemExit(_port_message("API", host, port, "--port", exc)) from None
    return sock


def _check_port_free(host: str, port: int) -> None:
    """SystemExit naming the holder if the telemetry port cannot be bound (the ingest process binds it)."""
    if not port:
        return
    with socket.socket(socket.AF_INET6 if ":" in host else socket.AF_INET) as sock:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            sock.bind((host, port))
        except OSError as exc:
            raise SystemExit(_port_message("telemetry", host, port, "ACS_TWIN_TELEMETRY_PORT", exc)) from None


def _port_message(what: str, host: str, port: int, knob: str, exc: OSError) -> str:
    from backend.core.processes import port_holder

    holder = port_holder(port) or "another process"
    return (
        f"acs-twin serve: the {what} port {host}:{port} is not available ({exc.strerror or exc}); "
        f"held by {holder}. Stop it or choose another port ({knob})."
    )


def _owned_server(config: uvicorn.Config, on_started: Callable[[], None]) -> uvicorn.Server:
    """uvicorn's server minus its re-raise of SIGTERM/SIGINT after shutdown (which killed the process before
    ``serve`` could stop its children); ``on_started`` runs once the server listens."""
    import uvicorn

    class OwnedServer(uvicorn.Server):
        @contextlib.contextmanager
        def capture_signals(self) -> Iterator[None]:
            if threading.current_thread() is not threading.main_thread():
                yield
                return
            previous = {sig: signal.signal(sig, self.handle_exit) for sig in (signal.SIGINT, signal.SIGTERM)}
            try:
                yield
            finally:
                for sig, handler in previous.items():
                    signal.signal(sig, handler)

        async def startup(self, sockets: list[socket.socket] | None = None) -> None:
            await super().startup(sockets)
            if self.started and not self.should_exit:
                on_started()

    return OwnedServer(config)


@dataclass
class _Children:
    """What ``serve`` started beside the server and stops when it stops."""

    emulator: subprocess.Popen[bytes] | None = None  # the demo satellite
    live_ingest: LiveChild | None = None  # the live link's ingest process, spawned ahead (backend.ingest.live_link)
    twin: threading.Thread | None = None  # the demo's 3D monitors (backend.twin.demo_twin)


def run(args: argparse.Namespace) -> int:
    """Build the app from Settings, serve until SIGTERM/SIGINT; children stop on exit.

    The demo emulator and the live link's ingest process start first, before the server's imports: their own
    imports, the emulator's flight and the ingest process's dictionary and decoder run beside the server's start-up
    (the emulator keeps trying to connect until the live listener is up; the ingest process opens the archive and
    listens once the app's start-up reaches the live link), off the critical path.
    """
    from backend.core.processes import stop_owned
    from backend.core.settings import Settings

    settings = Settings(**_overrides(args))
    api_socket = _bind_api_socket(settings.host, settings.port)
    if settings.live_enabled:
        _check_port_free(settings.host, settings.telemetry_port)
    children = _Children()
    if not args.no_emulator:
        children.emulator = start_emulator(settings, args.emulator_scenario, settings.telemetry_port)
    if settings.live_enabled:
        from backend.ingest.live_link import spawn_ingest

        children.live_ingest = spawn_ingest(settings)
    stop = threading.Event()
    try:
        config, services = _app_for(settings, args, children.emulator is not None)
        if children.live_ingest is not None:
            services.telemetry.adopt_live_ingest(children.live_ingest)
        server = _owned_server(config, lambda: _on_started(services, settings, args, children, stop))
        server.run(sockets=[api_socket])
    finally:
        stop.set()
        if children.emulator is not None:
            stop_owned(children.emulator)
        if children.twin is not None:
            children.twin.join(5)
        if children.live_ingest is not None:  # gone already, unless the server stopped before the live link started
            from backend.ingest.live_link import abandon_ingest

            abandon_ingest(children.live_ingest)
        api_socket.close()
    if not server.started:
        print("acs-twin serve: start-up failed (see above); no admin token was issued", file=sys.stderr)
        return 1
    print("acs-twin serve: stopped", flush=True)
    gc.freeze()  # the interpreter's exit skips the garbage collector's scan of everything the server loaded
    return 0


def _app_for(settings: Settings, args: argparse.Namespace, demo: bool) -> tuple[uvicorn.Config, Services]:
    """The server's configuration and the app's services (heavy imports here); the demo satellite's route starts
    with the emulator's flight."""
    import uvicorn

    from backend.app import create_app

    app = create_app(settings)
    services: Services = app.state.services
    if demo:
        services.twins.register_model(settings.live_satellite, args.emulator_scenario, None, from_run=True)
    return uvicorn.Config(app, log_level="warning"), services


def _on_started(
    services: Services, settings: Settings, args: argparse.Namespace, children: _Children, stop: threading.Event
) -> None:
    """Once the server listens: URLs and the one-time admin token (issued only now), the demo's monitors."""
    _announce(settings, services)
    if children.emulator is not None:
        print(
            f"  emulator  demo satellite {settings.live_satellite} ({args.emulator_scenario}) -> "
            f"tcp://{settings.host}:{services.telemetry.live_port}, log {settings.data_dir / 'emulator.log'}"
        )
        children.twin = start_demo_twin(services, settings, args.emulator_scenario, stop)
    print(flush=True)


def _announce(settings: Settings, services: Services) -> None:
    """Print the URLs and, on first start, the admin token."""
    token = first_admin_token(services)
    base = f"http://{settings.host}:{settings.port}"
    print(f"acs-twin control centre, data in {settings.data_dir.resolve()}")
    print(f"  API       {base}/api/v1   (OpenAPI {base}/openapi.json, docs {base}/docs)")
    print(f"  live      ws://{settings.host}:{settings.port}/api/v1/ws")
    print(f"  dashboard {base}/dashboard/")
    if token:
        print(f"  admin token (shown once, stored hashed): {token}")
    elif not settings.auth_enabled:
        print("  auth DISABLED: every caller is admin")


def start_demo_twin(services: Services, settings: Settings, scenario: str, stop: threading.Event) -> threading.Thread:
    """Thread: the 3D monitors on the demo satellite's live twin once its first samples arrived (demo_twin)."""
    from backend.app import monitor_urls
    from backend.twin.demo_twin import run_demo_twin

    ports = {role: int(url.rsplit(":", 1)[1]) for role, url in monitor_urls(settings).items()}
    thread = threading.Thread(
        target=run_demo_twin, args=(services, ports, scenario, stop), name="demo-twin", daemon=True
    )
    thread.start()
    urls = ", ".join(f"{role} {url}" for role, url in monitor_urls(settings).items())
    gate = "open with ?token=<API token>, " if settings.auth_enabled else ""
    print(f"  monitors  {urls} ({gate}live twin, once the first packets arrived; log {settings.data_dir / 'twin.log'})")
    return thread
