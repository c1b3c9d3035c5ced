"""The live intake: one corrupt stamp or value is dropped with its own reason and the next good
frame goes on; a stream that moves to a new clock or place restarts on it by itself; unstamped
frames never invalidate stamped ones; gaps are counted."""

import numpy as np
import pytest

from motion_style_ros.errors import MotionStyleError
from motion_style_ros.runtime.intake import Bounds, Dropped, Intake

PERIOD = 33_333_333  # ns, 30 Hz
T0 = 1_700_000_000 * 10**9
DAY = 86_400 * 10**9


def walk(k):
    return np.array([0.0, 0.9, 1.2 * k * PERIOD * 1e-9])  # 1.2 m/s


class Stream:
    """Feeds an intake frames ``k`` stamped ``T0 + k * PERIOD`` arriving 1 ms later
    (or as given), committing what it admits; records what happened to each."""

    def __init__(self, bounds=Bounds()):
        self.intake = Intake(bounds, PERIOD * 1e-9)
        self.log = []

    def send(self, k, stamp=None, receipt=None, root=None):
        stamp = T0 + k * PERIOD if stamp is None else stamp
        receipt = T0 + k * PERIOD + 10**6 if receipt is None else receipt  # 1 ms on the way
        try:
            frame = self.intake.admit(stamp, receipt, walk(k) if root is None else root)
        except Dropped as drop:
            self.log.append(drop.reason)
            return None
        self.intake.commit(frame, stamp)
        self.log.append("restart" if frame.restart else "ok")
        return frame


def test_a_stamp_a_day_ahead_is_dropped_and_the_next_good_frame_goes_on():
    s = Stream()
    for k in range(10):
        s.send(k)
    s.send(10, stamp=T0 + 10 * PERIOD + DAY)
    for k in range(10, 20):
        s.send(k)
    assert s.log == ["ok"] * 10 + ["stamp_jump"] + ["ok"] * 10


def test_a_first_frame_ahead_of_its_arrival_is_a_future_stamp():
    s = Stream()
    s.send(0, stamp=10**9 + DAY, receipt=10**9)
    s.send(1, stamp=10**9 + PERIOD, receipt=10**9 + PERIOD)
    assert s.log == ["future_stamp", "ok"]


def test_a_clock_reset_restarts_the_stream_after_restart_seconds():
    s = Stream()
    for k in range(30):
        s.send(k)
    # the publisher's clock starts again at 0; frames keep arriving at the same pace
    for k in range(30, 60):
        s.send(k, stamp=(k - 30 + 1) * PERIOD)
    dropped = s.log[30:].index("restart")
    assert s.log[30:30 + dropped] == ["out_of_order"] * dropped
    assert 0.25 <= dropped * PERIOD * 1e-9 <= 0.25 + 2 * PERIOD * 1e-9  # restart_seconds
    assert s.log[30 + dropped + 1:] == ["ok"] * (30 - dropped - 1)


def test_a_mocap_clock_ahead_for_good_is_followed_after_restart_seconds():
    s = Stream()
    for k in range(20):
        s.send(k, stamp=T0 + k * PERIOD, receipt=T0 - 30 * 10**9 + k * PERIOD)
    assert s.log[:8] == ["future_stamp"] * 8 and s.log[8] == "restart" and set(s.log[9:]) == {"ok"}


def test_huge_and_fast_roots_are_dropped_but_a_teleport_that_stays_restarts():
    s = Stream()
    for k in range(5):
        s.send(k)
    s.send(5, root=np.array([1e30, 0.0, 0.0]))
    s.send(5, root=walk(5) + 5.0)  # 8.7 m in one frame
    s.send(5)
    assert s.log[5:] == ["implausible_root", "implausible_speed", "ok"]
    for k in range(6, 30):  # now it stays 5 m away
        s.send(k, root=walk(k) + 5.0)
    assert s.log[8:16] == ["implausible_speed"] * 8 and s.log[16] == "restart"  # 0.27 s on


def test_an_unstamped_frame_never_invalidates_the_stamped_one_after_it():
    s = Stream()
    s.send(0)
    unstamped = s.send(1, stamp=0)  # stamped on the stream's clock: one period on
    assert unstamped.stamp_ns == T0 + PERIOD and not unstamped.own_stamp
    late = s.send(2, stamp=T0 + PERIOD - 1000)  # its own stamp lags the made-up one
    assert late is not None and late.stamp_ns > unstamped.stamp_ns
    assert s.send(3) is not None and s.log == ["ok"] * 4
    first = Stream()  # an unstamped first frame is taken at its arrival
    assert first.send(0, stamp=0, receipt=123).stamp_ns == 123


def test_bag_replays_at_any_rate_and_pauses_pass_but_gaps_are_counted():
    fast = Stream()
    for k in range(300):  # 10x: stamps run ahead of arrival by 0.9 periods a frame
        fast.send(k, receipt=T0 + k * PERIOD // 10)
    assert set(fast.log) == {"ok"}
    paused = Stream()
    for k in list(range(10)) + list(range(100, 110)):  # 3 s pause, in stamps and in arrival
        paused.send(k)
    assert set(paused.log) == {"ok"}
    assert paused.intake.gaps == 1 and paused.intake.frames_missing == 90
    assert paused.intake.longest_gap_s == pytest.approx(91 * PERIOD * 1e-9)


def test_duplicates_and_angles():
    s = Stream()
    s.send(0)
    s.send(0)
    assert s.log == ["ok", "duplicate_stamp"]
    with pytest.raises(Dropped, match=r"angles beyond \+-10000 rad for \['a'\]"):
        s.intake.check_angles(np.array([1e5, 0.1]), ["a", "b"])
    with pytest.raises(Dropped, match="NaN or infinite positions for"):
        s.intake.check_values(["a"], [np.nan])


@pytest.mark.parametrize("field", ["max_stamp_jump", "restart_seconds", "max_root_speed"])
def test_bounds_must_be_positive(field):
    with pytest.raises(MotionStyleError, match=f"{field} must be a positive number"):
        Bounds(**{field: 0.0})
