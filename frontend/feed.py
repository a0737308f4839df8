"""What the twin view needs from the rest of the system, as a small interface (``TwinFeed``), and a
feed backed by ``sim_core`` trajectories so that the views and tests run without the server.

The backend hands the monitors an object with these methods (its telemetry- and session-backed
feed); the frontend never imports the backend (DESIGN.md layers). Times are UTC seconds since the
Unix epoch; attitudes are scalar-first ``q_ib`` (body → ECI); positions ECI metres.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import numpy as np

from sim_core import orbit, quaternion
from sim_core.attitude_spline import AttitudeSpline
from sim_core.trajectory import Trajectory

__all__ = [
    "GroundStation",
    "FeedWindow",
    "TwinFeed",
    "WindowSource",
    "TrajectoryFeed",
    "DEFAULT_STATIONS",
    "attitude_error_rad",
    "hermite_orbit",
    "ORBIT_MARGIN_S",
    "ORBIT_TABLE_STEP_S",
    "NOMINAL_LABEL",
]

ORBIT_TABLE_STEP_S = 10.0  # cubic interpolation error ~ (n h)⁴ r / 384 ≈ 0.2 mm at LEO
NOMINAL_LABEL = "nominal twin"  # what a monitor's simulated side shows unless a diagnosed hypothesis is flown on it
ORBIT_MARGIN_S = 6000.0  # extrapolate a bit more than one LEO period beyond the data, both ways


@dataclass(frozen=True)
class GroundStation:
    """A ground station: WGS84 position and elevation mask."""

    name: str
    lat_deg: float
    lon_deg: float
    min_elevation_deg: float = 5.0


DEFAULT_STATIONS = (
    GroundStation("Kiruna", 67.857, 20.964),
    GroundStation("Svalbard", 78.230, 15.407),
    GroundStation("Moscow", 55.756, 37.617),
)


@dataclass(frozen=True)
class FeedWindow:
    """Samples of one time window for the panels: attitude error, wheels, MD moment, mode and flags."""

    t_unix_s: np.ndarray  # (N,)
    error_angle_rad: np.ndarray  # (N,) angle of Λ̃_sim ∘ Λ_actual
    wheel_speed_rad_s: np.ndarray  # (N, n_wheels), actual
    md_dipole_am2: np.ndarray  # (N, 3), actual
    mode: np.ndarray  # (N,) int
    fault_flags: np.ndarray  # (N,) int bit set
    observing: np.ndarray  # (N,) bool
    wheel_speed_simulated_rad_s: np.ndarray | None = None  # (N, n_wheels), the twin's where the feed flies wheels


@runtime_checkable
class TwinFeed(Protocol):
    """Data source of the twin view (implemented by the backend's session feed and by TrajectoryFeed)."""

    def span_unix_s(self) -> tuple[float, float]:
        """First and last instant with data (the end grows while live)."""
        ...

    def attitude_actual(self, t_unix_s: np.ndarray) -> np.ndarray:
        """Telemetry attitude q_ib at the given times, (N, 4)."""
        ...

    def attitude_simulated(self, t_unix_s: np.ndarray) -> np.ndarray:
        """Twin (simulated) attitude q_ib at the given times, (N, 4)."""
        ...

    def orbit_eci(self, t_unix_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Spacecraft position (m) and velocity (m/s) in ECI, (N, 3) each; may extend beyond the span."""
        ...

    def window(self, t0_unix_s: float, t1_unix_s: float) -> FeedWindow:
        """Panel samples in [t0, t1]."""
        ...

    def active_alarms(self, t_unix_s: float) -> list[str]:
        """Human-readable active alarms at an instant."""
        ...

    def ground_stations(self) -> list[GroundStation]:
        """Ground stations to draw with their visibility circles."""
        ...


@runtime_checkable
class WindowSource(Protocol):
    """Past windows of the archive for replay on the monitors (implemented by the backend over its archive)."""

    def archive_span_unix_s(self) -> tuple[float, float] | None:
        """First and last archived telemetry instant (None before any data arrived)."""
        ...

    def window_feed(self, t0_unix_s: float, t1_unix_s: float) -> TwinFeed:
        """A feed of the archived telemetry and twin in [t0, t1]; ValueError naming the field if it cannot."""
        ...


def attitude_error_rad(q_actual: np.ndarray, q_simulated: np.ndarray) -> np.ndarray:
    """Angle of the mismatch E = Λ̃_sim ∘ Λ_actual (seed 000 §4 error quaternion), rad."""
    return quaternion.angle(quaternion.multiply(quaternion.conjugate(q_simulated), q_actual))


class TrajectoryFeed:
    """TwinFeed over sim_core trajectories: one variant plays the telemetry, another the twin."""

    def __init__(
        self,
        actual: Trajectory,
        simulated: Trajectory | None = None,
        actual_variant: int = 0,
        simulated_variant: int = 0,
        stations: tuple[GroundStation, ...] = DEFAULT_STATIONS,
    ) -> None:
        simulated = actual if simulated is None else simulated
        for traj, v, name in (
            (actual, actual_variant, "actual_variant"),
            (simulated, simulated_variant, "simulated_variant"),
        ):
            if not 0 <= v < traj.n_variants:
                raise ValueError(f"{name}: {v} is not a variant of {traj.scenario_name!r}")
        if "epoch_unix_s" not in actual.extra:
            raise ValueError("actual: trajectory lacks extra['epoch_unix_s']")
        self._a, self._s, self._va, self._vs = actual, simulated, actual_variant, simulated_variant
        self._t = actual.t_s + actual.extra["epoch_unix_s"]
        t_sim = simulated.t_s + simulated.extra.get("epoch_unix_s", actual.extra["epoch_unix_s"])
        self._spline_a = AttitudeSpline(
            self._t, actual["q_ib"][actual_variant], actual["omega_b_rad_s"][actual_variant]
        )
        self._spline_s = AttitudeSpline(
            t_sim, simulated["q_ib"][simulated_variant], simulated["omega_b_rad_s"][simulated_variant]
        )
        self._stations = list(stations)
        self._orbit_t, self._orbit_r, self._orbit_v = _orbit_table(self._t, actual["r_eci_m"][actual_variant])

    def span_unix_s(self) -> tuple[float, float]:
        """First and last sample time of the actual trajectory."""
        return float(self._t[0]), float(self._t[-1])

    def attitude_actual(self, t_unix_s: np.ndarray) -> np.ndarray:
        """Actual attitude by the C¹ spline through the samples (seed 000 §7 vector splines)."""
        return self._spline_a.attitude(np.clip(t_unix_s, *self._spline_a.t_s[[0, -1]]))

    def attitude_simulated(self, t_unix_s: np.ndarray) -> np.ndarray:
        """Simulated attitude by the C¹ spline through the twin's samples."""
        return self._spline_s.attitude(np.clip(t_unix_s, *self._spline_s.t_s[[0, -1]]))

    def orbit_eci(self, t_unix_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Position and velocity by cubic Hermite interpolation of the orbit table (J2-extended past the data)."""
        t = np.clip(np.asarray(t_unix_s, dtype=float), self._orbit_t[0], self._orbit_t[-1])
        return hermite_orbit(self._orbit_t, self._orbit_r, self._orbit_v, t)

    def window(self, t0_unix_s: float, t1_unix_s: float) -> FeedWindow:
        """Samples of the actual variant in [t0, t1] with the error against the twin."""
        sel = (self._t >= t0_unix_s) & (self._t <= t1_unix_s)
        t = self._t[sel]
        s, v = self._a.series, self._va
        n = t.size
        return FeedWindow(
            t_unix_s=t,
            error_angle_rad=attitude_error_rad(s["q_ib"][v][sel], self.attitude_simulated(t)),
            wheel_speed_rad_s=s["wheel_speed_rad_s"][v][sel],
            md_dipole_am2=s["md_dipole_am2"][v][sel],
            mode=s["mode"][v][sel].astype(np.int64) if "mode" in s else np.zeros(n, np.int64),
            fault_flags=s["fault_flags"][v][sel].astype(np.int64) if "fault_flags" in s else np.zeros(n, np.int64),
            observing=s["observing"][v][sel] > 0 if "observing" in s else np.zeros(n, bool),
        )

    def active_alarms(self, t_unix_s: float) -> list[str]:
        """Engine events of both sides up to t: faults not yet cleared, and saturations in the last minute."""
        epoch = self._a.extra["epoch_unix_s"]
        out = []
        for label, traj, v in (("actual", self._a, self._va), ("twin", self._s, self._vs)):
            out += [f"{label}: {text}" for text in _active_events(traj.events[v], t_unix_s - epoch)]
        return out

    def ground_stations(self) -> list[GroundStation]:
        """The stations given at construction."""
        return list(self._stations)


_TRANSIENT_EVENTS = {"md_saturated", "wheel_momentum_limit", "allocation_infeasible"}
TRANSIENT_ALARM_S = 60.0  # a saturation event stays "active" this long on the panel


def _active_events(events: list[tuple[float, str, int]], t_s: float) -> list[str]:
    faults: dict[int, float] = {}
    transient: dict[tuple[str, int], float] = {}
    for t_ev, name, arg in events:
        if t_ev > t_s:
            break
        if name == "fault_onset":
            faults[arg] = t_ev
        elif name == "fault_cleared":
            faults.pop(arg, None)
        elif name in _TRANSIENT_EVENTS and t_s - t_ev <= TRANSIENT_ALARM_S:
            transient[(name, arg)] = t_ev
    return [f"fault {arg} since t+{t0:.1f} s" for arg, t0 in faults.items()] + [
        f"{name} ({arg}) at t+{t0:.1f} s" for (name, arg), t0 in transient.items()
    ]


def _orbit_table(t_unix_s: np.ndarray, r_eci_m: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Orbit every ORBIT_TABLE_STEP_S over the data and ORBIT_MARGIN_S beyond, by J2 propagation (seed 003 §3.2.3.2.1).

    The data's velocity is its finite-difference derivative; before the data the J2 flow is run
    backwards by reversing the velocity (the force field is conservative and time-reversible).
    """
    r = np.asarray(r_eci_m, dtype=float)
    v = np.gradient(r, t_unix_s, axis=0, edge_order=2)
    t_in = np.arange(t_unix_s[0], t_unix_s[-1], ORBIT_TABLE_STEP_S)
    idx = np.searchsorted(t_unix_s, t_in)
    r_in, v_in = r[idx], v[idx]
    t_after = np.arange(0.0, ORBIT_MARGIN_S + ORBIT_TABLE_STEP_S, ORBIT_TABLE_STEP_S)
    r_fwd, v_fwd = orbit.propagate_j2(r[-1], v[-1], t_after)
    r_back, v_back = orbit.propagate_j2(r[0], -v[0], t_after[1:])
    t = np.concatenate([t_unix_s[0] - t_after[1:][::-1], t_in, t_unix_s[-1] + t_after])
    r_all = np.concatenate([r_back[::-1], r_in, r_fwd])
    v_all = np.concatenate([-v_back[::-1], v_in, v_fwd])
    keep = np.concatenate([[True], np.diff(t) > 0.0])
    return t[keep], r_all[keep], v_all[keep]


def hermite_orbit(
    t_tab: np.ndarray, r_tab: np.ndarray, v_tab: np.ndarray, t: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Position and velocity at t by cubic Hermite interpolation of an orbit table (t, r, v), t inside it."""
    i = np.clip(np.searchsorted(t_tab, t, side="right") - 1, 0, t_tab.size - 2)
    h = (t_tab[i + 1] - t_tab[i])[..., None]
    s = ((t - t_tab[i])[..., None]) / h
    p0, p1, m0, m1 = r_tab[i], r_tab[i + 1], v_tab[i] * h, v_tab[i + 1] * h
    r = (2 * s**3 - 3 * s**2 + 1) * p0 + (s**3 - 2 * s**2 + s) * m0 + (-2 * s**3 + 3 * s**2) * p1 + (s**3 - s**2) * m1
    dr = (6 * s**2 - 6 * s) * p0 + (3 * s**2 - 4 * s + 1) * m0 + (-6 * s**2 + 6 * s) * p1 + (3 * s**2 - 2 * s) * m1
    return r, dr / h
