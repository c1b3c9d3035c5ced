"""A clip of skeletal motion and forward kinematics."""

from __future__ import annotations

import math
import functools
from dataclasses import dataclass

import numpy as np
from numba import njit

from motion_style_ros.core import jit
from motion_style_ros.core import rotations as rot
from motion_style_ros.core.skeleton import Skeleton, subset as skeleton_subset
from motion_style_ros.errors import MotionStyleError


@dataclass(eq=False)
class Motion:
    """Local joint rotations and translations over time, exactly what a BVH file describes.

    ``rotations`` is ``(T, J, 4)`` unit quaternions (w, x, y, z) of each joint relative to its parent;
    ``positions`` is ``(T, J, 3)`` each joint's translation in its parent's frame (the rest offset for
    joints without position channels; the pelvis carries the root trajectory).
    """

    skeleton: Skeleton
    rotations: np.ndarray
    positions: np.ndarray
    fps: float

    def __post_init__(self) -> None:
        j = self.skeleton.n_joints
        r, p = np.shape(self.rotations), np.shape(self.positions)
        if len(r) != 3 or r[1:] != (j, 4) or p != (r[0], j, 3):
            raise MotionStyleError(
                f"motion arrays of shape {r} and {p} do not fit a {j}-joint skeleton; "
                f"expected (T, {j}, 4) rotations and (T, {j}, 3) positions"
            )
        if not (np.isfinite(self.fps) and self.fps > 0):
            raise MotionStyleError(f"frame rate must be positive, got {self.fps}")

    @property
    def n_frames(self) -> int:
        return self.rotations.shape[0]

    @property
    def duration(self) -> float:
        return self.n_frames / self.fps

    @property
    def root_positions(self) -> np.ndarray:
        """World position of the pelvis over time, ``(T, 3)``."""
        return self.global_positions()[:, self.skeleton.pelvis]

    def __getitem__(self, frames: slice) -> "Motion":
        if not isinstance(frames, slice):
            raise TypeError("index a Motion with a slice of frames")
        return Motion(self.skeleton, self.rotations[frames], self.positions[frames], self.fps)

    def check_finite(self, source: str = "motion") -> "Motion":
        """Raise with the first bad frame if any value is NaN or infinite."""
        bad = ~(np.isfinite(self.rotations).all(axis=(1, 2)) & np.isfinite(self.positions).all(axis=(1, 2)))
        if bad.any():
            raise MotionStyleError(f"{source}: non-finite values at frame {int(np.argmax(bad))}")
        return self

    def global_transforms(self) -> tuple[np.ndarray, np.ndarray]:
        return forward_kinematics(self.skeleton, self.rotations, self.positions)

    def global_positions(self) -> np.ndarray:
        return self.global_transforms()[1]

    @classmethod
    def from_rotations(
        cls, skeleton: Skeleton, rotations: np.ndarray, root_positions: np.ndarray, fps: float
    ) -> "Motion":
        """A motion whose joints keep their rest offsets and whose pelvis follows ``root_positions``.

        ``root_positions`` is the pelvis translation in its parent's frame; for skeletons whose root is
        the pelvis, that is the world position.
        """
        positions = np.broadcast_to(skeleton.offsets, rotations.shape[:-1] + (3,)).copy()
        positions[:, skeleton.pelvis] = root_positions
        return cls(skeleton, rotations, positions, fps)


def rest_positions(skeleton: Skeleton, root_positions: np.ndarray) -> np.ndarray:
    """Local translations ``(P, J, 3)``: every joint's rest offset, the pelvis at
    ``root_positions`` ``(P, 3)`` (what forward kinematics of a streamed frame takes; cheaper
    than broadcasting the offsets and copying)."""
    positions = np.empty(root_positions.shape[:-1] + skeleton.offsets.shape)
    positions[...] = skeleton.offsets
    positions[..., skeleton.pelvis, :] = root_positions
    return positions


def forward_kinematics(
    skeleton: Skeleton, rotations: np.ndarray, positions: np.ndarray,
    joints: list[int] | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Global rotations ``(..., J, 4)`` and positions ``(..., J, 3)`` from local ones; with
    ``joints``, the global rotations of those joints only."""
    lead, n_joints = rotations.shape[:-2], rotations.shape[-2]
    q = jit.rows(rotations).reshape(-1, n_joints, 4)
    t = jit.rows(np.broadcast_to(positions, lead + (n_joints, 3)))
    g_rot, g_pos = jit.forward_kinematics(kinematic_arrays(skeleton)[0], q, t.reshape(-1, n_joints, 3))
    g_rot, g_pos = g_rot.reshape(lead + (n_joints, 4)), g_pos.reshape(lead + (n_joints, 3))
    return (g_rot if joints is None else g_rot[..., joints, :]), g_pos


@functools.cache
def kinematic_arrays(skeleton: Skeleton) -> tuple[np.ndarray, np.ndarray]:
    """The skeleton's parents (int64) and rest offsets (float64) as the compiled kernels take them,
    made once per skeleton."""
    return np.array(skeleton.parents, dtype=np.int64), jit.rows(skeleton.offsets)


def local_from_global(skeleton: Skeleton, global_rotations: np.ndarray) -> np.ndarray:
    """Local rotations from global ones (inverse of the rotation half of FK)."""
    local = np.array(global_rotations, dtype=np.float64, copy=True)
    for j, p in enumerate(skeleton.parents):
        if p >= 0:
            local[..., j, :] = rot.multiply(rot.conjugate(global_rotations[..., p, :]), global_rotations[..., j, :])
    return local


def subset(motion: Motion, keep: tuple[str, ...] | list[str]) -> Motion:
    """The motion on a joint subset: kept joints keep their global rotations and positions."""
    sub, idx = skeleton_subset(motion.skeleton, keep)
    g_rot, g_pos = motion.global_transforms()
    g_rot, g_pos = g_rot[:, idx], g_pos[:, idx]
    local_rot = local_from_global(sub, g_rot)
    local_pos = g_pos.copy()
    for j, p in enumerate(sub.parents):
        if p >= 0:
            local_pos[:, j] = rot.rotate(rot.conjugate(g_rot[:, p]), g_pos[:, j] - g_pos[:, p])
    return Motion(sub, local_rot, local_pos, motion.fps)


@njit(cache=True)
def check_frame(rotations, roots, tolerance):
    """A streamed frame's rotations ``(P, J, 4)`` normalised, and what is wrong with it: ``(0, ...)``
    nothing; ``(1, performer, 0, 0.0)`` a non-finite number; ``(2, performer, joint, norm)`` a
    quaternion whose norm is more than ``tolerance`` off 1."""
    out = np.empty_like(rotations)
    for r in range(rotations.shape[0]):
        finite = math.isfinite(roots[r, 0]) and math.isfinite(roots[r, 1]) and math.isfinite(roots[r, 2])
        for j in range(rotations.shape[1]):
            for c in range(4):
                finite = finite and math.isfinite(rotations[r, j, c])
        if not finite:
            return out, 1, r, 0, 0.0
    for r in range(rotations.shape[0]):
        for j in range(rotations.shape[1]):
            q = rotations[r, j]
            n = math.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
            if abs(n - 1.0) > tolerance:
                return out, 2, r, j, n
            for c in range(4):
                out[r, j, c] = q[c] / n
    return out, 0, 0, 0, 0.0
