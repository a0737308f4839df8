"""The FastAPI application factory: ``create_app(settings)`` builds everything, nothing at import."""

from __future__ import annotations

from collections.abc import AsyncIterator
from contextlib import asynccontextmanager

from fastapi import FastAPI
from fastapi.responses import HTMLResponse, RedirectResponse

from backend.core.errors import install_error_handlers
from backend.core.request_bounds import RequestBounds
from backend.core.settings import Settings
from backend.services import build_services

__all__ = ["create_app", "monitor_urls", "API_PREFIX"]

API_PREFIX = "/api/v1"

DESCRIPTION = """Control centre of the attitude-control system of Earth-observation small satellites:
telemetry archive, simulation jobs, alarms and live streams. Authenticate with
`Authorization: Bearer <token>`; roles viewer (reads), operator (changes), admin (tokens).
Errors are JSON `{"message", "field", "status"}`."""


def _routers() -> list:
    from backend.routes import (
        alarms,
        console,
        diagnoses,
        health,
        live,
        monitors,
        parameters,
        passes,
        satellites,
        simulations,
        telemetry,
        tokens,
        twin,
    )

    return [
        health.router,
        tokens.router,
        telemetry.router,
        console.router,
        parameters.router,
        passes.router,
        alarms.router,
        simulations.router,
        twin.router,
        live.router,
        satellites.router,
        diagnoses.router,
        monitors.router,
    ]


def monitor_urls(settings: Settings) -> dict[str, str]:
    """Where ``acs-twin serve`` puts the twin monitors: viewer_port + 0, 1, 2 for actual, simulated, overlay."""
    roles = ("actual", "simulated", "overlay")
    return {role: f"http://{settings.host}:{settings.viewer_port + i}" for i, role in enumerate(roles)}


def create_app(settings: Settings | None = None) -> FastAPI:
    """A new app with its own database engine, job manager and live hub; the dashboard at / and /dashboard,
    the API documentation at /docs (vendored Swagger UI, works offline)."""
    settings = settings or Settings()
    services = build_services(settings)

    @asynccontextmanager
    async def lifespan(app: FastAPI) -> AsyncIterator[None]:
        services.database_watch.start()
        services.jobs.start()
        services.diagnoses.start()
        services.telemetry.start()
        services.twins.start()  # recovers every twin from the archive in its own thread
        services.auth.start_revocation_watch()  # revocations by other processes (acs-twin token revoke)
        await services.telemetry.start_live()
        try:
            yield
        finally:
            await services.telemetry.stop_live()
            services.auth.stop_revocation_watch()
            services.twins.stop()
            services.database_watch.stop()
            services.close()

    app = FastAPI(
        title="acs-twin", version="1", description=DESCRIPTION, lifespan=lifespan, docs_url=None, redoc_url=None
    )
    app.state.services = services
    install_error_handlers(app)
    app.add_middleware(RequestBounds, max_bytes=int(settings.max_json_kb * 1000))
    for router in _routers():
        app.include_router(router, prefix=API_PREFIX)
    from frontend.dashboard_site import dashboard_app, offline_docs_html

    @app.get("/", include_in_schema=False)
    def root() -> RedirectResponse:
        return RedirectResponse("/dashboard/")

    @app.get("/docs", include_in_schema=False)
    def docs() -> HTMLResponse:
        return offline_docs_html(app.openapi_url or "/openapi.json", app.title)

    app.mount("/dashboard", dashboard_app(monitor_urls(settings), API_PREFIX))
    return app
