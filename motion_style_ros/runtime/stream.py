"""The streaming stylizer: one canonical-skeleton frame per performer in, one stylized frame out.

A :class:`StreamSession` carries everything a live stream needs between calls, whatever the model;
the model itself is a :class:`ModelStep` (:mod:`~motion_style_ros.runtime.recurrent`'s recurrent
step, :mod:`~motion_style_ros.runtime.windows`'s windows; :mod:`~motion_style_ros.runtime.backends`
names them) that turns each model frame's conditioned features into stylized feature blocks:

- **Rates.** The model runs on its own clock (``fps``, 30 Hz) with one model step per model frame
  for all performers together. Each model frame's input is interpolated between the two input
  frames around its time (slerp, lerp), so nothing waits for a future frame. Each input frame
  gets an output: the model's frames interpolated at ``stamp - latency`` with
  ``latency = delay_frames / fps + 1 / fps - 1 / input_fps`` (the step's own delay, plus 0 for
  30 Hz input, 25 ms for 120 Hz), so the output comes at the input's rate, evenly spaced and
  smooth (Hermite curves through the last three model frames); at rates that are not multiples of
  the model's, an output whose time is past the newest model frame holds it.
- **Pipelining.** With ``pipelined``, the output is one input frame later (``latency`` grows by
  ``1 / input_fps``, to 33.3 ms at 120 Hz input) and needs no model frame of its own input frame:
  :meth:`~StreamSession.step` returns it before running them, and :meth:`~StreamSession.catch_up`
  runs them once the caller has sent the output on (the next call runs them first otherwise). A
  live node's every frame then costs an interpolation on its way through, the model's work
  happens between frames, and the outputs are exactly those of an unpipelined session one input
  frame later.
- **Gaps and restarts.** A stamp more than ``gap_seconds`` after the previous one, or earlier
  than it, restarts the stream: every performer starts afresh on the next frame.
- **Trajectory.** The models output the root's velocity and yaw rate in the facing frame; they are
  integrated (:class:`~motion_style_ros.core.features.StreamDecoder`) from where the performer
  stood and faced on its first frame (and after every reset, which snaps it back there), so the
  stylized root moves with its own speed and turns. It drifts from the input's trajectory (a
  slower style falls behind); with ``follow_seconds`` set, the integrated ground point and heading
  are pulled towards the input's with that time constant instead, which bounds the drift (the
  stylized avatar keeps up with its performer on average).
- **Foot locking.** With ``foot_lock``, feet the input plants stay planted in the output and feet
  it lifts are no lower (:mod:`motion_style_ros.core.foot_lock`: causal two-bone leg IK on each
  model frame, judged on the input frame the output frame was made from), and a performer standing
  on both feet keeps the input's root motion (:mod:`motion_style_ros.core.standing`), so the style
  does not walk them away.
- **Conditioning.** With ``ground``, each performer's stream is moved down by how far its planted
  ankles rest above the training data's (:class:`~motion_style_ros.core.conform.StreamGround`: set
  on its first frame from the lower ankle, then followed while an ankle stands still) before the
  model, and the output is moved back up: other rigs' ankle joints sit higher or lower above the
  sole, and the models and the foot contact handling read absolute heights. The output keeps the
  input's floor. With ``conform``, the arm rolls and the performer's size are measured from the
  stream's first seconds (:meth:`~StreamSession.calibration`) and the frames turned and scaled to
  the training data's conventions on the way in and back on the way out.
- **Controls.** Style, alpha, part alphas and a second style with a mix weight change between
  any two frames and blend over ``blend_seconds`` (:mod:`motion_style_ros.runtime.controls`).
- **Intensity.** The model always gives the full style. Each model frame's decoded output is then
  turned from the input frame it was made from towards the stylized one by each joint's intensity
  (alpha times its part's alpha; :mod:`motion_style_ros.core.intensity`), in the conditioned
  frames, and the feet are locked after that blend, so they stay planted at every alpha; the lock
  comes in over the first ``LOCK_RAMP`` of the legs' intensity, so alpha 0 locks nothing. Between
  model frames (input faster than the model), an output whose intensity is below 1 also gets that
  share of what the model frames' interpolation misses of the input: alpha 0 gives every input
  frame back as it came (to float precision), ``latency`` later (the frame within a quarter of a
  frame of that time, where stamps jitter).
- **Bad input.** A frame with the wrong shape or dtype, NaN/Inf or non-unit quaternions raises
  :class:`MotionStyleError` before anything changes: the next good frame continues as if the
  bad one never came. Quaternions within 10 % of unit length are normalised.

The settings' defaults are :data:`motion_style_ros.runtime.defaults.DEFAULTS`, the node's.
"""

from __future__ import annotations

import numpy as np

from motion_style_ros.core import jit, rotations as rot
from motion_style_ros.core.conform import ANKLES, ROLL_MIN_FRAMES, StreamGround, StreamRolls, conform_rolls
from motion_style_ros.core.features import UP, StreamDecoder, StreamEncoder
from motion_style_ros.core.foot_lock import FootLock
from motion_style_ros.core.intensity import PARTS, blend, part_of_joints, toward
from motion_style_ros.core.motion import Motion, check_frame, forward_kinematics, rest_positions
from motion_style_ros.core.proportions import CONTACTS, StreamScale, clip_scale
from motion_style_ros.core.resample import Hermite, resample
from motion_style_ros.core.skeleton import canonical
from motion_style_ros.core.standing import Standing
from motion_style_ros.errors import MotionStyleError
from motion_style_ros.io.resources import rotation_stats
from motion_style_ros.runtime.defaults import DEFAULTS, StreamSettings
from motion_style_ros.runtime.model_step import ModelFrame, ModelStep
from motion_style_ros.runtime.controls import Controls
from motion_style_ros.runtime.onnx_model import neutral_style

QUATERNION_TOLERANCE = 0.1  # |norm - 1| above this is rejected, below it normalised
STAMP_TOLERANCE = 1e-6  # s: a model frame this close to an input frame takes that frame as it is
LOCK_RAMP = 0.25  # the legs' intensity at which foot locking is full (it grows from 0 at 0)
_LEGS = PARTS.index("legs")


class StreamSession:
    """A stream of ``performers`` performers through a model step (see the module docstring).

    ``card``: the model's card (``styles``, ``fps``, ``neutral_style``); ``input_fps``: the
    stream's nominal rate (default: the model's), which sets the output latency; ``settings``:
    the :class:`~motion_style_ros.runtime.defaults.StreamSettings` every backend's session shares
    (a backend's session takes them as an object, ``settings=``, or by name, ``foot_lock=False``).
    Until :meth:`set_style`, every performer gets the card's ``neutral_style`` at alpha 1.
    """

    def __init__(self, card: dict, step: ModelStep, performers: int, input_fps: float | None,
                 settings: StreamSettings) -> None:
        if not (isinstance(performers, (int, np.integer)) and performers >= 1):
            raise MotionStyleError(f"performers must be a whole number, at least 1; got {performers!r}")
        self.card = card
        self.model_step = step
        self.styles: list[str] = list(step.styles)
        self.fps = float(card["fps"])
        self.performers = int(performers)
        self.input_fps = self.fps if input_fps is None else _positive(input_fps, "input frame rate")
        self.settings = settings
        blend_seconds, follow_seconds, pipelined = settings.blend_seconds, settings.follow_seconds, settings.pipelined
        if not isinstance(pipelined, (bool, np.bool_)):
            raise MotionStyleError(f"pipelined must be true or false, got {pipelined!r}")
        self.pipelined = bool(pipelined)
        self.latency = (step.delay_frames / self.fps + max(0.0, 1.0 / self.fps - 1.0 / self.input_fps)
                        + (1.0 / self.input_fps if self.pipelined else 0.0))
        self.gap_seconds = _positive(settings.gap_seconds, "gap time")
        self._follow_gain = (
            0.0 if follow_seconds is None
            else 1.0 - np.exp(-1.0 / (self.fps * _positive(follow_seconds, "follow time")))
        )
        self.skeleton = canonical()
        neutral = neutral_style(card)
        self.controls = Controls(self.styles, self.performers, neutral, blend_seconds)
        self._encoder = StreamEncoder(self.performers, self.fps, self.skeleton)
        self._decoder = StreamDecoder(self.performers, self.fps, self.skeleton)
        self._foot_lock = FootLock(self.performers, self.fps, self.skeleton) if settings.foot_lock else None
        self._standing = Standing(self.performers, self.fps, self.skeleton) if settings.foot_lock else None
        stats = rotation_stats()
        self._ground = StreamGround(self.performers, self.fps, stats["ankle_height"]) if settings.ground else None
        self._rolls = StreamRolls(self.performers, self.fps, stats, self.skeleton) if settings.conform else None
        self._scale = StreamScale(self.performers, self.fps, stats["scale_reference"]) if settings.conform else None
        self._contacts = [self.skeleton.index(n) for n in CONTACTS]
        self._ankle_joints = [self.skeleton.index(n) for n in ANKLES]  # what grounding and foot locks read
        self._part = part_of_joints(self.skeleton)  # each joint's part: its column of the intensities
        # the raw input frames of the last delay_frames + 1 model frames (oldest first): what each
        # output frame is blended with
        depth = step.delay_frames + 1
        self._ring_q = np.zeros((self.performers, depth, self.skeleton.n_joints, 4))
        self._ring_p = np.zeros((self.performers, depth, 3))
        self._fresh = np.ones(self.performers, dtype=bool)
        self._remeasured = np.zeros(self.performers, dtype=bool)  # see StreamRolls.observe
        step.start(self.performers, self.controls.blend_seconds)
        phase_seconds = settings.phase_seconds
        if not (isinstance(phase_seconds, (int, float)) and 0.0 <= phase_seconds < 1.0 / self.fps):
            raise MotionStyleError(f"phase_seconds must be in [0, {1.0 / self.fps:g}), got {phase_seconds!r}")
        self._phase = float(phase_seconds)
        self.restart()

    # --- controls ---------------------------------------------------------------------------

    def set_style(self, style: str, performer: int | None = None) -> None:
        """Target style of one performer or all (``None``), blended in over ``blend_seconds``."""
        self.catch_up()
        self.controls.set_style(style, performer)

    def set_alpha(self, alpha: float, performer: int | None = None) -> None:
        """Intensity of the style in [0, 1]: 0 gives the input back, 1 the full style."""
        self.catch_up()
        self.controls.set_alpha(alpha, performer)

    def set_part_alpha(self, values, performer: int | None = None) -> None:
        """Scale alpha per body part: one number in [0, 1] for each of
        :data:`~motion_style_ros.core.intensity.PARTS` (torso, arms, legs)."""
        self.catch_up()
        self.controls.set_part_alpha(values, performer)

    def set_mix(self, style: str | None, weight: float, performer: int | None = None) -> None:
        """Mix a second style in with ``weight`` in [0, 1]; ``None`` removes it."""
        self.catch_up()
        self.controls.set_mix(style, weight, performer)

    def reset(self, performer: int | None = None, recalibrate: bool = False) -> None:
        """Start one performer or all afresh at their next frame: the model's initial state, the
        stylized root snapped back to the input's, controls at their targets; with
        ``recalibrate``, the stream's conditioning (arm rolls, size) is measured again too (a new
        rig: it otherwise holds across resets and gaps)."""
        self.catch_up()
        which = self.controls.which(performer)
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

    def conformed(self, motion: Motion) -> Motion:
        """A whole clip in the training data's joint frames, as the stream conditions its frames
        (the arm rolls; unchanged when ``conform`` is off)."""
        return motion if self._rolls is None else conform_rolls(motion, self._rolls.stats)

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
        self._frames = [*self._frames[-self._keep:], (stamp, q, p)]
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

    def run(self, motion: Motion, style: str, alpha: float = DEFAULTS["alpha"], calibration: Motion | None = None
            ) -> Motion:
        """A whole clip stylized through :meth:`step` (one performer, clip at ``input_fps``), the
        stream conditioned (arm rolls, size) from the whole clip at once, or from ``calibration``.
        The stream is run on past the clip's end (its last frame held) for the latency, and the
        first outputs, which belong before the clip, are dropped: output frame k is input frame
        k's (alpha 0 gives the clip back)."""
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
        delay = round(self.latency * self.input_fps)
        held = np.arange(motion.n_frames + delay).clip(max=motion.n_frames - 1)
        roots = motion.positions[:, self.skeleton.pelvis]
        frames = [self.step(motion.rotations[t : t + 1], roots[t : t + 1], k / motion.fps)
                  for k, t in enumerate(held)]
        rotations = np.concatenate([q for q, _ in frames[delay:]])
        positions = np.concatenate([p for _, p in frames[delay:]])
        return Motion.from_rotations(self.skeleton, rotations, positions, motion.fps)

    def restart(self) -> None:
        """Forget the stream's clock and outputs: the next frame starts the stream again, every
        performer afresh (as after a gap; :meth:`reset` keeps the clock running)."""
        self._pending: tuple[float, np.ndarray, np.ndarray] | None = None  # a frame's model frames to run
        self._stamp: float | None = None
        self._origin, self._ticks = 0.0, 0  # model frame k is at stream time origin + k / fps
        self._input: tuple[np.ndarray, np.ndarray] | None = None
        self._outputs: list[tuple[float, np.ndarray, np.ndarray]] = []  # the last three model frames
        # the raw input frames the last three model frames were made from, the Hermite curves
        # between the last two of each (made when first needed), the input frames that came in
        # over the latency, and the intensities of the last model frame
        self._inputs: list[tuple[float, np.ndarray, np.ndarray]] = []
        self._segments: dict[bool, Hermite] = {}  # by inputs (True) or outputs (False)
        self._frames: list[tuple[float, np.ndarray, np.ndarray]] = []
        self._keep = int(np.ceil(self.latency * self.input_fps)) + 2
        self._intensity = np.ones((self.performers, len(PARTS)))
        self.model_step.restart()

    # --- internals ----------------------------------------------------------------------------

    def _advance(self, stamp: float, q: np.ndarray, p: np.ndarray) -> None:
        """Run the model frames up to the input frame at ``stamp``, each one's input interpolated
        between the previous input frame and this one."""
        while (t := self._origin + self._ticks / self.fps) <= stamp + STAMP_TOLERANCE:
            if self._stamp is None or t >= stamp - STAMP_TOLERANCE:
                frame = q, p
            else:
                w = min(max((t - self._stamp) / (stamp - self._stamp), 0.0), 1.0)
                frame = rot.slerp(self._input[0], q, w), self._input[1] + w * (p - self._input[1])
            self._tick(t, *frame)
            self._ticks += 1
        self._stamp, self._input = stamp, (q, p)

    def _tick(self, t: float, q: np.ndarray, p: np.ndarray) -> None:
        """One model frame for all performers at stream time ``t``: conditioned, through the
        model step, decoded, placed, kept (at the time of the input frame it was made from)."""
        fresh = self._fresh.copy()
        features, lift = self._conditioned(q, p, fresh)
        if fresh.any():
            self._decoder.start(*self._encoder.facing(), which=fresh)
            self.controls.snap(fresh)
            if self._foot_lock is not None:
                self._foot_lock.reset(fresh)
                self._standing.reset(fresh)
        style, self._intensity = self.controls.advance(1.0 / self.fps)
        # A performer whose rig has just been measured (StreamRolls.observe) starts from the model's
        # initial state: nothing it remembers comes from its unconformed first frames. Its
        # trajectory goes on as it was.
        restate = fresh | self._remeasured
        self._remeasured = np.zeros(self.performers, dtype=bool)
        self._fresh[:] = False
        self._remember(q, p, fresh)
        out = self.model_step(
            ModelFrame(features, self._encoder.positions[:, self._ankle_joints], lift, fresh, restate), style)
        blocks = out.blocks if self._standing is None else self._standing(out.blocks, out.features)
        frame = self._blended(self._decoder(blocks), out.lift)
        frame = self._placed(frame, out.ankles)
        self._emit(t - self.model_step.delay_frames / self.fps, frame[0], frame[1] + out.lift)

    def _remember(self, q: np.ndarray, p: np.ndarray, fresh: np.ndarray) -> None:
        """Keep a model frame's raw input for the output frame made from it (a fresh performer's
        earlier slots hold it too, as a windowed step shows its first frame until it has more)."""
        self._ring_q[:, :-1] = self._ring_q[:, 1:]
        self._ring_p[:, :-1] = self._ring_p[:, 1:]
        self._ring_q[:, -1], self._ring_p[:, -1] = q, p
        if fresh.any():
            self._ring_q[fresh] = q[fresh, None]
            self._ring_p[fresh] = p[fresh, None]

    def _blended(self, styled: tuple[np.ndarray, np.ndarray], lift: np.ndarray
                 ) -> tuple[np.ndarray, np.ndarray]:
        """A decoded frame turned from its input frame (conditioned as the stream conditions it
        now, so that :meth:`_emit` gives that frame back exactly) by each joint's intensity."""
        if (self._intensity >= 1.0).all():
            return styled
        q, p = self._ring_q[:, 0], self._ring_p[:, 0]
        q = q if self._rolls is None else self._rolls.conform(q)
        p = (p if self._scale is None else self._scale.placed(p)) - lift
        return blend(q, p, *styled, self._intensity[:, self._part], self._intensity[:, _LEGS])

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
                _, g_pos = forward_kinematics(self.skeleton, q, rest_positions(self.skeleton, p), joints=[])
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

    def _placed(self, frame: tuple[np.ndarray, np.ndarray], ankles: np.ndarray
                ) -> tuple[np.ndarray, np.ndarray]:
        """A decoded frame with its feet locked on the input's ``ankles`` (an anchored root stays
        where the lock held it) and the trajectory pulled towards the input's (``follow_seconds``)."""
        if self._foot_lock is not None:
            strength = np.minimum(self._intensity[:, _LEGS] / LOCK_RAMP, 1.0)
            locked = self._foot_lock(*frame, ankles, strength=strength)
            self._decoder.move(locked[1] - frame[1])
            frame = locked
        if self._follow_gain:
            self._decoder.pull(*self._encoder.facing(), self._follow_gain)
        return frame

    def _emit(self, t: float, q: np.ndarray, p: np.ndarray) -> None:
        """Keep a model frame's output at stream time ``t``, in the stream's own joint frames, with
        the raw input frame it was made from."""
        if self._rolls is not None:
            q, p = self._rolls.undo(q), self._scale.to_stream(p)
        self._outputs = [*self._outputs[-2:], (t, q, p)]
        self._inputs = [*self._inputs[-2:], (t, self._ring_q[:, 0].copy(), self._ring_p[:, 0].copy())]
        self._segments.clear()

    def _output(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """The output at stream time ``t``: the model's, between its last two frames (held
        outside), with what that interpolation misses of the input frame at ``t`` where the
        intensity is below 1 (see the module docstring)."""
        q, p = self._curve(False, t)
        if (self._intensity >= 1.0).all():
            return q, p
        q_curve, p_curve = self._curve(True, t)
        q_in, p_in = self._input_at(t)
        keep = 1.0 - self._intensity
        missed = rot.multiply(rot.conjugate(q_curve), q_in)
        q = rot.multiply(q, toward(_IDENTITY, missed, keep[:, self._part]))
        return q, p + keep[:, _LEGS, None] * (p_in - p_curve)

    def _curve(self, inputs: bool, t: float) -> tuple[np.ndarray, np.ndarray]:
        """The last model frames' ``_inputs`` (or ``_outputs``) at ``t`` by the Hermite curve of
        their last two, made once per model frame (held past the last)."""
        frames = self._inputs if inputs else self._outputs
        t1, q1, p1 = frames[-1]
        if len(frames) == 1 or t >= t1 - STAMP_TOLERANCE:
            return q1.copy(), p1.copy()  # the caller may write into what it gets
        if inputs not in self._segments:
            self._segments[inputs] = Hermite(frames)
        return self._segments[inputs](t)

    def _input_at(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """The raw input at stream time ``t``: the frame within a quarter of a frame of it (stamps
        of a live stream jitter: alpha 0 still shows whole frames), else between the two around it."""
        frames, snap = self._frames, 0.25 / self.input_fps
        k = next((k for k in range(len(frames) - 1, -1, -1) if frames[k][0] <= t + snap), 0)
        t0, q0, p0 = frames[k]
        if k == len(frames) - 1 or t <= t0 + snap:
            return q0, p0
        t1, q1, p1 = frames[k + 1]
        if t >= t1 - snap:
            return q1, p1
        w = (t - t0) / (t1 - t0)
        return rot.slerp(q0, q1, w), p0 + w * (p1 - p0)

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
        p = jit.rows(p)
        q, problem, k, joint, norm = check_frame(jit.rows(q), p,
                                                         QUATERNION_TOLERANCE)
        if problem == 1:
            raise MotionStyleError(f"performer {k}: NaN or infinite values in the frame")
        if problem == 2:
            raise MotionStyleError(
                f"performer {k}: rotation of {self.skeleton.names[joint]} has norm "
                f"{norm:.3g}; expected unit quaternions (w, x, y, z)"
            )
        return q, p, single


_IDENTITY = np.array([1.0, 0.0, 0.0, 0.0])


def _positive(value: float, what: str) -> float:
    if not (isinstance(value, (int, float, np.number)) and np.isfinite(value) and value > 0):
        raise MotionStyleError(f"{what} must be a positive number, got {value!r}")
    return float(value)
