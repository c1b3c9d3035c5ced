"""A performer who stands on both feet is not walked away: the stylized root keeps to the input's.

A stylizer outputs the root's velocity and yaw rate, so a style can walk slower or faster than
its performer. On a performer who stands still (boxing, waving, talking), the stylizers tend to
add drift and small steps of their own, which the foot lock can only drag the planted feet after.
So, streamed frame by frame: once both of the input's feet have been in contact (the features'
``contact`` block) for ``hold_seconds``, the output's root velocity and yaw rate ease over
``ease_seconds`` into the input's own, and ease back when a foot leaves the ground. Walking never
stands on both feet that long, so its stylized speed is untouched. Pelvis height and every
rotation stay the stylizer's.
"""

from __future__ import annotations

import numpy as np

from motion_style_ros.core.easing import smoothstep
from motion_style_ros.core.features import Mask, feature_layout
from motion_style_ros.core.skeleton import Skeleton, canonical

ROOT_MOTION = [0, 1, 3]  # the root block's forward-plane velocity and yaw-rate columns


class Standing:
    """Root motion of standing performers taken from the input, for ``performers`` streams at
    ``fps`` (see the module docstring)."""

    def __init__(self, performers: int, fps: float, skeleton: Skeleton | None = None,
                 hold_seconds: float = 0.5, ease_seconds: float = 0.3) -> None:
        sk = skeleton or canonical()
        contact = feature_layout(sk).slices["contact"]
        self._contact = contact
        left = np.array([sk.names[j].endswith("_L") for j in sk.feet])
        self._sides = np.stack([left, ~left], axis=1).astype(np.float64)  # (feet, 2): which side each is
        self._frame = 1.0 / float(fps)
        self.hold_seconds = hold_seconds
        self._ease = self._frame / max(ease_seconds, self._frame)  # weight gained or lost per frame
        self._still = np.zeros(performers)  # seconds both feet have been down
        self._weight = np.zeros(performers)  # 0: the stylizer's root motion, 1: the input's

    def reset(self, which: Mask = None) -> None:
        which = slice(None) if which is None else which
        self._still[which] = 0.0
        self._weight[which] = 0.0

    def __call__(self, output: np.ndarray, features: np.ndarray) -> np.ndarray:
        """The model's output frame ``(P, >= 4)`` (root block first) with the root motion of
        standing performers eased into that of the input frame's ``features`` ``(P, F)``."""
        feet_down = (features[:, self._contact] > 0.5) @ self._sides  # (P, 2): feet down per side
        down = np.minimum.reduce(feet_down, axis=1) > 0.0
        self._still = np.where(down, self._still + self._frame, 0.0)
        target = self._still >= self.hold_seconds - 1e-9
        self._weight = np.minimum(np.maximum(self._weight + np.where(target, self._ease, -self._ease), 0.0), 1.0)
        if not self._weight.any():
            return output
        out = np.array(output, dtype=np.float64)
        w = smoothstep(self._weight)[:, None]
        out[:, ROOT_MOTION] = (1.0 - w) * out[:, ROOT_MOTION] + w * features[:, ROOT_MOTION]
        return out
