"""The shared playback clock: replay advances by wall time × speed and stops at the end, live
follow sits on the newest data (which grows), seeks clamp into the span, speeds outside ×1…×1000
are refused."""

from __future__ import annotations

import pytest

from frontend.playback import SPEEDS, PlaybackClock


class GrowingSpan:
    def __init__(self) -> None:
        self.end = 1000.0

    def __call__(self) -> tuple[float, float]:
        return 100.0, self.end


def test_replay_advances_by_wall_time_times_speed_and_stops_at_the_end():
    clock = PlaybackClock(GrowingSpan(), speed=100.0)
    assert clock.t_unix_s == 100.0
    clock.advance(1.0)
    assert clock.t_unix_s == 100.0  # paused
    clock.play()
    assert clock.advance(0.5) == pytest.approx(150.0)
    clock.advance(100.0)
    assert clock.t_unix_s == 1000.0 and not clock.playing


def test_play_at_the_end_restarts_from_the_beginning():
    clock = PlaybackClock(GrowingSpan(), speed=1000.0)
    clock.seek(1000.0)
    clock.play()
    assert clock.t_unix_s == 100.0


def test_live_follow_tracks_the_growing_end_and_a_seek_leaves_it():
    span = GrowingSpan()
    clock = PlaybackClock(span)
    clock.follow_live()
    assert clock.advance(0.0) == 1000.0
    span.end = 1234.5
    assert clock.advance(0.03) == 1234.5
    clock.seek(500.0)
    assert not clock.live and clock.advance(1.0) == 500.0


def test_seek_clamps_into_the_span():
    clock = PlaybackClock(GrowingSpan())
    clock.seek(-5.0)
    assert clock.t_unix_s == 100.0
    clock.seek(1e9)
    assert clock.t_unix_s == 1000.0


@pytest.mark.parametrize("speed", [0.5, 2000.0])
def test_speed_outside_the_range_names_the_field(speed):
    with pytest.raises(ValueError, match="speed"):
        PlaybackClock(GrowingSpan()).set_speed(speed)


def test_speed_range_is_one_to_one_thousand():
    assert SPEEDS[0] == 1.0 and SPEEDS[-1] == 1000.0
