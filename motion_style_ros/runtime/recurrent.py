"""The recurrent (Style-ERD) stylizer as a stream: one frame in, one stylized frame out.

A :class:`RecurrentSession` is a :class:`~motion_style_ros.runtime.stream.StreamSession` (rates,
pipelining, gaps, trajectory, foot locking, conditioning, controls, bad input: see there) around a
:class:`RecurrentStep`: the recurrent ONNX stylizer of the contract
:data:`~motion_style_ros.runtime.contract.RECURRENT` (raw ``encode()`` features, style weights,
alpha (always 1: the stream session applies the intensity), the LSTM state and a reset flag in; the stylized ``[root | rot6d]`` blocks and the next
state out), one call per model frame for all performers, its output frame that of its input frame.
The state starts from the model's learned initial state on a performer's first frame, after a
reset or gap, and once the stream's conditioning has been measured.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from motion_style_ros.runtime.backends import BACKENDS
from motion_style_ros.runtime.contract import RECURRENT, check_card
from motion_style_ros.runtime.defaults import StreamSettings
from motion_style_ros.runtime.onnx_model import OnnxModel, model_path, read_card
from motion_style_ros.runtime.model_step import ModelFrame, Stylized
from motion_style_ros.runtime.stream import StreamSession


class RecurrentStep:
    """The recurrent stylizer at ``path`` (its card ``card``) as a model step: no delay."""

    delay_frames = 0

    def __init__(self, path: Path, card: dict, threads: int) -> None:
        check_card(card, path, "recurrent")
        self.model = OnnxModel(path, threads)
        RECURRENT.check(self.model.input_names, path, "recurrent stylizer")
        self.styles = list(card["styles"])
        self._state_size = int(card["state_size"])

    def start(self, performers: int, blend_seconds: float) -> None:
        self._state = np.zeros((performers, self._state_size), dtype=np.float32)
        self._full = np.ones((performers, 1), dtype=np.float32)

    def restart(self) -> None:
        """Nothing to forget: the reset input restarts the state on a performer's fresh frame."""

    def __call__(self, frame: ModelFrame, style: np.ndarray) -> Stylized:
        out = self.model.run(features=frame.features, style=style, alpha=self._full, state=self._state,
                             reset=frame.restate[:, None].astype(np.float32))
        self._state = out["state_out"]
        return Stylized(out["output"], frame.features, frame.ankles, frame.lift)


class RecurrentSession(StreamSession):
    """A recurrent stylizer over a stream of ``performers`` performers (see the module docstring
    and :class:`~motion_style_ros.runtime.stream.StreamSession`).

    ``model``: a shipped model's file name or a path (the card beside it); ``threads``: ONNX
    Runtime threads; ``settings`` and the stream settings by name (``foot_lock=False``):
    :class:`~motion_style_ros.runtime.defaults.StreamSettings`.
    Until :meth:`set_style`, every performer gets the model's neutral style (its card's
    ``neutral_style``) at alpha 1.
    """

    def __init__(self, model: str | Path = BACKENDS["recurrent"].default_model, performers: int = 1,
                 input_fps: float | None = None, threads: int = 1, settings: StreamSettings | None = None,
                 **stream) -> None:
        path = model_path(str(model))
        card = read_card(path)
        step = RecurrentStep(path, card, threads)
        self.model = step.model
        super().__init__(card, step, performers, input_fps, StreamSettings.of(settings, stream))
