"""Torque-free rigid-body spin: the job runner's built-in workload (Euler's equations + kinematics).

A real, checkable computation the job machinery runs in worker processes alongside the engine:
scenario ``{"kind": "rigid-spin", "duration_s", "dt_s", "inertia_kg_m2", "omega0_rad_s"}`` with a
leading batch axis on the inertia diagonals and initial rates. Integrates J ω̇ = −ω × Jω and
Λ̇ = ½ Λ ∘ ω (seed 000 eq 1 with no wheels, no flexibility, no external torque) by classical RK4.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, model_validator

from sim_core import quaternion as qt

__all__ = ["RigidSpinScenario", "RigidSpinTrajectory", "simulate", "BYTES_PER_SAMPLE"]

MAX_STEPS = 1e9  # RK4 steps of one run; the result-size limit of the caller bites long before
BYTES_PER_SAMPLE = 8 * (1 + 4 + 3)  # t, q_ib, omega_b per batch member and step (float64)
PROGRESS_STEPS = 500  # progress is reported every 1 % and at least every 500 steps (tens of ms): a caller that
# stops the run by raising from it (a cancelled job) is heard at once, not after 1 % of a long run (seconds)


class RigidSpinScenario(BaseModel):
    """Inputs of a torque-free spin: batch of inertia diagonals and initial body rates."""

    # every number finite (Infinity / NaN name their field); an unknown key (a typo) names itself, as in Scenario.
    # As JSON, a rigid spin is told from a Scenario by its kind: the schema requires it, Python callers may omit it.
    model_config = ConfigDict(allow_inf_nan=False, extra="forbid", json_schema_extra={"required": ["kind"]})

    kind: str = Field("rigid-spin", pattern="^rigid-spin$")
    duration_s: float = Field(10.0, gt=0, examples=[10.0])
    dt_s: float = Field(0.01, gt=0, le=10.0, examples=[0.01])
    inertia_kg_m2: list[list[float]] = Field([[35.0, 30.0, 25.0]], min_length=1, examples=[[[500.0, 200.0, 300.0]]])
    omega0_rad_s: list[list[float]] = Field([[0.01, -0.02, 0.03]], min_length=1, examples=[[[0.5, -0.4, 0.7]]])

    @model_validator(mode="after")
    def _shapes(self) -> RigidSpinScenario:
        if any(len(row) != 3 or min(row) <= 0 for row in self.inertia_kg_m2):
            raise ValueError("inertia_kg_m2: each row must be 3 positive principal moments")
        if any(len(row) != 3 for row in self.omega0_rad_s):
            raise ValueError("omega0_rad_s: each row must have 3 components")
        if len(self.inertia_kg_m2) != len(self.omega0_rad_s):
            raise ValueError("omega0_rad_s: needs one row per inertia_kg_m2 row (batch size)")
        if not self.duration_s / self.dt_s <= MAX_STEPS:  # a denormal dt_s makes the ratio infinite
            raise ValueError(f"dt_s: duration_s / dt_s = {self.duration_s / self.dt_s:.3g} steps, over {MAX_STEPS:.0e}")
        return self

    @property
    def batch_size(self) -> int:
        """Number of batch members (fault variants)."""
        return len(self.inertia_kg_m2)

    @property
    def n_steps(self) -> int:
        """RK4 steps to cover duration_s."""
        return int(np.ceil(self.duration_s / self.dt_s))

    def output_bytes(self) -> int:
        """Size of the saved trajectory (all steps, all batch members), in bytes."""
        return (self.n_steps + 1) * self.batch_size * BYTES_PER_SAMPLE


@dataclass
class RigidSpinTrajectory:
    """Time history: t (n,), q_ib (batch, n, 4), omega_b (batch, n, 3) and the inertias."""

    t_s: np.ndarray
    q_ib: np.ndarray
    omega_b_rad_s: np.ndarray
    inertia_kg_m2: np.ndarray

    def summary(self) -> dict[str, Any]:
        """Final state and conservation residuals (energy, |H|) per batch member."""
        j, w = self.inertia_kg_m2[:, None, :], self.omega_b_rad_s
        energy = 0.5 * np.sum(j * w * w, axis=-1)
        h = np.linalg.norm(j * w, axis=-1)
        return {
            "kind": "rigid-spin",
            "steps": int(self.t_s.size - 1),
            "duration_s": float(self.t_s[-1]),
            "q_ib_final": self.q_ib[:, -1].tolist(),
            "omega_b_final_rad_s": self.omega_b_rad_s[:, -1].tolist(),
            "energy_rel_drift": (np.abs(energy[:, -1] / energy[:, 0] - 1.0)).tolist(),
            "momentum_rel_drift": (np.abs(h[:, -1] / h[:, 0] - 1.0)).tolist(),
        }

    def to_npz(self, path: Path) -> None:
        """Write the arrays to one .npz file."""
        np.savez(path, t_s=self.t_s, q_ib=self.q_ib, omega_b_rad_s=self.omega_b_rad_s, inertia_kg_m2=self.inertia_kg_m2)


def _rates(j: np.ndarray, q: np.ndarray, w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    dw = -np.cross(w, j * w) / j
    return qt.derivative(q, w), dw


def simulate(scenario: RigidSpinScenario, progress: Callable[[float], None] | None = None) -> RigidSpinTrajectory:
    """RK4 integration of torque-free rigid-body motion (seed 000 eq 1, no wheels, no torque)."""
    j = np.asarray(scenario.inertia_kg_m2, dtype=float)
    n, dt = scenario.n_steps, scenario.duration_s / scenario.n_steps
    q_hist = np.empty((j.shape[0], n + 1, 4))
    w_hist = np.empty((j.shape[0], n + 1, 3))
    q_hist[:, 0] = [1.0, 0.0, 0.0, 0.0]
    w_hist[:, 0] = scenario.omega0_rad_s
    report_every = max(1, min(n // 100, PROGRESS_STEPS))
    for k in range(n):
        q, w = q_hist[:, k], w_hist[:, k]
        k1q, k1w = _rates(j, q, w)
        k2q, k2w = _rates(j, q + 0.5 * dt * k1q, w + 0.5 * dt * k1w)
        k3q, k3w = _rates(j, q + 0.5 * dt * k2q, w + 0.5 * dt * k2w)
        k4q, k4w = _rates(j, q + dt * k3q, w + dt * k3w)
        q_hist[:, k + 1] = qt.normalize(q + dt / 6.0 * (k1q + 2 * k2q + 2 * k3q + k4q))
        w_hist[:, k + 1] = w + dt / 6.0 * (k1w + 2 * k2w + 2 * k3w + k4w)
        if progress is not None and ((k + 1) % report_every == 0 or k + 1 == n):
            progress((k + 1) / n)
    return RigidSpinTrajectory(np.arange(n + 1) * dt, q_hist, w_hist, j)
