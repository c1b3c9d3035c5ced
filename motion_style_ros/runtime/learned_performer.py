"""The ``learned_performer`` node without ROS: an endless stream of JointState vectors sampled from a
trained SAAE's prior (:class:`~motion_style_ros.runtime.saae.Sampler`) at the node's rate, and the
checks of its live parameters.

The node publishes :meth:`LearnedStream.next_frame` once a timer period; ``motion-style perform``
writes :meth:`LearnedStream.motion` to a BVH file. Frames come from chunks of
:data:`CHUNK_SECONDS`, each going on from the last with no seam (Sampler.chunk); a style change
reaches the windows drawn from the next chunk on and blends in over half a window
(Sampler.set_style).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from motion_style_ros.core.motion import Motion
from motion_style_ros.errors import MotionStyleError
from motion_style_ros.io.joint_state import JointStateLayout
from motion_style_ros.runtime.defaults import DEFAULTS
from motion_style_ros.runtime.saae import DEFAULT_MODEL, SPREAD, Sampler
from motion_style_ros.runtime.stylizer_settings import wrong_type

CHUNK_SECONDS = 0.25  # a style change shows in the windows drawn after at most this much
DYNAMIC = {"style": str, "frame_id": str}  # parameters that change live, with their types
MAX_SEED = 2**31 - 1


class LearnedStream:
    """New motion of one style from the SAAE at ``model`` (a shipped file name or a path; default the
    registry's saae model) at ``fps``, as ``layout`` vectors (canonical: root translation and
    rotation, then every bone's local rotation). ``style`` '' is the model's neutral style."""

    def __init__(self, model: str | Path = DEFAULT_MODEL, style: str = "", seed: int = 0, spread: float = SPREAD,
                 fps: float = 60.0, layout: JointStateLayout | None = None, threads: int = 1,
                 foot_lock: bool = DEFAULTS["foot_lock"]) -> None:
        if not (isinstance(fps, (int, float)) and not isinstance(fps, bool) and fps > 0):
            raise MotionStyleError(f"fps must be a positive number, got {fps!r}")
        if not (isinstance(seed, int) and not isinstance(seed, bool) and 0 <= seed <= MAX_SEED):
            raise MotionStyleError(f"seed must be a whole number from 0 to {MAX_SEED}, got {seed!r}")
        self.sampler = Sampler(model or DEFAULT_MODEL, None, seed=seed, spread=spread, threads=threads,
                               foot_lock=foot_lock)
        self.styles = self.sampler.styles
        self.neutral = self.sampler.style  # the card's neutral style (or its first)
        if reason := self.problem("style", style):
            raise MotionStyleError(reason)
        self.set_style(style)
        self.fps = float(fps)
        self.layout = layout or JointStateLayout.canonical()
        self.frames = 0  # frames handed out
        self._chunk: np.ndarray = np.zeros((0, len(self.layout.names)))

    @property
    def style(self) -> str:
        return self.sampler.style

    def problem(self, key: str, value) -> str | None:
        """Why ``value`` is no value for the live parameter ``key``, or None."""
        if reason := wrong_type(key, value, DYNAMIC[key]):
            return reason
        if key == "style" and value and value not in self.styles:
            return (f"unknown style {value!r}; this model knows: {', '.join(self.styles)} "
                    f"('' = {self.neutral})")
        return None

    def set_style(self, style: str) -> None:
        """The style of the windows drawn from the next chunk on ('' = the neutral style)."""
        self.sampler.set_style(style or self.neutral)

    def next_frame(self) -> np.ndarray:
        """The next frame's positions ``(len(layout.names),)``."""
        if not len(self._chunk):
            self._chunk = self.layout.encode_motion(self.sampler.chunk(CHUNK_SECONDS, self.fps))
        frame, self._chunk = self._chunk[0], self._chunk[1:]
        self.frames += 1
        return frame

    def motion(self, seconds: float) -> Motion:
        """The next ``seconds`` of the stream as a canonical-skeleton clip at ``fps`` (from the
        stream's own trajectory, which starts at the origin facing +Z)."""
        if not (isinstance(seconds, (int, float)) and seconds > 0 and np.isfinite(seconds)):
            raise MotionStyleError(f"seconds must be a positive number, got {seconds!r}")
        return self.sampler.chunk(float(seconds), self.fps)

