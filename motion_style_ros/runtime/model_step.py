"""The contract between a stream session and a backend's model: what the session hands a model
step each model frame (:class:`ModelFrame`), what the step gives back (:class:`Stylized`), and the
step itself (:class:`ModelStep`). A backend's runtime module implements a step and a
:class:`~motion_style_ros.runtime.stream.StreamSession` subclass that builds it."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np


@dataclass(frozen=True)
class ModelFrame:
    """One model frame of every performer as the stream hands it to a model step."""

    features: np.ndarray  # (P, F) encode() features, conditioned as the training data would show them
    ankles: np.ndarray  # (P, 2, 3) the input's ankles (what foot locks read)
    lift: np.ndarray  # (P, 3) what grounding took off the input and the output gets back
    fresh: np.ndarray  # (P,) bool: the performer starts afresh on this frame
    restate: np.ndarray  # (P,) bool: fresh, or its rig just measured (remembered context is stale)


@dataclass(frozen=True)
class Stylized:
    """A model step's output frame: the stylized ``[root | rot6d]`` blocks ``(P, n_out)`` and the
    input frame they belong to (``delay_frames`` model frames back): its features, ankles, lift."""

    blocks: np.ndarray
    features: np.ndarray
    ankles: np.ndarray
    lift: np.ndarray


class ModelStep(Protocol):
    """A backend's model inside a :class:`StreamSession`: one call per model frame."""

    delay_frames: int  # model frames by which its output frame lags its input frame
    styles: list[str]  # the card's styles and any of its own (a style bank's), as controls see them

    def start(self, performers: int, blend_seconds: float) -> None:
        """Make the per-performer state, once the stream's settings are checked."""

    def restart(self) -> None:
        """Forget the stream (a start or a gap)."""

    def __call__(self, frame: ModelFrame, style: np.ndarray) -> Stylized:
        """The stylized frame for this model frame (the full style: the session applies alpha),
        with the controls' style weights ``(P, S)``."""
