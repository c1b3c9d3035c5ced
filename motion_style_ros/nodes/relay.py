"""``relay``: every JointState on ``joint_states`` republished on ``stylized/joint_states`` as it
came, with the stylizer's QoS parameters.

``motion-style bench nodes`` measures it beside the stylizer: its latency is what DDS and an
rclpy node cost on this machine, the floor under the stylizer's.
"""

from __future__ import annotations

import sys

from sensor_msgs.msg import JointState

from motion_style_ros.nodes import PlayerNode, run

NAME = "relay"


class Relay(PlayerNode):
    def __init__(self) -> None:
        super().__init__(NAME)
        qos = self.stream_qos()
        publisher = self.create_publisher(JointState, "stylized/joint_states", qos)
        self.create_subscription(JointState, "joint_states", publisher.publish, qos)


def main(args=None) -> int:
    return run(Relay, NAME, args)


if __name__ == "__main__":
    sys.exit(main())
