"""A recorded bag through the stylizer, checked with launch_testing (docs/nodes.md: "Testing your
pipeline on a recorded bag" says how to point it at a bag of your own).

    launch_test test/launch/test_stylizer_bag.launch.py

(with the package installed in an ament prefix and that prefix sourced). The launch starts the
``stylizer`` (the installed executable, with the installed ``config/stylizer.yaml``) and
``bag_player`` on the bag; the active test listens to the player's input and the stylizer's
output, changes ``target_style`` halfway through the bag, and checks what a pipeline test checks:
every input frame stylized, each with its input's names and stamp, the change applied mid-bag, the
trajectory chunks well formed for ros2_control's JointTrajectoryController. After shutdown: every
process exited 0 and none printed an error line.
"""

import atexit
import re
import shutil
import tempfile
import time
import unittest
from pathlib import Path

import launch
import launch_ros.actions
import launch_testing
import launch_testing.actions
import launch_testing.asserts
import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from launch_ros.substitutions import FindPackageShare
from rcl_interfaces.srv import SetParameters
from rclpy.parameter import Parameter
from rclpy.qos import QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState
from trajectory_msgs.msg import JointTrajectory

from motion_style_ros.core.synthetic import synthetic_motion
from motion_style_ros.io.bags import JointStateRecord, read_joint_states, write_joint_states
from motion_style_ros.io.joint_state import JointStateLayout

FPS = 60.0
SECONDS = 4.0
FIRST_STYLE, CHANGED_STYLE = "elderly", "youthful"
TIMEOUT = 60.0  # for readiness on a loaded machine; never a timing assertion
BEST_EFFORT = QoSProfile(depth=1000, reliability=ReliabilityPolicy.BEST_EFFORT)
ERROR = re.compile(r"\[ERROR\]|Traceback|Failed to publish|context is invalid")


def bag_under_test() -> Path:
    """The bag to play: here a synthetic walk recorded with the package's own bag writer
    (io/bags.py). To test your own recording, return its folder instead."""
    folder = tempfile.mkdtemp(prefix="stylizer_bag_")
    atexit.register(shutil.rmtree, folder, ignore_errors=True)
    bag = Path(folder) / "walk"
    layout = JointStateLayout.canonical()
    walk = synthetic_motion("walk", FPS, SECONDS)
    start_ns = 1_700_000_000 * 10**9
    write_joint_states(bag, (JointStateRecord(start_ns + round(k * 1e9 / FPS), list(layout.names),
                                              layout.encode(walk.rotations[k], walk.root_positions[k]))
                             for k in range(walk.n_frames)))
    return bag


def generate_test_description():
    bag = bag_under_test()
    stylizer = launch_ros.actions.Node(
        package="motion_style_ros", executable="stylizer", name="stylizer", output="screen",
        parameters=[launch.substitutions.PathJoinSubstitution(
            [FindPackageShare("motion_style_ros"), "config", "stylizer.yaml"]),
            # A queue as deep as the bag, so that a busy machine delays frames instead of losing
            # them (the default, 10, keeps a live stream's latency low instead).
            {"target_style": FIRST_STYLE, "qos_depth": 1000}])
    # The player holds the bag until both the stylizer and this test listen to joint_states.
    player = launch_ros.actions.Node(
        package="motion_style_ros", executable="bag_player", name="bag_player", output="screen",
        parameters=[{"bag": str(bag), "wait_for_subscribers": 2}])
    return launch.LaunchDescription([
        stylizer, player, launch_testing.actions.ReadyToTest(),
    ]), {"stylizer": stylizer, "player": player, "bag": bag}


def stamp(msg) -> int:
    return msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec


def missing(recorded, messages) -> list[int]:
    """Indices of the recorded frames whose stamp no message carries."""
    have = {stamp(m) for m in messages}
    return [k for k, r in enumerate(recorded) if r.stamp_ns not in have]


class TestBagThroughStylizer(unittest.TestCase):

    @classmethod
    def setUpClass(cls):
        rclpy.init()
        cls.node = rclpy.create_node("bag_test")

    @classmethod
    def tearDownClass(cls):
        cls.node.destroy_node()
        rclpy.shutdown()

    def spin_until(self, condition, what, timeout=TIMEOUT):
        deadline = time.monotonic() + timeout
        while not condition():
            if time.monotonic() > deadline:
                self.fail(f"timed out waiting for {what() if callable(what) else what}")
            rclpy.spin_once(self.node, timeout_sec=0.05)

    def test_every_frame_stylized_and_a_change_applied_mid_bag(self, proc_info, player, bag):
        node = self.node
        recorded = read_joint_states(bag)
        outputs, inputs, chunks, in_use = [], [], [], []
        out_sub = node.create_subscription(JointState, "stylized/joint_states", outputs.append,
                                           BEST_EFFORT)
        node.create_subscription(JointTrajectory, "stylized/trajectory", chunks.append, 100)
        counted = []  # (frames_in, frames_out) of each report: counts since the one before

        def report(array):
            for status in array.status:
                values = {kv.key: kv.value for kv in status.values}
                in_use.append(values.get("target_style"))
                counted.append((int(values.get("frames_in", 0)), int(values.get("frames_out", 0))))

        node.create_subscription(DiagnosticArray, "/diagnostics", report, 10)
        # Matched to the stylizer's output before listening to the input: the player starts once
        # both the stylizer and this test listen there, and the first frames must not pass unseen.
        # Our side of the match shows in the publisher count; the stylizer's side is taken as done
        # once its diagnostics (a reader this test made after the output's) reach this test.
        self.spin_until(lambda: out_sub.get_publisher_count() > 0 and in_use, "the stylizer's output")
        settle = time.monotonic() + 1.0  # and a margin for a machine where discovery lags
        while time.monotonic() < settle:
            rclpy.spin_once(node, timeout_sec=0.05)
        node.create_subscription(JointState, "joint_states", inputs.append, BEST_EFFORT)

        self.spin_until(lambda: len(outputs) >= len(recorded) // 2, "half of the bag stylized")
        client = node.create_client(SetParameters, "stylizer/set_parameters")
        self.spin_until(client.service_is_ready, "the stylizer's set_parameters")
        future = client.call_async(SetParameters.Request(parameters=[
            Parameter("target_style", value=CHANGED_STYLE).to_parameter_msg()]))
        self.spin_until(future.done, "the parameter change")
        self.assertTrue(future.result().results[0].successful, future.result().results[0].reason)
        changed_at = len(outputs)

        proc_info.assertWaitForShutdown(process=player, timeout=TIMEOUT)  # the whole bag played
        self.spin_until(lambda: min(len(inputs), len(outputs)) >= len(recorded)
                        and CHANGED_STYLE in in_use, lambda: f"the last frames and a diagnostics "
                        f"report: {len(recorded)} recorded, {len(inputs)} in, {len(outputs)} out, "
                        f"styles reported {sorted(set(in_use))}, change at output {changed_at}, missing "
                        f"input frames {missing(recorded, outputs)}, the stylizer's count (in, out) "
                        f"{tuple(map(sum, zip(*counted)))}")
        end = time.monotonic() + 0.5  # anything beyond the bag's frames would show now
        while time.monotonic() < end:
            rclpy.spin_once(node, timeout_sec=0.05)

        self.assertEqual([stamp(m) for m in inputs], [r.stamp_ns for r in recorded])
        self.assertEqual([stamp(m) for m in outputs], [r.stamp_ns for r in recorded])  # each, once
        for out, record in zip(outputs, recorded):
            self.assertEqual(list(out.name), record.names)
            self.assertEqual(len(out.position), len(record.names))
        self.assertLess(changed_at, len(recorded))  # the change came while the bag still played
        self.assertEqual(in_use[0], FIRST_STYLE)
        self.assertEqual(in_use[-1], CHANGED_STYLE)

        # Trajectory chunks as a JointTrajectoryController takes them: the input's joint names,
        # one position per name per point, time_from_start strictly increasing within a chunk.
        self.assertTrue(chunks)
        for chunk in chunks:
            self.assertEqual(list(chunk.joint_names), recorded[0].names)
            times = [p.time_from_start.sec * 10**9 + p.time_from_start.nanosec for p in chunk.points]
            self.assertTrue(all(b > a for a, b in zip(times, times[1:])), times)
            self.assertTrue(all(len(p.positions) == len(chunk.joint_names) for p in chunk.points))


@launch_testing.post_shutdown_test()
class TestAfterShutdown(unittest.TestCase):

    def test_every_process_exited_cleanly(self, proc_info):
        launch_testing.asserts.assertExitCodes(proc_info)

    def test_no_error_line(self, proc_output, stylizer, player):
        for process in (stylizer, player):
            text = "".join(o.text.decode(errors="replace") for o in proc_output[process])
            self.assertEqual([line for line in text.splitlines() if ERROR.search(line)], [])
