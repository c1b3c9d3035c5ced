"""Faults with real processes: the performer killed and started again mid-stream (the stylizer
goes on by itself), the stylizer killed and started again (the recorder's bag stays whole and
readable, the performer goes on), a stream whose rate changes between 30, 60 and 120 Hz, and a node
whose teardown never returns."""

import signal
import subprocess
import sys
import time

import numpy as np
import pytest
from diagnostic_msgs.msg import DiagnosticArray
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
from ros_helpers import Listener, message, stamps, start_node, stop
from sensor_msgs.msg import JointState

from motion_style_ros.core.synthetic import synthetic_motion
from motion_style_ros.io import bags
from motion_style_ros.io.joint_state import JointStateLayout
from motion_style_ros.nodes.process import TEARDOWN_SECONDS

RELIABLE = QoSProfile(history=HistoryPolicy.KEEP_ALL, reliability=ReliabilityPolicy.RELIABLE)
LAYOUT = JointStateLayout.canonical()


@pytest.fixture(scope="module")
def model(small_model):
    return small_model


def kill(proc):
    proc.send_signal(signal.SIGKILL)
    proc.wait(20)


def test_the_stylizer_resumes_by_itself_when_its_performer_restarts(model, ros_env, tmp_path):
    stylizer = start_node("stylizer", ros_env, log=tmp_path / "stylizer.log", model=model, input_fps=60.0)
    performer = start_node("synthetic_performer", ros_env, log=tmp_path / "performer.log", fps=60)
    listener = Listener("fault_performer")
    try:
        out = listener.subscribe("stylized/joint_states")
        diagnostics = listener.subscribe("/diagnostics", DiagnosticArray, RELIABLE)
        listener.spin_until(lambda: len(out) > 60, "a second of stylized frames", procs=[stylizer])
        kill(performer)
        listener.spin_for(1.0)
        before = len(out)
        performer = start_node("synthetic_performer", ros_env, log=tmp_path / "performer2.log", fps=60)
        # its walk starts again at the origin, after a pause longer than the session's gap time
        listener.spin_until(lambda: len(out) > before + 60, "stylized frames of the new performer",
                            procs=[stylizer])
        assert stylizer.poll() is None
        listener.spin_for(1.2)
        values = {kv.key: kv.value for kv in diagnostics[-1].status[0].values}
        assert int(values["gaps"]) >= 1 and float(values["longest_gap_s"]) >= 1.0  # the pause, seen
    finally:
        listener.close()
        for proc in (performer, stylizer):
            stop(proc)


def test_a_killed_stylizer_leaves_the_recording_whole_and_starts_again(model, ros_env, tmp_path):
    bag = tmp_path / "bag"
    performer = start_node("synthetic_performer", ros_env, log=tmp_path / "performer.log", fps=60)
    recorder = start_node("recorder", ros_env, log=tmp_path / "recorder.log", bag=str(bag),
                          topics=["joint_states", "stylized/joint_states"])
    stylizer = start_node("stylizer", ros_env, log=tmp_path / "stylizer.log", model=model, input_fps=60.0)
    listener = Listener("fault_stylizer")
    try:
        inputs = listener.subscribe("joint_states")
        out = listener.subscribe("stylized/joint_states")
        listener.spin_until(lambda: len(out) > 60, "stylized frames", procs=[stylizer, recorder])
        kill(stylizer)
        listener.spin_for(0.5)
        before = len(out)
        stylizer = start_node("stylizer", ros_env, log=tmp_path / "stylizer2.log", model=model, input_fps=60.0)
        listener.spin_until(lambda: len(out) > before + 60, "stylized frames after the restart",
                            procs=[stylizer, recorder])
        received = len(inputs)
        assert performer.poll() is None and recorder.poll() is None
    finally:
        listener.close()
        for proc in (stylizer, recorder, performer):
            stop(proc)
    recorded = bags.read_joint_states(bag, ["/joint_states"])
    styled = bags.read_joint_states(bag, ["/stylized/joint_states"])
    # the performer never stopped: the recorder has its stream throughout (best effort, loopback)
    assert len(recorded) >= 0.9 * received and len(styled) > 60  # discovery of a new publisher takes a moment
    steps = np.diff(np.array([r.stamp_ns for r in recorded]))
    assert steps.max() < 0.2e9  # no hole in the input's recording while the stylizer was down


def test_a_stream_switching_between_30_60_and_120_hz_is_stylized_throughout(model, ros_env, tmp_path):
    stylizer = start_node("stylizer", ros_env, log=tmp_path / "stylizer.log", model=model, input_fps=60.0,
                          qos_reliability="reliable", qos_depth=1000)
    listener = Listener("fault_rates")
    try:
        publisher = listener.node.create_publisher(JointState, "joint_states", RELIABLE)
        out = listener.subscribe("stylized/joint_states", qos=RELIABLE)
        listener.spin_until(lambda: publisher.get_subscription_count(), "the stylizer", procs=[stylizer])
        t0, sent = 1_700_000_000 * 10**9, []
        t = 0.0
        for rate in (30.0, 120.0, 60.0, 30.0, 120.0):  # one second each, the walk going on
            motion = synthetic_motion("walk", rate, 1.0, start=t)
            for k, values in enumerate(LAYOUT.encode_motion(motion)):
                sent.append(t0 + round((t + k / rate) * 1e9))
                publisher.publish(message(sent[-1], LAYOUT.names, values))
            t += 1.0
        listener.spin_until(lambda: len(out) >= len(sent), "every frame stylized", procs=[stylizer])
        assert stamps(out).tolist() == sent
        assert np.isfinite(np.array([m.position for m in out])).all()
    finally:
        listener.close()
        stop(stylizer)


STUCK_TEARDOWN = """
import sys, time
from motion_style_ros.nodes.process import run
from motion_style_ros.nodes.synthetic_performer import SyntheticPerformer

class Stuck(SyntheticPerformer):
    def destroy_node(self):
        print("tearing down", file=sys.stderr, flush=True)
        time.sleep(120)  # a teardown that never returns

sys.exit(run(Stuck, "stuck_performer"))
"""


def test_a_node_whose_teardown_hangs_after_ctrl_c_says_where_and_exits_1(ros_env):
    """One Ctrl-C asks the node to stop; its teardown then never returns. Within the watchdog's
    time (under launch's 5 s before SIGTERM) it writes its threads' stacks and exits with 1."""
    proc = subprocess.Popen([sys.executable, "-c", STUCK_TEARDOWN, "--ros-args", "-r", "__ns:=/stuck"],
                            env=ros_env, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                            stderr=subprocess.PIPE, text=True)
    try:
        assert "performing a synthetic walk" in proc.stderr.readline()  # built
        time.sleep(1.0)  # spinning (a signal while it is built interrupts at once, another path)
        proc.send_signal(signal.SIGINT)
        start = time.monotonic()
        err = proc.stderr.read()
        code = proc.wait(30)
        took = time.monotonic() - start
    finally:
        if proc.poll() is None:
            kill(proc)
    assert code == 1, err
    assert TEARDOWN_SECONDS <= took < TEARDOWN_SECONDS + 4, took
    assert err.startswith("tearing down") and "Timeout" in err, err
    assert "in destroy_node" in err and "in _run" in err, err  # where it was stuck
