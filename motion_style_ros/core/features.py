"""Per-frame model features of a canonical-skeleton motion, computed causally, and their inverse.

Frame ``t`` uses frames ``<= t`` only (backward differences, no smoothing over the clip), so the
same function serves offline training and live streams. Everything is expressed in the
character's *facing frame*: the yaw of the body about +Y, from the left-right axis of hips and
shoulders. That makes features independent of where the performer stands and which way they face.

Layout (``feature_layout``), per frame:

- ``root`` (4): forward-plane velocity ``vx, vz`` (m/s, facing frame of frame t), pelvis height
  (m), yaw rate (rad/s);
- ``rot6d`` (6 per joint): local rotations in 6D; the pelvis's is relative to the facing frame;
- ``pos`` (3 per joint): joint positions relative to the pelvis's ground point, facing frame (m);
- ``vel`` (3 per joint): joint velocities, facing frame (m/s);
- ``contact`` (1 per foot joint): 1 where the foot joint is low and still.

Joints are the pelvis and its descendants (the canonical skeleton's static ``joint_Root`` is left
out). :func:`decode` rebuilds a motion from ``root`` and ``rot6d``; ``pos``, ``vel`` and
``contact`` are redundant views for models and losses.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from motion_style_ros.core import feature_kernels, jit
from motion_style_ros.core.motion import Motion, kinematic_arrays
from motion_style_ros.core.skeleton import Skeleton, canonical
from motion_style_ros.errors import MotionStyleError

FEATURE_VERSION = 1
UP = np.array([0.0, 1.0, 0.0])
_GROUND = np.array([1.0, 0.0, 1.0])  # a position's ground point: (x, 0, z)

# Contact: foot joint within this height of the floor (m) and slower than CONTACT_SPEED (m/s).
CONTACT_HEIGHT = {"Foot_L": 0.16, "Foot_R": 0.16, "Toes_L": 0.08, "Toes_R": 0.08}
CONTACT_SPEED = 0.6

_ACROSS = ("UpperLeg_L", "UpperLeg_R", "UpperArm_L", "UpperArm_R")

Mask = np.ndarray | slice | int | None  # which performers of a stream; None for all


@dataclass(frozen=True)
class FeatureLayout:
    joints: tuple[int, ...]  # skeleton joints described by the per-joint blocks
    slices: dict[str, slice]

    @functools.cached_property
    def size(self) -> int:
        return max(s.stop for s in self.slices.values())

    @functools.cached_property
    def index(self) -> np.ndarray:
        """``joints`` as an index array (a tuple is converted on every use)."""
        return np.array(self.joints, dtype=np.intp)


def feature_layout(skeleton: Skeleton | None = None) -> FeatureLayout:
    sk = skeleton or canonical()
    joints = tuple(j for j in range(sk.pelvis, sk.n_joints) if _descends(sk, j, sk.pelvis))
    n = len(joints)
    sizes = {"root": 4, "rot6d": 6 * n, "pos": 3 * n, "vel": 3 * n, "contact": len(sk.feet)}
    slices, start = {}, 0
    for name, size in sizes.items():
        slices[name] = slice(start, start + size)
        start += size
    return FeatureLayout(joints, slices)


def _descends(sk: Skeleton, j: int, ancestor: int) -> bool:
    while j > ancestor:
        j = sk.parents[j]
    return j == ancestor


def _check_canonical(sk: Skeleton) -> None:
    missing = [n for n in _ACROSS + tuple(CONTACT_HEIGHT) if n not in sk.names]
    if missing:
        raise MotionStyleError(
            f"features need the canonical skeleton; missing joints {', '.join(missing)} "
            "(retarget the motion first)"
        )


def facing_yaw(global_positions: np.ndarray, skeleton: Skeleton) -> np.ndarray:
    """Heading of the body (radians about +Y, 0 = facing +Z) from hips and shoulders, per frame."""
    lead = global_positions.shape[:-2]
    rows = jit.rows(global_positions).reshape((-1,) + global_positions.shape[-2:])
    return feature_kernels.facing_yaw(rows, _index(skeleton, _ACROSS)).reshape(lead)


@functools.cache
def _index(skeleton: Skeleton, names: tuple[str, ...]) -> np.ndarray:
    """Indices of named joints, looked up once per skeleton (streamed frames ask every time)."""
    return np.array([skeleton.index(n) for n in names], dtype=np.int64)


@functools.cache
def _feet(skeleton: Skeleton) -> np.ndarray:
    return np.array(skeleton.feet, dtype=np.int64)


@functools.cache
def _contact_heights(skeleton: Skeleton) -> np.ndarray:
    return np.array([CONTACT_HEIGHT.get(skeleton.names[j], 0.1) for j in skeleton.feet])


def _previous(x: np.ndarray) -> np.ndarray:
    """Each frame's predecessor along time; frame 0 stands in for its own (zero velocity)."""
    return np.concatenate([x[:1], x[:-1]])


def encode(motion: Motion) -> np.ndarray:
    """``(T, F)`` float32 features of a canonical-skeleton motion (see module docstring)."""
    _check_canonical(motion.skeleton)
    g_rot, g_pos = motion.global_transforms()
    sk = motion.skeleton
    yaw = facing_yaw(g_pos, sk)
    return _encode_frames(sk, feature_layout(sk), motion.rotations, g_rot[:, sk.pelvis], g_pos,
                          _previous(g_pos), yaw, _previous(yaw), motion.fps)


def _encode_frames(
    sk: Skeleton,
    lay: FeatureLayout,
    rotations: np.ndarray,
    pelvis_rot: np.ndarray,
    g_pos: np.ndarray,
    prev_g_pos: np.ndarray,
    yaw: np.ndarray,
    prev_yaw: np.ndarray,
    fps: float,
) -> np.ndarray:
    """Features of frames ``(..., J)`` (``pelvis_rot``: the pelvis's global rotation) given the
    global positions and heading (:func:`facing_yaw`) of each one's previous frame.

    The one implementation behind :func:`encode` (leading axis: time) and :class:`StreamEncoder`
    (leading axis: performers).
    """
    lead, n_joints = yaw.shape, rotations.shape[-2]

    def rows(a: np.ndarray, *shape: int) -> np.ndarray:
        return jit.rows(a).reshape((-1, *shape))

    out = feature_kernels.encode_rows(
        lay.index, _feet(sk), _contact_heights(sk), sk.pelvis, rows(rotations, n_joints, 4),
        rows(pelvis_rot, 4), rows(g_pos, n_joints, 3), rows(prev_g_pos, n_joints, 3), rows(yaw),
        rows(prev_yaw), float(fps), CONTACT_SPEED, lay.size)
    return out.reshape(lead + (lay.size,))


def _decoded_size(lay: FeatureLayout) -> int:
    return lay.slices["rot6d"].stop


def _check_decodable(f: np.ndarray, lay: FeatureLayout, lead: str) -> None:
    if f.ndim != 2 or f.shape[1] not in (lay.size, _decoded_size(lay)):
        raise MotionStyleError(
            f"features of shape {f.shape}; expected ({lead}, {lay.size}) or the root and rot6d "
            f"blocks alone, ({lead}, {_decoded_size(lay)})"
        )


def _pose(
    sk: Skeleton, lay: FeatureLayout, f: np.ndarray, yaw: np.ndarray, ground: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Local rotations ``(..., J, 4)`` and pelvis positions ``(..., 3)`` of decoded frames placed at
    ``ground`` with heading ``yaw``; the one implementation behind :func:`decode` and
    :class:`StreamDecoder`. Joints above the pelvis (the canonical static root) stay identity."""
    lead = f.shape[:-1]
    rotations, root_pos = feature_kernels.pose_rows(
        lay.index, sk.pelvis, sk.n_joints, jit.rows(f).reshape(-1, f.shape[-1]),
        jit.rows(yaw).reshape(-1),
        jit.rows(ground).reshape(-1, 3))
    return rotations.reshape(lead + (sk.n_joints, 4)), root_pos.reshape(lead + (3,))


def decode(
    features: np.ndarray,
    fps: float,
    skeleton: Skeleton | None = None,
    start_ground: np.ndarray | None = None,
    start_yaw: float = 0.0,
) -> Motion:
    """Rebuild a motion from ``root`` and ``rot6d`` features by integrating the root velocities.

    ``features`` is ``(T, F)``, or ``(T, 4 + 6 * joints)`` with the ``root`` and ``rot6d`` blocks
    alone (what the stylizers output). Frame 0's facing frame is placed at ``start_ground``
    (x, 0, z) with heading ``start_yaw``; later frames integrate yaw rate first, then velocity in
    the new facing frame, which inverts :func:`encode` exactly.
    """
    sk = skeleton or canonical()
    lay = feature_layout(sk)
    f = np.asarray(features, dtype=np.float64)
    _check_decodable(f, lay, "T")
    start = np.zeros(3) if start_ground is None else jit.rows(start_ground)
    yaw, ground = feature_kernels.trajectory(jit.rows(f), start, float(start_yaw), float(fps))
    rotations, root_pos = _pose(sk, lay, f, yaw, ground)
    return Motion.from_rotations(sk, rotations, root_pos, fps)


class StreamEncoder:
    """:func:`encode` one frame at a time for ``performers`` performers at once.

    Each performer's previous frame is carried for the backward differences; a performer's first
    frame (and its first after :meth:`reset`) has zero velocities, like frame 0 of a clip.
    """

    def __init__(self, performers: int, fps: float, skeleton: Skeleton | None = None) -> None:
        self.skeleton = skeleton or canonical()
        _check_canonical(self.skeleton)
        self.fps = fps
        self._layout = feature_layout(self.skeleton)
        self._last = np.zeros((performers, self.skeleton.n_joints, 3))  # global positions
        self._yaw = np.zeros(performers)  # and facing_yaw
        self._fresh = np.ones(performers, dtype=bool)

    def reset(self, which: Mask = None) -> None:
        """The next frame of these performers starts a new clip."""
        self._fresh[slice(None) if which is None else which] = True

    def __call__(self, rotations: np.ndarray, root_positions: np.ndarray) -> np.ndarray:
        """``(P, F)`` float32 features of one frame: local rotations ``(P, J, 4)`` and pelvis
        positions ``(P, 3)`` (the translation of the pelvis in its parent's frame)."""
        sk, lay = self.skeleton, self._layout
        return feature_kernels.encode_stream(
            *kinematic_arrays(sk), sk.pelvis, _index(sk, _ACROSS), lay.index, _feet(sk), _contact_heights(sk),
            jit.rows(rotations), jit.rows(root_positions),
            self._last, self._yaw, self._fresh, float(self.fps), CONTACT_SPEED, lay.size)

    @property
    def positions(self) -> np.ndarray:
        """World positions ``(P, J, 3)`` of each performer's last frame (the encoder's own array,
        overwritten by the next frame: copy what is kept)."""
        return self._last

    def facing(self) -> tuple[np.ndarray, np.ndarray]:
        """Ground point ``(P, 3)`` (x, 0, z) and heading ``(P,)`` of each performer's last frame:
        where a :class:`StreamDecoder` starts to follow that performer."""
        ground = self._last[:, self.skeleton.pelvis] * _GROUND
        return ground, self._yaw.copy()


class StreamDecoder:
    """:func:`decode` one frame at a time for ``performers`` performers at once.

    Each performer's ground point and heading are integrated from the frames' root velocities,
    starting where :meth:`start` placed it (the origin facing +Z until then).
    """

    def __init__(self, performers: int, fps: float, skeleton: Skeleton | None = None) -> None:
        self.skeleton = skeleton or canonical()
        self.fps = fps
        self._layout = feature_layout(self.skeleton)
        self._yaw = np.zeros(performers)
        self._ground = np.zeros((performers, 3))
        self._fresh = np.ones(performers, dtype=bool)

    def start(self, ground: np.ndarray, yaw: np.ndarray, which: Mask = None) -> None:
        """The next frame of these performers is a first frame, placed at ``ground`` (x, 0, z) with
        heading ``yaw`` (``decode``'s ``start_ground``, ``start_yaw``). ``ground`` ``(P, 3)`` and
        ``yaw`` ``(P,)`` hold every performer; only the selected ones are used."""
        which = slice(None) if which is None else which
        self._ground[which] = (np.asarray(ground, dtype=np.float64) * _GROUND)[which]
        self._yaw[which] = np.asarray(yaw, dtype=np.float64)[which]
        self._fresh[which] = True

    def pull(self, ground: np.ndarray, yaw: np.ndarray, gain: float) -> None:
        """Move every performer's ground point and heading the fraction ``gain`` of the way towards
        ``ground`` and ``yaw`` (bounds the drift of an integrated trajectory from a live one)."""
        feature_kernels.pull_stream(self._ground, self._yaw, jit.rows(ground),
                            jit.rows(yaw), self._fresh, float(gain))

    def move(self, offset: np.ndarray) -> None:
        """Move every performer's ground point by ``offset`` ``(P, 3)`` (its horizontal part): the
        trajectory goes on from where a correction of the last frame's root put it."""
        self._ground += np.asarray(offset, dtype=np.float64) * _GROUND

    def __call__(self, features: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Local rotations ``(P, J, 4)`` and pelvis positions ``(P, 3)`` of one frame of features
        ``(P, F)`` (or the ``root`` and ``rot6d`` blocks alone)."""
        lay = self._layout
        f = np.asarray(features, dtype=np.float64)
        _check_decodable(f, lay, str(len(self._yaw)))
        if f.shape[0] != len(self._yaw):
            raise MotionStyleError(
                f"features for {f.shape[0]} performers; this decoder has {len(self._yaw)}"
            )
        sk = self.skeleton
        return feature_kernels.decode_stream(lay.index, sk.pelvis, sk.n_joints, jit.rows(f), self._yaw,
                                     self._ground, self._fresh, float(self.fps))
