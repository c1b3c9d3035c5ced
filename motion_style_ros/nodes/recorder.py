"""``recorder``: record JointState topics to a rosbag2 MCAP bag (``ros2 bag record`` elsewhere).

Messages are stored as received (serialised CDR) with their arrival time as log time; the bag is
finalised when the node stops (Ctrl-C / SIGINT), so ``ros2 bag play`` and the bag player accept it.
"""

from __future__ import annotations

import sys
from datetime import datetime

from sensor_msgs.msg import JointState

from motion_style_ros.errors import MotionStyleError
from motion_style_ros.io.bags import BagWriter
from motion_style_ros.nodes.parameters import PlayerNode
from motion_style_ros.nodes.process import run

NAME = "recorder"


class Recorder(PlayerNode):
    def __init__(self) -> None:
        super().__init__(NAME)
        topics = self.param("topics", ["joint_states"], "JointState topics to record")
        bag = self.param("bag", "", "bag folder to create; empty: rosbag2_<date>_<time>")
        if not topics or not all(topics):
            raise MotionStyleError("parameter topics is empty; give topic names, e.g. ['joint_states']")
        # A deep queue so that bursts are not dropped while the bag writes.
        qos = self.stream_qos(depth=100)
        self.writer = BagWriter(bag or datetime.now().strftime("rosbag2_%Y_%m_%d-%H_%M_%S"))
        for topic in topics:
            resolved = self.resolve_topic_name(topic)
            self.create_subscription(JointState, topic, lambda data, t=resolved: self._record(t, data),
                                     qos, raw=True)
            self.get_logger().info(f"recording {resolved} to {self.writer.path}")

    def _record(self, topic: str, data: bytes) -> None:
        self.writer.write_raw(topic, self.get_clock().now().nanoseconds, data)

    def destroy_node(self) -> None:
        if hasattr(self, "writer"):
            self.writer.close()
            self.get_logger().info(f"wrote {self.writer.count} messages to {self.writer.path}")
        super().destroy_node()


def main(args=None) -> int:
    return run(Recorder, NAME, args)


if __name__ == "__main__":
    sys.exit(main())
