"""``synthetic_performer``: an endless procedural walk, run or wave as JointState, for the demo."""

from __future__ import annotations

import sys

from sensor_msgs.msg import JointState

from motion_style_ros.core.synthetic import KINDS, synthetic_motion
from motion_style_ros.errors import MotionStyleError
from motion_style_ros.io.joint_state import JointStateLayout
from motion_style_ros.nodes.messages import joint_state
from motion_style_ros.nodes.parameters import PlayerNode
from motion_style_ros.nodes.process import run

NAME = "synthetic_performer"


class SyntheticPerformer(PlayerNode):
    def __init__(self) -> None:
        super().__init__(NAME)
        self.kind = self.param("motion", "walk", f"what to perform: {', '.join(KINDS)}")
        self.fps = self.param("fps", 60, "frames per second", 1, 1000)
        topic = self.param("topic", "joint_states", "JointState topic to publish on")
        self.frame_id = self.param("frame_id", "", "header.frame_id of the messages")
        layout = self.param("layout", "",
                            "JointState layout YAML (config/layouts/); empty: canonical")
        if self.kind not in KINDS:
            raise MotionStyleError(f"parameter motion is {self.kind!r}; "
                                   f"choose one of {', '.join(KINDS)}")
        self.layout = JointStateLayout.from_yaml(layout) if layout else JointStateLayout.canonical()
        self.frame = 0
        self.chunk = self._chunk()
        self.publisher = self.create_publisher(JointState, topic, self.stream_qos())
        self.create_timer(1.0 / self.fps, self._tick)
        self.get_logger().info(f"performing a synthetic {self.kind} at {self.fps} fps on "
                               f"{self.publisher.topic_name}")

    def _chunk(self):
        """The next second of motion; chunks start where the last ended, so the stream is seamless."""
        motion = synthetic_motion(self.kind, self.fps, 1.0, start=self.frame / self.fps)
        return iter(self.layout.encode_motion(motion))

    def _tick(self) -> None:
        values = next(self.chunk, None)
        if values is None:
            self.chunk = self._chunk()
            values = next(self.chunk)
        self.frame += 1
        self.publisher.publish(joint_state(self.layout.names, values,
                                           self.get_clock().now().to_msg(), self.frame_id))


def main(args=None) -> int:
    return run(SyntheticPerformer, NAME, args)


if __name__ == "__main__":
    sys.exit(main())
