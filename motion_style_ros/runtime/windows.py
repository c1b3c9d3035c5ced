"""What every windowed backend (stgcn, most, saae) shares as a stream: windows over each performer's
history blended by overlap-add (:class:`OverlapWindows`, the model step's machinery) and the
session around such a step with reference clips (:class:`WindowsSession`; :class:`BanklessSession`
for the backends without latent seeds).

- **Windows.** The generator sees the last ``window`` model frames (a new performer's history is
  filled with its first frame) and runs every ``hop`` frames for all performers together, and
  also whenever a frame is due that no window has covered yet (``lookahead < hop - 1``, or just
  after a reset). Its outputs are blended by overlap-add (:mod:`motion_style_ros.core.overlap_add`):
  every window fades in and out over the ``lookahead + 1`` frames it contributes to, so no seam
  shows where one window takes over from the next.
- **Latency.** Frame ``t`` is emitted when frame ``t + lookahead`` comes in: the windows see
  ``lookahead`` frames of its future. More lookahead means more context and more windows to
  blend (smoother, closer to offline quality), at ``lookahead / fps`` seconds of delay. After a
  start or a reset, the performer's first stylized frame is shown for ``lookahead`` frames,
  refined as the windows that see its future come in.
- **Foot locking.** Feet are locked on the input frame each output frame was made from
  (``lookahead`` frames back).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from motion_style_ros.core.easing import smoothstep
from motion_style_ros.core.motion import Motion
from motion_style_ros.core.overlap_add import OverlapAdd
from motion_style_ros.core.resample import resample
from motion_style_ros.core.standing import ROOT_MOTION
from motion_style_ros.errors import MotionStyleError
from motion_style_ros.runtime.defaults import DEFAULTS, StreamSettings
from motion_style_ros.runtime.onnx_model import model_path, read_card
from motion_style_ros.runtime.model_step import ModelFrame, Stylized
from motion_style_ros.runtime.stream import StreamSession

def latent(seed: int, size: int) -> np.ndarray:
    """``size`` standard normal numbers from ``seed``, the same on every machine and numpy version:
    PCG64's raw output (a fixed algorithm, unlike ``Generator.standard_normal``) through Box-Muller."""
    pairs = (size + 1) // 2
    raw = np.random.PCG64(whole_seed(seed)).random_raw(2 * pairs)
    u = ((raw >> np.uint64(11)).astype(np.float64) + 0.5) / 2.0**53  # in (0, 1)
    r = np.sqrt(-2.0 * np.log(u[:pairs]))
    angle = 2.0 * np.pi * u[pairs:]
    return np.concatenate([r * np.cos(angle), r * np.sin(angle)])[:size]


def whole_seed(seed: int) -> int:
    """The seed as an int, or a one-line reason why it is not one."""
    if isinstance(seed, bool) or not (isinstance(seed, (int, np.integer)) and 0 <= seed < 2**63):
        raise MotionStyleError(f"latent seed must be a whole number from 0 to 2^63 - 1, got {seed!r}")
    return int(seed)


class OverlapWindows:
    """Windows over each performer's history blended by overlap-add, and every performer's style
    inputs (one per style) blended over ``blend_seconds``: the model step of every windowed backend.
    A subclass sets its sizes (:meth:`_sizes`) and layout (:meth:`_layout`) in ``__init__``, starts
    the style inputs in ``start`` (:meth:`_start_codes`) and runs its model on the window in
    ``_history`` in :meth:`run_window`; its output frame is ``lookahead`` model frames behind its input."""

    WINDOW_LEAST = 4  # the fewest frames a window may have
    WINDOW_MULTIPLE = 1  # and what its length must be a multiple of

    def _sizes(self, window: int | None, default: int, hop: int, lookahead: int) -> None:
        """``window`` (``default`` when None), ``hop`` and ``lookahead``, or a one-line reason why not
        (a lookahead of the window or more: :class:`~motion_style_ros.core.overlap_add.OverlapAdd`)."""
        self.window = default if window is None else window
        least, multiple = self.WINDOW_LEAST, self.WINDOW_MULTIPLE
        if not (isinstance(self.window, (int, np.integer)) and self.window >= least
                and self.window % multiple == 0):
            what = f"a multiple of {multiple} frames" if multiple > 1 else "a whole number of frames"
            raise MotionStyleError(f"window must be {what}, at least {least}; got {window!r}")
        if not (isinstance(hop, (int, np.integer)) and 1 <= hop <= self.window):
            raise MotionStyleError(f"hop must be 1 to {self.window} frames (the window), got {hop!r}")
        if not isinstance(lookahead, (int, np.integer)):
            raise MotionStyleError(f"lookahead must be a whole number of frames, got {lookahead!r}")
        self.hop, self.lookahead = int(hop), int(lookahead)
        self.delay_frames = self.lookahead

    def _layout(self, card: dict) -> None:
        """The input and output widths and the rate, from the card."""
        layout = card["feature_layout"]
        self._n_in, self._n_out = int(layout["contact"][1]), int(layout["rot6d"][1])
        self._fps = float(card["fps"])

    def _start_codes(self, performers: int, blend_seconds: float, codes: np.ndarray) -> None:
        """Every performer starts with ``codes`` (every style's input ``(S, ...)``), the styles' own."""
        self.performers, self.blend_seconds = performers, blend_seconds
        self.own_codes = codes
        # codes per performer and style: blended from _codes_from to _codes_to over blend_seconds
        self._codes_to = np.repeat(codes[None], performers, axis=0)
        self._codes_from = self._codes_to.copy()
        self._code_progress = np.ones(performers)

    def run_window(self, style: np.ndarray) -> np.ndarray:
        """The model's output ``(P, window, n_out)`` for the window in ``_history``, at the style
        weights ``style`` ``(P, S)``."""
        raise NotImplementedError

    def restart(self) -> None:
        self._n = 0  # model frames since the stream started
        self._last_window = -self.hop
        self._history = np.zeros((self.performers, self.window, self._n_in), dtype=np.float32)
        self._ola = OverlapAdd(self.window, self.lookahead, self.performers, self._n_out)
        self._start = np.zeros(self.performers, dtype=int)  # each performer's first frame
        # the input's ankles of the frames in the overlap-add slots (for foot locking)
        self._ankles = np.zeros((self.performers, self.lookahead + 1, 2, 3))
        self._lifts = np.zeros((self.performers, self.lookahead + 1, 3))  # and their ground lifts

    def __call__(self, frame: ModelFrame, style: np.ndarray) -> Stylized:
        """Adds the frame to the windows; returns frame ``n - lookahead``, blended from the windows
        that cover it (a window runs every ``hop`` frames, or when no window covers that frame)."""
        n, lookahead, fresh = self._n, self.lookahead, frame.fresh
        self._history[:, :-1] = self._history[:, 1:]
        self._history[:, -1] = frame.features
        self._ola.shift()
        for kept, new in ((self._ankles, frame.ankles), (self._lifts, frame.lift)):
            kept[:, :-1] = kept[:, 1:]  # in place: np.roll allocates and costs several times more
            kept[:, -1] = new
        if fresh.any():
            self._codes_from[fresh] = self._codes_to[fresh]
            self._code_progress[fresh] = 1.0
            self._history[fresh] = frame.features[fresh][:, None]
            self._ola.clear(fresh)
            self._ankles[fresh] = self._ankles[fresh, -1:]
            self._lifts[fresh] = self._lifts[fresh, -1:]
            self._start[fresh] = n
        step = np.inf if self.blend_seconds == 0 else (1.0 / self._fps) / self.blend_seconds
        self._code_progress = np.minimum(self._code_progress + step, 1.0)
        due = np.maximum(n - lookahead, self._start)  # the frame each performer emits now
        slot = due - (n - lookahead)
        if n - self._last_window >= self.hop or not self._ola.covered(slot).all():
            self._ola.add(self.run_window(style))
            self._last_window = n
        blocks = self._ola.frame(slot)
        # A performer's first frame is shown until its lookahead has come in, refined as windows
        # arrive, and stays where it started: its root does not move.
        blocks[np.ix_(due == self._start, ROOT_MOTION)] = 0.0
        self._n += 1
        every = np.arange(self.performers)
        return Stylized(blocks, self._history[every, due - n - 1], self._ankles[every, slot],
                        self._lifts[every, slot])

    def mixed_codes(self, style: np.ndarray) -> np.ndarray:
        """``(P, ...)`` float32: each performer's codes mixed by its style weights ``(P, S)``."""
        return np.einsum("ps,ps...->p...", style.astype(np.float64), self.current_codes()).astype(np.float32)

    def current_codes(self) -> np.ndarray:
        """``(P, S, ...)``: every performer's codes as they are now (mid-blend included)."""
        w = smoothstep(self._code_progress).reshape(-1, *(1,) * (self._codes_to.ndim - 1))
        return self._codes_from + w * (self._codes_to - self._codes_from)

    def blend_to(self, which: slice | int, codes: np.ndarray, style: int | None = None) -> None:
        """Blend the performers ``which`` from their current codes to ``codes`` (every style's
        ``(S, ...)``, or with ``style`` that style's) over ``blend_seconds``."""
        self._codes_from[which] = self.current_codes()[which]
        self._code_progress[which] = 0.0 if self.blend_seconds else 1.0
        if style is None:
            self._codes_to[which] = codes
        else:
            self._codes_to[which, style] = codes


class WindowsSession(StreamSession):
    """A :class:`~motion_style_ros.runtime.stream.StreamSession` around an :class:`OverlapWindows`
    step ``windows`` (its ``window``, ``hop`` and ``lookahead`` mirrored), with reference clips: a
    subclass gives :meth:`reference_codes` (a clip's style input for each style, and how much it
    looks like each style) and this class sets them as a target."""

    def __init__(self, windows: OverlapWindows, performers: int, input_fps: float | None,
                 settings: StreamSettings) -> None:
        self.windows = windows
        self.window, self.hop, self.lookahead = windows.window, windows.hop, windows.lookahead
        super().__init__(windows.card, windows, performers, input_fps, settings)

    def reference_codes(self, motion: Motion) -> tuple[np.ndarray, np.ndarray]:
        raise NotImplementedError

    def set_reference(self, motion: Motion, style: str | None = None, performer: int | None = None
                      ) -> str:
        """Move like this recording: the clip's :meth:`reference_codes` become the input of
        ``style`` (by default the style the clip looks most like), which becomes the target;
        returns it."""
        return self.use_reference(*self.reference_codes(motion), style, performer)

    def use_reference(self, codes: np.ndarray, logits: np.ndarray, style: str | None = None,
                      performer: int | None = None) -> str:
        """:meth:`set_reference` with the clip's :meth:`reference_codes` already made (a node makes
        them off the thread that streams)."""
        k = int(np.argmax(logits)) if style is None else self.controls.style_index(style)
        return self._target(codes, k, performer)

    def _target(self, code: np.ndarray, k: int, performer: int | None) -> str:
        """Blend style ``k``'s input of the performer (or all) to ``code`` and make it the target."""
        which = self.controls.which(performer)
        self.catch_up()  # the model frames a pipelined step left run with the codes they had
        self.windows.blend_to(which, code, k)
        self.set_style(self.styles[k], performer)
        return self.styles[k]

    def reference_clip(self, motion: Motion, frames: int) -> Motion:
        """A reference clip as the style encoder reads it (at the model's rate, conformed to the
        training data's frames), or a one-line reason why it cannot serve: not a canonical-skeleton
        :class:`Motion`, not finite, or shorter than ``frames`` model frames."""
        if not isinstance(motion, Motion):
            raise MotionStyleError(f"a reference must be a Motion, got {type(motion).__name__}")
        if motion.skeleton.names != self.skeleton.names:
            raise MotionStyleError(
                f"reference clip on a skeleton of {motion.skeleton.n_joints} joints "
                f"({', '.join(motion.skeleton.names[:3])}, ...); it must be on the canonical skeleton "
                "(retarget it first: motion-style retarget)"
            )
        if not (np.isfinite(motion.rotations).all() and np.isfinite(motion.positions).all()):
            raise MotionStyleError("reference clip has NaN or infinite values")
        if motion.fps != self.fps:
            motion = resample(motion, self.fps)
        motion = self.conformed(motion)  # the encoder reads rotations: in the training data's frames
        if motion.n_frames < frames:
            raise MotionStyleError(
                f"reference clip too short: {motion.n_frames} frames at {self.fps:g} fps; it needs at "
                f"least {frames} ({frames / self.fps:.1f} s)"
            )
        return motion


class BanklessSession(WindowsSession):
    """A windowed backend's session without latent seeds: the step ``STEP(path, card, threads,
    window, hop, lookahead)`` (with ``bank=`` where ``NO_BANK`` is empty: a style bank file,
    default the model's own beside it) of the model ``model`` (default: ``DEFAULT_MODEL``);
    ``window``, ``hop``, ``lookahead`` as for :class:`~motion_style_ros.runtime.stgcn.StgcnSession`. A backend without a bank
    refuses one with ``NO_BANK``'s reason. Until :meth:`set_style`, every performer gets the card's
    ``neutral_style`` at alpha 1; ``settings`` and the stream settings by name:
    :class:`~motion_style_ros.runtime.defaults.StreamSettings`."""

    STEP: type[OverlapWindows]
    DEFAULT_MODEL: str
    NO_BANK: str = ""  # why this backend takes no style bank ("": it takes one)

    def __init__(self, model: str | Path | None = None, performers: int = 1, input_fps: float | None = None,
                 threads: int = 1, window: int | None = None, hop: int = DEFAULTS["hop"],
                 lookahead: int = DEFAULTS["lookahead"], bank: str | Path | None = None,
                 settings: StreamSettings | None = None, **stream) -> None:
        if bank is not None and self.NO_BANK:
            raise MotionStyleError(self.NO_BANK)
        path = model_path(str(self.DEFAULT_MODEL if model is None else model))
        windows = self.STEP(path, read_card(path), threads, window, hop, lookahead,
                            **({} if self.NO_BANK else {"bank": bank}))
        super().__init__(windows, performers, input_fps, StreamSettings.of(settings, stream))

    def clear_reference(self, performer: int | None = None) -> None:
        """Every style back to its own input (drops a reference), blended over ``blend_seconds``."""
        self.catch_up()
        self.windows.blend_to(self.controls.which(performer), self.windows.own_codes)
