"""``learned_performer``: endless new motion of a chosen style, sampled from a trained SAAE's prior
(:mod:`motion_style_ros.runtime.learned_performer`), as JointState: a performer for the
stylizers, a robot or an avatar with no mocap at all.

The stream and the checks of the live parameters are
:mod:`motion_style_ros.runtime.learned_performer`'s; this module is the ROS shell. ``style``
changes live: a change is checked in the on-set callback (an unknown style is rejected with the
model's styles as the reason) and applied after it (post-set), to the windows drawn from the next
chunk on, where it blends in over half a window: no seam.
"""

from __future__ import annotations

import sys

from rcl_interfaces.msg import SetParametersResult
from rclpy.qos import qos_profile_sensor_data
from sensor_msgs.msg import JointState

from motion_style_ros.errors import MotionStyleError
from motion_style_ros.io.joint_state import JointStateLayout
from motion_style_ros.nodes.messages import joint_state
from motion_style_ros.nodes.parameters import PlayerNode
from motion_style_ros.nodes.process import run
from motion_style_ros.runtime import learned_performer as learned
from motion_style_ros.runtime.saae import DEFAULT_MODEL, SPREAD
from motion_style_ros.runtime.warmup import warm_kernels
from motion_style_ros.runtime.stgcn import MAX_SPREAD

NAME = "learned_performer"


class LearnedPerformer(PlayerNode):
    def __init__(self) -> None:
        super().__init__(NAME)
        self.stream = None  # until the parameters are read: changes before that are not checked
        self.add_on_set_parameters_callback(self._on_set_parameters)
        self.add_post_set_parameters_callback(self._post_set_parameters)
        model = self.param("model", DEFAULT_MODEL, "SAAE model: a shipped model's file name (models/) or "
                           "a path, its JSON model card beside it")
        style = self.param("style", "", "style to perform, one of the model card's styles; '' = the "
                           "model's neutral style (changes live, blending in)", read_only=False)
        seed = self.param("seed", 0, "seed of the prior samples: the same seed, the same motion",
                          0, learned.MAX_SEED)
        spread = self.param("spread", SPREAD, "how far each window's style input lies from its style's "
                            "mean, in its stds: 0 = the mean (clearest style), 1 = as trained", 0.0, MAX_SPREAD)
        foot_lock = self.param("foot_lock", True, "hold the feet the stream brings down where they land "
                               "(and its root back where it runs ahead of them)")
        self.fps = self.param("fps", 60, "frames per second", 1, 1000)
        topic = self.param("topic", "joint_states", "JointState topic to publish on")
        self.frame_id = self.param("frame_id", "", "header.frame_id of the messages", read_only=False)
        layout = self.param("layout", "", "JointState layout YAML (config/layouts/); empty: canonical")
        layout = JointStateLayout.from_yaml(layout) if layout else JointStateLayout.canonical()
        # checks the style
        stream = learned.LearnedStream(model, style, seed, spread, self.fps, layout, foot_lock=foot_lock)
        if reason := stream.problem("frame_id", self.frame_id):  # dynamically typed: checked here
            raise MotionStyleError(f"parameter frame_id: {reason}")
        self.stream = stream
        warm_kernels()  # before the first tick: the stream does not wait for numba
        self.publisher = self.create_publisher(JointState, topic, qos_profile_sensor_data)
        self.create_timer(1.0 / self.fps, self._tick)
        self.get_logger().info(f"performing {self.stream.style!r} sampled from "
                               f"{self.stream.sampler.path.name} (seed {seed}) at {self.fps} fps on "
                               f"{self.publisher.topic_name}")

    def _on_set_parameters(self, parameters) -> SetParametersResult:
        """Check a change; nothing changes until it is applied."""
        if self.stream is None:
            return SetParametersResult(successful=True)
        for p in parameters:
            if p.name in learned.DYNAMIC and (reason := self.stream.problem(p.name, p.value)):
                return SetParametersResult(successful=False, reason=reason)
        return SetParametersResult(successful=True)

    def _post_set_parameters(self, parameters) -> None:
        """Apply an accepted change: a style to the next chunk's windows, a frame_id to the next message."""
        if self.stream is None:
            return
        for p in parameters:
            if p.name == "style":
                self.stream.set_style(p.value)
                self.get_logger().info(f"style {self.stream.style!r} from the next chunk on")
            elif p.name == "frame_id":
                self.frame_id = p.value

    def _tick(self) -> None:
        self.publisher.publish(joint_state(self.stream.layout.names, self.stream.next_frame(),
                                           self.get_clock().now().to_msg(), self.frame_id))


def main(args=None) -> int:
    return run(LearnedPerformer, NAME, args)


if __name__ == "__main__":
    sys.exit(main())
