"""Python client of the acs-twin API: upload, samples, simulations with progress, results, live data.

from backend.client import Client
with Client("http://127.0.0.1:8000", token="acs_…") as api:
    api.upload("pass.dat", satellite="NOAA-20")
    t_ns, q0 = api.samples("q_ib_0", max_points=2000)
    job = api.simulate({"library": "somov-ge4-scan"}, progress=print)
    arrays = api.results(job["id"])            # numpy arrays of trajectory.npz
    twin = api.start_twin("2026-03-20T00:05:00Z", 200.0, satellite="REFSAT", alternatives={"nominal": []})
    residuals = api.twin_residuals(twin["id"])   # attitude_deg, rate_deg_s, wheel_speed_rpm arrays
    for item in api.subscribe(["parameters/q_ib_0"]):
        ...
"""

from __future__ import annotations

import io
import json
import time
from collections.abc import Callable, Iterator
from datetime import datetime
from pathlib import Path
from typing import Any

import httpx
import numpy as np

__all__ = ["Client", "ClientError"]

FINAL_STATES = ("succeeded", "failed", "cancelled", "interrupted")


class ClientError(Exception):
    """An error answer of the API: HTTP status, message and the offending field."""

    def __init__(self, status: int, message: str, field: str | None) -> None:
        super().__init__(f"{status}: {message}" + (f" (field {field})" if field else ""))
        self.status, self.message, self.field = status, message, field


def _iso(moment: datetime | str | None) -> str | None:
    return moment.isoformat() if isinstance(moment, datetime) else moment


class Client:
    """Synchronous client; ``token`` is sent as a Bearer token on every request."""

    def __init__(
        self, base_url: str = "http://127.0.0.1:8000", token: str | None = None, timeout_s: float = 60.0
    ) -> None:
        self.base_url = base_url.rstrip("/")
        self._token = token
        headers = {"Authorization": f"Bearer {token}"} if token else {}
        self._http = httpx.Client(base_url=self.base_url + "/api/v1", headers=headers, timeout=timeout_s)

    def __enter__(self) -> Client:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        """Close the HTTP connection pool."""
        self._http.close()

    def _call(self, method: str, path: str, **kwargs: Any) -> httpx.Response:
        answer = self._http.request(method, path, **kwargs)
        if answer.status_code >= 400:
            try:
                body = answer.json()
            except ValueError:
                body = {"message": answer.text}
            raise ClientError(answer.status_code, str(body.get("message")), body.get("field"))
        return answer

    def health(self) -> dict[str, Any]:
        """GET /health."""
        return self._call("GET", "/health").json()

    def upload(
        self,
        data: bytes | str | Path,
        satellite: str = "NOAA-20",
        dictionary: str = "noaa20_apid11_ccsdspy.yaml",
        format: str = "ccsds",
        source: str | None = None,
    ) -> dict[str, Any]:
        """Upload telemetry (bytes or a file path); returns the ingest report."""
        if isinstance(data, (str, Path)):
            source = source or Path(data).name
            data = Path(data).read_bytes()
        params = {"satellite": satellite, "dictionary": dictionary, "format": format, "source": source or "client"}
        return self._call(
            "POST",
            "/telemetry/uploads",
            params=params,
            content=data,
            headers={"Content-Type": "application/octet-stream"},
        ).json()

    def samples(
        self,
        name: str,
        start: datetime | str | None = None,
        end: datetime | str | None = None,
        max_points: int = 1000,
        satellite: str = "NOAA-20",
    ) -> tuple[np.ndarray, np.ndarray]:
        """(t_utc_ns int64, values float64) of a parameter, downsampled to max_points."""
        params = {
            k: v
            for k, v in {
                "start": _iso(start),
                "end": _iso(end),
                "max_points": max_points,
                "satellite": satellite,
            }.items()
            if v is not None
        }
        body = self._call("GET", f"/parameters/{name}/samples", params=params).json()
        return np.asarray(body["t_utc_ns"], dtype=np.int64), np.asarray(body["values"], dtype=float)

    def start_simulation(self, scenario: dict[str, Any]) -> str:
        """Queue a simulation; returns the job id."""
        return self._call("POST", "/simulations", json=scenario).json()["id"]

    def job(self, job_id: str) -> dict[str, Any]:
        """Status, progress and summary of a job."""
        return self._call("GET", f"/simulations/{job_id}").json()

    def cancel(self, job_id: str) -> dict[str, Any]:
        """Cancel a queued or running job."""
        return self._call("DELETE", f"/simulations/{job_id}").json()

    def wait(
        self,
        job_id: str,
        progress: Callable[[float], None] | None = None,
        poll_s: float = 0.5,
        timeout_s: float | None = None,
    ) -> dict[str, Any]:
        """Poll until the job is final, reporting progress; TimeoutError after timeout_s."""
        deadline = None if timeout_s is None else time.monotonic() + timeout_s
        while True:
            job = self.job(job_id)
            if progress is not None:
                progress(job["progress"])
            if job["status"] in FINAL_STATES:
                return job
            if deadline is not None and time.monotonic() > deadline:
                raise TimeoutError(f"job {job_id} still {job['status']} after {timeout_s} s")
            time.sleep(poll_s)

    def simulate(
        self,
        scenario: dict[str, Any],
        progress: Callable[[float], None] | None = None,
        poll_s: float = 0.5,
        timeout_s: float | None = None,
    ) -> dict[str, Any]:
        """Start a simulation and wait for it; the final job."""
        return self.wait(self.start_simulation(scenario), progress, poll_s, timeout_s)

    def results(self, job_id: str) -> dict[str, np.ndarray]:
        """The job's trajectory.npz as a dict of numpy arrays."""
        content = self._call("GET", f"/simulations/{job_id}/files/trajectory.npz").content
        with np.load(io.BytesIO(content)) as npz:
            return {name: npz[name] for name in npz.files}

    def start_twin(
        self,
        align_utc: datetime | str,
        duration_s: float,
        faults: list[str] | None = None,
        alternatives: dict[str, list[str]] | None = None,
        **fields: Any,
    ) -> dict[str, Any]:
        """Start a twin session aligned to archived telemetry (fields: satellite, scenario, …); the session."""
        body = {
            "align_utc": _iso(align_utc),
            "duration_s": duration_s,
            "faults": faults or [],
            "alternatives": alternatives or {},
            **fields,
        }
        return self._call("POST", "/twin/sessions", json=body).json()

    def twin_residuals(
        self,
        session_id: str,
        variant: int = 0,
        max_points: int = 1000,
        poll_s: float = 0.5,
        timeout_s: float | None = None,
    ) -> dict[str, Any]:
        """Wait for the session's simulation, then its residuals (numpy arrays) and every variant's summary."""
        session = self._call("GET", f"/twin/sessions/{session_id}").json()
        self.wait(session["job_id"], poll_s=poll_s, timeout_s=timeout_s)
        body = self._call(
            "GET", f"/twin/sessions/{session_id}/residuals", params={"variant": variant, "max_points": max_points}
        ).json()
        arrays = {k: np.asarray(body[k], dtype=float) for k in ("t_s", "attitude_deg", "rate_deg_s", "wheel_speed_rpm")}
        return {**body, **arrays}

    def subscribe(self, topics: list[str], timeout_s: float | None = None) -> Iterator[dict[str, Any]]:
        """Live items ``{"topic", "data"}`` of the topics, as they arrive (WebSocket)."""
        from websockets.sync.client import connect

        url = self.base_url.replace("http", "ws", 1) + "/api/v1/ws"
        headers = {"Authorization": f"Bearer {self._token}"} if self._token else None
        with connect(url, additional_headers=headers) as socket:
            socket.send(json.dumps({"op": "subscribe", "topics": topics}))
            while True:
                message = json.loads(socket.recv(timeout=timeout_s))
                if message["type"] == "error":
                    raise ClientError(422, message["message"], message.get("field"))
                yield from message["items"]
