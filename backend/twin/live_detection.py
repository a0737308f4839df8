"""Anomaly detection on a live twin's residuals: the window test of :mod:`sim_core.fault_detection` per segment.

Within one twin segment (from a re-synchronisation to the next) the residual twin − telemetry of each wheel speed
and each body rate is a signal the twin explains up to (1) the telemetry's rounding, bounded by one quantum over
any difference of two samples (the twin's own start value, rounded too, cancels in a difference); (2) what the
twin does not know of the satellite (its own truth: inertia ±2 %, wheel tilt, an unestimated gyro bias), which
makes a wheel residual drift: bounded by ``WHEEL_DRIFT_COUNTS_PER_S`` (the ``relative`` term of the test, summed
over the window); (3) a random walk (wheels) or white noise (rates, the onboard estimator's). The window test of
:func:`sim_core.fault_detection.window_alarm` over ``WINDOWS_S`` inside the segment alarms when
|r_k − r_{k−L}| > quantum + drift·L + N_SIGMA σ_L. The stated false-alarm rate is its union bound
(:func:`sim_core.fault_detection.false_alarms_per_day`) over the channels and windows tested, valid while the
drift bound and the Gaussian part hold.

A satellite whose onboard FDIR isolates a wheel reconfigures within seconds and the twin, synchronised with the
isolation flags, follows it on the remaining wheels: its residuals see only the seconds before the isolation.
So a wheel's isolation flag rising in telemetry is a detection too (channel ``wheel k isolated onboard``, no test
ratio): the spacecraft's own claim, which adds no false alarm of ours.

Calibration (``somov-ge4-scan``, reference dictionary, 4 Hz housekeeping, 560 s flights through a scheduled turn,
after the satellite's MEKF converged; twin segments of 60 s): the largest |r_k − r_{k−L}| of a wheel was 1.3 / 1.5
counts over 10 / 30 s when the satellite flies the twin's model, 2.4 / 3.6 counts with its own truth (seed 1):
an excess of ≤ 0.14 count/s over the rounding, taken twice (0.3) as the drift bound, and a walk of 0.1 count/√s;
the rate residuals (the MEKF's estimate against the twin's) had σ ≈ 3e-6 rad/s with differences up to 2.2e-5
rad/s, hence a white σ of 1e-5 rad/s (twice the 5e-6 that makes those differences 3σ).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from sim_core import fault_detection as fd

__all__ = ["WINDOWS_S", "Detection", "ResidualDetector"]

NS_PER_S = 1_000_000_000
WINDOWS_S = (10.0, 30.0)  # windows that fit in one RESYNC_S = 60 s segment
WHEEL_DRIFT_COUNTS_PER_S = 0.3  # truth-mismatch drift bound of a wheel residual, in tachometer counts (calibration)
WHEEL_WALK_COUNTS_PER_SQRT_S = 0.1  # random-walk σ of a wheel residual per √s, in counts (calibration)
RATE_NOISE_RAD_S = 1e-5  # white σ of a body-rate residual (calibration)
WHEEL_COUNT_FALLBACK_RAD_S = 0.25 * np.pi / 30.0  # scale of the wheel bounds when the dictionary sends floats


@dataclass(frozen=True)
class Detection:
    """The detector fired: when (UTC ns), on which residual channel, the window (s) and the test ratio (σ)."""

    t_utc_ns: int
    channel: str
    window_s: float | None
    ratio: float | None


class ResidualDetector:
    """The window test on one twin's wheel-speed and body-rate residuals, segment by segment; latches once fired."""

    def __init__(self, n_wheels: int, wheel_quantum_rad_s: float) -> None:
        self.channels = [f"wheel {k + 1} speed" for k in range(n_wheels)] + [f"rate {a}" for a in "xyz"]
        self._n_wheels, self._quantum = n_wheels, wheel_quantum_rad_s
        self._dt_s: float | None = None
        self._segment_ns: int | None = None
        self._t = np.empty(0, np.int64)
        self._r = np.empty((len(self.channels), 0))
        self.fired: Detection | None = None
        self._isolated: np.ndarray | None = None  # the newest isolation flags seen

    @property
    def false_alarms_per_day(self) -> float | None:
        """Union bound on false alarms per day at the sample interval (the stated rate); None before data."""
        if self._dt_s is None:
            return None
        return fd.false_alarms_per_day(len(self.channels), self._dt_s, fd.N_SIGMA, len(WINDOWS_S))

    def update(
        self, segment_start_ns: int, t_ns: np.ndarray, residual: np.ndarray, isolated: np.ndarray | None = None
    ) -> Detection | None:
        """Add residual rows (n, wheels + 3 rates) of the segment that started at ``segment_start_ns`` (and the
        onboard isolation flags (n, wheels) of those rows); the detection if the test fails on one of them or a
        flag rises (once: the detector latches until :meth:`rearm`)."""
        rise = self._isolation(t_ns, isolated)
        if segment_start_ns != self._segment_ns:
            self._segment_ns, self._t, self._r = segment_start_ns, np.empty(0, np.int64), self._r[:, :0]
        self._t = np.concatenate([self._t, t_ns])
        self._r = np.concatenate([self._r, residual.T], axis=1)
        if self._t.size < 2:
            return None
        self._dt_s = float(np.median(np.diff(self._t))) / NS_PER_S
        if self.fired is not None:
            return None
        if rise is not None:
            self.fired = rise
            return rise
        nw, q = self._n_wheels, self._quantum or WHEEL_COUNT_FALLBACK_RAD_S
        wheel = self._test(
            self._r[:nw], WHEEL_WALK_COUNTS_PER_SQRT_S * q, 0.0, self._quantum, WHEEL_DRIFT_COUNTS_PER_S * q
        )
        rate = self._test(self._r[nw:], 0.0, RATE_NOISE_RAD_S, 0.0, 0.0)
        hits = [(a.index, a.channel + offset, a) for a, offset in ((wheel, 0), (rate, nw)) if a is not None]
        if not hits:
            return None
        index, channel, alarm = min(hits, key=lambda h: h[0])
        self.fired = Detection(int(self._t[index]), self.channels[channel], alarm.window * self._dt_s, alarm.ratio)
        return self.fired

    def _isolation(self, t_ns: np.ndarray, isolated: np.ndarray | None) -> Detection | None:
        """The first row where a wheel's onboard isolation flag rises, as a detection."""
        if isolated is None or isolated.size == 0:
            return None
        flags = np.asarray(isolated) != 0
        before = np.concatenate([self._isolated[None, :] if self._isolated is not None else flags[:1], flags[:-1]])
        self._isolated = flags[-1]
        rows, wheels = np.nonzero(flags & ~before)
        if rows.size == 0:
            return None
        return Detection(int(t_ns[rows[0]]), f"wheel {wheels[0] + 1} isolated onboard", None, None)

    def _test(self, r: np.ndarray, walk: float, white: float, quantum: float, drift: float) -> fd.Alarm | None:
        """:func:`sim_core.fault_detection.window_alarm` on channels of one kind: walk σ per √s, white σ, rounding
        quantum, drift bound per s."""
        if r.shape[0] == 0:
            return None
        dt, n = float(self._dt_s or 1.0), r.shape[1]
        q_var = np.full((r.shape[0], n - 1), walk**2 * dt)
        r_var = np.full(r.shape, white**2)
        relative = np.full((r.shape[0], n - 1), drift * dt)
        return fd.window_alarm(r, q_var, r_var, quantum, dt, windows_s=WINDOWS_S, relative=relative)

    def rearm(self) -> None:
        """Let the detector fire again (some time after its last detection)."""
        self.fired = None
