"""``stylizer``: restyle JointState streams live, one stylizer session per performer.

Performer ``N`` (parameter ``performers``: a topic prefix each, ``""`` for none) subscribes
``N/joint_states`` and publishes ``N/stylized/joint_states`` (the input's names in the input's order,
its stamp carried through), ``N/stylized/trajectory`` (JointTrajectory chunks that ros2_control's
JointTrajectoryController accepts), with ``publish_markers`` ``N/stylized/markers`` (the stylized
skeleton for RViz) and with ``robot_urdf`` ``N/stylized/robot/...`` on the robot's joints. Names are
relative, so node namespaces and remaps apply. Style, alpha, a mix style, the latent seed and a
reference clip change live through parameters and blend in over ``blend_seconds``; ``~/reset``
starts every stream afresh. Bad messages are dropped and counted per reason; the counts, frame
counts and processing latency go to ``/diagnostics`` once a second.

This module is the ROS shell: parameters, subscriptions, services and diagnostics; the publishers
and their messages are :mod:`motion_style_ros.nodes.stylizer_outputs`'. What happens to a frame is
:mod:`motion_style_ros.runtime.performer`'s; the parameters, their checks and how a change reaches
the sessions are :mod:`motion_style_ros.runtime.stylizer_settings`'.
"""

from __future__ import annotations

import sys

from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rcl_interfaces.msg import SetParametersResult
from rclpy.parameter import Parameter
from rclpy.subscription import MessageInfo
from sensor_msgs.msg import JointState
from std_srvs.srv import Trigger

from motion_style_ros.io.joint_state import JointStateLayout
from motion_style_ros.nodes.parameters import Parameters, PlayerNode
from motion_style_ros.nodes.process import run
from motion_style_ros.nodes.stylizer_outputs import PerformerTopics
from motion_style_ros.runtime import stylizer_settings as settings_
from motion_style_ros.runtime.onnx_model import neutral_style
from motion_style_ros.runtime.performer import PerformerStream, seconds
from motion_style_ros.runtime.live_settings import LiveSettings
from motion_style_ros.runtime.robot_target import RobotTarget
from motion_style_ros.runtime.trajectory import Chunker

NAME = "stylizer"
LEVELS = {0: DiagnosticStatus.OK, 1: DiagnosticStatus.WARN, 2: DiagnosticStatus.ERROR}


class StylizerBase(Parameters):
    """The stylizer, mixed into a plain or a managed rclpy node: parameters, one :class:`PerformerTopics`
    per prefix, ``~/reset``, diagnostics.

    Parameters follow the ROS 2 rules: a change is checked in the on-set callback and applied
    after it (post-set), by the executor before the next frame. A reference clip is read off the
    streams' thread (runtime.references; rclpy's multi-threaded executor costs the streams far
    more: 280-840 ms p50 at 120 Hz here, against 4-5 ms); if it is unusable, the parameter goes
    back to the clip in use.
    """

    def _setup(self) -> None:
        """What every stylizer node does first: the parameter callbacks."""
        self.performers: list[PerformerTopics] = []
        self.live: LiveSettings | None = None
        self.add_on_set_parameters_callback(self._on_set_parameters)
        self.add_post_set_parameters_callback(self._post_set_parameters)

    def _configure(self) -> None:
        """Read the parameters, load the model, build the sessions, publishers, timer and services."""
        values = {p.name: self.param(p.name, p.default, p.description, p.low, p.high, read_only=not p.live)
                  for p in settings_.PARAMETERS}
        qos, trajectory_qos = self.stream_qos(), self.qos(
            "trajectory_qos", "reliable", 10, "stylized/trajectory (reliable: JointTrajectoryController "
            "subscribes reliably)")
        self.spec = spec = settings_.check_start(values)
        self.backend, self.max_latency_ms = spec.name, values["max_latency_ms"]
        self.layout = (JointStateLayout.from_yaml(values["layout"]) if values["layout"]
                       else JointStateLayout.canonical())
        prefixes = values["performers"]
        sessions = settings_.sessions(spec, values["model"] or spec.default_model, len(prefixes), values)
        session = sessions[0]
        target = settings_.target_style(session.styles, neutral_style(session.card))
        values["target_style"] = self.param(target.name, target.default, target.description, read_only=False)
        bounds = settings_.bounds(values)
        period_ns = round(1e9 / session.input_fps)

        def chunker() -> Chunker:
            return Chunker(values["trajectory_points"], period_ns, session.gap_seconds,
                           values["trajectory_velocities"])

        self.performers = []
        for prefix, s in zip(prefixes, sessions):
            robot = RobotTarget(values["robot_urdf"], values["robot_map"] or None) if values["robot_urdf"] else None
            p = PerformerTopics(self, prefix, qos, trajectory_qos, values["publish_markers"], robot is not None)
            p.stream = PerformerStream(p.input, s, self.layout, bounds, chunker(), p, self.get_logger(),
                                       robot, robot and chunker())
            self.performers.append(p)
        self.live = LiveSettings(sessions, spec, values, self.get_logger().error)
        self._diagnostics = self.create_publisher(DiagnosticArray, "/diagnostics", 10)
        self._timer = self.create_timer(1.0, self._publish_diagnostics)
        self._reset_service = self.create_service(Trigger, "~/reset", self._reset)
        self.get_logger().info(
            f"stylizing {', '.join(p.input for p in self.performers)} "
            f"with {session.model.path.name} ({spec.name}, {session.fps:g} Hz model, "
            f"{1e3 * session.latency:.1f} ms latency) into {self.live.values['target_style']!r}")

    # --- parameters ---------------------------------------------------------------------------

    def _on_set_parameters(self, parameters) -> SetParametersResult:
        """Check a change; nothing changes until it is applied (runtime.live_settings)."""
        if not self.performers:  # a managed node not configured yet: checked at configure
            return SetParametersResult(successful=True)
        reason = self.live.check({p.name: p.value for p in parameters if p.name in settings_.DYNAMIC})
        return SetParametersResult(successful=reason is None, reason=reason or "")

    def _post_set_parameters(self, parameters) -> None:
        if self.performers:
            self.live.accept({p.name: p.value for p in parameters if p.name in settings_.DYNAMIC})

    def _apply_pending(self) -> None:
        self.live.apply_pending(lambda path: self.set_parameters([Parameter("reference", value=path)]))

    # --- streaming ------------------------------------------------------------------------------

    def on_state(self, p: PerformerTopics, msg: JointState, info: MessageInfo) -> None:
        if self.live.pending:
            self._apply_pending()
        p.stream.frame(msg.name, msg.position, msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec,
                       info["received_timestamp"], self.live.values["frame_id"] or msg.header.frame_id)

    # --- service and diagnostics --------------------------------------------------------------

    def _reset(self, request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        for p in self.performers:
            p.stream.reset(recalibrate=True)
        response.success = True
        response.message = (f"reset {len(self.performers)} performer(s): each one's next frame "
                            "starts a fresh stream, its rig measured again")
        return response

    def _publish_diagnostics(self) -> None:
        if self.live.pending:
            self._apply_pending()
        array = DiagnosticArray()
        for p in self.performers:
            level, message, values = p.stream.status(self.live.values, self.backend, self.max_latency_ms)
            array.status.append(DiagnosticStatus(
                level=LEVELS[level], name=f"{self.get_name()}: {p.input}", message=message,
                hardware_id=p.stream.session.model.path.name,
                values=[KeyValue(key=k, value=str(v)) for k, v in values.items()]))
        if failure := self.live.references.failure:  # the last clip asked for could not be used (undone)
            array.status.append(DiagnosticStatus(
                level=DiagnosticStatus.WARN, name=f"{self.get_name()}: reference",
                message=f"reference clip unusable: {failure}"))
        array.header.stamp = self.get_clock().now().to_msg()
        self._diagnostics.publish(array)

    # --- lifecycle ----------------------------------------------------------------------------

    def _activate(self) -> None:
        for p in self.performers:
            p.subscribe()

    def _deactivate(self) -> None:
        """Stop listening, so nothing more is published; the streams start afresh on activation."""
        for p in self.performers:
            p.stream.flush()
            p.destroy(publishers=False)
            p.stream.session.restart()
            p.stream.clear()

    def _cleanup(self) -> None:
        """Free the sessions, publishers, timer and services (a managed node can configure again)."""
        for p in self.performers:
            p.destroy(publishers=True)
        for thing, destroy in ((self._timer, self.destroy_timer), (self._reset_service, self.destroy_service),
                               (self._diagnostics, self.destroy_publisher)):
            destroy(thing)
        self.performers = []
        self.live = None


class Stylizer(StylizerBase, PlayerNode):
    """The plain node: configured and streaming from the start."""

    def __init__(self) -> None:
        PlayerNode.__init__(self, NAME)
        self._setup()
        self._configure()
        self._activate()


def stamp_seconds(stamp: Time) -> float:
    """A message stamp as the session's float seconds, as the node converts it."""
    return seconds(stamp.sec * 1_000_000_000 + stamp.nanosec)


def main(args=None) -> int:
    return run(Stylizer, NAME, args)


if __name__ == "__main__":
    sys.exit(main())
