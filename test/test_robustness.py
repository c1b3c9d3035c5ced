"""The bad-input campaign against a real stylizer process: every kind of bad JointState is sent
between good frames. The node never crashes, never publishes a non-finite value, counts every bad
frame by its reason, and stylizes the good frame right after each bad one."""

import numpy as np
from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
from ros_helpers import Listener, message, stamps, start_node, stop
from sensor_msgs.msg import JointState

from motion_style_ros.core.synthetic import synthetic_motion
from motion_style_ros.io.joint_state import JointStateLayout

RELIABLE = QoSProfile(history=HistoryPolicy.KEEP_ALL, reliability=ReliabilityPolicy.RELIABLE)
LAYOUT = JointStateLayout.canonical()
NAMES = LAYOUT.names
T0 = 1_700_000_000 * 10**9
PERIOD = 33_333_333
DAY = 86_400 * 10**9


def bad_frames(stamp, values, previous):
    """(reason it must be dropped for, or None if it must be stylized; the message) per kind."""
    def msg(names=NAMES, positions=values, at=stamp):
        return message(at, list(names), np.asarray(positions, dtype=float))

    def with_(index, value):
        v = values.copy()
        v[index] = value
        return v

    garbage = msg()
    garbage.velocity, garbage.effort = [float("nan")] * 3, [1e300]  # unused fields: ignored
    negative = msg()
    negative.header.stamp = Time(sec=-5, nanosec=0)
    return [
        ("mismatched_lengths", msg(positions=values[:-1])),
        ("mismatched_lengths", msg(positions=np.append(values, 0.0))),
        ("mismatched_lengths", msg(positions=[])),
        ("non_finite", msg(positions=with_(7, np.nan))),
        ("non_finite", msg(positions=with_(0, np.inf))),
        ("non_finite", msg(positions=with_(40, -np.inf))),
        ("bad_names", msg(names=["spine_rx" if n == "Spine_rx" else n for n in NAMES])),
        ("bad_names", msg(names=NAMES[1:], positions=values[1:])),
        ("bad_names", msg(names=[NAMES[0]] + NAMES[:-1])),  # a duplicate name, one missing
        ("bad_names", msg(names=[], positions=[])),
        ("bad_names", msg(names=["" if k == 5 else n for k, n in enumerate(NAMES)])),
        ("duplicate_stamp", msg(at=previous)),
        ("out_of_order", msg(at=previous - 10 * PERIOD)),
        ("out_of_order", negative),
        ("stamp_jump", msg(at=stamp + DAY)),
        ("stamp_jump", msg(at=stamp + 365 * DAY)),
        ("implausible_angle", msg(positions=np.full_like(values, 1e30))),
        ("implausible_angle", msg(positions=with_(10, 1e6))),
        ("implausible_angle", msg(positions=np.full_like(values, np.finfo(float).max))),
        ("implausible_root", msg(positions=with_(slice(0, 3), 1e30))),
        ("implausible_root", msg(positions=with_(1, 2e5))),
        ("implausible_speed", msg(positions=with_(0, values[0] + 10.0))),
        (None, garbage),
    ]


def test_no_bad_frame_stops_or_poisons_the_stream(small_model, ros_env, tmp_path):
    proc = start_node("stylizer", ros_env, log=tmp_path / "log", model=small_model, input_fps=30.0,
                      qos_reliability="reliable", qos_depth=1000)
    listener = Listener("campaign")
    frames = LAYOUT.encode_motion(synthetic_motion("walk", 30.0, 40.0))
    try:
        publisher = listener.node.create_publisher(JointState, "joint_states", RELIABLE)
        out = listener.subscribe("stylized/joint_states", qos=RELIABLE)
        diagnostics = listener.subscribe("/diagnostics", DiagnosticArray, RELIABLE)
        listener.spin_until(lambda: publisher.get_subscription_count(), "the stylizer", procs=[proc])
        k, expected, accepted = 0, {}, []

        def good():
            nonlocal k
            publisher.publish(message(T0 + k * PERIOD, NAMES, frames[k]))
            accepted.append(T0 + k * PERIOD)
            k += 1

        for _ in range(10):
            good()
        n_kinds = len(bad_frames(T0, frames[0], T0))
        for i in range(n_kinds):  # each bad frame made against the last good one
            reason, bad = bad_frames(T0 + k * PERIOD, frames[k], T0 + (k - 1) * PERIOD)[i]
            publisher.publish(bad)
            if reason is None:
                accepted.append(T0 + k * PERIOD)
                k += 1
            else:
                expected[reason] = expected.get(reason, 0) + 1
            good()  # the next good frame
            n = len(accepted)
            listener.spin_until(lambda: len(out) >= n, f"the good frame after a {reason} frame", procs=[proc])
        listener.spin_for(1.5)
        assert proc.poll() is None  # no crash
        assert stamps(out).tolist() == accepted  # every good frame, and only those, stylized
        assert np.isfinite(np.array([m.position for m in out])).all()
        values = {kv.key: kv.value for kv in diagnostics[-1].status[0].values}
        counted = {k.removeprefix("dropped_"): int(v) for k, v in values.items()
                   if k.startswith("dropped_") and int(v)}
        assert counted == expected and int(values["dropped"]) == sum(expected.values())
        print(f"{n_kinds} kinds of bad frame: {sum(expected.values())} dropped by reason {counted}")
    finally:
        listener.close()
        stop(proc)


def test_no_bad_parameter_value_is_taken_and_each_says_why(small_model, ros_env, tmp_path):
    from rcl_interfaces.srv import SetParameters
    from rclpy.parameter import Parameter

    short = tmp_path / "short.bvh"
    short.write_text("HIERARCHY\nROOT Hips\n{\n}\nMOTION\nFrames: 3\nFrame Time: 0.0333333\n")
    cases = [
        ({"alpha": 1.5}, "out of range"), ({"alpha": -0.1}, "out of range"),
        ({"alpha": "high"}, "alpha must be of type double, got string"),
        ({"alpha": float("nan")}, ""), ({"mix_weight": 2.0}, "out of range"),
        ({"target_style": "sad"}, "unknown style 'sad'; this model knows: active, elderly, normal"),
        ({"target_style": 3}, "target_style must be of type string, got integer"),
        ({"target_style": ""}, "unknown style ''"), ({"mix_style": "nope"}, "('' = no mix)"),
        ({"latent_seed": -1}, "out of range"), ({"latent_seed": 1.5}, "latent_seed must be of type integer"),
        ({"seed_spread": 9.0}, "out of range"), ({"reference": str(short)}, "needs backend stgcn"),
        ({"frame_id": 7}, "frame_id must be of type string"), ({"model": "other.onnx"}, "read-only"),
        ({"backend": "stgcn"}, "read-only"), ({"performers": ["x"]}, "read-only"),
        ({"input_fps": 60.0}, "read-only"), ({"alpha": True}, "alpha must be of type double, got bool"),
        ({"blend_seconds": 1.0}, "read-only"),
    ]
    proc = start_node("stylizer", ros_env, log=tmp_path / "log", model=small_model, input_fps=30.0,
                      qos_reliability="reliable", qos_depth=1000)
    listener = Listener("campaign_parameters")
    frames = LAYOUT.encode_motion(synthetic_motion("walk", 30.0, 10.0))
    try:
        client = listener.node.create_client(SetParameters, "/stylizer/set_parameters")
        publisher = listener.node.create_publisher(JointState, "joint_states", RELIABLE)
        out = listener.subscribe("stylized/joint_states", qos=RELIABLE)
        listener.spin_until(lambda: publisher.get_subscription_count(), "the stylizer", procs=[proc])
        for k, (values, reason) in enumerate(cases):
            request = SetParameters.Request(
                parameters=[Parameter(n, value=v).to_parameter_msg() for n, v in values.items()])
            (result,) = listener.call(client, request, procs=[proc]).results
            assert not result.successful and reason in result.reason, (values, result.reason)
            publisher.publish(message(T0 + k * PERIOD, NAMES, frames[k]))  # the stream goes on
            listener.spin_until(lambda: len(out) > k, f"the frame after {values}", procs=[proc])
        assert proc.poll() is None and np.isfinite(np.array([m.position for m in out])).all()
    finally:
        listener.close()
        stop(proc)
