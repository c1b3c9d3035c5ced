"""The MoST stylizer (Kim et al. 2024) as a stream: frames in, frames out, ``lookahead`` frames
later; the style taken from a reference motion of any action, or a style's mean.

:class:`MostSession` is a :class:`~motion_style_ros.runtime.stream.StreamSession` around a
:class:`MostStep`, the step graph of the contract :data:`~motion_style_ros.runtime.contract.MOST`
(content encoder, part-attentive style modulator, generator) with the style side of the encoder
(:data:`~motion_style_ros.runtime.contract.MOST_STYLE`) beside it:

- **Windows.** As :mod:`~motion_style_ros.runtime.windowed` has them: the last ``window`` model
  frames, a window every ``hop`` frames (or when a due frame is not covered yet), blended by
  overlap-add, frame ``t`` emitted when frame ``t + lookahead`` comes in.
- **Style features.** A style motion is its body-part style feature ``S`` and its mean content
  feature ``C`` (``(parts, dim)`` each). Each style of the card has its mean over train windows
  (``style_means`` beside the model), so ``target_style`` works without a clip; a reference clip
  (:meth:`MostSession.set_reference`) is encoded once, window by window, its windows' features
  averaged, and replaces one style's (the one named, or the nearest mean's). A window's step then
  runs the content encoder, the modulator and the generator only. The features a window gets are
  the styles' mixed by the style weights (style and mix); feature changes blend over
  ``blend_seconds`` like style and alpha.
- **Alpha.** Inside the graph, the style vector moves from the window's own (the window restyled
  like itself: its reconstruction) to the target's by alpha.
- **Foot locking.** Feet are locked on the input frame each output frame was made from.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from motion_style_ros.core.easing import smoothstep
from motion_style_ros.core.features import encode
from motion_style_ros.core.motion import Motion
from motion_style_ros.core.overlap_add import OverlapAdd
from motion_style_ros.core.resample import resample
from motion_style_ros.core.standing import ROOT_MOTION
from motion_style_ros.errors import MotionStyleError
from motion_style_ros.runtime.contract import MOST, MOST_STYLE, check_card
from motion_style_ros.runtime.defaults import DEFAULTS
from motion_style_ros.runtime.onnx_model import OnnxModel, model_path, read_card
from motion_style_ros.runtime.stream import ModelFrame, StreamSession, Stylized

DEFAULT_MODEL = "most.onnx"


class MostStep:
    """The MoST step graph at ``path`` (card ``card``, its companions beside it) as a model step:
    windows over the history, overlap-add, every performer's style features per style; its output
    frame is ``lookahead`` model frames behind its input."""

    aligned = True

    def __init__(self, path: Path, card: dict, threads: int, window: int | None, hop: int,
                 lookahead: int) -> None:
        check_card(card, path, "most")
        self.card = card
        self.window = int(card["window"]) if window is None else window
        if not (isinstance(self.window, (int, np.integer)) and self.window >= 4):
            raise MotionStyleError(f"window must be a whole number of frames, at least 4; got {window!r}")
        if not (isinstance(hop, (int, np.integer)) and 1 <= hop <= self.window):
            raise MotionStyleError(f"hop must be 1 to {self.window} frames (the window), got {hop!r}")
        if not (isinstance(lookahead, (int, np.integer)) and 0 <= lookahead < self.window):
            raise MotionStyleError(f"lookahead must be 0 to {self.window - 1} frames, got {lookahead!r}")
        self.window, self.hop, self.lookahead = int(self.window), int(hop), int(lookahead)
        self.delay_frames = self.lookahead
        self.model = OnnxModel(path, threads)
        MOST.check(self.model.input_names, path, "MoST step graph")
        files = card["files"]
        self.style_encoder = OnnxModel(model_path(str(path.with_name(files["style_encoder"]))), threads)
        MOST_STYLE.check(self.style_encoder.input_names, path, "MoST style encoder")
        self.styles = list(card["styles"])
        self.means = _read_means(path.with_name(files["style_means"]), len(self.styles),
                                 (len(card["parts"]), int(card["feature_dim"])))
        layout = card["feature_layout"]
        self._n_in, self._n_out = int(layout["contact"][1]), int(layout["rot6d"][1])
        self._fps = float(card["fps"])

    def start(self, performers: int, blend_seconds: float) -> None:
        self.performers, self.blend_seconds = performers, blend_seconds
        # features per performer and style (P, S, 2, parts, dim): blended from _from to _to
        self._to = np.repeat(self.means[None], performers, axis=0)
        self._from = self._to.copy()
        self._progress = np.ones(performers)

    def restart(self) -> None:
        self._n = 0  # model frames since the stream started
        self._last_window = -self.hop
        self._history = np.zeros((self.performers, self.window, self._n_in), dtype=np.float32)
        self._ola = OverlapAdd(self.window, self.lookahead, self.performers, self._n_out)
        self._start = np.zeros(self.performers, dtype=int)
        self._ankles = np.zeros((self.performers, self.lookahead + 1, 2, 3))
        self._lifts = np.zeros((self.performers, self.lookahead + 1, 3))

    def __call__(self, frame: ModelFrame, style: np.ndarray, alpha: np.ndarray) -> Stylized:
        """Adds the frame to the windows; returns frame ``n - lookahead``, blended from the windows
        that cover it (a window runs every ``hop`` frames, or when no window covers that frame)."""
        n, lookahead, fresh = self._n, self.lookahead, frame.fresh
        self._history[:, :-1] = self._history[:, 1:]
        self._history[:, -1] = frame.features
        self._ola.shift()
        for kept, new in ((self._ankles, frame.ankles), (self._lifts, frame.lift)):
            kept[:, :-1] = kept[:, 1:]
            kept[:, -1] = new
        if fresh.any():
            self._from[fresh] = self._to[fresh]
            self._progress[fresh] = 1.0
            self._history[fresh] = frame.features[fresh][:, None]
            self._ola.clear(fresh)
            self._ankles[fresh] = self._ankles[fresh, -1:]
            self._lifts[fresh] = self._lifts[fresh, -1:]
            self._start[fresh] = n
        step = np.inf if self.blend_seconds == 0 else (1.0 / self._fps) / self.blend_seconds
        self._progress = np.minimum(self._progress + step, 1.0)
        due = np.maximum(n - lookahead, self._start)
        slot = due - (n - lookahead)
        if n - self._last_window >= self.hop or not self._ola.covered(slot).all():
            target = np.einsum("ps,pskcd->pkcd", style.astype(np.float64), self.current_features())
            self._ola.add(self.model.run(features=self._history, style=target[:, 0].astype(np.float32),
                                         pooled=target[:, 1].astype(np.float32),
                                         alpha=np.asarray(alpha, dtype=np.float32).reshape(-1, 1))["output"])
            self._last_window = n
        blocks = self._ola.frame(slot)
        blocks[np.ix_(due == self._start, ROOT_MOTION)] = 0.0  # a first frame stays where it started
        self._n += 1
        every = np.arange(self.performers)
        return Stylized(blocks, self._history[every, due - n - 1], self._ankles[every, slot],
                        self._lifts[every, slot])

    def current_features(self) -> np.ndarray:
        """``(P, S, 2, parts, dim)``: every performer's features per style as they are now
        (mid-blend included); ``[:, :, 0]`` the style features, ``[:, :, 1]`` the mean content ones."""
        w = smoothstep(self._progress)[:, None, None, None, None]
        return self._from + w * (self._to - self._from)

    def blend_to(self, which: slice | int, features: np.ndarray, style: int | None = None) -> None:
        """Blend the performers ``which`` from their current features to ``features`` (every
        style's ``(S, 2, parts, dim)``, or with ``style`` that style's ``(2, parts, dim)``)."""
        self._from[which] = self.current_features()[which]
        self._progress[which] = 0.0 if self.blend_seconds else 1.0
        if style is None:
            self._to[which] = features
        else:
            self._to[which, style] = features


def _read_means(path: Path, styles: int, shape: tuple[int, int]) -> np.ndarray:
    """Every style's mean features ``(S, 2, parts, dim)`` from the npz the exporter wrote, or a
    one-line reason why they cannot be read."""
    if not path.is_file():
        raise MotionStyleError(f"{path}: the styles' mean features are missing (they ship beside the model)")
    with np.load(path, allow_pickle=False) as npz:
        if {"style", "pooled"} - set(npz.files):
            raise MotionStyleError(f"{path}: expected arrays 'style' and 'pooled', found {', '.join(npz.files)}")
        means = np.stack([npz["style"], npz["pooled"]], axis=1).astype(np.float64)
    if means.shape != (styles, 2, *shape) or not np.isfinite(means).all():
        raise MotionStyleError(f"{path}: mean features of shape {means.shape[:1] + means.shape[2:]}, "
                               f"expected {(styles, *shape)} finite values (one per style of the card)")
    return means


class MostSession(StreamSession):
    """The MoST stylizer over a stream of ``performers`` performers (see the module docstring and
    :class:`~motion_style_ros.runtime.stream.StreamSession`).

    ``model``: the step graph's file name or path (card and companions beside it); ``window``:
    frames per window (default: the card's); ``hop``: frames between windows; ``lookahead``: output
    delay in model frames (0 to ``window - 1``). Until :meth:`set_style`, every performer gets the
    card's ``neutral_style`` at alpha 1. ``bank``: not taken (no style bank for this backend; given
    by the node to every windowed backend); ``phase_seconds``: as for the stream session.
    """

    def __init__(
        self,
        model: str | Path = DEFAULT_MODEL,
        performers: int = 1,
        input_fps: float | None = None,
        blend_seconds: float = DEFAULTS["blend_seconds"],
        threads: int = 1,
        gap_seconds: float = DEFAULTS["gap_seconds"],
        follow_seconds: float | None = DEFAULTS["follow_seconds"],
        window: int | None = None,
        hop: int = DEFAULTS["hop"],
        lookahead: int = DEFAULTS["lookahead"],
        foot_lock: bool = DEFAULTS["foot_lock"],
        ground: bool = DEFAULTS["ground"],
        pipelined: bool = DEFAULTS["pipelined"],
        conform: bool = DEFAULTS["conform"],
        bank: str | Path | None = None,
        phase_seconds: float = 0.0,
    ) -> None:
        if bank is not None:
            raise MotionStyleError("a style bank needs backend stgcn (style codes); the most backend takes "
                                   "a reference clip (set_reference) instead")
        path = model_path(str(model))
        self.steps = MostStep(path, read_card(path), threads, window, hop, lookahead)
        s = self.steps
        self.window, self.hop, self.lookahead = s.window, s.hop, s.lookahead
        self.model, self.style_encoder = s.model, s.style_encoder
        super().__init__(s.card, s, performers, input_fps, blend_seconds, gap_seconds, follow_seconds,
                         foot_lock, ground, pipelined, conform, phase_seconds)

    # --- controls ---------------------------------------------------------------------------

    def features(self, performer: int = 0) -> np.ndarray:
        """``(S, 2, parts, dim)``: the performer's features per style as they are now."""
        return self.steps.current_features()[self.controls.which(performer)]

    def set_reference(self, motion: Motion, style: str | None = None, performer: int | None = None
                      ) -> str:
        """Move like this recording, whatever its action: the clip's style features (computed once
        here) replace those of ``style`` (by default the style whose mean they are nearest) and
        that style becomes the target. Returns it."""
        return self.use_reference(*self.reference_codes(motion), style, performer)

    def use_reference(self, features: np.ndarray, logits: np.ndarray, style: str | None = None,
                      performer: int | None = None) -> str:
        """:meth:`set_reference` with the clip's :meth:`reference_codes` already made (a node makes
        them off the thread that streams)."""
        k = int(np.argmax(logits)) if style is None else self.controls.style_index(style)
        which = self.controls.which(performer)
        self.catch_up()
        self.steps.blend_to(which, features, k)
        self.set_style(self.styles[k], performer)
        return self.styles[k]

    def clear_reference(self, performer: int | None = None) -> None:
        """Every style back to its mean features (drops a reference), blended over ``blend_seconds``."""
        self.catch_up()
        self.steps.blend_to(self.controls.which(performer), self.steps.means)

    def reference_codes(self, motion: Motion) -> tuple[np.ndarray, np.ndarray]:
        """A clip's style features ``(2, parts, dim)`` (the mean over its windows, a window every
        half window) and how near they are to each style's mean ``(S,)`` (minus the squared
        distance: the nearest is the largest), or a one-line reason why the clip cannot serve as
        a reference."""
        if not isinstance(motion, Motion):
            raise MotionStyleError(f"a reference must be a Motion, got {type(motion).__name__}")
        if motion.skeleton.names != self.skeleton.names:
            raise MotionStyleError(
                f"reference clip on a skeleton of {motion.skeleton.n_joints} joints "
                f"({', '.join(motion.skeleton.names[:3])}, ...); it must be on the canonical skeleton "
                "(retarget it first: motion-style retarget)")
        if not (np.isfinite(motion.rotations).all() and np.isfinite(motion.positions).all()):
            raise MotionStyleError("reference clip has NaN or infinite values")
        if motion.fps != self.fps:
            motion = resample(motion, self.fps)
        motion = self.conformed(motion)  # the encoder reads rotations: in the training data's frames
        w = self.window
        if motion.n_frames < w:
            raise MotionStyleError(
                f"reference clip too short: {motion.n_frames} frames at {self.fps:g} fps; it needs at "
                f"least {w} ({w / self.fps:.1f} s)")
        features = encode(motion)
        starts = sorted({*range(0, len(features) - w + 1, max(1, w // 2)), len(features) - w})
        out = self.style_encoder.run(features=np.stack([features[s : s + w] for s in starts]).astype(np.float32))
        clip = np.stack([out["style"].mean(axis=0), out["pooled"].mean(axis=0)]).astype(np.float64)
        distance = ((self.steps.means - clip) ** 2).sum(axis=(1, 2, 3))
        return clip, -distance
