"""The demo twin waits out a full job queue at start-up instead of dying (issue 16)."""

from __future__ import annotations

import threading
from pathlib import Path
from types import SimpleNamespace

from backend.core.errors import ApiError
from backend.twin import demo_twin


def test_a_full_job_queue_is_retried_until_the_session_is_admitted(tmp_path: Path, monkeypatch) -> None:
    answers = [ApiError(429, "job queue full", "job_queue_size")] * 2 + [{"id": "s1", "job_id": "j1"}]

    def start_session(services, body, actor):
        answer = answers.pop(0)
        if isinstance(answer, Exception):
            raise answer
        return answer

    import backend.twin.session_service as twin_routes

    monkeypatch.setattr(twin_routes, "start_session", start_session)
    monkeypatch.setattr(demo_twin, "POLL_S", 0.01)
    services = SimpleNamespace(settings=SimpleNamespace(data_dir=tmp_path))
    assert demo_twin._start_when_admitted(services, body=None, stop=threading.Event()) == {"id": "s1", "job_id": "j1"}
    assert (tmp_path / "twin.log").read_text().count("job queue full") == 2


def test_a_stop_while_waiting_ends_the_wait(tmp_path: Path, monkeypatch) -> None:
    import backend.twin.session_service as twin_routes

    def full(services, body, actor):
        raise ApiError(429, "job queue full", "job_queue_size")

    monkeypatch.setattr(twin_routes, "start_session", full)
    stop = threading.Event()
    stop.set()
    services = SimpleNamespace(settings=SimpleNamespace(data_dir=tmp_path))
    assert demo_twin._start_when_admitted(services, body=None, stop=stop) is None
