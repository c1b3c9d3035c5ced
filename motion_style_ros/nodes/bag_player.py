"""``bag_player``: play the JointState messages of a rosbag2 bag with their recorded timing.

For machines without the ``ros2`` CLI (``ros2 bag play`` does the same elsewhere). Messages are
republished as recorded (serialised bytes, so header.stamp is kept); the gaps between them follow the
recording's log times divided by ``rate``.

Every message is checked before any is played (it deserialises as a JointState with a position per
name, all finite). A damaged bag stops the node with one line (exit 2); ``skip_damaged:=true`` plays
its readable messages instead and logs how many it skipped.
"""

from __future__ import annotations

import sys
import time

import numpy as np
from rclpy.qos import qos_profile_sensor_data
from sensor_msgs.msg import JointState

from motion_style_ros.errors import MotionStyleError
from motion_style_ros.io.bags import DamagedBag, read_checked
from motion_style_ros.nodes.parameters import PlayerNode
from motion_style_ros.nodes.process import run

NAME = "bag_player"


class BagPlayer(PlayerNode):
    def __init__(self) -> None:
        super().__init__(NAME)
        bag = self.param("bag", "", "rosbag2 folder or .mcap file with sensor_msgs/JointState")
        self.rate = self.param("rate", 1.0, "playback speed factor", 0.01, 100.0)
        self.loop = self.param("loop", False, "start over at the end instead of exiting")
        topic = self.param("topic", "", "publish every message on this topic; "
                                        "empty: each on its recorded topic")
        self.wait = self.param("wait_for_subscribers", 0, "hold playback until this many subscribers "
                               "are matched on every topic (start the consumers first)", 0, 1000)
        skip_damaged = self.param("skip_damaged", False, "play the readable messages of a damaged bag "
                                  "(saying how many were skipped) instead of refusing it")
        if not bag:
            raise MotionStyleError("parameter bag is empty; give a bag: --ros-args -p bag:=my_bag")
        try:
            contents = read_checked(bag, skip_damaged=skip_damaged)
        except DamagedBag as exc:
            if skip_damaged:
                raise
            raise MotionStyleError(f"{exc}; {readable_part(bag)}") from None
        if contents.damage:
            skipped = "an unknown number of" if contents.skipped is None else str(contents.skipped)
            self.get_logger().warning(f"{bag}: {contents.damage}; playing its {len(contents.messages)} "
                                      f"readable messages, {skipped} skipped")
        self.messages = [(t, log, data) for t, log, data, _ in contents.messages]
        if not self.messages:
            raise MotionStyleError(f"{bag}: its JointState topics hold no messages; nothing to play")
        topics = sorted({t for t, _, _ in self.messages})
        self.publishers_by_topic = {
            t: self.create_publisher(JointState, topic or t, qos_profile_sensor_data) for t in topics}
        log = np.array([t for _, t, _ in self.messages], dtype=np.int64)
        self.offsets = (log - log[0]) / self.rate  # ns after the start of a pass
        gaps = np.diff(log)
        # A loop restarts one typical gap (1 s for a lone message) after the last message.
        typical = float(np.median(gaps)) if len(gaps) else 1e9
        self.pass_ns = self.offsets[-1] + max(typical, 1e6) / self.rate
        self.index = 0
        self.start = time.monotonic_ns()
        self.timer = self.create_timer(1e-3, self._tick)
        self.get_logger().info(f"playing {len(self.messages)} messages from {bag} ({', '.join(topics)}) "
                               f"x {self.rate:g}")

    def _tick(self) -> None:
        now = time.monotonic_ns()
        if self.wait:
            if min(p.get_subscription_count() for p in self.publishers_by_topic.values()) < self.wait:
                return
            self.wait, self.start = 0, now
        while now - self.start >= self.offsets[self.index]:
            topic, _, data = self.messages[self.index]
            self.publishers_by_topic[topic].publish(data)
            self.index += 1
            if self.index == len(self.messages):
                if not self.loop:
                    self.timer.cancel()
                    self.done.set_result(True)
                    return
                self.index = 0
                self.start += int(self.pass_ns)
        self.timer.timer_period_ns = max(int(self.start + self.offsets[self.index] - now), 100_000)
        self.timer.reset()


def readable_part(bag: str) -> str:
    """What ``skip_damaged:=true`` would play of a damaged bag, for the error that refuses it."""
    try:
        contents = read_checked(bag, skip_damaged=True)
    except DamagedBag:
        return "no message in it can be read"
    return f"skip_damaged:=true plays the {len(contents.messages)} messages that can be read"


def main(args=None) -> int:
    return run(BagPlayer, NAME, args)


if __name__ == "__main__":
    sys.exit(main())
