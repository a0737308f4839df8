"""Shared test fixtures: where the real third-party data lives, and the databases under test."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

REPO_ROOT = Path(__file__).resolve().parents[1]
SHARED_DATA = REPO_ROOT.parent / "shared" / "data"


@pytest.fixture(scope="session")
def shared_data() -> Path:
    """The ../shared/data folder of real reference data (README there gives provenance)."""
    if not SHARED_DATA.is_dir():
        pytest.fail(f"reference data missing: expected {SHARED_DATA} beside the repository")
    return SHARED_DATA


@pytest.fixture(scope="session")
def postgres_url() -> str:
    """URL of the PostgreSQL server used as the production path (CI sets it; else skip)."""
    url = os.environ.get("ACS_TWIN_TEST_POSTGRES_URL")
    if not url:
        pytest.skip("ACS_TWIN_TEST_POSTGRES_URL not set")
    return url


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """The files holding a ``slow`` test first, each file's tests kept together and in order: scripts/test.sh hands
    whole files to its two workers in this order (``--dist loadfile --no-loadscope-reorder``), so they start on the
    long files and finish together on short ones (xdist's own reorder, by test count, left the long one-test
    files — live diagnosis, OpenAPI fuzzing, the warm command — for the end, one worker alone on them)."""
    slow_files = {item.path for item in items if item.get_closest_marker("slow")}
    items.sort(key=lambda item: item.path not in slow_files)
