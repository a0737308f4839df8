"""The operator dashboard as a small ASGI app: the static files of ``frontend/dashboard`` (no build
step) plus ``config.json`` telling the page where the REST API and the twin monitors are.

The backend mounts it, e.g. ``app.mount("/dashboard", dashboard_app(monitor_urls))``.
"""

from __future__ import annotations

from pathlib import Path

__all__ = ["DASHBOARD_DIR", "SWAGGER_UI", "dashboard_app", "dashboard_config", "offline_docs_html"]

DASHBOARD_DIR = Path(__file__).resolve().parent / "dashboard"
SWAGGER_UI = "/dashboard/vendor/swagger-ui"  # vendored Swagger UI (see its PROVENANCE.md), served with the dashboard


def dashboard_config(monitor_urls: dict[str, str] | None = None, api_base: str = "/api/v1") -> dict:
    """What the page reads from config.json: the API prefix and the monitor URL of each role."""
    urls = dict(monitor_urls or {})
    for role, url in urls.items():
        if not str(url).startswith(("http://", "https://", "/")):
            raise ValueError(f"monitor_urls[{role!r}]: expected an http(s) URL or an absolute path, got {url!r}")
    if not api_base.startswith("/"):
        raise ValueError(f"api_base: expected an absolute path such as /api/v1, got {api_base!r}")
    return {"api_base": api_base.rstrip("/"), "monitors": urls}


def dashboard_app(monitor_urls: dict[str, str] | None = None, api_base: str = "/api/v1"):
    """Starlette app serving the dashboard (index.html at its root) and its config.json."""
    from starlette.applications import Starlette
    from starlette.responses import JSONResponse
    from starlette.routing import Mount, Route
    from starlette.staticfiles import StaticFiles

    config = dashboard_config(monitor_urls, api_base)

    async def config_json(request) -> JSONResponse:
        return JSONResponse(config, headers={"Cache-Control": "no-store"})

    return Starlette(
        routes=[
            Route("/config.json", config_json),
            Mount("/", StaticFiles(directory=DASHBOARD_DIR, html=True)),
        ]
    )


def offline_docs_html(openapi_url: str, title: str):
    """Swagger UI page for the API, its script and style from the vendored copy instead of a CDN."""
    from fastapi.openapi.docs import get_swagger_ui_html

    return get_swagger_ui_html(
        openapi_url=openapi_url,
        title=f"{title} — API",
        swagger_favicon_url="data:,",
        swagger_js_url=f"{SWAGGER_UI}/swagger-ui-bundle.js",
        swagger_css_url=f"{SWAGGER_UI}/swagger-ui.css",
    )
