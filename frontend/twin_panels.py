"""The control panel of one monitor viewer (one browser client): playback (time, timeline, play/pause, speed,
live follow), replay of a past window of the archive, camera presets, and the operator panels — attitude error
(actual − simulated), wheel speeds, MD moment, mode and fault flags, active alarms (seed 000 §7 in-flight support).
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from datetime import UTC, datetime
from typing import TYPE_CHECKING, Generic, TypeVar

import numpy as np

from frontend.feed import NOMINAL_LABEL, FeedWindow
from frontend.globe import EARTH_CREDIT
from frontend.playback import SPEEDS, PlaybackClock
from frontend.twin_geometry import TwinFrame

if TYPE_CHECKING:
    import viser

__all__ = [
    "TwinPanels",
    "ClockMirror",
    "CAMERA_PRESETS",
    "PLOT_WINDOW_S",
    "REPLAY_LENGTHS_MIN",
    "format_utc",
    "parse_utc",
]

CAMERA_PRESETS = ("whole Earth", "chase", "line of sight")
PLOT_WINDOW_S = 300.0
RPM_PER_RAD_S = 30.0 / np.pi
ARCSEC_PER_RAD = 180.0 / np.pi * 3600.0
WHEEL_COLOURS = ("#e6194b", "#3cb44b", "#4363d8", "#f58231", "#911eb4", "#46f0f0")
MD_COLOURS = ("#e6194b", "#3cb44b", "#4363d8")
REPLAY_LENGTHS_MIN = ("5", "10", "30", "60", "120")  # replay window lengths offered (minutes)

T = TypeVar("T")


def _simulated_markdown(label: str) -> str:
    return f"simulated: **{label}**"


def format_utc(t_unix_s: float) -> str:
    """ISO-8601 UTC with milliseconds, as the panels show time."""
    return datetime.fromtimestamp(t_unix_s, tz=UTC).isoformat(timespec="milliseconds").replace("+00:00", "Z")


def parse_utc(text: str) -> float:
    """UTC seconds since the Unix epoch of an ISO-8601 instant ('Z' or an offset; naive means UTC)."""
    try:
        t = datetime.fromisoformat(text.strip().replace("Z", "+00:00"))
    except ValueError:
        raise ValueError(f"from: {text!r} is not an ISO-8601 UTC instant (e.g. 2026-03-20T00:05:00Z)") from None
    return (t if t.tzinfo else t.replace(tzinfo=UTC)).timestamp()


def _plot_scales() -> dict:
    """Plain seconds on x (not epoch time) over a fixed sliding window ending now."""
    return {"x": {"time": False, "range": [-PLOT_WINDOW_S, 0.0]}}


def _axes() -> tuple[dict, dict]:
    """x axis as is; a wide y axis so that values like 20,000 are not clipped."""
    return ({}, {"size": 64})


def _empty(n_series: int) -> tuple[np.ndarray, ...]:
    """Initial plot data spanning the window: viser keeps the relative x zoom, a zero span breaks it."""
    return (np.array([-PLOT_WINDOW_S, 0.0]),) + tuple(np.zeros(2) for _ in range(n_series))


def _set_plot(plot: viser.GuiUplotHandle, data: tuple[np.ndarray, ...]) -> None:
    """Send a plot's data unless the client already holds the same values (viser resends a tuple of arrays on every
    assignment, equal or not: a paused view would get its three plots again at every panel update)."""
    held = plot.data
    if len(held) == len(data) and all(np.array_equal(a, b, equal_nan=True) for a, b in zip(held, data, strict=True)):
        return
    plot.data = data


class ClockMirror(Generic[T]):
    """A control that shows a state of the viewer's clock and that the operator sets (the timeline, the speed, the
    Live follow box): :meth:`show` puts the clock's state on it every frame, the control's callback hands the
    operator's value to ``apply``.

    viser sets an operator's value on the handle (its event loop) before it runs the handle's callback (its thread
    pool): a frame in between must not put the clock's state back, or it reverts the operator's change in the
    browser and the callback then reads the reverted value (the change is lost). So a frame leaves the control alone
    while it holds a value that its callback has not applied yet (the handle differs from what was last shown or
    applied), and puts the clock's state on it only when that state has changed since the last frame: the
    timeline moves with the clock's advance but not over the operator's drag, and a box the operator ticked is not
    unticked by a frame between its callback and the clock following it (a window swapped back to live follow at
    the next render). A frame may still overwrite a value viser sets within the few instructions between its check
    and its write (viser takes none of our locks): the browser then shows the clock's state again (consistent, the
    change lost)."""

    def __init__(self, handle: viser.GuiInputHandle[T], apply: Callable[[T], None]) -> None:
        self.handle, self._apply = handle, apply
        self._lock = threading.Lock()  # a callback (any of viser's pool threads) against the render thread's frame
        self._shown = self._clock = handle.value  # last put on the control or applied from it; the clock's state

        @handle.on_update
        def _(event) -> None:
            if event.client is None:  # our own show() (viser calls the callbacks of a server-side assignment too)
                return
            with self._lock:  # callbacks in order: each applies the newest value the operator left
                value = self.handle.value
                try:
                    self._apply(value)
                finally:  # a refused value too: the control follows the clock again at its next change
                    self._shown = value

    def show(self, clock_state: T) -> None:
        """Put the clock's state on the control (every frame), unless the operator's change is still on its way to
        the clock or the clock has not moved since the last frame."""
        with self._lock:
            if self.handle.value != self._shown or clock_state == self._clock:
                return
            self._clock = self.handle.value = self._shown = clock_state


class TwinPanels:
    """GUI of one browser client (``target`` is its viser ClientHandle, or a server for a shared panel), bound to
    the viewer's own clock; the camera preset and the replay window are this client's alone."""

    def __init__(
        self,
        target: viser.ClientHandle | viser.ViserServer,
        role: str,
        clock: PlaybackClock,
        n_wheels: int,
        archive_span: Callable[[], tuple[float, float] | None] | None = None,
        on_live: Callable[[bool], None] | None = None,
        on_window: Callable[[float, float], None] | None = None,
        on_link: Callable[[bool], None] | None = None,
    ) -> None:
        self.target, self.role, self.clock = target, role, clock
        self.camera_preset: str | None = None
        self._archive_span, self._on_live, self._on_window, self._on_link = archive_span, on_live, on_window, on_link
        self._lock = threading.Lock()
        gui = target.gui
        gui.configure_theme(
            show_share_button=False, dark_mode=True, control_width="large", titlebar_content=None, show_logo=False
        )
        gui.add_markdown(f"**acs-twin — {role} monitor**")
        self.banner = gui.add_markdown("")  # STALE warning at the top, where the eye is (show_window)
        self.simulated_label = NOMINAL_LABEL
        self.simulated_text = gui.add_markdown(_simulated_markdown(NOMINAL_LABEL))  # what the simulated side flies
        t0, t1 = clock.span_unix_s()
        with gui.add_folder("Playback"):
            self.time_text = gui.add_text("UTC", initial_value=format_utc(clock.t_unix_s), disabled=True)
            self.slider = gui.add_slider(
                "Timeline (s)", min=0.0, max=max(t1 - t0, 1.0), step=0.25, initial_value=clock.t_unix_s - t0
            )
            self.play = gui.add_button_group("Replay", ("play", "pause"))
            self.speed = gui.add_dropdown("Speed", tuple(f"x{s:g}" for s in SPEEDS), initial_value=f"x{clock.speed:g}")
            self.live = gui.add_checkbox("Live follow", initial_value=clock.live)
            self.link = (
                gui.add_checkbox(
                    "Link viewers",
                    initial_value=False,
                    hint="move together with the other viewers that tick it (e.g. actual and simulated monitors)",
                )
                if on_link is not None
                else None
            )
            self.camera = gui.add_button_group("Camera", CAMERA_PRESETS)
        self.window_from = self.window_length = self.window_load = None
        with gui.add_folder("Replay a past window"):
            self.archive_text = gui.add_markdown(self._archive_note())
            if on_window is not None:
                span = archive_span() if archive_span is not None else None
                self.window_from = gui.add_text("From (UTC)", initial_value=format_utc(span[0] if span else t0))
                self.window_length = gui.add_dropdown("Length (min)", REPLAY_LENGTHS_MIN, initial_value="10")
                self.window_load = gui.add_button("Load window")
            self.window_status = gui.add_markdown("live" if clock.live else "—")
        with gui.add_folder("Attitude error (actual − simulated)"):
            self.error_plot = gui.add_uplot(
                data=_empty(1),
                series=({"label": "t − now (s)"}, {"label": "error (arcsec)", "stroke": "#ff5050"}),
                scales=_plot_scales(),
                axes=_axes(),
                aspect=2.0,
            )
        with gui.add_folder("Wheel speeds (rpm)", expand_by_default=False):
            self.wheel_source = gui.add_markdown("telemetry")  # the simulated monitor plots the twin's when it flies
            self.wheel_plot = gui.add_uplot(
                data=_empty(n_wheels),
                series=({"label": "t − now (s)"},)
                + tuple(
                    {"label": f"RW{k + 1}", "stroke": WHEEL_COLOURS[k % len(WHEEL_COLOURS)]} for k in range(n_wheels)
                ),
                scales=_plot_scales(),
                axes=_axes(),
                aspect=2.0,
            )
        with gui.add_folder("MD moment (A·m²)", expand_by_default=False):
            self.md_plot = gui.add_uplot(
                data=_empty(3),
                series=({"label": "t − now (s)"},)
                + tuple({"label": f"m{'xyz'[k]}", "stroke": MD_COLOURS[k]} for k in range(3)),
                scales=_plot_scales(),
                axes=_axes(),
                aspect=2.0,
            )
        with gui.add_folder("Mode and flags"):
            self.flags = gui.add_markdown("—")
            self.image_motion = gui.add_markdown("—")
        with gui.add_folder("Active alarms"):
            self.alarms = gui.add_markdown("none")
        gui.add_markdown(f"<small>{EARTH_CREDIT}</small>")
        self._wire()

    def _archive_note(self) -> str:
        span = self._archive_span() if self._archive_span is not None else None
        if span is None:
            return "no archive to replay from" if self._on_window is None else "archive: no telemetry yet"
        return f"archive holds {format_utc(span[0])} … {format_utc(span[1])}"

    def _wire(self) -> None:  # self.clock, not a copy: linking viewers swaps it
        self._timeline = ClockMirror(self.slider, lambda v: self.clock.seek(self.clock.span_unix_s()[0] + float(v)))
        self._speed = ClockMirror(self.speed, lambda v: self.clock.set_speed(float(v[1:])))
        self._live = ClockMirror(self.live, self._follow_live)

        @self.play.on_click
        def _(event) -> None:
            if self.play.value == "play":
                self.clock.play()
            else:
                self.clock.pause()

        if self.link is not None:

            @self.link.on_update
            def _(event) -> None:
                if event.client is not None and self._on_link is not None:
                    self._on_link(bool(self.link.value))

        @self.camera.on_click
        def _(event) -> None:
            if event.client is not None:
                with self._lock:
                    self.camera_preset = self.camera.value

        if self.window_load is not None:

            @self.window_load.on_click
            def _(event) -> None:
                self.load_window()

    def _follow_live(self, on: bool) -> None:
        if self._on_live is not None:
            self._on_live(on)
        else:
            self.clock.follow_live(on)

    def load_window(self) -> None:
        """Ask for the window the panel's From and Length name (what the Load button does)."""
        assert self.window_from is not None and self.window_length is not None and self._on_window is not None
        try:
            t0 = parse_utc(self.window_from.value)
        except ValueError as exc:
            self.show_window_status(f"not loaded: {exc}")
            return
        self._on_window(t0, t0 + 60.0 * float(self.window_length.value))

    def show_simulated(self, label: str) -> None:
        """Name what the simulated side flies (the nominal twin, or a diagnosed hypothesis)."""
        self.simulated_label = label
        self.simulated_text.content = _simulated_markdown(label)

    def show_window_status(self, text: str) -> None:
        """What the replay-window part says (loading, replaying which window, an error)."""
        self.window_status.content = text

    def take_preset(self) -> str | None:
        """The camera preset this client asked for (kept for the chase and line-of-sight views that move on)."""
        with self._lock:
            preset = self.camera_preset
            if preset == "whole Earth":
                self.camera_preset = None
            return preset

    def show_time(self, f: TwinFrame) -> None:
        """Time, timeline and control states, every frame (cheap: unchanged values are not sent; the controls the
        operator sets as :class:`ClockMirror`)."""
        t0, t1 = self.clock.span_unix_s()
        self.time_text.value = format_utc(f.t_unix_s)
        self.slider.max = max(t1 - t0, 1.0)
        self._timeline.show(float(np.round((f.t_unix_s - t0) * 4.0) / 4.0))
        self._speed.show(f"x{self.clock.speed:g}")
        self._live.show(self.clock.live)

    def show_window(self, t_unix_s: float, w: FeedWindow, alarms: list[str], image_motion_rad_s: np.ndarray) -> None:
        """Plots of the last PLOT_WINDOW_S, mode/flags, image motion, alarms and the archive's span (a few times
        per second)."""
        self.archive_text.content = self._archive_note()
        stale = [a for a in alarms if a.startswith("STALE")]
        self.banner.content = f"### ⚠ {stale[0]}: the view is not live" if stale else ""
        along, across = np.asarray(image_motion_rad_s) * 1e3
        self.image_motion.content = (
            "image motion at the boresight: off the Earth"
            if np.isnan(along)
            else f"image motion at the boresight: along {along:+.2f}, across {across:+.2f} mrad/s"
        )
        x = w.t_unix_s - t_unix_s
        if x.size >= 2:
            _set_plot(self.error_plot, (x, w.error_angle_rad * ARCSEC_PER_RAD))
            wheels, source = w.wheel_speed_rad_s, "telemetry"
            if self.role == "simulated" and w.wheel_speed_simulated_rad_s is not None:
                wheels, source = w.wheel_speed_simulated_rad_s, f"simulated: {self.simulated_label}"
            self.wheel_source.content = source
            _set_plot(self.wheel_plot, (x,) + tuple(wheels[:, k] * RPM_PER_RAD_S for k in range(wheels.shape[1])))
            _set_plot(self.md_plot, (x,) + tuple(w.md_dipole_am2[:, k] for k in range(3)))
        if x.size:
            self.flags.content = (
                f"mode **{int(w.mode[-1])}** · fault flags **0x{int(w.fault_flags[-1]):04x}** · "
                f"{'**scanning**' if w.observing[-1] else 'not scanning'} · "
                f"error **{w.error_angle_rad[-1] * ARCSEC_PER_RAD:.1f}″**"
            )
        self.alarms.content = "\n".join(f"- {a}" for a in alarms) if alarms else "none"
