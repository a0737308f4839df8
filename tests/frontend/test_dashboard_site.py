"""The dashboard site: index.html, its ES modules and its vendored uPlot and Swagger UI (with licences) are
served without a build step, config.json tells the page where the API and the monitors are, bad URLs are
refused; no module builds markup from strings and nothing loads from another site."""

from __future__ import annotations

import re

import pytest
from fastapi.testclient import TestClient

from frontend.dashboard_site import DASHBOARD_DIR, dashboard_app, dashboard_config


def test_dashboard_serves_index_script_styles_and_config():
    urls = {"actual": "http://127.0.0.1:8081/", "simulated": "http://127.0.0.1:8082/"}
    with TestClient(dashboard_app(urls)) as client:
        index = client.get("/")
        assert index.status_code == 200 and "acs-twin" in index.text and 'type="module" src="js/main.js"' in index.text
        modules = sorted(p.name for p in (DASHBOARD_DIR / "js").glob("*.js"))
        imported = {m for p in (DASHBOARD_DIR / "js").glob("*.js") for m in IMPORT.findall(p.read_text())}
        assert imported <= set(modules) and "main.js" in modules
        vendored = [
            "vendor/uplot/uPlot.iife.min.js",
            "vendor/uplot/uPlot.min.css",
            "vendor/swagger-ui/swagger-ui-bundle.js",
            "vendor/swagger-ui/swagger-ui.css",
        ]
        for path in ["dashboard.css", *vendored] + [f"js/{m}" for m in modules]:
            answer = client.get("/" + path)
            assert answer.status_code == 200, path
            if path.endswith(".js"):
                assert "javascript" in answer.headers["content-type"], path  # module scripts need a JS MIME type
        assert client.get("/config.json").json() == {"api_base": "/api/v1", "monitors": urls}


IMPORT = re.compile(r'from "\./([a-z]+\.js)"')
MARKUP_SINKS = re.compile(r"innerHTML|outerHTML|insertAdjacentHTML|document\.write")
FOREIGN_URL = re.compile(r"(src|href)=\"(https?:)?//")


def test_no_module_builds_markup_from_strings_and_nothing_loads_from_another_site():
    for path in (DASHBOARD_DIR / "js").glob("*.js"):
        code = "\n".join(line for line in path.read_text().splitlines() if not line.lstrip().startswith("//"))
        assert not MARKUP_SINKS.search(code), path.name
    assert not FOREIGN_URL.search((DASHBOARD_DIR / "index.html").read_text())


def test_vendored_swagger_ui_carries_its_apache_licence_and_provenance():
    licence = (DASHBOARD_DIR / "vendor/swagger-ui/LICENSE").read_text()
    assert "Apache License" in licence and "Version 2.0" in licence
    assert "SmartBear" in (DASHBOARD_DIR / "vendor/swagger-ui/NOTICE").read_text()
    assert "npm pack swagger-ui-dist" in (DASHBOARD_DIR / "vendor/swagger-ui/PROVENANCE.md").read_text()


def test_vendored_uplot_carries_its_mit_licence_and_provenance():
    licence = (DASHBOARD_DIR / "vendor/uplot/LICENSE").read_text()
    assert "MIT" in licence and "Leon Sorokin" in licence
    assert "npm" in (DASHBOARD_DIR / "vendor/uplot/PROVENANCE.md").read_text()


@pytest.mark.parametrize(("args", "field"), [(({"actual": "ftp://x"},), "monitor_urls"), (({}, "api/v1"), "api_base")])
def test_bad_config_names_the_field(args, field):
    with pytest.raises(ValueError, match=field):
        dashboard_config(*args)
