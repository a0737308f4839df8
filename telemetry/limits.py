"""Limit checking of decoded parameters (issue 5): yellow/red low/high limits -> alarm levels.

A sample is *red* outside [red_low, red_high], else *yellow* outside [yellow_low, yellow_high],
else nominal; a NaN sample is red (an unknown value of a monitored parameter is unsafe).  Checking
is vectorised over a whole ingest batch; the alarm transitions are the indices where the level
changes, starting from the level the parameter had before the batch.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from telemetry.dictionary import DerivedParameter, Dictionary, Parameter

__all__ = [
    "NOMINAL",
    "YELLOW",
    "RED",
    "SEVERITY_NAMES",
    "LimitSet",
    "limit_levels",
    "level_changes",
    "limit_set",
    "dictionary_limits",
]

NOMINAL, YELLOW, RED = 0, 1, 2
SEVERITY_NAMES = ("nominal", "yellow", "red")


@dataclass(frozen=True)
class LimitSet:
    """Yellow and red limits of one parameter (engineering units; infinite = no limit)."""

    yellow_low: float = -math.inf
    yellow_high: float = math.inf
    red_low: float = -math.inf
    red_high: float = math.inf

    def __post_init__(self) -> None:
        bounds = (self.red_low, self.yellow_low, self.yellow_high, self.red_high)
        if any(math.isnan(b) for b in bounds):
            raise ValueError("limits: a limit is NaN (use +/-inf for 'no limit')")
        if not self.red_low <= self.yellow_low <= self.yellow_high <= self.red_high:
            raise ValueError(f"limits: need red_low <= yellow_low <= yellow_high <= red_high, got {bounds}")


def limit_levels(values: np.ndarray, limits: LimitSet) -> np.ndarray:
    """Alarm level per sample (0 nominal, 1 yellow, 2 red) of a 1-D array (issue 5 limits)."""
    v = np.asarray(values, dtype=np.float64)
    if v.ndim != 1:
        raise ValueError(f"values: expected a 1-D array, got shape {v.shape}")
    red = ~((v >= limits.red_low) & (v <= limits.red_high))
    yellow = ~((v >= limits.yellow_low) & (v <= limits.yellow_high))
    return np.where(red, RED, np.where(yellow, YELLOW, NOMINAL)).astype(np.int8)


def level_changes(levels: np.ndarray, initial_level: int = NOMINAL) -> np.ndarray:
    """Indices where the level differs from the previous sample (the first vs ``initial_level``)."""
    lv = np.asarray(levels, dtype=np.int8)
    if initial_level not in (NOMINAL, YELLOW, RED):
        raise ValueError(f"initial_level: expected 0, 1 or 2, got {initial_level}")
    previous = np.concatenate(([np.int8(initial_level)], lv[:-1]))
    return np.flatnonzero(lv != previous)


def limit_set(
    red_low: float | None, yellow_low: float | None, yellow_high: float | None, red_high: float | None
) -> LimitSet:
    """LimitSet from optional bounds (None = none); a missing yellow bound falls back to the red one."""
    rl = -math.inf if red_low is None else float(red_low)
    rh = math.inf if red_high is None else float(red_high)
    yl = rl if yellow_low is None else float(yellow_low)
    yh = rh if yellow_high is None else float(yellow_high)
    return LimitSet(yellow_low=yl, yellow_high=yh, red_low=rl, red_high=rh)


def dictionary_limits(dictionary: Dictionary) -> dict[str, LimitSet]:
    """Limits of every limited parameter of a telemetry dictionary (telemetry.dictionary.Dictionary)."""
    limits: dict[str, LimitSet] = {}
    for packet in dictionary.packets.values():
        parameters: tuple[Parameter | DerivedParameter, ...] = (*packet.parameters, *packet.derived)
        for parameter in parameters:
            b = parameter.limits
            if any(v is not None for v in (b.red_low, b.yellow_low, b.yellow_high, b.red_high)):
                limits[parameter.name] = limit_set(b.red_low, b.yellow_low, b.yellow_high, b.red_high)
    return limits
