"""Every compiled kernel a stream and the clip functions run, made ready before the first frame.

The core's arithmetic is compiled by numba on first use (:mod:`motion_style_ros.core.jit`) and
cached on disk. The first use after an install compiles it (17-45 s on a small 2-core
machine), later ones load the cache (a fraction of a second); :func:`warm_kernels` pays either
before a node subscribes, so that neither lands on a live stream's first frames. It streams a
second of a synthetic walk through a session with every conditioning on and an echo for a model
(no model file needed), and runs the clip functions once.
"""

from __future__ import annotations

import functools
import time

import numpy as np

from motion_style_ros.core.conform import conform_rolls
from motion_style_ros.core.features import encode, decode
from motion_style_ros.core.foot_lock import FootLock
from motion_style_ros.core.proportions import clip_scale
from motion_style_ros.core.resample import resample
from motion_style_ros.core.synthetic import synthetic_motion
from motion_style_ros.io.joint_state import JointStateLayout, rotation_values, rotations_from_values
from motion_style_ros.io.resources import rotation_stats
from motion_style_ros.runtime.defaults import StreamSettings
from motion_style_ros.runtime.model_step import ModelFrame, Stylized
from motion_style_ros.runtime.stream import StreamSession

_CARD = {"styles": ["echo"], "fps": 30.0, "neutral_style": "echo"}


class _Echo:
    """A model step that gives each model frame's own root and rotations back."""

    delay_frames = 0
    styles = _CARD["styles"]

    def start(self, performers: int, blend_seconds: float) -> None:
        pass

    def restart(self) -> None:
        pass

    def __call__(self, frame: ModelFrame, style: np.ndarray) -> Stylized:
        return Stylized(frame.features[:, :130], frame.features, frame.ankles, frame.lift)


@functools.cache
def warm_kernels() -> float:
    """Compile or load every kernel (once per process); the seconds it took."""
    start = time.monotonic()
    walk = synthetic_motion("walk", 120.0, 1.0)
    session = StreamSession(_CARD, _Echo(), 1, 120.0, StreamSettings(blend_seconds=0.2, gap_seconds=0.25))
    for k in range(walk.n_frames):
        session.step(walk.rotations[k], walk.root_positions[k], k / walk.fps)
    clip = resample(walk, 30.0)
    decode(encode(clip), clip.fps)
    conform_rolls(clip, rotation_stats())
    clip_scale(clip)
    FootLock(1, clip.fps)(clip.rotations[:1], clip.root_positions[:1])
    layout = JointStateLayout.canonical()
    layout.decode(layout.names, layout.encode(clip.rotations[0], clip.root_positions[0]))
    rotations_from_values(rotation_values(clip.rotations[0]))
    return time.monotonic() - start
