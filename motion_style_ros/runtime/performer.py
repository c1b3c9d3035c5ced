"""One performer of the stylizer node, without ROS: everything the node does with a JointState
between its subscription and its publishers, so that it is tested without a ROS graph.

A frame goes through the intake (:mod:`~motion_style_ros.runtime.intake`: values, stamps,
plausibility, restarts on a new timeline), is decoded by the layout, stylized by the session and
encoded back in the message's own name order; names the layout does not stylize (a VMC avatar's
fingers, a robot's extra joints) go out as they came, with the pose they came with. Each output is
queued as a trajectory point (:mod:`~motion_style_ros.runtime.trajectory`) and, with a robot
target, mapped onto the robot. What goes out is handed to an :class:`Outputs` (the node's
publishers); drops and restarts are counted, and :meth:`PerformerStream.status` turns the counts
into a diagnostics level (:mod:`~motion_style_ros.runtime.health`).
"""

from __future__ import annotations

import time
from collections import deque
from typing import Protocol

import numpy as np

from motion_style_ros.core.motion import forward_kinematics
from motion_style_ros.errors import MotionStyleError
from motion_style_ros.io.joint_state import FrameDelay, JointStateLayout, to_ros
from motion_style_ros.runtime.health import health
from motion_style_ros.runtime.intake import DROP_REASONS, RESTART_REASONS, Bounds, Dropped, Intake
from motion_style_ros.runtime.robot_target import RobotTarget
from motion_style_ros.runtime.trajectory import Chunk, Chunker

WARN_EVERY = 10.0  # s between two warnings of the same kind
LATENCY_SECONDS = 5.0  # the latency percentiles are over the frames published in this last time
# the live controls, as the diagnostics report them
CONTROLS = ("target_style", "alpha", "mix_style", "mix_weight", "latent_seed", "seed_spread", "reference")


class Outputs(Protocol):
    """Where a performer's outputs go (the node's publishers); stamps in nanoseconds."""

    def state(self, names: tuple[str, ...], positions: np.ndarray, stamp_ns: int, frame_id: str,
              rotations: np.ndarray, root: np.ndarray) -> None: ...

    def trajectory(self, names: tuple[str, ...], chunk: Chunk, frame_id: str) -> None: ...

    def robot_state(self, names: list[str], positions: np.ndarray, stamp_ns: int, frame_id: str,
                    base_position: np.ndarray, base_orientation: np.ndarray) -> None: ...

    def robot_trajectory(self, names: list[str], chunk: Chunk, frame_id: str) -> None: ...


class Logger(Protocol):
    def info(self, message: str) -> None: ...

    def warning(self, message: str) -> None: ...


class PerformerStream:
    """One performer's stream (see the module docstring). ``name`` is its input topic, for logs and
    the diagnostics."""

    def __init__(self, name: str, session, layout: JointStateLayout, bounds: Bounds, chunker: Chunker,
                 outputs: Outputs, logger: Logger, robot: RobotTarget | None = None,
                 robot_chunker: Chunker | None = None) -> None:
        self.name = name
        self.session = session
        self.layout = layout
        self.outputs = outputs
        self.logger = logger
        self.counts = dict.fromkeys(["frames_in", "frames_out", *(f"dropped_{r}" for r in DROP_REASONS),
                                     *(f"restarted_{r}" for r in RESTART_REASONS)], 0)
        self.intake = Intake(bounds, 1.0 / session.input_fps)
        self.chunker = chunker
        self.robot, self.robot_chunker = robot, robot_chunker
        # (publish time, latency from DDS receipt to publication), both ns
        self.latencies: deque[tuple[int, int]] = deque()
        self.reported: dict[str, int] = {}  # the counters at the last status, and when
        self.reported_at = time.monotonic()
        self.calibration_state = "measuring"  # logged when it changes
        self.warned: dict[str, float] = {}
        self.names: tuple[str, ...] = ()
        self.slots = np.zeros(0, dtype=np.intp)  # input index of each layout name
        self.extra = np.zeros(0, dtype=np.intp)  # input index of each other name (passed through)
        # The other names' values go out with the pose they came with: the frame of stamp - latency.
        self.delay = FrameDelay(session.gap_seconds)
        self.latency_ns = round(session.latency * 1e9)
        sk = session.skeleton
        self._bones = np.array([[sk.parents[j], j] for j in range(sk.pelvis + 1, sk.n_joints)]).ravel()
        self.clear()

    @property
    def dropped(self) -> int:
        return sum(self.counts[f"dropped_{r}"] for r in DROP_REASONS)

    def clear(self) -> None:
        """Forget the stream: the next frame may have any stamp and starts a new trajectory."""
        self.intake.clear()
        self.chunker.clear()
        if self.robot is not None:
            self.robot.reset()
            self.robot_chunker.clear(np.zeros(len(self.robot.names), dtype=bool))
        self.chunk_frame_id = ""
        self.delay.clear()

    def frame(self, names, positions, stamp_ns: int, receipt_ns: int, frame_id: str) -> None:
        """One JointState (``stamp_ns`` 0: unstamped; ``frame_id``: the outputs'): stylized and
        handed on, or dropped and counted."""
        self.counts["frames_in"] += 1
        try:
            values = self.intake.check_values(names, positions)
            try:
                self.intake.check_angles(*self.layout.angles(names, values))
                rotations, root = self.layout.decode(names, values)
            except MotionStyleError as exc:
                raise Dropped("bad_names", str(exc)) from None
            frame = self.intake.admit(stamp_ns, receipt_ns, root)
            if frame.restart:
                self.restart("new_timeline", "its frames agree on a new clock or place for "
                             f"{self.intake.bounds.restart_seconds:g} s")
            try:
                rotations, root = self.session.step(rotations, root, seconds(frame.stamp_ns))
            except MotionStyleError as exc:
                raise Dropped("invalid_frame", str(exc)) from None
        except Dropped as drop:
            self.counts[f"dropped_{drop.reason}"] += 1
            self.warn(drop.reason, f"{self.name}: dropped a JointState ({drop.reason.replace('_', ' ')}): {drop}")
            return
        if not (np.isfinite(rotations).all() and np.isfinite(root).all()):
            self.restart("non_finite_output", "the model's output was not finite")
            return
        self.intake.commit(frame, stamp_ns)
        out_stamp = stamp_ns or frame.stamp_ns  # an unstamped frame goes out on the stream's clock
        self._use_names(names)
        out = values.copy()  # names the layout ignores or passes through: as they came, in step
        if self.extra.size:
            self.delay.push(frame.stamp_ns, values[self.extra])
            out[self.extra] = self.delay.at(frame.stamp_ns - self.latency_ns)
        out[self.slots] = self.layout.encode(rotations, root)
        self.outputs.state(self.names, out, out_stamp, frame_id, rotations, root)
        now = time.time_ns()
        self.latencies.append((now, now - receipt_ns))
        self.counts["frames_out"] += 1
        self.chunk_frame_id = frame_id
        for chunk in self.chunker.add(frame.stamp_ns, out):
            self.outputs.trajectory(self.names, chunk, frame_id)
        if self.robot is not None:
            q = self.robot.step(rotations, root, seconds(frame.stamp_ns))
            self.outputs.robot_state(self.robot.names, q, out_stamp, frame_id, *self.robot.base_pose)
            for chunk in self.robot_chunker.add(frame.stamp_ns, q):
                self.outputs.robot_trajectory(self.robot.names, chunk, frame_id)
        self.session.catch_up()  # pipelined: the model frames of this input, now that it is sent on

    def bone_lines(self, rotations: np.ndarray, root: np.ndarray) -> np.ndarray:
        """``(2B, 3)``: each bone below the pelvis of a stylized frame as a start and an end point,
        REP-103 axes (what RViz draws as a LINE_LIST)."""
        sk = self.session.skeleton
        offsets = sk.offsets.copy()
        offsets[sk.pelvis] = root
        return to_ros(forward_kinematics(sk, rotations, offsets)[1][self._bones])

    def restart(self, reason: str, why: str) -> None:
        """Start the stream afresh (its rig measurements kept), counted by reason."""
        self.flush()
        self.session.reset()
        self.session.restart()
        self.clear()
        self.counts[f"restarted_{reason}"] += 1
        self.logger.warning(f"{self.name}: stream restarted ({reason.replace('_', ' ')}): {why}")

    def reset(self, recalibrate: bool = False) -> None:
        """Start afresh on the next frame (``recalibrate``: measure the rig again too)."""
        self.flush()
        self.session.reset(recalibrate=recalibrate)
        self.session.restart()
        self.clear()

    def flush(self) -> None:
        """Hand on the trajectory chunks that are still filling."""
        for chunk in self.chunker.flush():
            self.outputs.trajectory(self.names, chunk, self.chunk_frame_id)
        if self.robot is not None:
            for chunk in self.robot_chunker.flush():
                self.outputs.robot_trajectory(self.robot.names, chunk, self.chunk_frame_id)

    def warn(self, kind: str, message: str) -> None:
        """A warning, at most once every :data:`WARN_EVERY` seconds per kind."""
        now = time.monotonic()
        if now - self.warned.get(kind, -np.inf) >= WARN_EVERY:
            self.warned[kind] = now
            self.logger.warning(message)

    def status(self, controls: dict, backend: str, max_latency_ms: float) -> tuple[int, str, dict]:
        """The performer's diagnostics: level (runtime.health), message and key values, from the
        counts since the last status; ``controls``: the node's live settings."""
        dropped = self.dropped
        since = time.time_ns() - round(LATENCY_SECONDS * 1e9)
        while self.latencies and self.latencies[0][0] < since:
            self.latencies.popleft()
        ms = 1e-6 * np.array([latency for _, latency in self.latencies])
        p50, p99 = (np.percentile(ms, [50, 99]) if len(ms) else (np.nan, np.nan))
        calibration = self.session.calibration()
        if calibration["state"] not in (self.calibration_state, "measuring"):  # once per change
            unmeasured = calibration["state"] == "arms never hung"
            (self.logger.warning if unmeasured else self.logger.info)(
                f"{self.name}: {describe_calibration(calibration)}")
        self.calibration_state = calibration["state"]
        intake = self.intake
        values = {**self.counts, "dropped": dropped, "gaps": intake.gaps,
                  "frames_missing": intake.frames_missing, "longest_gap_s": f"{intake.longest_gap_s:.3f}",
                  "latency_p50_ms": f"{p50:.3f}", "latency_p99_ms": f"{p99:.3f}",
                  "output_latency_ms": f"{self.latency_ns * 1e-6:.3f}",
                  "model": str(self.session.model.path), "backend": backend, "input": self.name,
                  **{f"calibration_{k}": v for k, v in calibration.items()},
                  **{k: controls[k] for k in CONTROLS}}
        counts = {**self.counts, "dropped": dropped}
        now = time.monotonic()
        level, reasons = health(self.reported, counts, now - self.reported_at, self.session.input_fps,
                                float(p99) if len(ms) else 0.0, max_latency_ms)
        self.reported, self.reported_at = counts, now
        summary = f"{self.counts['frames_in']} frames in, {self.counts['frames_out']} out, {dropped} dropped"
        return level, f"{'; '.join(reasons)} ({summary})" if reasons else summary, values

    def _use_names(self, names) -> None:
        """Where the layout's names sit in this message (worked out again when they change); a
        trajectory never mixes two name lists."""
        if tuple(names) == self.names:
            return
        self.flush()
        self.names = tuple(names)
        where = {n: i for i, n in enumerate(self.names)}
        self.slots = np.array([where[n] for n in self.layout.names], dtype=np.intp)
        self.extra = np.setdiff1d(np.arange(len(self.names)), self.slots)
        self.delay.clear()
        angular = np.zeros(len(self.names), dtype=bool)
        angular[self.slots] = self.layout.angular
        self.chunker.clear(angular)


def seconds(ns: int) -> float:
    """A stamp in nanoseconds as the session's float seconds (offline replays convert stamps the
    same way)."""
    return ns // 1_000_000_000 + (ns % 1_000_000_000) * 1e-9


def describe_calibration(calibration: dict) -> str:
    """One line for a log: what :meth:`StreamSession.calibration` found."""
    if calibration["state"] == "off":
        return "stream conditioning is off"
    line = (f"stream measured ({calibration['state']}): arm rolls {calibration['arm_rolls_deg']} deg, "
            f"size {calibration['scale']:g} of the training performers'")
    if calibration["state"] == "arms never hung":
        line += "; the arms stay as they come until they hang by the body for a moment"
    return line
