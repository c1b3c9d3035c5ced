"""The streaming stylizer: one canonical-skeleton frame per performer in, one stylized frame out.

A :class:`RecurrentSession` wraps a recurrent ONNX stylizer (the Style-ERD contract: raw
``encode()`` features, style weights, alpha, the LSTM state and a reset flag in; the stylized
``[root | rot6d]`` blocks and the next state out) and carries everything a live stream needs
between calls:

- **Rates.** The model runs on its own clock (``fps``, 30 Hz) with one ONNX call per model frame
  for all performers together. Each model frame's input is interpolated between the two input
  frames around its time (slerp, lerp), so nothing waits for a future frame. Each input frame
  gets an output: the model's frames interpolated at ``stamp - latency`` with
  ``latency = 1 / fps - 1 / input_fps`` (0 for 30 Hz input, 25 ms for 120 Hz), so the output
  comes at the input's rate, evenly spaced and smooth; at rates that are not multiples of the
  model's, an output whose time is past the newest model frame holds it. Latency never exceeds
  one model frame.
- **Pipelining.** With ``pipelined``, the output is one input frame later (``latency`` grows by
  ``1 / input_fps``, to 33.3 ms at 120 Hz input) and needs no model frame of its own input frame:
  :meth:`~RecurrentSession.step` returns it before running them, and :meth:`~RecurrentSession.catch_up`
  runs them once the caller has sent the output on (the next call runs them first otherwise). A
  live node's every frame then costs an interpolation on its way through, the model's work
  happens between frames, and the outputs are exactly those of an unpipelined session one input
  frame later.
- **Gaps and restarts.** A stamp more than ``gap_seconds`` after the previous one, or earlier
  than it, restarts the stream: every performer starts afresh on the next frame.
- **Trajectory.** The model outputs the root's velocity and yaw rate in the facing frame; they are
  integrated (:class:`~motion_style_ros.core.features.StreamDecoder`) from where the performer
  stood and faced on its first frame (and after every reset, which snaps it back there), so the
  stylized root moves with its own speed and turns. It drifts from the input's trajectory (a
  slower style falls behind); with ``follow_seconds`` set, the integrated ground point and heading
  are pulled towards the input's with that time constant instead, which bounds the drift (the
  stylized avatar keeps up with its performer on average).
- **Foot locking.** With ``foot_lock`` (the default), feet the input plants stay planted in the
  output and feet it lifts are no lower (:mod:`motion_style_ros.core.foot_lock`: causal two-bone
  leg IK on each model frame), and a performer standing on both feet keeps the input's root
  motion (:mod:`motion_style_ros.core.standing`), so the style does not walk them away.
- **Grounding.** With ``ground`` (the default), each performer's stream is moved down by how far
  its planted ankles rest above the training data's (:class:`~motion_style_ros.core.conform.StreamGround`:
  set on its first frame from the lower ankle, then followed while an ankle stands still) before
  the stylizer, and the output is moved back up: other rigs' ankle joints sit higher or lower
  above the sole, and the stylizers and the foot contact handling read absolute heights. The
  output keeps the input's floor.
- **Controls.** Style, alpha and a second style with a mix weight change between any two
  frames and blend over ``blend_seconds`` (:mod:`motion_style_ros.runtime.controls`).
- **Bad input.** A frame with the wrong shape or dtype, NaN/Inf or non-unit quaternions raises
  :class:`MotionStyleError` before anything changes: the next good frame continues as if the
  bad one never came. Quaternions within 10 % of unit length are normalised.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from motion_style_ros.core import rotations as rot
from motion_style_ros.core.conform import ANKLES, ROLL_MIN_FRAMES, StreamGround, StreamRolls
from motion_style_ros.core.features import FEATURE_VERSION, UP, StreamDecoder, StreamEncoder
from motion_style_ros.core.foot_lock import FootLock
from motion_style_ros.core.motion import Motion, forward_kinematics
from motion_style_ros.core.proportions import CONTACTS, StreamScale, clip_scale
from motion_style_ros.core.resample import Hermite, resample
from motion_style_ros.core.skeleton import canonical
from motion_style_ros.core.standing import Standing
from motion_style_ros.errors import MotionStyleError
from motion_style_ros.io.datasets import rotation_stats
from motion_style_ros.runtime.controls import Controls
from motion_style_ros.runtime.onnx_model import OnnxModel, model_path, read_card

INPUTS = ("features", "style", "alpha", "state", "reset")
QUATERNION_TOLERANCE = 0.1  # |norm - 1| above this is rejected, below it normalised
STAMP_TOLERANCE = 1e-6  # s: a model frame this close to an input frame takes that frame as it is


class RecurrentSession:
    """A recurrent stylizer over a stream of ``performers`` performers (see the module docstring).

    ``model``: a shipped model's file name or a path (the card beside it); ``input_fps``: the
    stream's nominal rate (default: the model's), which sets the output latency; ``threads``:
    ONNX Runtime threads; ``phase_seconds`` (in [0, 1 / fps)): how much later than the stream's
    start the model's clock ticks, so that sessions serving several streams in one process run
    their model frames on different input frames rather than all on the same one; ``foot_lock``,
    ``ground`` and ``pipelined``: see the module docstring. Until :meth:`set_style`, every
    performer gets the model's neutral style (its card's ``neutral_style``) at alpha 1.
    """

    def __init__(
        self,
        model: str | Path = "style_erd.onnx",
        performers: int = 1,
        input_fps: float | None = None,
        blend_seconds: float = 0.3,
        threads: int = 1,
        gap_seconds: float = 0.5,
        follow_seconds: float | None = None,
        foot_lock: bool = True,
        phase_seconds: float = 0.0,
        ground: bool = True,
        pipelined: bool = False,
        conform: bool = True,
    ) -> None:
        path = model_path(str(model))
        card = read_card(path)
        _check_card(card, path)
        self.model = OnnxModel(path, threads)
        missing = set(INPUTS) - set(self.model.input_names)
        if missing:
            raise MotionStyleError(
                f"{path}: not a recurrent stylizer (no inputs {', '.join(sorted(missing))})"
            )
        self._setup_stream(card, performers, input_fps, blend_seconds, gap_seconds, follow_seconds,
                           foot_lock, ground, pipelined, conform=conform)
        self._state = np.zeros((self.performers, int(card["state_size"])), dtype=np.float32)
        if not (isinstance(phase_seconds, (int, float)) and 0.0 <= phase_seconds < 1.0 / self.fps):
            raise MotionStyleError(f"phase_seconds must be in [0, {1.0 / self.fps:g}), got {phase_seconds!r}")
        self._phase = float(phase_seconds)
        self.restart()

    def _setup_stream(self, card: dict, performers: int, input_fps: float | None, blend_seconds: float,
                      gap_seconds: float, follow_seconds: float | None, foot_lock: bool, ground: bool,
                      pipelined: bool, delay_frames: int = 0, conform: bool = True,
                      extra_styles: tuple[str, ...] = ()) -> None:
        """Everything of the stream that does not depend on the model: rates and latency (plus
        ``delay_frames`` model frames of the model's own, and an input frame when ``pipelined``),
        controls (over the card's styles and ``extra_styles``), feature encoder and decoder, foot
        locking."""
        if not (isinstance(performers, (int, np.integer)) and performers >= 1):
            raise MotionStyleError(f"performers must be a whole number, at least 1; got {performers!r}")
        self.card = card
        self.styles: list[str] = [*card["styles"], *extra_styles]
        self.fps = float(card["fps"])
        self.performers = int(performers)
        self.input_fps = self.fps if input_fps is None else _positive(input_fps, "input frame rate")
        if not isinstance(pipelined, (bool, np.bool_)):
            raise MotionStyleError(f"pipelined must be true or false, got {pipelined!r}")
        self.pipelined = bool(pipelined)
        self.latency = (delay_frames / self.fps + max(0.0, 1.0 / self.fps - 1.0 / self.input_fps)
                        + (1.0 / self.input_fps if self.pipelined else 0.0))
        self.gap_seconds = _positive(gap_seconds, "gap time")
        self._follow_gain = (
            0.0 if follow_seconds is None
            else 1.0 - np.exp(-1.0 / (self.fps * _positive(follow_seconds, "follow time")))
        )
        self.skeleton = canonical()
        neutral = card.get("neutral_style", self.styles[0])
        self._controls = Controls(self.styles, self.performers, neutral, blend_seconds)
        self._encoder = StreamEncoder(self.performers, self.fps, self.skeleton)
        self._decoder = StreamDecoder(self.performers, self.fps, self.skeleton)
        self._foot_lock = FootLock(self.performers, self.fps, self.skeleton) if foot_lock else None
        self._standing = Standing(self.performers, self.fps, self.skeleton) if foot_lock else None
        stats = rotation_stats()
        self._ground = StreamGround(self.performers, self.fps, stats["ankle_height"]) if ground else None
        self._rolls = StreamRolls(self.performers, self.fps, stats, self.skeleton) if conform else None
        self._scale = StreamScale(self.performers, self.fps, stats["scale_reference"]) if conform else None
        self._contacts = [self.skeleton.index(n) for n in CONTACTS]
        self._ankle_joints = [self.skeleton.index(n) for n in ANKLES]  # what grounding and foot locks read
        self._fresh = np.ones(self.performers, dtype=bool)
        self._remeasured = np.zeros(self.performers, dtype=bool)  # see StreamRolls.observe
        self._phase = 0.0

    # --- controls ---------------------------------------------------------------------------

    def set_style(self, style: str, performer: int | None = None) -> None:
        """Target style of one performer or all (``None``), blended in over ``blend_seconds``."""
        self.catch_up()
        self._controls.set_style(style, performer)

    def set_alpha(self, alpha: float, performer: int | None = None) -> None:
        """Strength of the style in [0, 1]; 0 is the model's neutral branch alone."""
        self.catch_up()
        self._controls.set_alpha(alpha, performer)

    def set_mix(self, style: str | None, weight: float, performer: int | None = None) -> None:
        """Mix a second style in with ``weight`` in [0, 1]; ``None`` removes it."""
        self.catch_up()
        self._controls.set_mix(style, weight, performer)

    def reset(self, performer: int | None = None, recalibrate: bool = False) -> None:
        """Start one performer or all afresh at their next frame: learned initial state, the
        stylized root snapped back to the input's, controls at their targets; with
        ``recalibrate``, the stream's conditioning (arm rolls, size) is measured again too (a new
        rig: it otherwise holds across resets and gaps)."""
        self.catch_up()
        which = self._controls.which(performer)
        if recalibrate and self._rolls is not None:
            self._rolls.clear(which)
            self._scale.clear(which)
        self._fresh[which] = True
        self._encoder.reset(which)

    def calibration(self, performer: int = 0) -> dict:
        """How far a performer's stream has been measured (arm rolls, size; see
        :mod:`motion_style_ros.core.conform`, :mod:`motion_style_ros.core.proportions`): ``state``
        is ``off``, ``measuring`` (the stream's first seconds), ``measured``, ``clip`` (a whole
        clip's, offline) or ``arms never hung`` (the rolls cannot be measured yet: the stream goes
        on unconformed), with the rolls in degrees and the scale."""
        if self._rolls is None:
            return {"state": "off"}
        rolls = self._rolls
        if rolls.frozen[performer]:
            state = "clip"
        elif rolls.frames[performer] < rolls.settle_frames:
            state = "measuring"
        elif (rolls.hanging_frames(performer) < ROLL_MIN_FRAMES).any():
            state = "arms never hung"
        else:
            state = "measured"
        return {"state": state, "arm_rolls_deg": np.degrees(rolls.angles[performer]).round(1).tolist(),
                "scale": round(float(self._scale.scale[performer]), 3)}

    # --- streaming ----------------------------------------------------------------------------

    def step(
        self, rotations: np.ndarray, root_positions: np.ndarray, stamp: float | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """The stylized frame of every performer for one input frame.

        ``rotations`` ``(P, 22, 4)`` local quaternions (w, x, y, z) of the canonical skeleton,
        ``root_positions`` ``(P, 3)`` pelvis positions in metres (for one performer, ``(22, 4)``
        and ``(3,)`` work too); ``stamp`` in seconds (default: ``1 / input_fps`` after the
        previous frame). Returns the same shapes, float64. When ``pipelined``, the frame's model
        frames are left for :meth:`catch_up`.
        """
        q, p, single = self._check_frame(rotations, root_positions)
        self.catch_up()
        stamp = self._check_stamp(stamp)
        if self._stamp is not None and not (0.0 <= stamp - self._stamp <= self.gap_seconds):
            self.restart()
        if self._stamp is None:
            # The first model frame takes the first input frame; with a phase, the second one
            # comes phase_seconds later than it would.
            self._origin = stamp + (self._phase - 1.0 / self.fps if self._phase else 0.0)
            self.reset()
        if self.pipelined and self._outputs:  # a stream's first frame has no model frame yet
            self._pending = stamp, q, p
        else:
            self._advance(stamp, q, p)
        out_q, out_p = self._output(stamp - self.latency)
        return (out_q[0], out_p[0]) if single else (out_q, out_p)

    def catch_up(self) -> None:
        """Run the model frames that the last :meth:`step` left for later (``pipelined``)."""
        if self._pending is not None:
            pending, self._pending = self._pending, None
            self._advance(*pending)

    def run(self, motion: Motion, style: str, alpha: float = 1.0, calibration: Motion | None = None
            ) -> Motion:
        """A whole clip stylized through :meth:`step` (one performer, clip at ``input_fps``), the
        stream conditioned (arm rolls, size) from the whole clip at once, or from ``calibration``."""
        if self.performers != 1:
            raise MotionStyleError(
                f"run() stylizes one clip; this session has {self.performers} performers"
            )
        if motion.fps != self.input_fps:
            raise MotionStyleError(
                f"clip at {motion.fps:g} fps; this session takes {self.input_fps:g} fps input "
                f"(make the session with input_fps={motion.fps:g} or resample the clip)"
            )
        if motion.skeleton.names != self.skeleton.names:
            raise MotionStyleError("run() needs a canonical-skeleton clip (retarget it first)")
        self.set_style(style)
        self.set_alpha(alpha)
        self.set_mix(None, 0.0)
        self.restart()
        if self._rolls is not None:  # offline, the conditioning comes from the whole clip at once
            whole = motion if calibration is None else calibration
            self._rolls.calibrate(0, whole)
            self._scale.calibrate(0, clip_scale(resample(whole, self.fps), self._scale.reference))
        roots = motion.positions[:, self.skeleton.pelvis]
        frames = [self.step(motion.rotations[t : t + 1], roots[t : t + 1], t / motion.fps)
                  for t in range(motion.n_frames)]
        rotations = np.concatenate([q for q, _ in frames])
        positions = np.concatenate([p for _, p in frames])
        return Motion.from_rotations(self.skeleton, rotations, positions, motion.fps)

    # --- internals ----------------------------------------------------------------------------

    def restart(self) -> None:
        """Forget the stream's clock and outputs: the next frame starts the stream again, every
        performer afresh (as after a gap; :meth:`reset` keeps the clock running)."""
        self._pending: tuple[float, np.ndarray, np.ndarray] | None = None  # a frame's model frames to run
        self._stamp: float | None = None
        self._origin, self._ticks = 0.0, 0  # model frame k is at stream time origin + k / fps
        self._input: tuple[np.ndarray, np.ndarray] | None = None
        self._outputs: list[tuple[float, np.ndarray, np.ndarray]] = []  # the last three model frames
        self._segment: Hermite | None = None  # the curve between the last two, made when first needed

    def _advance(self, stamp: float, q: np.ndarray, p: np.ndarray) -> None:
        """Run the model frames up to the input frame at ``stamp``, each one's input interpolated
        between the previous input frame and this one."""
        while (t := self._origin + self._ticks / self.fps) <= stamp + STAMP_TOLERANCE:
            if self._stamp is None or t >= stamp - STAMP_TOLERANCE:
                frame = q, p
            else:
                w = np.clip((t - self._stamp) / (stamp - self._stamp), 0.0, 1.0)
                frame = rot.slerp(self._input[0], q, w), self._input[1] + w * (p - self._input[1])
            self._tick(t, *frame)
            self._ticks += 1
        self._stamp, self._input = stamp, (q, p)

    def _conditioned(self, q: np.ndarray, p: np.ndarray, fresh: np.ndarray
                     ) -> tuple[np.ndarray, np.ndarray]:
        """Features of the frame as the training data would show it (arm rolls conformed, moved
        down by each performer's ground offset), and the offsets as lifts ``(P, 3)`` to add back
        to the output (see the module docstring)."""
        conformed = q if self._rolls is None else self._rolls.conform(q)
        if self._scale is not None:
            self._scale.start(fresh)
            p = self._scale.to_canonical(p)
        lift = np.zeros((self.performers, 3))
        if self._ground is not None:
            if fresh.any():
                positions = np.broadcast_to(self.skeleton.offsets, q.shape[:-1] + (3,)).copy()
                positions[:, self.skeleton.pelvis] = p
                _, g_pos = forward_kinematics(self.skeleton, q, positions, joints=[])
                self._ground.start(g_pos[:, self._ankle_joints], fresh)
            lift = self._ground.offset[:, None] * UP
        features = self._encoder(conformed, p - lift)
        if self._ground is not None:
            self._ground.update(self._encoder.positions[:, self._ankle_joints] + lift[:, None])
        if self._rolls is not None:
            positions = self._encoder.positions
            rolled = self._rolls.observe(q, positions)
            sized = self._scale.observe(positions[:, self._contacts] - positions[:, self.skeleton.pelvis, None])
            self._remeasured = rolled | sized
        return features, lift

    def _emit(self, t: float, q: np.ndarray, p: np.ndarray) -> None:
        """Keep a model frame's output at stream time ``t``, in the stream's own joint frames."""
        if self._rolls is not None:
            q, p = self._rolls.undo(q), self._scale.to_stream(p)
        self._outputs = [*self._outputs[-2:], (t, q, p)]
        self._segment = None

    def _tick(self, t: float, q: np.ndarray, p: np.ndarray) -> None:
        """One model frame for all performers at stream time ``t``."""
        fresh = self._fresh.copy()
        features, lift = self._conditioned(q, p, fresh)
        if fresh.any():
            self._decoder.start(*self._encoder.facing(), which=fresh)
            self._controls.snap(fresh)
            if self._foot_lock is not None:
                self._foot_lock.reset(fresh)
                self._standing.reset(fresh)
        style, alpha = self._controls.advance(1.0 / self.fps)
        # A performer whose rig has just been measured (StreamRolls.observe) starts from the learned
        # initial state: nothing the network remembers comes from its unconformed first frames.
        # Its trajectory goes on as it was.
        restate = fresh | self._remeasured
        self._remeasured = np.zeros(self.performers, dtype=bool)
        out = self.model.run(
            features=features, style=style, alpha=alpha, state=self._state,
            reset=restate[:, None].astype(np.float32),
        )
        self._state = out["state_out"]
        self._fresh[:] = False
        output = out["output"] if self._standing is None else self._standing(out["output"], features)
        frame = self._placed(self._decoder(output), self._encoder.positions[:, self._ankle_joints])
        self._emit(t, frame[0], frame[1] + lift)

    def _placed(self, frame: tuple[np.ndarray, np.ndarray], ankles: np.ndarray
                ) -> tuple[np.ndarray, np.ndarray]:
        """A decoded frame with its feet locked on the input's ``ankles`` (an anchored root stays
        where the lock held it) and the trajectory pulled towards the input's (``follow_seconds``)."""
        if self._foot_lock is not None:
            locked = self._foot_lock(*frame, ankles)
            self._decoder.move(locked[1] - frame[1])
            frame = locked
        if self._follow_gain:
            self._decoder.pull(*self._encoder.facing(), self._follow_gain)
        return frame

    def _output(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """The model's output at stream time ``t``, between its last two frames (held outside)."""
        t1, q1, p1 = self._outputs[-1]
        if len(self._outputs) == 1 or t >= t1 - STAMP_TOLERANCE:
            return q1.copy(), p1.copy()  # the caller may write into what it gets
        if self._segment is None:
            self._segment = Hermite(self._outputs)
        return self._segment(t)

    def _check_stamp(self, stamp: float | None) -> float:
        if stamp is None:
            return 0.0 if self._stamp is None else self._stamp + 1.0 / self.input_fps
        try:
            value = float(stamp)
        except (TypeError, ValueError):
            raise MotionStyleError(f"stamp must be a number of seconds, got {stamp!r}") from None
        if not np.isfinite(value):
            raise MotionStyleError(f"stamp must be finite, got {value}")
        return value

    def _check_frame(self, rotations, root_positions) -> tuple[np.ndarray, np.ndarray, bool]:
        """Float64 ``(P, J, 4)`` unit quaternions and ``(P, 3)`` positions, or an error."""
        q, p = np.asarray(rotations), np.asarray(root_positions)
        for what, a in (("rotations", q), ("root positions", p)):
            if a.dtype.kind != "f":
                raise MotionStyleError(f"{what} of dtype {a.dtype}; expected floating-point numbers")
        single = self.performers == 1 and q.ndim == 2 and p.ndim == 1
        if single:
            q, p = q[None], p[None]
        n, j = self.performers, self.skeleton.n_joints
        if q.shape != (n, j, 4) or p.shape != (n, 3):
            raise MotionStyleError(
                f"rotations of shape {np.shape(rotations)} and root positions of shape "
                f"{np.shape(root_positions)}; expected ({n}, {j}, 4) local quaternions (w, x, y, z) "
                f"of the canonical skeleton's {j} joints and ({n}, 3) pelvis positions"
            )
        bad = ~(np.isfinite(q).all(axis=(1, 2)) & np.isfinite(p).all(axis=1))
        if bad.any():
            raise MotionStyleError(
                f"performer {int(np.argmax(bad))}: NaN or infinite values in the frame"
            )
        q, p = q.astype(np.float64), p.astype(np.float64)
        norm = rot.norm(q)
        off = np.abs(norm - 1.0) > QUATERNION_TOLERANCE
        if off.any():
            k, joint = np.argwhere(off)[0]
            raise MotionStyleError(
                f"performer {k}: rotation of {self.skeleton.names[joint]} has norm "
                f"{norm[k, joint]:.3g}; expected unit quaternions (w, x, y, z)"
            )
        return q / norm[..., None], p, single


def describe_calibration(calibration: dict) -> str:
    """One line for a log: what :meth:`RecurrentSession.calibration` found."""
    if calibration["state"] == "off":
        return "stream conditioning is off"
    line = (f"stream measured ({calibration['state']}): arm rolls {calibration['arm_rolls_deg']} deg, "
            f"size {calibration['scale']:g} of the training performers'")
    if calibration["state"] == "arms never hung":
        line += "; the arms stay as they come until they hang by the body for a moment"
    return line


def _positive(value: float, what: str) -> float:
    if not (isinstance(value, (int, float, np.number)) and np.isfinite(value) and value > 0):
        raise MotionStyleError(f"{what} must be a positive number, got {value!r}")
    return float(value)


def _check_card(card: dict, path: Path, kind: str = "recurrent", keys: tuple[str, ...] = ("state_size",)
                ) -> None:
    """The card describes a ``kind`` stylizer (with ``keys`` too) on the features this package
    computes."""
    missing = [k for k in ("kind", "styles", "fps", *keys, "feature_version") if k not in card]
    if missing:
        raise MotionStyleError(f"{path.with_suffix('.json')}: model card lacks {', '.join(missing)}")
    if card["kind"] != kind:
        raise MotionStyleError(f"{path}: a {card['kind']!r} model, not a {kind} stylizer")
    if card.get("skeleton", "canonical") != "canonical":
        raise MotionStyleError(
            f"{path}: made for skeleton {card['skeleton']!r}; the session streams the canonical one"
        )
    if card["feature_version"] != FEATURE_VERSION:
        raise MotionStyleError(
            f"{path}: made for feature version {card['feature_version']}; this package computes "
            f"version {FEATURE_VERSION} (retrain or update the package)"
        )
