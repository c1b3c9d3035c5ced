"""Alpha as intensity: the performer's own frame turned towards the stylized one, per body part.

A stylizer's output at alpha 1 is the full style; at alpha 0 it is the input itself (every local
rotation and the root, not the model's reconstruction of it), and in between each joint's local
rotation is slerped from the input's towards the stylized one and the root moved linearly. The
weight is ``alpha`` times the joint's part alpha (:data:`PARTS`), so a teleoperator can restyle the
arms and keep the legs as performed, or an avatar keep its tracked hands' arms.

The legs' part carries the pelvis, the root joint and the root's trajectory: the lower body steps as
one, so legs kept as performed walk exactly as performed, feet included.
"""

from __future__ import annotations

import numpy as np

from motion_style_ros.core import rotations as rot
from motion_style_ros.core.skeleton import Skeleton
from motion_style_ros.errors import MotionStyleError

PARTS = ("torso", "arms", "legs")  # the order of a part-alpha vector
# the skeleton's parts (Skeleton.parts) in each; the root joint and pelvis go with the legs
_MEMBERS = {"torso": ("torso",), "arms": ("arm_l", "arm_r"), "legs": ("leg_l", "leg_r")}


def part_of_joints(skeleton: Skeleton) -> np.ndarray:
    """``(J,)`` the index into :data:`PARTS` of each joint's part."""
    part = np.full(skeleton.n_joints, PARTS.index("legs"))  # the root joint and any unlisted one
    for k, name in enumerate(PARTS):
        for member in _MEMBERS[name]:
            part[list(skeleton.parts[member])] = k
    part[skeleton.pelvis] = PARTS.index("legs")
    return part


def check_part_alpha(values) -> tuple[float, ...]:
    """``values`` as one number in [0, 1] per part of :data:`PARTS`, or a one-line reason why not."""
    allowed = f"{len(PARTS)} numbers in [0, 1], for {', '.join(PARTS)}"
    try:
        parts = tuple(float(v) for v in values)
    except (TypeError, ValueError):
        raise MotionStyleError(f"part alpha must be {allowed}; got {values!r}") from None
    if len(parts) != len(PARTS) or not all(0.0 <= v <= 1.0 for v in parts):  # rejects NaN too
        raise MotionStyleError(f"part alpha must be {allowed}; got {list(parts)}")
    return parts


def toward(a: np.ndarray, b: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """Quaternions ``(..., 4)`` ``weights`` ``(...)`` of the way from ``a`` to ``b`` (slerp),
    ``a`` and ``b`` themselves at weights 0 and 1."""
    q = rot.slerp(a, b, weights)
    q = np.where((weights <= 0.0)[..., None], a, q)
    return np.where((weights >= 1.0)[..., None], b, q)


def blend(q_input: np.ndarray, p_input: np.ndarray, q_styled: np.ndarray, p_styled: np.ndarray,
          weights: np.ndarray, root_weight: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The frame ``weights`` ``(P, J)`` of the way from the input's local rotations ``(P, J, 4)``
    to the stylized ones, and the roots ``(P, 3)`` ``root_weight`` ``(P,)`` of the way (linear)."""
    w = root_weight[:, None]
    p = np.where(w >= 1.0, p_styled, p_input + w * (p_styled - p_input))
    return toward(q_input, q_styled, weights), p
