"""Left-right mirroring of canonical-skeleton motion (training augmentation: a performer who leads
with the other hand, turns the other way).

The world is reflected across its YZ plane (``x -> -x``) and every joint takes its mate's motion
(``_L`` <-> ``_R``). In local terms, with ``M`` the world reflection and ``C_j`` a fixed reflection
of joint ``j``'s own frame, the mate's global rotation is ``M G_j C_j``, so its local rotation is
``C_parent L_j C_j`` and the pelvis's position is ``M p``. ``C_j`` must map the mate's bone offsets
onto the joint's own (``C_parent o_mate(k) = o_k`` for every child ``k``); where two reflections do
(a bone along its X axis keeps its length under a 180 degree roll), the one whose mirrored rotations
match the mate's real ones on Bandai walks and runs was taken (fitted joint by joint from the
pelvis down; ``test/test_mirror.py`` checks it against the rolled alternative). The canonical
skeleton's spine frames have their lateral axis along Z, the pelvis's along Y, and the limbs'
frames are mirror images already (``C = -I``: the limb's local rotations are copied to its mate
unchanged).
"""

from __future__ import annotations

import functools

import numpy as np

from motion_style_ros.core import rotations as rot
from motion_style_ros.core.motion import Motion
from motion_style_ros.core.skeleton import canonical
from motion_style_ros.errors import MotionStyleError

WORLD = np.diag([-1.0, 1.0, 1.0])
# The reflection of each joint's frame, by name (joint_Root's is the world's: it does not move).
_FRAMES = {"joint_Root": (-1, 1, 1), "Hips": (1, -1, 1), "Spine": (1, 1, -1), "Chest": (1, 1, -1),
           "Neck": (1, 1, -1), "Head": (1, 1, -1)}
_LIMB = (-1, -1, -1)


def mate(name: str) -> str:
    """The joint on the other side (``Hand_L`` -> ``Hand_R``); a joint on the midline is its own."""
    side = name[-2:]
    return name[:-2] + {"_L": "_R", "_R": "_L"}[side] if side in ("_L", "_R") else name


@functools.cache
def _tables() -> tuple[np.ndarray, np.ndarray]:
    sk = canonical()
    mates = np.array([sk.index(mate(n)) for n in sk.names])
    frames = np.array([np.diag(_FRAMES.get(n, _LIMB)).astype(float) for n in sk.names])
    return mates, frames


def mirror(motion: Motion) -> Motion:
    """The motion mirrored left to right (the same skeleton, frame rate and length)."""
    sk = canonical()
    if motion.skeleton.names != sk.names:
        raise MotionStyleError("mirror() needs a canonical-skeleton motion (retarget it first)")
    mates, frames = _tables()
    local = rot.to_matrix(motion.rotations)[:, mates]  # each joint takes its mate's rotation
    parents = np.array([max(p, 0) for p in sk.parents])
    outer = np.where(np.array(sk.parents)[:, None, None] < 0, WORLD, frames[parents])
    mirrored = outer @ local @ frames  # C_parent L C (for joint_Root: M L M)
    positions = motion.positions.copy()
    positions[:, sk.pelvis] = motion.positions[:, sk.pelvis] @ WORLD
    return Motion(motion.skeleton, rot.from_matrix(mirrored), positions, motion.fps)
