"""Diagnostics levels by the rules a user reads in runtime/health.py."""

from motion_style_ros.runtime.health import ERROR, OK, WARN, health


def counts(frames_in, frames_out, dropped=0, **restarts):
    return {"frames_in": frames_in, "frames_out": frames_out, "dropped": dropped,
            "restarted_new_timeline": 0, "restarted_non_finite_output": 0, **restarts}


def test_levels():
    start = counts(0, 0)
    assert health(start, counts(120, 120), 1.0, 120.0, 2.0, 20.0) == (OK, [])
    assert health(start, counts(0, 0), 1.0, 120.0, 0.0, 20.0) == (WARN, ["no input"])
    level, reasons = health(start, counts(60, 58, dropped=2), 1.0, 120.0, 30.0, 20.0)
    assert level == WARN and reasons == ["input at 60.0 Hz, nominal 120 Hz", "2 dropped",
                                         "latency p99 30.0 ms over 20 ms"]
    assert health(start, counts(30, 0, dropped=30), 1.0, 30.0, 0.0, 20.0)[0] == ERROR
    assert health(start, counts(30, 29, restarted_non_finite_output=1), 1.0, 30.0, 0.0, 20.0)[0] == ERROR
    level, reasons = health(counts(30, 30), counts(60, 52, dropped=8, restarted_new_timeline=1), 1.0,
                            30.0, 0.0, 20.0)
    assert level == WARN and reasons == ["8 dropped", "restarted on a new clock or place"]
