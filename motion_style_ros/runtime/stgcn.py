"""The ST-GCN stylizer as a stream: frames in, frames out, ``lookahead`` frames later.

:class:`StgcnSession` is a :class:`~motion_style_ros.runtime.windows.WindowsSession` (windows
blended by overlap-add, the stream session's rates, gaps, root trajectory, controls, foot lock and
conditioning) around a :class:`StgcnStep`, the generator of the contract
:data:`~motion_style_ros.runtime.contract.WINDOWED` with its mapping network and style encoder:

- **Style codes.** Each performer has a code per style from the mapping network and its latent
  seed (:func:`latent`: the same seed gives the same code on every machine), or a reference clip's
  code through the style encoder (:meth:`StgcnSession.set_reference`). The code a window gets is
  the codes mixed by the style weights (style and mix); the stream session applies alpha to the
  output frames. Seed and reference changes blend over ``blend_seconds`` like style.
- **Seed spread.** A seed's code is moved away from (or towards) its style's mean code, the mean
  over :data:`MEAN_SEEDS` fixed seeds, by ``seed_spread`` (StyleGAN's truncation trick, read the
  other way): 1 is the mapping network's code as trained, 0 gives every seed the style's mean
  code, above 1 the seeds differ more, at some cost in how surely the style is recognised.
- **Style bank.** Styles enrolled from a user's clips (:mod:`motion_style_ros.runtime.style_bank`)
  come after the model's own in ``styles``, each with its one fixed code: seeds do not move it.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from motion_style_ros.core.features import encode
from motion_style_ros.core.motion import Motion
from motion_style_ros.errors import MotionStyleError
from motion_style_ros.runtime import style_bank
from motion_style_ros.runtime.backends import BACKENDS
from motion_style_ros.runtime.contract import WINDOWED, check_card
from motion_style_ros.runtime.controls import unit_interval
from motion_style_ros.runtime.defaults import DEFAULTS, StreamSettings
from motion_style_ros.runtime.onnx_model import OnnxModel, model_path, read_card
from motion_style_ros.runtime.windows import OverlapWindows, WindowsSession, latent

DEFAULT_MODEL = BACKENDS["stgcn"].default_model
MEAN_SEEDS = range(1_000_000, 1_000_064)  # the seeds whose codes average to a style's mean code
MAX_SPREAD = 4.0


def _spread(value: float) -> float:
    if isinstance(value, bool) or not (isinstance(value, (int, float, np.number)) and
                                       0.0 <= value <= MAX_SPREAD):
        raise MotionStyleError(f"seed spread must be a number from 0 to {MAX_SPREAD:g} "
                               f"(1 = the codes as trained), got {value!r}")
    return float(value)


class StgcnStep(OverlapWindows):
    """The windowed generator at ``path`` (card ``card``, its companions beside it) as a model
    step: windows over the history, overlap-add, every performer's style codes (seeds, references,
    the style bank ``bank``); its output frame is ``lookahead`` model frames behind its input."""

    WINDOW_MULTIPLE = 4

    def __init__(self, path: Path, card: dict, threads: int, window: int | None, hop: int,
                 lookahead: int, latent_seed: int, seed_spread: float, bank: str | Path | None) -> None:
        check_card(card, path, "stgcn")
        self.card = card
        self._sizes(window, int(card["window"]), hop, lookahead)
        self.model = OnnxModel(path, threads)
        WINDOWED.check(self.model.input_names, path, "windowed generator")
        companions = {k: model_path(str(path.with_name(name))) for k, name in card["files"].items()}
        self.mapping = OnnxModel(companions["mapping"], threads)
        self.style_encoder = OnnxModel(companions["style_encoder"], threads)
        self.model_digest = style_bank.digest([path, companions["style_encoder"]])
        known = list(card["styles"])
        self.bank_path, self.bank = style_bank.open_bank(bank, path, self.model_digest, int(card["style_dim"]), known)
        self.styles = [*known, *self.bank]
        self.known = len(known)
        self._bank_codes = np.array([e.code for e in self.bank.values()]).reshape(len(self.bank), int(card["style_dim"]))
        self._layout(card)
        self._seed, self._spread = latent_seed, seed_spread  # checked in start()

    def start(self, performers: int, blend_seconds: float) -> None:
        self.seed_spread = _spread(self._spread)
        self._mean_codes = self._mapped(*MEAN_SEEDS).mean(axis=0)
        self._start_codes(performers, blend_seconds, self.seed_codes(self._seed))

    def run_window(self, style: np.ndarray) -> np.ndarray:
        return self.model.run(features=self._history, code=self.mixed_codes(style))["output"]

    # --- codes --------------------------------------------------------------------------------

    def seed_codes(self, seed: int) -> np.ndarray:
        """``(S, D)``: every style's code for one seed, at the seed spread (the bank's codes as
        they are)."""
        seeded = self._mean_codes + self.seed_spread * (self._mapped(seed)[0] - self._mean_codes)
        return np.concatenate([seeded, self._bank_codes])

    def _mapped(self, *seeds: int) -> np.ndarray:
        """``(K, S, D)``: every style's code for each seed from the mapping network, as trained
        (one run for all of them)."""
        n, size = self.known, int(self.card["latent_dim"])
        z = np.repeat(np.stack([latent(seed, size) for seed in seeds]), n, axis=0).astype(np.float32)
        style = np.tile(np.eye(n, dtype=np.float32), (len(seeds), 1))
        return self.mapping.run(z=z, style=style)["code"].astype(np.float64).reshape(len(seeds), n, -1)


class StgcnSession(WindowsSession):
    """The windowed stylizer over a stream of ``performers`` performers (see the module docstring
    and :class:`~motion_style_ros.runtime.stream.StreamSession`).

    ``model``: the generator's file name or path (card and companions beside it); ``window``:
    frames per window (default: the card's; a multiple of 4); ``hop``: frames between windows;
    ``lookahead``: output delay in model frames (0 to ``window - 1``); ``latent_seed``: every
    performer's seed; ``seed_spread``: see the module docstring. Until :meth:`set_style`, every
    performer gets the card's ``neutral_style`` at alpha 1. ``bank``: a style bank file (default:
    the model's own, beside it, if there is one); ``settings`` and the stream settings by name:
    :class:`~motion_style_ros.runtime.defaults.StreamSettings`.
    """

    def __init__(self, model: str | Path = DEFAULT_MODEL, performers: int = 1, input_fps: float | None = None,
                 threads: int = 1, window: int | None = None, hop: int = DEFAULTS["hop"],
                 lookahead: int = DEFAULTS["lookahead"], latent_seed: int = 0,
                 seed_spread: float = DEFAULTS["seed_spread"], bank: str | Path | None = None,
                 settings: StreamSettings | None = None, **stream) -> None:
        path = model_path(str(model))
        w = StgcnStep(path, read_card(path), threads, window, hop, lookahead, latent_seed, seed_spread, bank)
        self.model, self.mapping, self.style_encoder = w.model, w.mapping, w.style_encoder
        self.model_digest, self.bank, self.bank_path = w.model_digest, w.bank, w.bank_path
        super().__init__(w, performers, input_fps, StreamSettings.of(settings, stream))

    @property
    def seed_spread(self) -> float:
        """How far seeds' codes lie from their style's mean (1: as trained); :meth:`set_seed` sets it."""
        return self.windows.seed_spread

    # --- controls ---------------------------------------------------------------------------

    def set_seed(self, latent_seed: int, performer: int | None = None, mix_seed: int | None = None,
                 mix_weight: float = 0.0, spread: float | None = None) -> None:
        """Every style's code from the mapping network and this seed (mixed with ``mix_seed``'s
        codes by ``mix_weight`` in [0, 1]), at ``spread`` (default: the session's ``seed_spread``,
        which a value given here replaces); drops a reference. Blends over ``blend_seconds``."""
        which = self.controls.which(performer)
        if spread is not None:
            self.windows.seed_spread = _spread(spread)
        codes = self.windows.seed_codes(latent_seed)
        if mix_seed is not None:
            w = unit_interval(mix_weight, "seed mix weight")
            codes = (1.0 - w) * codes + w * self.windows.seed_codes(mix_seed)
        self.catch_up()  # the model frames a pipelined step left run with the codes they had
        self.windows.blend_to(which, codes)

    def codes(self, performer: int = 0) -> np.ndarray:
        """``(S, D)``: the performer's code for each style as it is now (mid-blend included)."""
        return self.windows.current_codes()[self.controls.which(performer)]

    def set_reference(self, motion: Motion, style: str | None = None, performer: int | None = None
                      ) -> str:
        """Move like this recording: the reference clip's style code (style encoder) becomes the
        target. ``style`` names the clip's style (which encoder head to read); by default the
        encoder's own classifier recognises it. Sets that style as the target; returns it."""
        return self.use_reference(*self.reference_codes(motion), style, performer)

    def use_reference(self, codes: np.ndarray, logits: np.ndarray, style: str | None = None,
                      performer: int | None = None) -> str:
        """:meth:`set_reference` with the clip's :meth:`reference_codes` already made (a node makes
        them off the thread that streams)."""
        k = int(np.argmax(logits)) if style is None else self.controls.style_index(style)
        if k < self.windows.known:
            head = k
        else:  # an enrolled style: its own head, or for a mixed entry the clip's closest style
            enrolled = self.bank[self.styles[k]].head
            head = int(np.argmax(logits)) if enrolled == style_bank.MIX else self.styles.index(enrolled)
        return self._target(codes[head], k, performer)

    def enrol(self, clips: list[Motion], names: list[str], head: str | None = None) -> style_bank.Entry:
        """A bank entry from a few clips of one style (see :mod:`~motion_style_ros.runtime.style_bank`)."""
        read = [self.reference_codes(m) for m in clips]
        frames = [round(m.n_frames * self.fps / m.fps) for m in clips]
        return style_bank.enrol([c for c, _ in read], [x for _, x in read], frames, names,
                                self.styles[: self.windows.known], head)

    def reference_codes(self, motion: Motion) -> tuple[np.ndarray, np.ndarray]:
        """A clip's code under every style's head ``(S, D)`` and the style logits ``(S,)``, or a
        one-line reason why the clip cannot serve as a reference."""
        motion = self.reference_clip(motion, self.window)
        features = encode(motion)
        features = features[: len(features) // 4 * 4][None].astype(np.float32)
        out = self.style_encoder.run(features=features)
        return out["codes"][0], out["logits"][0]
