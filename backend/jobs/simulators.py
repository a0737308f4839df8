"""Which simulation a job runs: the sim_core engine, or the built-in rigid spin (``kind: rigid-spin``).

A body is either a full sim_core Scenario, a library scenario ``{"library": NAME, "set": [...]}``
(``acs-twin scenarios`` lists them), or a rigid-spin scenario (``kind: rigid-spin``): :func:`scenario_kind`
tells which. It is validated in the API process (limits are checked before queueing) and run on a Dask
worker by :func:`run_job`, which returns the ``trajectory.npz`` bytes and the summary; the task reports
progress as Dask events on ``PROGRESS_TOPIC`` and stops at the next report once the job's cancel Event is set.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal

from pydantic import BaseModel, ConfigDict, Field

if TYPE_CHECKING:
    from sim_core.scenario import Scenario

__all__ = [
    "PROGRESS_TOPIC",
    "JobCancelled",
    "JobCost",
    "JobOutput",
    "LibraryScenario",
    "ScenarioKind",
    "cancel_event_name",
    "library_names",
    "run_job",
    "scenario_kind",
    "validate_scenario",
]

FLOAT_BYTES = 8
JobOutput = tuple[bytes, dict[str, Any]]  # what a job's task returns: trajectory.npz bytes, the summary (JSON)


class JobCancelled(Exception):
    """Raised inside a worker by the progress callback once cancellation was requested."""


@dataclass(frozen=True)
class JobCost:
    """What limits are checked against: simulated time, batch size, result size."""

    duration_s: float
    batch_size: int
    output_bytes: int


ScenarioKind = Literal["rigid-spin", "library", "scenario"]


def scenario_kind(body: object) -> ScenarioKind:
    """Which simulation a body asks for: ``kind: rigid-spin``, else a ``library`` key, else a full Scenario."""
    if isinstance(body, dict) and body.get("kind") == "rigid-spin":
        return "rigid-spin"
    return "library" if isinstance(body, dict) and "library" in body else "scenario"


class LibraryScenario(BaseModel):
    """A library scenario by name, with overrides applied in order (sim_core.scenario.apply_overrides)."""

    model_config = ConfigDict(extra="forbid")

    library: str = Field(description="A name GET /api/v1/scenarios lists.", examples=["somov-ge4-scan"])
    set: list[str] = Field(
        default_factory=list,
        description="Overrides 'path.to.field=value' (a scenario field, dotted), applied in order.",
        examples=[["duration_s=600", "output_dt_s=1.0"]],
    )


def library_names() -> list[str]:
    """Names of the sim_core library scenarios."""
    from sim_core import scenario_library

    return scenario_library.names()


def _engine_scenario(body: dict[str, Any]) -> Scenario:
    from sim_core import scenario_library
    from sim_core.scenario import Scenario, apply_overrides

    if scenario_kind(body) == "scenario":
        return Scenario.model_validate(body)
    request = LibraryScenario.model_validate(body)  # ValidationError naming the field: an unknown key, a set not text
    if request.library not in scenario_library.names():
        raise ValueError(f"library: unknown scenario {request.library!r}; one of {scenario_library.names()}")
    return apply_overrides(scenario_library.get(request.library), request.set)


MAX_STEPS = 10**9  # dynamics steps of one job: far above any real scenario (one orbit at 0.01 s: 580,100)


def _steps(scenario: Scenario, field: str) -> int:
    """``getattr(scenario, field) / dynamics_dt_s`` as a count (ValueError naming the field when not finite/too big)."""
    for name in ("duration_s", "dynamics_dt_s", "output_dt_s"):
        value = float(getattr(scenario, name))
        if not (math.isfinite(value) and value > 0 and math.isfinite(1.0 / value)):
            raise ValueError(f"{name}: must be a finite, normal number of seconds > 0, got {value!r}")
    steps = float(getattr(scenario, field)) / float(scenario.dynamics_dt_s)
    if not steps <= MAX_STEPS:
        raise ValueError(f"{field}: {field} / dynamics_dt_s = {steps:.3g} steps, over {MAX_STEPS:.0e}")
    return max(round(steps), 1)


def _engine_cost(scenario: Scenario) -> JobCost:
    from sim_core.closed_loop import record_width

    n_out = -(-_steps(scenario, "duration_s") // _steps(scenario, "output_dt_s"))
    n_wheels = len(scenario.spacecraft.cluster.wheels)
    batch = len(scenario.variants)
    return JobCost(scenario.duration_s, batch, n_out * batch * record_width(n_wheels) * FLOAT_BYTES)


def validate_scenario(body: dict[str, Any]) -> tuple[dict[str, Any], JobCost]:
    """Parse a scenario body (ValueError/ValidationError naming the field) and estimate its cost."""
    if scenario_kind(body) == "rigid-spin":
        from sim_core.rigid_spin import RigidSpinScenario

        spin = RigidSpinScenario.model_validate(body)
        return spin.model_dump(), JobCost(spin.duration_s, spin.batch_size, spin.output_bytes())
    scenario = _engine_scenario(body)
    return scenario.model_dump(mode="json"), _engine_cost(scenario)


PROGRESS_TOPIC = "acs-twin-job-progress"  # Dask event topic: [job_id, fraction] from the task to the server
REPORT_EVERY_S = 0.25  # a task reports progress and looks at its cancel Event at most this often


def cancel_event_name(job_id: str) -> str:
    """Name of the ``distributed.Event`` the server sets to cancel a job."""
    return f"acs-twin-cancel-{job_id}"


class _JobLink:
    """A running task's line to the server: progress as Dask events, cancellation as a Dask Event (both throttled)."""

    def __init__(self, job_id: str) -> None:
        from distributed import Event, get_worker

        self._job_id, self._worker = job_id, get_worker()
        self._cancel = Event(cancel_event_name(job_id))
        self._reported = self._asked = -math.inf
        self._cancelled = False

    def report(self, fraction: float) -> None:
        """Send ``fraction`` to the server (the last one always)."""
        now = time.monotonic()
        if now - self._reported >= REPORT_EVERY_S or fraction >= 1.0:
            self._reported = now
            self._worker.log_event(PROGRESS_TOPIC, [self._job_id, float(fraction)])

    def is_cancelled(self) -> bool:
        """True once the server set the cancel Event."""
        now = time.monotonic()
        if not self._cancelled and now - self._asked >= REPORT_EVERY_S:
            self._asked = now
            self._cancelled = self._cancel.is_set()
        return self._cancelled

    def progress(self, fraction: float) -> None:
        """:meth:`report`, then raise JobCancelled once cancelled (for loops in this thread)."""
        self.report(fraction)
        if self.is_cancelled():
            raise JobCancelled


def _engine_npz(body: dict[str, Any], link: _JobLink, options: dict[str, Any], out: Path) -> dict[str, Any]:
    import numpy as np

    from backend.jobs.trajectory_files import write_npz
    from sim_core.engine import Cancelled, simulate
    from sim_core.scenario import Scenario

    available = options.get("wheel_available")
    try:
        trajectory = simulate(
            Scenario.model_validate(body),
            progress=link.report,  # the engine's own thread polls cancel and stops its compiled loop
            cancel=link.is_cancelled,
            wheel_available=None if available is None else np.asarray(available, dtype=bool),
            fdir=bool(options.get("fdir", False)),
        )
    except Cancelled:
        raise JobCancelled from None
    write_npz(trajectory, out)
    return {"variants": [trajectory.summary(v) for v in range(trajectory.n_variants)]}


def _rigid_spin_npz(body: dict[str, Any], link: _JobLink, out: Path) -> dict[str, Any]:
    from sim_core import rigid_spin

    trajectory = rigid_spin.simulate(rigid_spin.RigidSpinScenario.model_validate(body), link.progress)
    trajectory.to_npz(out)
    return trajectory.summary()


def run_job(job_id: str, body: dict[str, Any], options: dict[str, Any] | None = None) -> JobOutput:
    """Dask task: simulate the job; its trajectory.npz bytes and summary (JobCancelled once cancelled).

    The server writes the files, so a worker on another machine needs no shared disk."""
    import tempfile

    link = _JobLink(job_id)
    with tempfile.TemporaryDirectory(prefix="acs-twin-job-") as scratch:
        out = Path(scratch) / "trajectory.npz"
        if scenario_kind(body) == "rigid-spin":
            summary = _rigid_spin_npz(body, link, out)
        else:
            summary = _engine_npz(body, link, options or {}, out)
        link.report(1.0)
        return out.read_bytes(), summary
