"""``bvh_player``: play a humanoid BVH file as JointState on the canonical skeleton, in real time."""

from __future__ import annotations

import sys

import numpy as np

from sensor_msgs.msg import JointState

from motion_style_ros.core.retarget import Retargeter, find_map
from motion_style_ros.core.skeleton import canonical
from motion_style_ros.errors import MotionStyleError
from motion_style_ros.io import bvh
from motion_style_ros.io.joint_state import JointStateLayout
from motion_style_ros.nodes.messages import joint_state
from motion_style_ros.nodes.parameters import PlayerNode
from motion_style_ros.nodes.process import run

NAME = "bvh_player"


def load(path: str, layout: JointStateLayout):
    """``(frames (T, len(names)), fps)`` of a BVH file retargeted to the canonical skeleton."""
    if not path:
        raise MotionStyleError("parameter file is empty; give a BVH file: --ros-args -p file:=take.bvh")
    source = bvh.read(path).to_motion()
    motion = Retargeter(source.skeleton, canonical(), find_map(source.skeleton, path))(source)
    return layout.encode_motion(motion.check_finite(path)), motion.fps


def lap(frames: np.ndarray, layout: JointStateLayout) -> np.ndarray:
    """What a loop adds to every frame of the next pass: the root's horizontal travel over a pass
    (plus a frame's step), so a looped walk walks on instead of jumping back to its start, which a
    stylizer would drop as a speed no one makes (the channels as the layout encodes them)."""
    rotations, root = layout.decode(layout.names, frames[0])
    _, last = layout.decode(layout.names, frames[-1])
    _, second = layout.decode(layout.names, frames[1 if len(frames) > 1 else 0])
    travel = last - root + (second - root)
    travel[1] = 0.0  # core Y is up: only the horizontal travel carries on
    return layout.encode(rotations, root + travel) - layout.encode(rotations, root)


class BvhPlayer(PlayerNode):
    def __init__(self) -> None:
        super().__init__(NAME)
        path = self.param("file", "", "BVH file of a humanoid (canonical, CMU or Unity joint names)")
        rate = self.param("rate", 1.0, "playback speed factor", 0.01, 100.0)
        self.loop = self.param("loop", False, "start over at the end instead of exiting (the root "
                               "walks on from where the clip ends)")
        topic = self.param("topic", "joint_states", "JointState topic to publish on")
        self.frame_id = self.param("frame_id", "", "header.frame_id of the messages")
        self.wait = self.param("wait_for_subscribers", 0, "hold playback until this many subscribers "
                               "are matched (start the consumers first, miss no frame)", 0, 1000)
        layout = self.param("layout", "",
                            "JointState layout YAML (config/layouts/); empty: canonical")
        start = self.param("start_frame", 0, "first frame to play (CMU files begin with a calibration "
                           "T-pose at the origin: 1 skips it)", 0, 10_000_000)
        self.layout = JointStateLayout.from_yaml(layout) if layout else JointStateLayout.canonical()
        self.frames, fps = load(path, self.layout)
        if start >= len(self.frames):
            raise MotionStyleError(f"parameter start_frame is {start}; {path} has {len(self.frames)} frames")
        self.frames = self.frames[start:]
        self.lap = lap(self.frames, self.layout)
        self.passes = 0
        self.index = 0
        self.publisher = self.create_publisher(JointState, topic, self.stream_qos())
        self.create_timer(1.0 / (fps * rate), self._tick)
        self.get_logger().info(f"playing {path}: {len(self.frames)} frames at {fps:g} fps x {rate:g} "
                               f"on {self.publisher.topic_name}")

    def _tick(self) -> None:
        if self.index == 0 and self.publisher.get_subscription_count() < self.wait:
            return
        self.wait = 0
        if self.index == len(self.frames):
            if not self.loop:
                self.done.set_result(True)
                return
            self.index = 0
            self.passes += 1
        self.publisher.publish(joint_state(self.layout.names, self.frames[self.index] + self.passes * self.lap,
                                           self.get_clock().now().to_msg(), self.frame_id))
        self.index += 1


def main(args=None) -> int:
    return run(BvhPlayer, NAME, args)


if __name__ == "__main__":
    sys.exit(main())
