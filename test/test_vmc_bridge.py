"""vmc_bridge node: real UDP in and out, the node in its own process, JointState over DDS."""

import socket
import time

import numpy as np
import pytest
import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from rclpy.qos import qos_profile_sensor_data
from ros_helpers import TIMEOUT, start_node, stop
from sensor_msgs.msg import JointState

from motion_style_ros.core import rotations as rot
from motion_style_ros.core.motion import Motion
from motion_style_ros.core.skeleton import canonical
from motion_style_ros.io import vmc
from motion_style_ros.io.joint_state import JointStateLayout

LAYOUT = JointStateLayout.canonical()


@pytest.fixture(scope="module")
def clip(datasets):
    from motion_style_ros.io.datasets import index_bandai, load_clip

    info = next(i for i in index_bandai(datasets) if i.content == "walk")
    return load_clip(info)[:20]


@pytest.fixture
def vmc_out():
    """The avatar host the bridge streams to: a VMC receiver on a free port."""
    frames = []
    receiver = vmc.VmcReceiver(frames.append, port=0).start()
    receiver.frames = frames
    yield receiver
    receiver.close()


def free_udp_port():
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class Harness:
    """The test's own ROS node: watches the bridge's topics and feeds its input topic."""

    def __init__(self, proc):
        self.proc = proc
        self.node = rclpy.create_node("vmc_bridge_test")
        self.states, self.diagnostics = [], []
        self.node.create_subscription(JointState, "joint_states", self.states.append,
                                      qos_profile_sensor_data)
        self.node.create_subscription(DiagnosticArray, "/diagnostics", self.diagnostics.append, 10)
        self.stylized = self.node.create_publisher(JointState, "stylized/joint_states",
                                                   qos_profile_sensor_data)

    def spin_until(self, done, what, timeout=TIMEOUT):
        deadline = time.monotonic() + timeout
        while not done():
            assert self.proc.poll() is None, f"vmc_bridge exited with {self.proc.returncode}"
            if time.monotonic() > deadline:
                return False
            rclpy.spin_once(self.node, timeout_sec=0.05)
        return True

    def exchange(self, send, received, what):
        """Send (again if nothing came back for a while: UDP and best-effort DDS may lose one)
        until ``received`` grows."""
        n = len(received)
        for _ in range(10):
            send()
            if self.spin_until(lambda: len(received) > n, what, timeout=TIMEOUT / 10):
                return received[-1]
        pytest.fail(f"no {what} came back")

    def counters(self):
        status = self.diagnostics[-1].status[0]
        return {kv.key: float(kv.value) for kv in status.values}


@pytest.fixture
def bridge(ros_env, vmc_out, tmp_path):
    port = free_udp_port()
    log = tmp_path / "vmc_bridge.log"
    proc = start_node("vmc_bridge", ros_env, log=log, osc_port=port, send_port=vmc_out.address[1])
    rclpy.init()
    harness = Harness(proc)
    harness.sender = vmc.VmcSender("127.0.0.1", port)
    harness.port = port
    try:
        ready = harness.spin_until(
            lambda: harness.node.count_publishers("joint_states") > 0
            and harness.node.count_subscribers("stylized/joint_states") > 0, "bridge")
        assert ready, "vmc_bridge did not come up"
        yield harness
    finally:
        harness.node.destroy_node()
        rclpy.shutdown()
        stop(proc, timeout=15)
        print(log.read_text())  # shown by pytest when the test fails


def decoded(state):
    rotations, root = LAYOUT.decode(state.name, state.position)
    return rotations, root


def assert_pose(rotations, root, motion, t):
    err = np.degrees(rot.angle_between(rotations[1:], motion.rotations[t, 1:]))
    assert err.max() < 0.01, err.max()  # OSC carries float32
    got = Motion.from_rotations(canonical(), rotations[None], root[None], motion.fps)
    np.testing.assert_allclose(got.global_positions()[0], motion.global_positions()[t], atol=1e-4)


def test_recorded_stream_round_trips_over_udp(bridge, clip, vmc_out):
    frames = vmc.VmcEncoder()(clip)
    for t, frame in enumerate(frames):
        state = bridge.exchange(lambda f=frame, t=t: bridge.sender.send(f, t / clip.fps), bridge.states,
                                f"JointState for VMC frame {t}")
        assert list(state.name) == LAYOUT.names
        assert_pose(*decoded(state), clip, t)

    # And back out: stylized JointStates are streamed as VMC to the avatar host.
    values = LAYOUT.encode_motion(clip)
    got = []
    for t in range(clip.n_frames):
        msg = JointState(name=LAYOUT.names, position=values[t].tolist())
        got.append(bridge.exchange(lambda m=msg: bridge.stylized.publish(m), vmc_out.frames,
                                   f"VMC frame for JointState {t}"))
    back = vmc.VmcDecoder(fps=clip.fps)(got)
    for t in range(clip.n_frames):
        assert_pose(back.rotations[t], back.root_positions[t], clip, t)


def test_garbage_is_counted_and_the_next_good_frame_comes_through(bridge, clip):
    frames = vmc.VmcEncoder()(clip[:2])
    # A first frame no rig can be built from (every bone at its parent): refused, not fatal.
    flat = vmc.VmcFrame({b: (np.zeros(3), q) for b, (_, q) in frames[0].bones.items()})
    bridge.sender.send(flat, 0.0)
    assert bridge.spin_until(lambda: bridge.diagnostics and bridge.counters()["conversion_errors"] == 1,
                             "conversion error in diagnostics")
    first = bridge.exchange(lambda: bridge.sender.send(frames[0], 0.0), bridge.states, "first frame")
    assert_pose(*decoded(first), clip, 0)

    def osc(address, *args):
        from pythonosc.osc_message_builder import OscMessageBuilder

        b = OscMessageBuilder(address)
        for a in args:
            b.add_arg(a)
        return b.build().dgram

    garbage = [
        bytes(np.random.default_rng(1).integers(0, 256, 300, dtype=np.uint8)),
        vmc.frame_bundle(frames[1], 0.1).dgram[:-13],  # truncated bundle
        osc(vmc.BONE_ADDRESS, "Hips", "x", 0.0, 0.0, 0.0, 0.0, 0.0, 1.0),  # wrong type
        osc(vmc.BONE_ADDRESS, "Hips", 1, 2),  # too few arguments
        osc(vmc.ROOT_ADDRESS, "root", *[float("nan")] * 7),  # not finite
    ]
    unknown = osc("/not/vmc", "Joy", 1.0)
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as raw:
        for data in garbage + [unknown]:
            raw.sendto(data, ("127.0.0.1", bridge.port))

    # A frame missing a bone: completed from the last pose the bridge saw. After the garbage the
    # sender's pattern is learnt again, so a frame that is no whole pose ends when the next begins.
    partial = vmc.VmcFrame({b: v for b, v in frames[1].bones.items() if b != "LeftLowerArm"})
    state = bridge.exchange(lambda: (bridge.sender.send(partial, 0.2), bridge.sender.send(partial, 0.2)),
                            bridge.states, "partial frame")
    completed = vmc.VmcFrame({**frames[1].bones, "LeftLowerArm": frames[0].bones["LeftLowerArm"]})
    expected = vmc.VmcDecoder(fps=clip.fps)([frames[0], completed])
    assert_pose(*decoded(state), expected, 1)

    assert bridge.spin_until(lambda: bridge.diagnostics and bridge.counters()["malformed"] >= len(garbage)
                             and bridge.counters()["frames"] >= 3, "diagnostics")
    counts = bridge.counters()
    assert counts["malformed"] == len(garbage)
    assert counts["ignored"] == 1
    assert counts["frames"] >= 3 and counts["conversion_errors"] == 1  # the flat frame alone
    assert bridge.proc.poll() is None


def test_thru_blendshapes_and_ok_state_pass_the_bridge_with_their_frame(bridge, clip, vmc_out):
    """A frame with blendshapes and a /VMC/Thru message: the pose on joint_states, the blendshapes on
    blendshapes with its stamp, and when the pose comes back, the frame goes out with both, the Thru
    message byte for byte. A frame sent while calibrating is counted, not published."""
    from pythonosc import osc_packet

    blends = []
    bridge.node.create_subscription(JointState, "blendshapes", blends.append, qos_profile_sensor_data)
    (frame,) = vmc.VmcEncoder()(clip[:1])
    thru = vmc.build_message("/VMC/Thru/Cue", ["scene 2", 3, 0.25])
    calibrating = vmc.VmcFrame(frame.bones, ok=(1, 2, 0))
    bridge.sender.send(calibrating, 0.0)
    shaped = vmc.VmcFrame(frame.bones, blendshapes={"Joy": 0.75, "A": 0.125}, apply=True, ok=(1, 3, 0))
    messages = [m.message for m in osc_packet.OscPacket(vmc.frame_bundle(shaped, 0.5).dgram).messages]
    packet = vmc.bundle(messages[:-1] + [thru] + messages[-1:])
    state = bridge.exchange(lambda: bridge.sender.send_packet(packet), bridge.states, "the shaped frame")
    assert bridge.spin_until(lambda: blends, "blendshapes")
    assert list(blends[-1].name) == ["Joy", "A"] and list(blends[-1].position) == [0.75, 0.125]
    assert blends[-1].header.stamp == state.header.stamp
    back = bridge.exchange(lambda: bridge.stylized.publish(state), vmc_out.frames, "the frame back out")
    assert back.blendshapes == {"Joy": 0.75, "A": 0.125} and back.apply and back.ok == (1, 3, 0)
    assert [m.dgram for m in back.passthrough if m.address.startswith("/VMC/Thru")] == [thru.dgram]
    assert bridge.spin_until(lambda: bridge.diagnostics and bridge.counters().get("calibrating") == 1,
                             "calibrating count")
    assert bridge.counters()["frames"] >= 2
