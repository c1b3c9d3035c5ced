"""The managed stylizer as a real process: every lifecycle transition through the real
lifecycle services, and what the node does in each state (nothing published unless active)."""

import pytest
from lifecycle_msgs.msg import State, Transition
from lifecycle_msgs.srv import ChangeState, GetState
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
from ros_helpers import Listener, message, start_node, stop
from sensor_msgs.msg import JointState

from motion_style_ros.core.synthetic import synthetic_motion
from motion_style_ros.io.joint_state import JointStateLayout

RELIABLE = QoSProfile(history=HistoryPolicy.KEEP_ALL, reliability=ReliabilityPolicy.RELIABLE)
LAYOUT = JointStateLayout.canonical()
T0 = 1_700_000_000 * 10**9
PERIOD = 33_333_333


@pytest.fixture(scope="module")
def model(small_model):
    return small_model


def test_lifecycle_transitions_with_a_real_process(model, ros_env, tmp_path):
    proc = start_node("stylizer_managed", ros_env, log=tmp_path / "log", model=model, input_fps=30.0,
                      qos_reliability="reliable", qos_depth=100)
    listener = Listener("lifecycle_test")
    frames = LAYOUT.encode_motion(synthetic_motion("walk", 30.0, 10.0))
    sent = [0]
    try:
        change = listener.node.create_client(ChangeState, "/stylizer/change_state")
        get = listener.node.create_client(GetState, "/stylizer/get_state")
        publisher = listener.node.create_publisher(JointState, "joint_states", RELIABLE)
        got = listener.subscribe("stylized/joint_states", qos=RELIABLE)

        def state():
            return listener.call(get, GetState.Request(), procs=[proc]).current_state.id

        def transition(id_):
            assert listener.call(change, ChangeState.Request(transition=Transition(id=id_)),
                                 procs=[proc], resend_after=None).success

        def stream(n):
            """Publish n frames; how many stylized frames came back."""
            before = len(got)
            for _ in range(n):
                k = sent[0]
                publisher.publish(message(T0 + k * PERIOD, LAYOUT.names, frames[k % len(frames)]))
                sent[0] += 1
                listener.spin_for(0.005)
            listener.spin_for(1.0)
            return len(got) - before

        assert state() == State.PRIMARY_STATE_UNCONFIGURED
        assert publisher.get_subscription_count() == 0  # no model, no session, no subscription
        transition(Transition.TRANSITION_CONFIGURE)
        assert state() == State.PRIMARY_STATE_INACTIVE
        assert listener.subscriptions["stylized/joint_states"].get_publisher_count() == 1
        assert stream(20) == 0  # configured but not active: nothing in, nothing out
        transition(Transition.TRANSITION_ACTIVATE)
        assert state() == State.PRIMARY_STATE_ACTIVE
        listener.spin_until(lambda: publisher.get_subscription_count() == 1, "the subscription", procs=[proc])
        assert stream(30) == 30
        transition(Transition.TRANSITION_DEACTIVATE)
        assert state() == State.PRIMARY_STATE_INACTIVE
        assert stream(20) == 0
        transition(Transition.TRANSITION_CLEANUP)
        assert state() == State.PRIMARY_STATE_UNCONFIGURED
        listener.spin_until(lambda: listener.subscriptions["stylized/joint_states"].get_publisher_count() == 0,
                            "the publishers gone", procs=[proc])
        transition(Transition.TRANSITION_CONFIGURE)  # configure again: the same parameters
        transition(Transition.TRANSITION_ACTIVATE)
        listener.spin_until(lambda: publisher.get_subscription_count() == 1, "the subscription", procs=[proc])
        assert stream(30) == 30
        transition(Transition.TRANSITION_ACTIVE_SHUTDOWN)
        assert proc.wait(20) == 0  # shutdown ends the process
    finally:
        listener.close()
        stop(proc)
        print((tmp_path / "log").read_text())


def test_a_configure_that_fails_says_why_and_leaves_the_node_unconfigured(ros_env, tmp_path):
    proc = start_node("stylizer_managed", ros_env, log=tmp_path / "log", model=tmp_path / "missing.onnx")
    listener = Listener("lifecycle_fail")
    try:
        change = listener.node.create_client(ChangeState, "/stylizer/change_state")
        get = listener.node.create_client(GetState, "/stylizer/get_state")
        request = ChangeState.Request(transition=Transition(id=Transition.TRANSITION_CONFIGURE))
        # a failed configure leaves the node unconfigured, so sending it again (Listener.call) is safe
        assert not listener.call(change, request, procs=[proc]).success
        assert listener.call(get, GetState.Request(), procs=[proc]).current_state.id == \
            State.PRIMARY_STATE_UNCONFIGURED
    finally:
        listener.close()
        stop(proc)
    log = (tmp_path / "log").read_text()
    assert "cannot configure:" in log and "missing.onnx" in log and "Traceback" not in log, log
