"""Which simulation a job runs: the sim_core engine, or the built-in rigid spin (``kind: rigid-spin``).

A body is either a full sim_core Scenario, a library scenario ``{"library": NAME, "set": [...]}``
(``acs-twin scenarios`` lists them), or a rigid-spin scenario. It is validated in the API process
(limits are checked before queueing) and run in a worker process by :func:`run_in_worker`, which
writes ``trajectory.npz`` and ``summary.json`` (or ``error.txt``).
"""

from __future__ import annotations

import json
import math
import traceback
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

__all__ = ["JobCost", "validate_scenario", "run_in_worker", "JobCancelled", "library_names"]

FLOAT_BYTES = 8


class JobCancelled(Exception):
    """Raised inside a worker by the progress callback once cancellation was requested."""


@dataclass(frozen=True)
class JobCost:
    """What limits are checked against: simulated time, batch size, result size."""

    duration_s: float
    batch_size: int
    output_bytes: int


def _is_rigid_spin(body: dict[str, Any]) -> bool:
    return body.get("kind") == "rigid-spin"


def library_names() -> list[str]:
    """Names of the sim_core library scenarios."""
    from sim_core import scenario_library

    return scenario_library.names()


def _engine_scenario(body: dict[str, Any]) -> Any:
    from sim_core import scenario_library
    from sim_core.scenario import Scenario, apply_overrides

    if "library" not in body:
        return Scenario.model_validate(body)
    unknown = set(body) - {"library", "set"}
    if unknown:
        raise ValueError(f"{sorted(unknown)[0]}: a library body has only 'library' and 'set'")
    if body["library"] not in scenario_library.names():
        raise ValueError(f"library: unknown scenario {body['library']!r}; one of {scenario_library.names()}")
    sets = body.get("set", [])
    if not isinstance(sets, list) or not all(isinstance(s, str) for s in sets):
        raise ValueError("set: expected a list of 'path.to.field=value' strings")
    return apply_overrides(scenario_library.get(body["library"]), sets)


MAX_STEPS = 10**9  # dynamics steps of one job: far above any real scenario (one orbit at 0.01 s: 580,100)


def _steps(scenario: Any, field: str) -> int:
    """``getattr(scenario, field) / dynamics_dt_s`` as a count (ValueError naming the field when not finite/too big)."""
    for name in ("duration_s", "dynamics_dt_s", "output_dt_s"):
        value = float(getattr(scenario, name))
        if not (math.isfinite(value) and value > 0 and math.isfinite(1.0 / value)):
            raise ValueError(f"{name}: must be a finite, normal number of seconds > 0, got {value!r}")
    steps = float(getattr(scenario, field)) / float(scenario.dynamics_dt_s)
    if not steps <= MAX_STEPS:
        raise ValueError(f"{field}: {field} / dynamics_dt_s = {steps:.3g} steps, over {MAX_STEPS:.0e}")
    return max(round(steps), 1)


def _engine_cost(scenario: Any) -> JobCost:
    from sim_core.closed_loop import record_width

    n_out = -(-_steps(scenario, "duration_s") // _steps(scenario, "output_dt_s"))
    n_wheels = len(scenario.spacecraft.cluster.wheels)
    batch = len(scenario.variants)
    return JobCost(scenario.duration_s, batch, n_out * batch * record_width(n_wheels) * FLOAT_BYTES)


def validate_scenario(body: dict[str, Any]) -> tuple[dict[str, Any], JobCost]:
    """Parse a scenario body (ValueError/ValidationError naming the field) and estimate its cost."""
    if _is_rigid_spin(body):
        from sim_core.rigid_spin import RigidSpinScenario

        spin = RigidSpinScenario.model_validate(body)
        return spin.model_dump(), JobCost(spin.duration_s, spin.batch_size, spin.output_bytes())
    scenario = _engine_scenario(body)
    return scenario.model_dump(mode="json"), _engine_cost(scenario)


def _run_engine(
    body: dict[str, Any],
    out: Path,
    progress: Callable[[float], None],
    cancelled: Callable[[], bool],
    options: dict[str, Any],
) -> None:
    import numpy as np

    from backend.jobs.trajectory_files import write_npz
    from sim_core.engine import Cancelled, simulate
    from sim_core.scenario import Scenario

    available = options.get("wheel_available")
    try:
        trajectory = simulate(
            Scenario.model_validate(body),
            progress=progress,
            cancel=cancelled,
            wheel_available=None if available is None else np.asarray(available, dtype=bool),
            fdir=bool(options.get("fdir", False)),
        )
    except Cancelled:
        raise JobCancelled from None
    write_npz(trajectory, out / "trajectory.npz")
    summary = {"variants": [trajectory.summary(v) for v in range(trajectory.n_variants)]}
    (out / "summary.json").write_text(json.dumps(summary))


def _run_rigid_spin(body: dict[str, Any], out: Path, progress: Callable[[float], None]) -> None:
    from sim_core import rigid_spin

    trajectory = rigid_spin.simulate(rigid_spin.RigidSpinScenario.model_validate(body), progress)
    trajectory.to_npz(out / "trajectory.npz")
    (out / "summary.json").write_text(json.dumps(trajectory.summary()))


def run_in_worker(
    body: dict[str, Any], out_dir: str, progress_value: Any, cancel_event: Any, options: dict[str, Any] | None = None
) -> None:
    """Worker-process entry: simulate, write trajectory.npz + summary.json, or error.txt."""
    from backend.core.processes import become_owned_child

    become_owned_child()  # a job never outlives the server (kill -9 included)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)

    def progress(fraction: float) -> None:
        progress_value.value = float(fraction)
        if cancel_event.is_set():
            raise JobCancelled

    try:
        if _is_rigid_spin(body):
            _run_rigid_spin(body, out, progress)
        else:
            _run_engine(body, out, progress, cancel_event.is_set, options or {})
    except JobCancelled:
        (out / "cancelled").touch()
        raise SystemExit(3) from None
    except Exception:
        (out / "error.txt").write_text(traceback.format_exc())
        raise SystemExit(1) from None
