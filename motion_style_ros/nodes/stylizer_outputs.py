"""The stylizer node's outputs per performer: its publishers and the messages they carry (the
:class:`~motion_style_ros.runtime.performer.Outputs` a
:class:`~motion_style_ros.runtime.performer.PerformerStream` hands its frames to)."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from builtin_interfaces.msg import Duration, Time
from geometry_msgs.msg import Point, PoseStamped
from rclpy.exceptions import InvalidTopicNameException
from rclpy.qos import QoSProfile
from sensor_msgs.msg import JointState
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint
from visualization_msgs.msg import Marker, MarkerArray

from motion_style_ros.errors import MotionStyleError
from motion_style_ros.nodes.messages import doubles, joint_state, prefixed
from motion_style_ros.nodes.process import WithInfo
from motion_style_ros.runtime.performer import PerformerStream
from motion_style_ros.runtime.trajectory import Chunk

if TYPE_CHECKING:
    from motion_style_ros.nodes.stylizer import StylizerBase


def stamp(ns: int) -> Time:
    return Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)


class PerformerTopics:
    """One performer's publishers and subscription: the :class:`~motion_style_ros.runtime.performer.Outputs`
    of its :class:`~motion_style_ros.runtime.performer.PerformerStream`."""

    def __init__(self, node: StylizerBase, prefix: str, qos: QoSProfile, trajectory_qos: QoSProfile,
                 markers: bool, robot: bool) -> None:
        self.node, self.prefix, self.qos = node, prefix, qos
        try:
            self.state_out = node.create_publisher(JointState, self.topic("stylized/joint_states"), qos)
            self.trajectory_out = node.create_publisher(JointTrajectory, self.topic("stylized/trajectory"),
                                                        trajectory_qos)
            self.markers_out = (node.create_publisher(MarkerArray, self.topic("stylized/markers"), qos)
                                if markers else None)
            self.robot_outs = (
                node.create_publisher(JointState, self.topic("stylized/robot/joint_states"), qos),
                node.create_publisher(JointTrajectory, self.topic("stylized/robot/trajectory"), trajectory_qos),
                node.create_publisher(PoseStamped, self.topic("stylized/robot/base_pose"), qos),
            ) if robot else ()
        except InvalidTopicNameException as exc:
            raise MotionStyleError(f"parameter performers: {exc}") from None
        self.input = node.resolve_topic_name(self.topic("joint_states"))
        self.subscription = None
        self.stream: PerformerStream | None = None

    def topic(self, name: str) -> str:
        return prefixed(self.prefix, name)

    def subscribe(self) -> None:
        self.subscription = self.node.create_subscription(
            JointState, self.topic("joint_states"), WithInfo(lambda msg, info: self.node.on_state(self, msg, info)),
            self.qos)

    def destroy(self, publishers: bool) -> None:
        """Stop listening (and, with ``publishers``, publishing)."""
        if self.subscription is not None:
            self.node.destroy_subscription(self.subscription)
            self.subscription = None
        if publishers:
            for pub in (self.state_out, self.trajectory_out, self.markers_out, *self.robot_outs):
                if pub is not None:
                    self.node.destroy_publisher(pub)

    def markers(self, rotations: np.ndarray, root: np.ndarray, stamp: Time) -> MarkerArray:
        """The stylized skeleton's bones below the pelvis as one LINE_LIST, in REP-103 axes (in the
        node's frame_id, or 'world')."""
        ends = self.stream.bone_lines(rotations, root)
        marker = Marker(ns=self.prefix or "stylizer", id=0, type=Marker.LINE_LIST, action=Marker.ADD,
                        points=[Point(x=x, y=y, z=z) for x, y, z in ends.tolist()])
        marker.header.stamp = stamp
        marker.header.frame_id = self.node.live.values["frame_id"] or "world"
        marker.pose.orientation.w = 1.0
        marker.scale.x = 0.03  # line width, m
        marker.color.r, marker.color.g, marker.color.b, marker.color.a = 0.95, 0.45, 0.1, 1.0
        return MarkerArray(markers=[marker])

    # --- Outputs ------------------------------------------------------------------------------

    def state(self, names, positions: np.ndarray, stamp_ns: int, frame_id: str, rotations: np.ndarray,
              root: np.ndarray) -> None:
        self.state_out.publish(joint_state(names, positions, stamp(stamp_ns), frame_id))
        if self.markers_out is not None:
            self.markers_out.publish(self.markers(rotations, root, stamp(stamp_ns)))

    def trajectory(self, names, chunk: Chunk, frame_id: str) -> None:
        self.trajectory_out.publish(trajectory(names, chunk, frame_id))

    def robot_state(self, names, positions: np.ndarray, stamp_ns: int, frame_id: str,
                    base_position: np.ndarray, base_orientation: np.ndarray) -> None:
        self.robot_outs[0].publish(joint_state(names, positions, stamp(stamp_ns), frame_id))
        pose = PoseStamped()
        pose.header.stamp, pose.header.frame_id = stamp(stamp_ns), frame_id or "world"
        pose.pose.position.x, pose.pose.position.y, pose.pose.position.z = base_position.tolist()
        o = pose.pose.orientation
        o.w, o.x, o.y, o.z = base_orientation.tolist()
        self.robot_outs[2].publish(pose)

    def robot_trajectory(self, names, chunk: Chunk, frame_id: str) -> None:
        self.robot_outs[1].publish(trajectory(names, chunk, frame_id))


def trajectory(names, chunk: Chunk, frame_id: str) -> JointTrajectory:
    """One JointTrajectory; its header.stamp stays zero ("start on receipt" for
    JointTrajectoryController: the frames are already past)."""
    msg = JointTrajectory(joint_names=list(names))
    msg.header.frame_id = frame_id
    for offset, positions, velocities in zip(chunk.times_ns, chunk.positions, chunk.velocities):
        msg.points.append(JointTrajectoryPoint(
            positions=doubles(positions), velocities=[] if velocities is None else doubles(velocities),
            time_from_start=Duration(sec=offset // 1_000_000_000, nanosec=offset % 1_000_000_000)))
    return msg
