"""The sender's rig: VMC frames to motion on the canonical skeleton and back."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from motion_style_ros.core import rotations as rot
from motion_style_ros.core.motion import Motion
from motion_style_ros.core.retarget import MAPS, Retargeter, find_map, tpose
from motion_style_ros.core.skeleton import Skeleton, canonical
from motion_style_ros.errors import MotionStyleError
from motion_style_ros.io.vmc.protocol import (
    UNITY_PARENTS,
    VmcFrame,
    core_to_unity_position,
    core_to_unity_rotation,
    unity_to_core_position,
    unity_to_core_rotation,
)


def _unity_tree(present: Sequence[str]) -> tuple[list[str], list[int]]:
    """The body bones among ``present``, parents first, each with its nearest present ancestor."""
    names = [b for b in UNITY_PARENTS if b in present]
    parents = []
    for b in names:
        p = UNITY_PARENTS[b]
        while p is not None and p not in present:
            p = UNITY_PARENTS[p]
        parents.append(-1 if p is None else names.index(p))
    return names, parents


def unity_rig(frame: VmcFrame) -> Skeleton:
    """The sender's rig, from a frame's bone local positions (taken as the rest offsets)."""
    names, parents = _unity_tree(list(frame.bones))
    offsets = unity_to_core_position(np.stack([frame.bones[b][0] for b in names]))
    return Skeleton(tuple(names), tuple(parents), offsets, pelvis=0)


def root_transform(frame: VmcFrame) -> tuple[np.ndarray, np.ndarray]:
    """The avatar root's position and rotation in the core frame.

    A v2.1 root offset is taken off the position (an MR marionette places the avatar at
    ``(p - offset) / scale``). The scale (the marionette shrinks the whole avatar by it) is left
    out: it scales the body and its root motion alike, and retargeting to the canonical
    proportions takes that out again.
    """
    p = frame.root[0] if frame.root_offset is None else frame.root[0] - frame.root_offset
    return unity_to_core_position(p), rot.normalize(unity_to_core_rotation(frame.root[1]))


def rig_motion(rig: Skeleton, frames: Sequence[VmcFrame], fps: float) -> Motion:
    """Frames on ``rig`` in the core frame; the root transform is folded into the hips."""
    pos = unity_to_core_position([[f.bones[b][0] for b in rig.names] for f in frames])
    q = rot.normalize(unity_to_core_rotation([[f.bones[b][1] for b in rig.names] for f in frames]))
    roots = [root_transform(f) for f in frames]
    root_p = np.stack([r[0] for r in roots])
    root_q = np.stack([r[1] for r in roots])
    pos[:, 0] = root_p + rot.rotate(root_q, pos[:, 0])
    q[:, 0] = rot.multiply(root_q, q[:, 0])
    return Motion(rig, q, pos, fps)


def tpose_rig(source: Skeleton) -> Skeleton:
    """A Unity-named rig with ``source``'s proportions whose rest pose is the T-pose.

    This is how a normalised (VRM) avatar looks to VMC: identity local rotations in the T-pose, so
    offsets are the T-pose's world-frame bone vectors.
    """
    tp = tpose(source, find_map(source))
    unity = MAPS["unity"].joints
    joint_of = {unity[c][-1]: j for c, j in tp.joints.items()}  # "Chest", not "UpperChest"
    names, parents = _unity_tree(list(joint_of))
    offsets = np.stack([
        tp.positions[joint_of[b]] - (tp.positions[joint_of[names[p]]] if p >= 0 else 0.0)
        for b, p in zip(names, parents)
    ])
    return Skeleton(tuple(names), tuple(parents), offsets, pelvis=0)


class VmcDecoder:
    """Complete VMC frames -> motion on ``target`` (the canonical skeleton by default).

    The sender's rig is built from a frame's bone local positions (its rest offsets: bones do not
    stretch) and retargeted by bone names and T-pose. Its rest pose is whatever identity local
    rotations make of those offsets, a T-pose on a normalised VRM avatar, an A-pose or any other on
    a Unity humanoid: :func:`~motion_style_ros.core.retarget.tpose` works out from the offsets
    how each bone turns into the T-pose, so proportions and rest pose both come from the stream.
    The rig is built again when a frame's bones or offsets differ from it (another avatar, a new
    calibration) and after :meth:`reset`.
    """

    def __init__(self, target: Skeleton | None = None, fps: float = 30.0) -> None:
        self.target = target or canonical()
        self.fps = fps
        self.rig: Skeleton | None = None
        self._retarget: Retargeter | None = None

    def reset(self) -> None:
        self.rig = self._retarget = None

    @property
    def retarget(self) -> Retargeter | None:
        """The sender rig -> target retargeting in use (None before a frame built the rig)."""
        return self._retarget

    def _fits(self, frame: VmcFrame) -> bool:
        """Whether ``frame`` has the rig's body bones, with its offsets to within 0.1 mm (the hips'
        position is the root motion, not an offset)."""
        rig = self.rig
        if rig is None or len(frame.bones) < rig.n_joints:
            return False
        try:
            offsets = np.stack([frame.bones[b][0] for b in rig.names[1:]])
        except KeyError:
            return False
        names, _ = _unity_tree(list(frame.bones))
        return tuple(names) == rig.names and bool(
            np.abs(unity_to_core_position(offsets) - rig.offsets[1:]).max() < 1e-4)

    def __call__(self, frames: Sequence[VmcFrame]) -> Motion:
        if not self._fits(frames[0]):
            rig = unity_rig(frames[0])
            lengths = [np.linalg.norm(rig.offsets[rig.index(b)])
                       for b in ("LeftLowerLeg", "LeftFoot", "RightLowerLeg", "RightFoot")]
            if min(lengths) < 1e-6:
                raise MotionStyleError("VMC frame has zero-length legs; no rig can be built from it")
            self._retarget = Retargeter(rig, self.target, MAPS["unity"], find_map(self.target))
            self.rig = rig
        return self._retarget(rig_motion(self.rig, frames, self.fps))


class VmcEncoder:
    """Motion on ``source`` (canonical by default) -> VMC frames for a T-posed Unity rig with the
    source's proportions (what :class:`VmcLink` sends before it knows the sender's rig)."""

    def __init__(self, source: Skeleton | None = None) -> None:
        self.source = source or canonical()
        self.rig = tpose_rig(self.source)
        self._retarget = Retargeter(self.source, self.rig, find_map(self.source), MAPS["unity"])

    def __call__(self, motion: Motion) -> list[VmcFrame]:
        m = self._retarget(motion)
        pos = core_to_unity_position(m.positions)
        q = core_to_unity_rotation(m.rotations)
        dt = 1.0 / m.fps
        return [
            VmcFrame({b: (pos[t, j], q[t, j]) for j, b in enumerate(self.rig.names)}, time=t * dt)
            for t in range(m.n_frames)
        ]
