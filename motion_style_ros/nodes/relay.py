"""``relay``: every JointState on ``N/joint_states`` republished on ``N/stylized/joint_states`` as
it came, for each topic prefix ``N`` of ``performers`` (as the stylizer's), with the stylizer's QoS
parameters.

``motion-style bench nodes`` measures it beside the stylizer: its latency and CPU are what DDS and
an rclpy node cost on this machine for that many streams, the floor under the stylizer's.
"""

from __future__ import annotations

import sys

from sensor_msgs.msg import JointState

from motion_style_ros.nodes.messages import prefixed

from motion_style_ros.nodes.parameters import PlayerNode

from motion_style_ros.nodes.process import run
from motion_style_ros.runtime.stylizer_settings import check_prefixes

NAME = "relay"


class Relay(PlayerNode):
    def __init__(self) -> None:
        super().__init__(NAME)
        qos = self.stream_qos()
        prefixes = self.param("performers", [""], "topic prefix of each stream ('' = the node's namespace)")
        check_prefixes(prefixes)
        for prefix in prefixes:
            publisher = self.create_publisher(JointState, prefixed(prefix, "stylized/joint_states"), qos)
            self.create_subscription(JointState, prefixed(prefix, "joint_states"), publisher.publish, qos)


def main(args=None) -> int:
    return run(Relay, NAME, args)


if __name__ == "__main__":
    sys.exit(main())
