"""``stylizer``: restyle JointState streams live, one stylizer session per performer.

Performer ``N`` (parameter ``performers``: a topic prefix each, ``""`` for none) subscribes
``N/joint_states`` and publishes ``N/stylized/joint_states`` (the input's names in the input's order,
its stamp carried through), ``N/stylized/trajectory`` (JointTrajectory chunks that ros2_control's
JointTrajectoryController accepts) and, with ``publish_markers``, ``N/stylized/markers`` (the stylized
skeleton for RViz). Names are relative, so node namespaces and remaps apply. Every performer has its
own session: their streams need not be in step. Style, alpha and a mix style change live through
parameters and blend in over ``blend_seconds``; ``~/reset`` starts every stream afresh. Bad messages
are dropped and counted per reason; the counts, frame counts and processing latency go to
``/diagnostics`` once a second.
"""

from __future__ import annotations

import sys
import threading
import time
from collections import deque

import numpy as np
from builtin_interfaces.msg import Duration, Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import Point, PoseStamped
from rcl_interfaces.msg import SetParametersResult
from rclpy.parameter import Parameter
from rclpy.exceptions import InvalidTopicNameException
from rclpy.qos import QoSProfile
from rclpy.subscription import MessageInfo
from sensor_msgs.msg import JointState
from std_srvs.srv import Trigger
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint
from visualization_msgs.msg import Marker, MarkerArray

from motion_style_ros.core.motion import forward_kinematics
from motion_style_ros.errors import MotionStyleError
from motion_style_ros.io import bvh
from motion_style_ros.io.joint_state import FrameDelay, JointStateLayout, to_ros
from motion_style_ros.nodes import Parameters, PlayerNode, joint_state, run
from motion_style_ros.runtime.robot_target import RobotTarget
from motion_style_ros.runtime.backends import BACKENDS, with_feature
from motion_style_ros.runtime.health import health
from motion_style_ros.runtime.intake import DROP_REASONS, RESTART_REASONS, Bounds, Dropped, Intake
from motion_style_ros.runtime.trajectory import VELOCITIES, Chunk, Chunker
from motion_style_ros.runtime.offline import NODE_SETTINGS, canonical_clip, default_model
from motion_style_ros.runtime.session import RecurrentSession, describe_calibration
from motion_style_ros.runtime.windowed import MAX_SPREAD

NAME = "stylizer"
# Parameters that change live, with their types (checked by the node: rclpy's own message would
# name the types by number).
DYNAMIC = {"target_style": str, "alpha": float, "mix_style": str, "mix_weight": float,
           "latent_seed": int, "seed_spread": float, "reference": str, "frame_id": str}
TYPE_NAMES = {str: "string", float: "double", int: "integer", bool: "bool", list: "array",
              type(None): "nothing (not set)"}
LEVELS = {0: DiagnosticStatus.OK, 1: DiagnosticStatus.WARN, 2: DiagnosticStatus.ERROR}
WARN_EVERY = 10.0  # s between two warnings of the same kind
LATENCY_SECONDS = 5.0  # the latency percentiles are over the frames published in this last time


class Performer:
    """One performer's topics, session, counters and what its outputs continue from."""

    def __init__(self, node: Stylizer, prefix: str, session: RecurrentSession, qos: QoSProfile,
                 trajectory_qos: QoSProfile, markers: bool, bounds: Bounds, chunker: Chunker,
                 robot: RobotTarget | None = None, robot_chunker: Chunker | None = None) -> None:
        self.prefix = prefix
        self.session = session
        try:
            self.state_out = node.create_publisher(JointState, self.topic("stylized/joint_states"), qos)
            self.trajectory_out = node.create_publisher(JointTrajectory,
                                                        self.topic("stylized/trajectory"), trajectory_qos)
            self.markers_out = (node.create_publisher(MarkerArray, self.topic("stylized/markers"), qos)
                                if markers else None)
            self.robot, self.robot_chunker = robot, robot_chunker
            if robot is not None:
                self.robot_state_out = node.create_publisher(
                    JointState, self.topic("stylized/robot/joint_states"), qos)
                self.robot_trajectory_out = node.create_publisher(
                    JointTrajectory, self.topic("stylized/robot/trajectory"), trajectory_qos)
                self.robot_base_out = node.create_publisher(
                    PoseStamped, self.topic("stylized/robot/base_pose"), qos)
        except InvalidTopicNameException as exc:
            raise MotionStyleError(f"parameter performers: {exc}") from None
        self.input = node.resolve_topic_name(self.topic("joint_states"))
        self.qos = qos
        self.subscription = None
        self.counts = dict.fromkeys(["frames_in", "frames_out", *(f"dropped_{r}" for r in DROP_REASONS),
                                     *(f"restarted_{r}" for r in RESTART_REASONS)], 0)
        self.intake = Intake(bounds, 1.0 / session.input_fps)
        self.chunker = chunker
        # (publish time, latency from DDS receipt to publication), both ns
        self.latencies: deque[tuple[int, int]] = deque()
        self.reported: dict[str, int] = {}  # the counters at the last status, and when
        self.reported_at = time.monotonic()
        self.calibration_state = "measuring"  # logged when it changes
        self.names: tuple[str, ...] = ()
        self.slots = np.zeros(0, dtype=np.intp)  # input index of each layout name
        self.extra = np.zeros(0, dtype=np.intp)  # input index of each other name (passed through)
        # The other names' values go out with the pose they came with: the frame of stamp - latency.
        self.delay = FrameDelay(session.gap_seconds)
        self.latency_ns = round(session.latency * 1e9)
        self.clear()

    def subscribe(self, node: StylizerBase) -> None:
        self.subscription = node.create_subscription(
            JointState, self.topic("joint_states"), lambda msg, info: node.on_state(self, msg, info),
            self.qos)

    def destroy(self, node: StylizerBase, publishers: bool) -> None:
        """Stop listening (and, with ``publishers``, publishing)."""
        if self.subscription is not None:
            node.destroy_subscription(self.subscription)
            self.subscription = None
        if publishers:
            robot = ((self.robot_state_out, self.robot_trajectory_out, self.robot_base_out)
                     if self.robot is not None else ())
            for pub in (self.state_out, self.trajectory_out, self.markers_out, *robot):
                if pub is not None:
                    node.destroy_publisher(pub)

    def topic(self, name: str) -> str:
        return f"{self.prefix.rstrip('/')}/{name}" if self.prefix else name

    def clear(self) -> None:
        """Forget the stream: the next frame may have any stamp and starts a new trajectory."""
        self.intake.clear()
        self.chunker.clear()
        if self.robot is not None:
            self.robot.reset()
            self.robot_chunker.clear(np.zeros(len(self.robot.names), dtype=bool))
        self.chunk_frame_id = ""
        self.delay.clear()

    @property
    def dropped(self) -> int:
        return sum(self.counts[f"dropped_{r}"] for r in DROP_REASONS)


class StylizerBase(Parameters):
    """The stylizer, mixed into a plain or a managed rclpy node: parameters, one :class:`Performer`
    per prefix, ``~/reset``, diagnostics.

    Parameters follow the ROS 2 rules: a change is checked in the on-set callback and applied
    after it (post-set), by the executor before the next frame. A reference clip is checked
    quickly on set (the file, its length from the header) and then read, retargeted and encoded
    on a worker thread, so the streams never wait for it (rclpy's multi-threaded executor costs
    the streams far more: 280-840 ms p50 at 120 Hz here, against 4-5 ms). If the worker finds the
    clip unusable, it says why in one line and the parameter goes back to the clip in use.
    """

    def _setup(self) -> None:
        """What every stylizer node does first: the parameter callbacks."""
        self.performers: list[Performer] = []
        self._pending: deque[dict] = deque()  # checked parameter changes, for the streams' thread
        self._staged: dict[str, tuple] = {}  # reference path -> its clip's codes, once read
        self._loads = 0  # reference reads started; a newer one makes an older one's result stale
        self._reverting: str | None = None
        self.add_on_set_parameters_callback(self._on_set_parameters)
        self.add_post_set_parameters_callback(self._post_set_parameters)

    def _configure(self) -> None:
        """Read the parameters, load the model, build the sessions, publishers, timer and services."""
        prefixes = self.param("performers", [""], "topic prefix of each performer (one session each): "
                              "performer N subscribes N/joint_states and publishes N/stylized/...; "
                              "'' = the node's namespace")
        model = self.param("model", "", "stylizer model: a shipped model's file name (models/) or a "
                           "path, its JSON model card beside it; '' = the backend's shipped model")
        backend = self.param("backend", "recurrent", f"stylizer backend: {', '.join(BACKENDS)}")
        window = self.param("window", 0, "stgcn: frames per window, a multiple of 4; 0 = the model "
                            "card's", 0, 1024)
        bank = self.param("style_bank", "", "stgcn: a style bank file of enrolled styles (motion-style "
                          "style add); '' = the model's own (<model>_styles.json) if there is one")
        hop = self.param("hop", 4, "stgcn: model frames between two windows", 1, 1024)
        lookahead = self.param("lookahead", NODE_SETTINGS["lookahead"], "stgcn: model frames of the "
                               "future each output "
                               "frame waits for (latency lookahead / model fps); more is smoother",
                               0, 1023)
        input_fps = self.param("input_fps", 0.0, "nominal input rate in Hz (0: the model's rate); "
                               "sets the output latency, 1/model_fps - 1/input_fps", 0.0, 1000.0)
        blend = self.param("blend_seconds", 0.3, "seconds over which a style/alpha/mix change blends "
                           "in", 0.0, 60.0)
        layout = self.param("layout", "", "JointState layout YAML (config/layouts/); '' = canonical")
        qos = self.stream_qos()
        trajectory_points = self.param("trajectory_points", 6, "points per JointTrajectory chunk", 1, 120)
        velocities = self.param("trajectory_velocities", VELOCITIES[0], "velocities of the trajectory "
                                "points: inner (all but each chunk's last, which JointTrajectoryController "
                                "accepts by default), all (set its allow_nonzero_velocity_at_trajectory_end), "
                                "none (positions only)")
        trajectory_qos = self.qos("trajectory_qos", "reliable", 10, "stylized/trajectory (reliable: "
                                  "JointTrajectoryController subscribes reliably)")
        self.max_latency_ms = self.param("max_latency_ms", 20.0, "diagnostics: a processing latency "
                                         "p99 over this is a warning", 0.1, 1e4)
        robot_urdf = self.param("robot_urdf", "", "a humanoid robot's URDF: the stylized motion is also "
                                "mapped onto its joints (stylized/robot/...); '' = none")
        robot_map = self.param("robot_map", "", "robot_urdf: a YAML body map naming its knee, elbow, "
                               "... joints where the names do not say; '' = found from the URDF")
        publish_markers = self.param("publish_markers", False, "publish the stylized skeleton as "
                                     "a visualization_msgs/MarkerArray on stylized/markers")
        threads = self.param("threads", 1, "ONNX Runtime threads per performer", 1, 16)
        foot_lock = self.param("foot_lock", True, "keep the feet the input plants planted in the "
                               "output (causal leg IK)")
        follow = self.param("follow_seconds", NODE_SETTINGS["follow_seconds"], "time constant (s) with "
                            "which the stylized root "
                            "trajectory is pulled towards the input's, so the avatar stays with its "
                            "performer; 0 = free (the style's own speed and turns, drifting)",
                            0.0, 600.0)
        pipelined = self.param("pipelined", False, "publish each frame before running the model "
                               "frames it does not need, which then run between frames: every frame "
                               "costs an interpolation on its way through, at one input frame more "
                               "latency (1/input_fps)")
        if velocities not in VELOCITIES:
            raise MotionStyleError(f"parameter trajectory_velocities is {velocities!r}; allowed: "
                                   f"{', '.join(VELOCITIES)}")
        if backend not in BACKENDS:
            raise MotionStyleError(f"parameter backend is {backend!r}; allowed: {', '.join(BACKENDS)}")
        self.spec = spec = BACKENDS[backend]
        if bank and not spec.style_bank:
            raise MotionStyleError(f"parameter style_bank needs backend {' or '.join(with_feature('style_bank'))} "
                                   f"(style codes); {backend} has a fixed set of styles")
        if not prefixes or len(set(prefixes)) != len(prefixes):
            raise MotionStyleError(f"parameter performers is {list(prefixes)}; give distinct topic "
                                   "prefixes, e.g. ['alice', 'bob'] (or [''] for one performer)")
        self.backend = backend
        self.layout = JointStateLayout.from_yaml(layout) if layout else JointStateLayout.canonical()
        model = model or default_model(backend)
        common = dict(input_fps=input_fps or None, blend_seconds=blend, threads=threads,
                      follow_seconds=follow or None, foot_lock=foot_lock, pipelined=pipelined)
        if spec.lookahead:
            sessions = [spec.session_class()(model, **common, window=window or None, hop=hop,
                                             lookahead=lookahead, bank=bank or None) for _ in prefixes]
        else:
            session = spec.session_class()(model, **common)
            # Performers' model frames fall on different input frames (one in input_fps / model
            # fps runs the model), so that streams in step do not all run it on the same one.
            spread = max(1, round(session.input_fps / session.fps))
            sessions = [session] + [
                spec.session_class()(model, **common, phase_seconds=(k % spread) / session.input_fps)
                for k in range(1, len(prefixes))]
        session = sessions[0]
        self.styles = session.styles
        self.period_ns = round(1e9 / session.input_fps)
        self.settings = {
            "target_style": self.param("target_style", session.card.get("neutral_style", session.styles[0]),
                                       f"style to restyle into: {', '.join(session.styles)}",
                                       read_only=False),
            "alpha": self.param("alpha", 1.0, "strength of the style: 0 = the model's neutral "
                                "motion, 1 = the full style", 0.0, 1.0, read_only=False),
            "mix_style": self.param("mix_style", "", "a second style mixed in with mix_weight; "
                                    "'' = none", read_only=False),
            "mix_weight": self.param("mix_weight", 0.0, "weight of mix_style: 0 = target_style "
                                     "alone, 1 = mix_style alone", 0.0, 1.0, read_only=False),
            "latent_seed": self.param("latent_seed", 0, "stgcn: seed of the style codes (the same "
                                      "seed, the same codes on every machine); the recurrent "
                                      "backend has no latent space and ignores it", 0, 2**31 - 1,
                                      read_only=False),
            "seed_spread": self.param("seed_spread", 1.0, "stgcn: how far the seeds' codes lie from "
                                      "their style's mean code: 1 = as trained, 0 = one code per "
                                      "style, more = seeds differ more (the style less surely)",
                                      0.0, MAX_SPREAD, read_only=False),
            "reference": self.param("reference", "", "stgcn: a BVH clip whose style code (style "
                                    "encoder) replaces the target style's: move like this "
                                    "recording; '' = the latent seed's code", read_only=False),
            "frame_id": self.param("frame_id", "", "header.frame_id of the outputs; '' = the input's "
                                   "(markers: 'world')", read_only=False),
        }
        for key, value in self.settings.items():
            if reason := self._problem(key, value):
                raise MotionStyleError(f"parameter {key}: {reason}")
        defaults = Bounds()
        bounds = Bounds(
            max_stamp_jump=self.param("max_stamp_jump", defaults.max_stamp_jump, "s a frame's stamp may run "
                                      "ahead of the time since the previous frame arrived (and a first "
                                      "frame ahead of its arrival); more is dropped", 1e-3, 1e6),
            restart_seconds=self.param("restart_seconds", defaults.restart_seconds, "s of frames on a new "
                                       "clock or at a new place (clock reset, teleport) after which the "
                                       "stream restarts on them by itself", 1e-3, 600.0),
            max_root_distance=self.param("max_root_distance", defaults.max_root_distance, "m from the "
                                         "origin (each axis) beyond which a frame's root is dropped",
                                         1e-3, 1e9),
            max_root_speed=self.param("max_root_speed", defaults.max_root_speed, "m/s the root may move "
                                      "between two frames; faster is dropped", 1e-3, 1e6),
            max_angle=self.param("max_angle", defaults.max_angle, "rad beyond which an angle is "
                                 "dropped as no rotation", 1.0, 1e9))
        robots = ([RobotTarget(robot_urdf, robot_map or None) for _ in prefixes] if robot_urdf
                  else [None] * len(prefixes))
        self.performers = [
            Performer(self, prefix, s, qos, trajectory_qos, publish_markers, bounds,
                      Chunker(trajectory_points, self.period_ns, s.gap_seconds, velocities),
                      robot, robot and Chunker(trajectory_points, self.period_ns, s.gap_seconds, velocities))
            for prefix, s, robot in zip(prefixes, sessions, robots)]
        self._reference = None  # the codes of the reference parameter's clip, once read
        if self.settings["reference"]:
            self._staged[self.settings["reference"]] = self._read_reference(self.settings["reference"])
        self._apply(self.settings)
        skeleton = session.skeleton
        self._bones = np.array([[skeleton.parents[j], j]
                                for j in range(skeleton.pelvis + 1, skeleton.n_joints)]).ravel()
        self._warned: dict[str, float] = {}
        self._diagnostics = self.create_publisher(DiagnosticArray, "/diagnostics", 10)
        self._timer = self.create_timer(1.0, self._publish_diagnostics)
        self._reset_service = self.create_service(Trigger, "~/reset", self._reset)
        self.get_logger().info(
            f"stylizing {', '.join(p.input for p in self.performers)} "
            f"with {session.model.path.name} ({backend}, {session.fps:g} Hz model, "
            f"{1e3 * session.latency:.1f} ms latency) into {self.settings['target_style']!r}")

    # --- parameters ---------------------------------------------------------------------------

    def _problem(self, key: str, value) -> str | None:
        """Why ``value`` is no value for the live parameter ``key``, or None. (Ranges are checked
        by the descriptors before the callback runs.)"""
        want = DYNAMIC[key]
        if type(value) is not want:
            got = TYPE_NAMES.get(type(value), type(value).__name__)
            return f"{key} must be of type {TYPE_NAMES[want]}, got {got} {value!r}"
        if key in ("target_style", "mix_style") and value not in self.styles and not (
                key == "mix_style" and value == ""):
            return (f"unknown style {value!r}; this model knows: {', '.join(self.styles)}"
                    + (" ('' = no mix)" if key == "mix_style" else ""))
        if key == "reference" and value and not self.spec.reference_clips:
            return (f"a reference clip needs backend {' or '.join(with_feature('reference_clips'))} (its "
                    f"style encoder); this node runs {self.backend}: '' is the only value allowed")
        return None

    def _on_set_parameters(self, parameters) -> SetParametersResult:
        """Check a change; nothing changes until it is applied."""
        changes = {p.name: p.value for p in parameters if p.name in DYNAMIC}
        if not self.performers:  # a managed node not configured yet: checked at configure
            return SetParametersResult(successful=True)
        for key, value in changes.items():
            if reason := self._problem(key, value):
                return SetParametersResult(successful=False, reason=reason)
        path = changes.get("reference")
        if path and path != self._reverting:
            try:
                self._check_reference(path)
            except MotionStyleError as exc:
                return SetParametersResult(successful=False, reason=" ".join(str(exc).split()))
        return SetParametersResult(successful=True)

    def _post_set_parameters(self, parameters) -> None:
        """Queue an accepted change for the executor's next frame; a new reference clip first goes
        to a worker thread, which queues it once it is read."""
        changes = {p.name: p.value for p in parameters if p.name in DYNAMIC}
        if not changes or not self.performers:
            return
        path = changes.get("reference")
        reverting, self._reverting = "reference" in changes and path == self._reverting, None
        if reverting and path:
            self._staged[path] = self._reference
        elif path:
            self._loads += 1
            previous = self.settings["reference"]
            threading.Thread(target=self._load_reference, args=(path, previous, changes, self._loads),
                             daemon=True).start()
            return
        self._pending.append(changes)

    def _check_reference(self, path: str) -> None:
        """What can be known of a reference clip at once: a readable BVH file, long enough."""
        frames, frame_time = bvh.duration(path)
        session = self.performers[0].session
        if frames * frame_time * session.fps < session.window:
            raise MotionStyleError(
                f"reference clip too short: {frames * frame_time:.2f} s; it needs at least "
                f"{session.window / session.fps:.1f} s ({session.window} frames at {session.fps:g} fps)")

    def _load_reference(self, path: str, previous: str, changes: dict, load: int) -> None:
        """The worker thread: read, retarget and encode the clip, then queue the change, or
        log why the clip cannot be used and set the parameter back."""
        try:
            self._staged[path] = self._read_reference(path)
        except MotionStyleError as exc:
            self.get_logger().error(f"parameter reference: {' '.join(str(exc).split())}; keeping "
                                    f"{previous or 'the latent seed'!r}")
            self._pending.append({"_revert_reference": previous})
            return
        if load == self._loads:  # else a newer clip was asked for meanwhile
            self._pending.append(changes)

    def _read_reference(self, path: str) -> tuple:
        """A reference clip's style codes and logits (the slow part: read, retarget, encode)."""
        return self.performers[0].session.reference_codes(canonical_clip(path))

    def _apply_pending(self) -> None:
        while self._pending:
            changes = self._pending.popleft()
            if "_revert_reference" in changes:
                self._reverting = changes["_revert_reference"]
                self.set_parameters([Parameter("reference", value=self._reverting)])
                continue
            self._apply(changes)
            self.settings.update(changes)

    def _apply(self, changes: dict) -> None:
        """Hand changed controls to every session; they blend in from the next frame. A reference
        clip is read (and checked) when it is set, before anything changes; it stays in use when the
        target style or the seed changes (the seed's codes are derived again, then the clip's
        replaces the target style's), without being read again."""
        settings = {**self.settings, **changes}
        reference = None
        if self.spec.reference_clips and settings["reference"] and (
                {"reference", "target_style", "latent_seed", "seed_spread"} & changes.keys()):
            reference = (self._staged.pop(settings["reference"]) if "reference" in changes
                         else self._reference)
        if "reference" in changes or reference is not None:
            self._reference = reference  # None once the parameter is emptied
        for p in self.performers:
            if "target_style" in changes:
                p.session.set_style(changes["target_style"])
            if "alpha" in changes:
                p.session.set_alpha(changes["alpha"])
            if "mix_style" in changes or "mix_weight" in changes:
                p.session.set_mix(settings["mix_style"] or None, settings["mix_weight"])
            if not self.spec.latent_seeds:
                continue
            if {"latent_seed", "seed_spread"} & changes.keys() or (
                    "reference" in changes and not settings["reference"]):
                p.session.set_seed(settings["latent_seed"], spread=settings["seed_spread"])
            if reference is not None:
                p.session.use_reference(*reference, settings["target_style"])

    # --- streaming ------------------------------------------------------------------------------

    def on_state(self, p: Performer, msg: JointState, info: MessageInfo) -> None:
        if self._pending:
            self._apply_pending()
        p.counts["frames_in"] += 1
        own_ns = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
        try:
            positions = p.intake.check_values(msg.name, msg.position)
            try:
                p.intake.check_angles(*self.layout.angles(msg.name, positions))
                rotations, root = self.layout.decode(msg.name, positions)
            except MotionStyleError as exc:
                raise Dropped("bad_names", str(exc)) from None
            frame = p.intake.admit(own_ns, info["received_timestamp"], root)
            if frame.restart:
                self._restart(p, "new_timeline", "its frames agree on a new clock or place for "
                              f"{p.intake.bounds.restart_seconds:g} s")
            try:
                rotations, root = p.session.step(rotations, root, ns_seconds(frame.stamp_ns))
            except MotionStyleError as exc:
                raise Dropped("invalid_frame", str(exc)) from None
        except Dropped as drop:
            p.counts[f"dropped_{drop.reason}"] += 1
            what = drop.reason.replace("_", " ")
            self._warn(drop.reason, f"{p.input}: dropped a JointState ({what}): {drop}")
            return
        if not (np.isfinite(rotations).all() and np.isfinite(root).all()):
            self._restart(p, "non_finite_output", "the model's output was not finite")
            return
        p.intake.commit(frame, own_ns)
        stamp = msg.header.stamp if own_ns else Time(sec=frame.stamp_ns // 1_000_000_000,
                                                      nanosec=frame.stamp_ns % 1_000_000_000)
        self._use_names(p, msg.name)
        out = positions.copy()  # names the layout ignores or passes through: as they came, in step
        if p.extra.size:
            p.delay.push(frame.stamp_ns, positions[p.extra])
            out[p.extra] = p.delay.at(frame.stamp_ns - p.latency_ns)
        out[p.slots] = self.layout.encode(rotations, root)
        frame_id = self.settings["frame_id"] or msg.header.frame_id
        p.state_out.publish(joint_state(p.names, out, stamp, frame_id))
        now = time.time_ns()
        p.latencies.append((now, now - info["received_timestamp"]))
        p.counts["frames_out"] += 1
        self._add_point(p, frame.stamp_ns, out, frame_id)
        if p.markers_out is not None:
            p.markers_out.publish(self._markers(p, rotations, root, stamp))
        if p.robot is not None:
            self._robot(p, rotations, root, stamp, frame.stamp_ns, frame_id)
        p.session.catch_up()  # pipelined: the model frames of this input, now that it is sent on

    def _restart(self, p: Performer, reason: str, why: str) -> None:
        """Start the performer's stream afresh (its rig measurements kept), counted by reason."""
        self._flush(p)
        p.session.reset()
        p.session.restart()
        p.clear()
        p.counts[f"restarted_{reason}"] += 1
        self.get_logger().warning(f"{p.input}: stream restarted ({reason.replace('_', ' ')}): {why}")

    def _robot(self, p: Performer, rotations: np.ndarray, root: np.ndarray, stamp, stamp_ns: int,
               frame_id: str) -> None:
        """The stylized frame on the robot: its joints (JointState, trajectory chunks) and base."""
        q = p.robot.step(rotations, root, ns_seconds(stamp_ns))
        p.robot_state_out.publish(joint_state(p.robot.names, q, stamp, frame_id))
        for chunk in p.robot_chunker.add(stamp_ns, q):
            p.robot_trajectory_out.publish(trajectory(p.robot.names, chunk, frame_id))
        position, quat = p.robot.base_pose
        pose = PoseStamped()
        pose.header.stamp, pose.header.frame_id = stamp, frame_id or "world"
        pose.pose.position.x, pose.pose.position.y, pose.pose.position.z = position.tolist()
        o = pose.pose.orientation
        o.w, o.x, o.y, o.z = quat.tolist()
        p.robot_base_out.publish(pose)

    def _use_names(self, p: Performer, names) -> None:
        """Where the layout's names sit in this message (worked out again when they change); a
        trajectory never mixes two name lists."""
        if tuple(names) == p.names:
            return
        self._flush(p)
        p.names = tuple(names)
        where = {n: i for i, n in enumerate(p.names)}
        p.slots = np.array([where[n] for n in self.layout.names], dtype=np.intp)
        p.extra = np.setdiff1d(np.arange(len(p.names)), p.slots)
        p.delay.clear()
        angular = np.zeros(len(p.names), dtype=bool)
        angular[p.slots] = self.layout.angular
        p.chunker.clear(angular)

    def _add_point(self, p: Performer, stamp_ns: int, positions: np.ndarray, frame_id: str) -> None:
        """Queue one trajectory point; publish the chunks it completes (runtime.trajectory)."""
        p.chunk_frame_id = frame_id
        for chunk in p.chunker.add(stamp_ns, positions):
            self._publish_chunk(p, chunk)

    def _flush(self, p: Performer) -> None:
        """Publish the chunk that is still filling."""
        for chunk in p.chunker.flush():
            self._publish_chunk(p, chunk)
        if p.robot is not None:
            for chunk in p.robot_chunker.flush():
                p.robot_trajectory_out.publish(trajectory(p.robot.names, chunk, p.chunk_frame_id))

    def _publish_chunk(self, p: Performer, chunk: Chunk) -> None:
        p.trajectory_out.publish(trajectory(p.names, chunk, p.chunk_frame_id))

    def _markers(self, p: Performer, rotations: np.ndarray, root: np.ndarray, stamp) -> MarkerArray:
        """The stylized skeleton's bones below the pelvis as one LINE_LIST, in REP-103 axes."""
        skeleton = p.session.skeleton
        offsets = skeleton.offsets.copy()
        offsets[skeleton.pelvis] = root
        ends = to_ros(forward_kinematics(skeleton, rotations, offsets)[1][self._bones])
        marker = Marker(ns=p.prefix or NAME, id=0, type=Marker.LINE_LIST, action=Marker.ADD,
                        points=[Point(x=x, y=y, z=z) for x, y, z in ends.tolist()])
        marker.header.stamp = stamp
        marker.header.frame_id = self.settings["frame_id"] or "world"
        marker.pose.orientation.w = 1.0
        marker.scale.x = 0.03  # line width, m
        marker.color.r, marker.color.g, marker.color.b, marker.color.a = 0.95, 0.45, 0.1, 1.0
        return MarkerArray(markers=[marker])

    def _warn(self, kind: str, message: str) -> None:
        now = time.monotonic()
        if now - self._warned.get(kind, -np.inf) >= WARN_EVERY:
            self._warned[kind] = now
            self.get_logger().warning(message)

    # --- service and diagnostics --------------------------------------------------------------

    def _reset(self, request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        for p in self.performers:
            self._flush(p)
            p.session.reset(recalibrate=True)
            p.session.restart()
            p.clear()
        response.success = True
        response.message = (f"reset {len(self.performers)} performer(s): each one's next frame "
                            "starts a fresh stream, its rig measured again")
        return response

    def _publish_diagnostics(self) -> None:
        if self._pending:
            self._apply_pending()
        array = DiagnosticArray(status=[self._status(p) for p in self.performers])
        array.header.stamp = self.get_clock().now().to_msg()
        self._diagnostics.publish(array)

    def _status(self, p: Performer) -> DiagnosticStatus:
        dropped = p.dropped
        since = time.time_ns() - round(LATENCY_SECONDS * 1e9)
        while p.latencies and p.latencies[0][0] < since:
            p.latencies.popleft()
        ms = 1e-6 * np.array([latency for _, latency in p.latencies])
        p50, p99 = (np.percentile(ms, [50, 99]) if len(ms) else (np.nan, np.nan))
        calibration = p.session.calibration()
        if calibration["state"] not in (p.calibration_state, "measuring"):  # once per change
            unmeasured = calibration["state"] == "arms never hung"
            (self.get_logger().warn if unmeasured else self.get_logger().info)(
                f"{p.input}: {describe_calibration(calibration)}")
        p.calibration_state = calibration["state"]
        values = {**p.counts, "dropped": dropped, "gaps": p.intake.gaps,
                  "frames_missing": p.intake.frames_missing, "longest_gap_s": f"{p.intake.longest_gap_s:.3f}",
                  "latency_p50_ms": f"{p50:.3f}",
                  "latency_p99_ms": f"{p99:.3f}", "output_latency_ms": f"{p.latency_ns * 1e-6:.3f}",
                  "model": str(p.session.model.path),
                  "backend": self.backend, "input": p.input,
                  **{f"calibration_{k}": v for k, v in calibration.items()},
                  **{k: self.settings[k] for k in ("target_style", "alpha", "mix_style", "mix_weight",
                                              "latent_seed", "seed_spread", "reference")}}
        counts = {**p.counts, "dropped": dropped}
        now = time.monotonic()
        level, reasons = health(p.reported, counts, now - p.reported_at, p.session.input_fps,
                                float(p99) if len(ms) else 0.0, self.max_latency_ms)
        p.reported, p.reported_at = counts, now
        summary = f"{p.counts['frames_in']} frames in, {p.counts['frames_out']} out, {dropped} dropped"
        return DiagnosticStatus(
            level=LEVELS[level], name=f"{self.get_name()}: {p.input}",
            message=f"{'; '.join(reasons)} ({summary})" if reasons else summary,
            hardware_id=p.session.model.path.name,
            values=[KeyValue(key=k, value=str(v)) for k, v in values.items()])

    # --- lifecycle ----------------------------------------------------------------------------

    def _activate(self) -> None:
        for p in self.performers:
            p.subscribe(self)

    def _deactivate(self) -> None:
        """Stop listening, so nothing more is published; the streams start afresh on activation."""
        for p in self.performers:
            self._flush(p)
            p.destroy(self, publishers=False)
            p.session.restart()
            p.clear()

    def _cleanup(self) -> None:
        """Free the sessions, publishers, timer and services (a managed node can configure again)."""
        for p in self.performers:
            p.destroy(self, publishers=True)
        for thing, destroy in ((self._timer, self.destroy_timer), (self._reset_service, self.destroy_service),
                               (self._diagnostics, self.destroy_publisher)):
            destroy(thing)
        self.performers, self._pending, self._staged = [], deque(), {}


def trajectory(names, chunk: Chunk, frame_id: str) -> JointTrajectory:
    """One JointTrajectory; its header.stamp stays zero ("start on receipt" for
    JointTrajectoryController: the frames are already past)."""
    msg = JointTrajectory(joint_names=list(names))
    msg.header.frame_id = frame_id
    for offset, positions, velocities in zip(chunk.times_ns, chunk.positions, chunk.velocities):
        msg.points.append(JointTrajectoryPoint(
            positions=positions.tolist(), velocities=[] if velocities is None else velocities.tolist(),
            time_from_start=Duration(sec=offset // 1_000_000_000, nanosec=offset % 1_000_000_000)))
    return msg


def ns_seconds(ns: int) -> float:
    """A stamp in nanoseconds as the session's float seconds (offline replays convert stamps the
    same way: :func:`stamp_seconds`)."""
    return ns // 1_000_000_000 + (ns % 1_000_000_000) * 1e-9


class Stylizer(StylizerBase, PlayerNode):
    """The plain node: configured and streaming from the start."""

    def __init__(self) -> None:
        PlayerNode.__init__(self, NAME)
        self._setup()
        self._configure()
        self._activate()


def stamp_seconds(stamp: Time) -> float:
    return ns_seconds(stamp.sec * 1_000_000_000 + stamp.nanosec)


def seconds(ns: int) -> str:
    """Nanoseconds as exact decimal seconds (a float would blur the last digits)."""
    return f"{ns // 1_000_000_000}.{ns % 1_000_000_000:09d}"


def main(args=None) -> int:
    return run(Stylizer, NAME, args)



if __name__ == "__main__":
    sys.exit(main())
