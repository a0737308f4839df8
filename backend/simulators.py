"""Which simulation a job runs: the sim_core engine when present, else the built-in rigid spin.

Each scenario is validated in the API process (so limits are checked before queueing) and run in
a worker process by :func:`run_in_worker`, which writes ``trajectory.npz`` and ``summary.json``.
"""

from __future__ import annotations

import importlib.util
import json
import traceback
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

__all__ = ["JobCost", "validate_scenario", "run_in_worker", "engine_available", "JobCancelled"]


class JobCancelled(Exception):
    """Raised inside a worker by the progress callback once cancellation was requested."""


@dataclass(frozen=True)
class JobCost:
    """What limits are checked against: simulated time, batch size, result size."""

    duration_s: float
    batch_size: int
    output_bytes: int


def engine_available() -> bool:
    """True once sim_core.engine and sim_core.scenario exist (the lead's engine has landed)."""
    return all(importlib.util.find_spec(m) is not None
               for m in ("sim_core.engine", "sim_core.scenario"))


def _is_rigid_spin(body: dict[str, Any]) -> bool:
    return body.get("kind") == "rigid-spin" or not engine_available()


def validate_scenario(body: dict[str, Any]) -> tuple[dict[str, Any], JobCost]:
    """Parse a scenario body (ValueError naming the field) and estimate its cost."""
    if _is_rigid_spin(body):
        from backend.rigid_spin import RigidSpinScenario

        spin = RigidSpinScenario.model_validate(body)
        return spin.model_dump(), JobCost(spin.duration_s, spin.batch_size, spin.output_bytes())
    from sim_core.scenario import Scenario  # type: ignore[import-not-found]

    scenario = Scenario.model_validate(body)
    return scenario.model_dump(mode="json"), _engine_cost(scenario)


def _engine_cost(scenario: Any) -> JobCost:
    duration_s = float(scenario.duration_s)
    batch = int(getattr(scenario, "batch_size", 1))
    estimate = getattr(scenario, "output_bytes", None)
    output = int(estimate()) if callable(estimate) else int(duration_s / 0.5 * batch * 8 * 64)
    return JobCost(duration_s, batch, output)


def _simulate(body: dict[str, Any], progress: Callable[[float], None]) -> Any:
    if _is_rigid_spin(body):
        from backend import rigid_spin

        return rigid_spin.simulate(rigid_spin.RigidSpinScenario.model_validate(body), progress)
    from sim_core.engine import simulate  # type: ignore[import-not-found]
    from sim_core.scenario import Scenario  # type: ignore[import-not-found]

    return simulate(Scenario.model_validate(body), progress=progress)


def run_in_worker(body: dict[str, Any], out_dir: str, progress_value: Any, cancel_event: Any) -> None:
    """Worker-process entry: simulate, write trajectory.npz + summary.json, or error.txt."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)

    def progress(fraction: float) -> None:
        progress_value.value = float(fraction)
        if cancel_event.is_set():
            raise JobCancelled

    try:
        trajectory = _simulate(body, progress)
        trajectory.to_npz(out / "trajectory.npz")
        (out / "summary.json").write_text(json.dumps(trajectory.summary()))
    except JobCancelled:
        (out / "cancelled").touch()
        raise SystemExit(3) from None
    except Exception:
        (out / "error.txt").write_text(traceback.format_exc())
        raise SystemExit(1) from None
