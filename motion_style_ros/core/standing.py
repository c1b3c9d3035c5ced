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
from numba import njit

from motion_style_ros.core import jit
from motion_style_ros.core.features import Mask, feature_layout
from motion_style_ros.core.skeleton import Skeleton, canonical

ROOT_MOTION = [0, 1, 3]  # the root block's forward-plane velocity and yaw-rate columns
_ROOT_MOTION = np.array(ROOT_MOTION, dtype=np.int64)

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
        """The model's output frame ``(P, >= 4)`` (root block first) as float64 with the root
        motion of standing performers eased into that of the input frame's ``features`` ``(P, F)``
        (:func:`motion_style_ros.core.stand`)."""
        return stand(self._contact.start, self._sides, _ROOT_MOTION, self._frame, float(self.hold_seconds),
                             self._ease, self._still, self._weight,
                             jit.rows(output), jit.rows(features, np.float32))


@njit(cache=True)
def stand(contact, sides, columns, frame, hold, ease, still, weight, output, features):
    """:class:`~motion_style_ros.core.standing.Standing`'s frame: the model's output rows ``(P, >=
    4)`` as float64 with the root motion (``columns``) of performers standing on both feet
    eased into that of ``features`` ``(P, F)``; ``still`` and ``weight`` ``(P,)`` updated in place.
    ``contact``: the features' first contact column; ``sides`` ``(feet, 2)``: each foot's side."""
    out = output.copy()
    for r in range(out.shape[0]):
        left = right = 0.0
        for i in range(sides.shape[0]):
            if features[r, contact + i] > 0.5:
                left += sides[i, 0]
                right += sides[i, 1]
        still[r] = still[r] + frame if min(left, right) > 0.0 else 0.0
        step = ease if still[r] >= hold - 1e-9 else -ease
        weight[r] = min(max(weight[r] + step, 0.0), 1.0)
        x = min(max(weight[r], 0.0), 1.0)
        w = x * x * (3.0 - 2.0 * x)  # easing.smoothstep
        if w == 0.0:
            continue
        for c in columns:
            out[r, c] = (1.0 - w) * out[r, c] + w * features[r, c]
    return out
