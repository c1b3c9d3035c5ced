"""The MoST stylizer (Kim et al. 2024) as a stream: frames in, frames out, ``lookahead`` frames
later; the style taken from a reference motion of any action, or a style's mean.

:class:`MostSession` is a :class:`~motion_style_ros.runtime.windows.BanklessSession` (a stream
session) around a :class:`MostStep`, the step graph of the contract :data:`~motion_style_ros.runtime.contract.MOST`
(content encoder, part-attentive style modulator, generator) with the style side of the encoder
(:data:`~motion_style_ros.runtime.contract.MOST_STYLE`) beside it:

- **Windows.** As :mod:`~motion_style_ros.runtime.windows` has them: the last ``window`` model
  frames, a window every ``hop`` frames (or when a due frame is not covered yet), blended by
  overlap-add, frame ``t`` emitted when frame ``t + lookahead`` comes in.
- **Style features.** A style motion is its body-part style feature ``S`` and its mean content
  feature ``C`` (``(parts, dim)`` each). Each style of the card has its mean over train windows
  (``style_means`` beside the model), so ``target_style`` works without a clip; a reference clip
  (:meth:`MostSession.set_reference`) is encoded once, window by window, its windows' features
  averaged, and replaces one style's (the one named, or the nearest mean's). A window's step then
  runs the content encoder, the modulator and the generator only. The features a window gets are
  the styles' mixed by the style weights (style and mix); feature changes blend over
  ``blend_seconds`` like style.
- **Alpha.** The graph's own alpha input (the style vector moved from the window's own towards the
  target's) is held at 1: the stream session applies the intensity to the output frames.
- **Style bank.** Styles enrolled from a user's clips (:mod:`~motion_style_ros.runtime.style_bank`:
  the clips' own style features, averaged) come after the card's in ``styles``, each with its
  features in place of a mean.
- **Foot locking.** Feet are locked on the input frame each output frame was made from.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from motion_style_ros.core.features import encode
from motion_style_ros.core.motion import Motion
from motion_style_ros.errors import MotionStyleError
from motion_style_ros.io import files
from motion_style_ros.runtime import style_bank
from motion_style_ros.runtime.contract import MOST, MOST_STYLE, check_card
from motion_style_ros.runtime.onnx_model import OnnxModel, model_path
from motion_style_ros.runtime.windows import BanklessSession, OverlapWindows

DEFAULT_MODEL = "most.onnx"


class MostStep(OverlapWindows):
    """The MoST step graph at ``path`` (card ``card``, its companions beside it) as a model step:
    :class:`~motion_style_ros.runtime.windows.OverlapWindows`' windows and overlap-add, every
    performer's style features per style ``(S, 2, parts, dim)`` as its style inputs; its output
    frame is ``lookahead`` model frames behind its input."""

    def __init__(self, path: Path, card: dict, threads: int, window: int | None, hop: int,
                 lookahead: int, bank: str | Path | None = None) -> None:
        check_card(card, path, "most")
        self.card = card
        self._sizes(window, int(card["window"]), hop, lookahead)
        self.model = OnnxModel(path, threads)
        MOST.check(self.model.input_names, path, "MoST step graph")
        files = card["files"]
        encoder = model_path(str(path.with_name(files["style_encoder"])))
        self.style_encoder = OnnxModel(encoder, threads)
        MOST_STYLE.check(self.style_encoder.input_names, path, "MoST style encoder")
        known = list(card["styles"])
        shape = (2, len(card["parts"]), int(card["feature_dim"]))
        self.model_digest = style_bank.digest([path, encoder])
        self.bank_path, self.bank = style_bank.open_bank(bank, path, self.model_digest, int(np.prod(shape)),
                                                         known, [style_bank.FEATURES])
        self.styles, self.known = [*known, *self.bank], len(known)
        enrolled = np.array([e.code for e in self.bank.values()]).reshape((len(self.bank), *shape))
        self.means = np.concatenate([_read_means(path.with_name(files["style_means"]), len(known), shape[1:]),
                                     enrolled])
        self._layout(card)

    def start(self, performers: int, blend_seconds: float) -> None:
        # [:, :, 0] the style features, [:, :, 1] the mean content ones
        self._start_codes(performers, blend_seconds, self.means)
        self._full = np.ones((performers, 1), dtype=np.float32)

    def run_window(self, style: np.ndarray) -> np.ndarray:
        target = self.mixed_codes(style)
        return self.model.run(features=self._history, style=target[:, 0], pooled=target[:, 1],
                              alpha=self._full)["output"]


def _read_means(path: Path, styles: int, shape: tuple[int, int]) -> np.ndarray:
    """Every style's mean features ``(S, 2, parts, dim)`` from the npz the exporter wrote, or a
    one-line reason why they cannot be read."""
    if not path.is_file():
        raise MotionStyleError(f"{path}: the styles' mean features are missing (they ship beside the model)")
    with np.load(files.check(path, "arrays"), allow_pickle=False) as npz:
        if {"style", "pooled"} - set(npz.files):
            raise MotionStyleError(f"{path}: expected arrays 'style' and 'pooled', found {', '.join(npz.files)}")
        means = np.stack([npz["style"], npz["pooled"]], axis=1).astype(np.float64)
    if means.shape != (styles, 2, *shape) or not np.isfinite(means).all():
        raise MotionStyleError(f"{path}: mean features of shape {means.shape[:1] + means.shape[2:]}, "
                               f"expected {(styles, *shape)} finite values (one per style of the card)")
    return means


class MostSession(BanklessSession):
    """The MoST stylizer over a stream of ``performers`` performers (see the module docstring and
    :class:`~motion_style_ros.runtime.windows.BanklessSession`): ``model`` the step graph's file
    name or path (card and companions beside it). A reference clip's style features (computed once)
    replace those of ``style`` (by default the style whose mean they are nearest)."""

    STEP = MostStep
    DEFAULT_MODEL = DEFAULT_MODEL

    @property
    def model(self) -> OnnxModel:
        """The step graph."""
        return self.windows.model

    @property
    def style_encoder(self) -> OnnxModel:
        """The style side of the encoder, run once per reference clip."""
        return self.windows.style_encoder

    @property
    def bank(self) -> dict[str, style_bank.Entry]:
        """The enrolled styles (after the card's in ``styles``)."""
        return self.windows.bank

    @property
    def bank_path(self) -> Path | None:
        return self.windows.bank_path

    @property
    def model_digest(self) -> str:
        """The digest a style bank of this model records."""
        return self.windows.model_digest

    # --- controls ---------------------------------------------------------------------------

    def features(self, performer: int = 0) -> np.ndarray:
        """``(S, 2, parts, dim)``: the performer's features per style as they are now."""
        return self.windows.current_codes()[self.controls.which(performer)]

    def reference_codes(self, motion: Motion) -> tuple[np.ndarray, np.ndarray]:
        """A clip's style features ``(2, parts, dim)`` (the mean over its windows, a window every
        half window) and how near they are to each style's mean ``(S,)`` (minus the squared
        distance: the nearest is the largest), or a one-line reason why the clip cannot serve as
        a reference."""
        w = self.window
        motion = self.reference_clip(motion, w)
        features = encode(motion)
        starts = sorted({*range(0, len(features) - w + 1, max(1, w // 2)), len(features) - w})
        out = self.style_encoder.run(features=np.stack([features[s : s + w] for s in starts]).astype(np.float32))
        clip = np.stack([out["style"].mean(axis=0), out["pooled"].mean(axis=0)]).astype(np.float64)
        distance = ((self.windows.means - clip) ** 2).sum(axis=(1, 2, 3))
        return clip, -distance

    def enrol(self, clips: list[Motion], names: list[str], head: str | None = None) -> style_bank.Entry:
        """A bank entry from a few clips of one style: their own style features (see
        :mod:`~motion_style_ros.runtime.style_bank`); ``head`` is stgcn's and must be None."""
        if head is not None:
            raise MotionStyleError("--head reads stgcn's encoder heads; a most entry is the clips' own "
                                   "style features")
        read = [self.reference_codes(m) for m in clips]
        frames = [round(m.n_frames * self.fps / m.fps) for m in clips]
        known = self.windows.known
        return style_bank.enrol_features([f for f, _ in read], [-near[:known] for _, near in read], frames,
                                         names, self.styles[:known])
