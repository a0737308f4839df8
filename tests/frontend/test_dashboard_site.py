"""The dashboard site: index.html and its vendored uPlot (with licence) are served without a build
step, config.json tells the page where the API and the monitors are, bad URLs are refused."""

from __future__ import annotations

import pytest
from fastapi.testclient import TestClient

from frontend.dashboard_site import DASHBOARD_DIR, dashboard_app, dashboard_config


def test_dashboard_serves_index_script_styles_and_config():
    urls = {"actual": "http://127.0.0.1:8081/", "simulated": "http://127.0.0.1:8082/"}
    with TestClient(dashboard_app(urls)) as client:
        index = client.get("/")
        assert index.status_code == 200 and "acs-twin" in index.text and "dashboard.js" in index.text
        for path in ("dashboard.js", "dashboard.css", "vendor/uplot/uPlot.iife.min.js", "vendor/uplot/uPlot.min.css"):
            assert client.get("/" + path).status_code == 200, path
        assert client.get("/config.json").json() == {"api_base": "/api/v1", "monitors": urls}


def test_vendored_uplot_carries_its_mit_licence_and_provenance():
    licence = (DASHBOARD_DIR / "vendor/uplot/LICENSE").read_text()
    assert "MIT" in licence and "Leon Sorokin" in licence
    assert "npm" in (DASHBOARD_DIR / "vendor/uplot/PROVENANCE.md").read_text()


@pytest.mark.parametrize(("args", "field"), [(({"actual": "ftp://x"},), "monitor_urls"),
                                             (({}, "api/v1"), "api_base")])
def test_bad_config_names_the_field(args, field):
    with pytest.raises(ValueError, match=field):
        dashboard_config(*args)
