"""Retargeting between humanoid skeletons by bone-name map and T-pose alignment.

Each supported naming (the canonical Bandai/Unity skeleton, CMU, Unity HumanBodyBones as sent by
VMC) maps canonical joint names to its own. Every skeleton is first put in a T-pose built from one
table of desired bone directions, so a source whose zero pose is not a T-pose still lines up. A
mapped joint then takes the source joint's global rotation times a constant T-pose alignment, and a
per-frame swing makes the bone to its next mapped joint point exactly where the source's does (the
source may have extra joints in between, such as CMU's LowerBack and Neck, whose rotation would
otherwise be lost). Joints with two child chains (Hips, and Chest when the shoulders are apart) are
oriented from the source's positions: the bone up the spine exactly, the left-right axis in the
least-squares sense. The pelvis follows the source's hip centre scaled by the leg-length ratio.

Positions are matched bone by bone; a bone's twist comes from the T-pose alignment alone, so local
rotations follow the target rig's conventions only as far as the rigs' T-pose frames agree (CMU
knees bend about the canonical knee axis to within a degree; CMU elbows 36-40 degrees off it, a
per-subject twist of the CMU forearm frames that no skeleton-level rule can see).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from motion_style_ros.core import rotations as rot
from motion_style_ros.core.motion import Motion, forward_kinematics, local_from_global
from motion_style_ros.core.skeleton import Skeleton
from motion_style_ros.errors import MotionStyleError

# Canonical joints, parents first (the canonical skeleton's order without its static joint_Root).
CANONICAL_JOINTS = (
    "Hips", "Spine", "Chest", "Neck", "Head",
    "Shoulder_L", "UpperArm_L", "LowerArm_L", "Hand_L",
    "Shoulder_R", "UpperArm_R", "LowerArm_R", "Hand_R",
    "UpperLeg_L", "LowerLeg_L", "Foot_L", "Toes_L",
    "UpperLeg_R", "LowerLeg_R", "Foot_R", "Toes_R",
)
# Unity's required humanoid bones; the others (Chest, Neck, shoulders, toes) may be missing.
REQUIRED_JOINTS = (
    "Hips", "Spine", "Head", "UpperArm_L", "LowerArm_L", "Hand_L", "UpperArm_R", "LowerArm_R",
    "Hand_R", "UpperLeg_L", "LowerLeg_L", "Foot_L", "UpperLeg_R", "LowerLeg_R", "Foot_R",
)

_X, _Y, _Z = np.eye(3)

# T-pose: canonical joint -> (joints its bone may end at, nearest first; world direction of it).
_BONE_DIRECTIONS: dict[str, tuple[tuple[str, ...], np.ndarray]] = {
    "Hips": (("Spine", "Chest", "Neck", "Head"), _Y),
    "Spine": (("Chest", "Neck", "Head"), _Y),
    "Chest": (("Neck", "Head"), _Y),
    "Neck": (("Head",), _Y),
    "UpperLeg_L": (("LowerLeg_L", "Foot_L"), -_Y),
    "LowerLeg_L": (("Foot_L",), -_Y),
    "Foot_L": (("Toes_L",), _Z),
    "UpperLeg_R": (("LowerLeg_R", "Foot_R"), -_Y),
    "LowerLeg_R": (("Foot_R",), -_Y),
    "Foot_R": (("Toes_R",), _Z),
}
for _side, _out in (("L", _X), ("R", -_X)):
    _BONE_DIRECTIONS[f"Shoulder_{_side}"] = ((f"UpperArm_{_side}", f"LowerArm_{_side}"), _out)
    _BONE_DIRECTIONS[f"UpperArm_{_side}"] = ((f"LowerArm_{_side}", f"Hand_{_side}"), _out)
    _BONE_DIRECTIONS[f"LowerArm_{_side}"] = ((f"Hand_{_side}",), _out)

# Joints whose left-right axis comes from a pair of mapped children (left minus right points to +X).
_LATERAL = {"Hips": ("UpperLeg_L", "UpperLeg_R"), "Chest": ("Shoulder_L", "Shoulder_R")}


@dataclass(frozen=True)
class BoneMap:
    """A naming of the humanoid bones: canonical joint -> candidate joint names, first present wins.

    ``frames`` gives, for skeletons whose rest pose is not a standing pose, each joint's global
    rotation in the T-pose (a guess refined by the bone directions); otherwise a joint starts from
    its rest rotation and turns the least it can.
    """

    name: str
    joints: dict[str, tuple[str, ...]]
    frames: dict[str, np.ndarray] = field(default_factory=dict)

    def resolve(self, skeleton: Skeleton) -> dict[str, int]:
        """Canonical joint -> joint index in ``skeleton``, for the bones it has."""
        names = {n: i for i, n in enumerate(skeleton.names)}
        found = {}
        for canon, candidates in self.joints.items():
            hit = next((names[c] for c in candidates if c in names), None)
            if hit is not None:
                found[canon] = hit
        return found

    def missing(self, skeleton: Skeleton) -> list[str]:
        """Names of required bones ``skeleton`` lacks, as this naming spells them."""
        found = self.resolve(skeleton)
        return [self.joints[c][0] for c in REQUIRED_JOINTS if c not in found]


def _axes(spec: str) -> np.ndarray:
    """The frame whose local X, Y, Z point along the world axes in ``spec`` (``"+Y-X+Z"``)."""
    cols = [(-1.0 if spec[i] == "-" else 1.0) * np.eye(3)["XYZ".index(spec[i + 1])] for i in (0, 2, 4)]
    return rot.from_matrix(np.stack(cols, axis=-1))


# The Bandai rig's bones all lie along their local X, so its rest pose fixes no twist: these are its
# joint frames in a T-pose as its clips use them (a signed permutation of the world axes each; with
# them, retargeted CMU knees bend about local Y as Bandai's do, to within a degree).
_CANONICAL_FRAMES = {
    "Hips": _axes("+Y-X+Z"),
    **{j: _axes("+Y+Z+X") for j in ("Spine", "Chest", "Neck", "Head")},
    **{f"{j}_L": _axes("+X+Y+Z") for j in ("Shoulder", "UpperArm", "LowerArm", "Hand")},
    **{f"{j}_R": _axes("+X-Y-Z") for j in ("Shoulder", "UpperArm", "LowerArm", "Hand")},
    "UpperLeg_L": _axes("-Y+X+Z"), "LowerLeg_L": _axes("-Y+X+Z"),
    "Foot_L": _axes("+Z+X+Y"), "Toes_L": _axes("+Z+X+Y"),
    "UpperLeg_R": _axes("+Y+X-Z"), "LowerLeg_R": _axes("+Y+X-Z"),
    "Foot_R": _axes("-Z+X-Y"), "Toes_R": _axes("-Z+X-Y"),
}


def _sided(left: dict[str, str]) -> dict[str, tuple[str, ...]]:
    """Both sides of a map given for the left one (``_L`` -> ``_R``, ``Left`` -> ``Right``)."""
    out = {}
    for canon, name in left.items():
        out[canon] = (name,)
        if canon.endswith("_L"):
            out[canon[:-2] + "_R"] = (name.replace("Left", "Right"),)
    return out


MAPS: dict[str, BoneMap] = {
    "canonical": BoneMap(
        "canonical", {c: (c,) for c in CANONICAL_JOINTS}, _CANONICAL_FRAMES
    ),
    # cgspeed's CMU BVH and its 21-joint subset (Holden et al., Aberman et al.'s Xia retarget).
    "cmu": BoneMap("cmu", _sided({
        "Hips": "Hips", "Spine": "Spine", "Chest": "Spine1", "Neck": "Neck1", "Head": "Head",
        "Shoulder_L": "LeftShoulder", "UpperArm_L": "LeftArm", "LowerArm_L": "LeftForeArm",
        "Hand_L": "LeftHand", "UpperLeg_L": "LeftUpLeg", "LowerLeg_L": "LeftLeg",
        "Foot_L": "LeftFoot", "Toes_L": "LeftToeBase",
    })),
    # Unity HumanBodyBones, as VMC senders name them; the neck and shoulders hang off UpperChest.
    "unity": BoneMap("unity", {**_sided({
        "Hips": "Hips", "Spine": "Spine", "Neck": "Neck", "Head": "Head",
        "Shoulder_L": "LeftShoulder", "UpperArm_L": "LeftUpperArm", "LowerArm_L": "LeftLowerArm",
        "Hand_L": "LeftHand", "UpperLeg_L": "LeftUpperLeg", "LowerLeg_L": "LeftLowerLeg",
        "Foot_L": "LeftFoot", "Toes_L": "LeftToes",
    }), "Chest": ("UpperChest", "Chest")}),
}


def find_map(skeleton: Skeleton, what: str = "skeleton") -> BoneMap:
    """The first naming in :data:`MAPS` that covers every required bone of ``skeleton``.

    ``what`` names the skeleton's origin (e.g. a file) in the error raised when none does.
    """
    misses = {name: m.missing(skeleton) for name, m in MAPS.items()}
    for name, miss in misses.items():
        if not miss:
            return MAPS[name]
    best = max(MAPS, key=lambda n: len(MAPS[n].resolve(skeleton)))
    raise MotionStyleError(
        f"{what} is not a humanoid skeleton this package knows: closest is the {best} naming, "
        f"which lacks {', '.join(misses[best])} (known namings: {', '.join(MAPS)})"
    )


def _frame(primary: np.ndarray, lateral: np.ndarray) -> np.ndarray:
    """Orthonormal frames ``(..., 3, 3)``: first column along ``primary``, second towards ``lateral``."""
    e1 = primary / np.linalg.norm(primary, axis=-1, keepdims=True)
    e2 = lateral - np.sum(lateral * e1, axis=-1, keepdims=True) * e1
    e2 /= np.linalg.norm(e2, axis=-1, keepdims=True)
    return np.stack([e1, e2, np.cross(e1, e2)], axis=-1)


def _path(skeleton: Skeleton, ancestor: int, joint: int) -> list[int] | None:
    """Joints from just below ``ancestor`` down to ``joint``, or None if it is not a descendant."""
    path = []
    while joint > ancestor:
        path.append(joint)
        joint = skeleton.parents[joint]
    return path[::-1] if joint == ancestor else None


def _first_below(skeleton: Skeleton, joints: dict[str, int], j: int, names: tuple[str, ...],
                 mapped: set[int]) -> str | None:
    """First of ``names`` present that hangs below joint ``j`` with no other mapped joint between."""
    for name in names:
        path = _path(skeleton, j, joints[name]) if name in joints else None
        if path is not None and not mapped.intersection(path[:-1]):
            return name
    return None


@dataclass(frozen=True)
class TPose:
    """A skeleton's T-pose under a bone map: global rotations and positions of every joint."""

    skeleton: Skeleton
    joints: dict[str, int]  # canonical joint -> index, for the mapped ones
    rotations: np.ndarray  # (J, 4) global
    positions: np.ndarray  # (J, 3) global, the root at its rest offset

    @property
    def local_rotations(self) -> np.ndarray:
        return local_from_global(self.skeleton, self.rotations)

    def vector(self, a: str, b: str) -> np.ndarray:
        """T-pose vector from canonical joint ``a`` to ``b``, in ``a``'s frame."""
        ja, jb = self.joints[a], self.joints[b]
        return rot.rotate(rot.conjugate(self.rotations[ja]), self.positions[jb] - self.positions[ja])

    def leg_length(self) -> float:
        """Hip-to-ankle length, mean of both legs (straight in the T-pose)."""
        p, j = self.positions, self.joints
        return float(np.mean([
            np.linalg.norm(p[j[f"LowerLeg_{s}"]] - p[j[f"UpperLeg_{s}"]])
            + np.linalg.norm(p[j[f"Foot_{s}"]] - p[j[f"LowerLeg_{s}"]])
            for s in "LR"
        ]))


def tpose(skeleton: Skeleton, bone_map: BoneMap | None = None) -> TPose:
    """Put ``skeleton`` in the T-pose: spine and head up, arms along +-X, legs down, feet flat.

    Each mapped joint turns so the bone to its next mapped joint points the table's way; Hips (and
    Chest when the shoulders are apart) also turn their left child to the +X side. Unmapped joints
    keep their rest rotation relative to their parent.
    """
    bone_map = bone_map or find_map(skeleton)
    missing = bone_map.missing(skeleton)
    if missing:
        raise MotionStyleError(f"skeleton lacks the {bone_map.name} bones {', '.join(missing)}")
    joints = bone_map.resolve(skeleton)
    canon_of = {j: c for c, j in joints.items()}
    mapped = set(joints.values())
    g_rot = rot.identity((skeleton.n_joints,))
    tiny = 1e-6 * np.abs(skeleton.offsets).sum()  # bones shorter than this have no direction

    def rest_vector(j: int, name: str) -> np.ndarray:
        # Unmapped joints between j and the target keep identity local rotations, so offsets add up.
        return skeleton.offsets[_path(skeleton, j, joints[name])].sum(axis=0)

    for j, p in enumerate(skeleton.parents):
        parent = g_rot[p] if p >= 0 else rot.identity()
        canon = canon_of.get(j)
        ref = parent
        if canon in bone_map.frames:
            ref = bone_map.frames[canon]
        g_rot[j] = ref
        if canon not in _BONE_DIRECTIONS:
            continue
        ends, direction = _BONE_DIRECTIONS[canon]
        end = _first_below(skeleton, joints, j, ends, mapped)
        if end is None:
            continue
        primary = rest_vector(j, end)
        if np.linalg.norm(primary) < tiny:
            continue
        pair = _LATERAL.get(canon)
        sides = [_first_below(skeleton, joints, j, (s,), mapped) for s in pair] if pair else []
        lateral = rest_vector(j, sides[0]) - rest_vector(j, sides[1]) if sides and all(sides) else None
        if lateral is not None and np.linalg.norm(lateral) > tiny:
            g_rot[j] = rot.from_matrix(_frame(direction, _X) @ _frame(primary, lateral).T)
        else:
            g_rot[j] = rot.multiply(rot.between(rot.rotate(ref, primary), direction), ref)
    local = local_from_global(skeleton, g_rot)
    _, g_pos = forward_kinematics(skeleton, local, skeleton.offsets)
    return TPose(skeleton, joints, g_rot, g_pos)


@dataclass(frozen=True)
class _Drive:
    """How one mapped target joint follows the source, all in canonical joint names."""

    canon: str
    align: np.ndarray  # (4,) source T-pose global^-1 * target T-pose global
    end: str | None  # the bone's far joint, matched exactly each frame
    end_vector: np.ndarray | None  # rest vector to it in the target joint's frame
    lateral: tuple[str, str] | None  # (left, right) children that fix the twist
    lateral_vector: np.ndarray | None


class Retargeter:
    """Maps motions of one humanoid skeleton onto another; build once, apply to clips or chunks."""

    def __init__(self, source: Skeleton, target: Skeleton,
                 source_map: BoneMap | None = None, target_map: BoneMap | None = None) -> None:
        self.source, self.target = source, target
        self.source_tpose = tpose(source, source_map)
        self.target_tpose = tpose(target, target_map)
        src_j, tgt_j = self.source_tpose.joints, self.target_tpose.joints
        self.common = [c for c in CANONICAL_JOINTS if c in src_j and c in tgt_j]
        self._drives = {tgt_j[c]: self._drive(c) for c in self.common}
        self.scale = self.target_tpose.leg_length() / self.source_tpose.leg_length()

    def _below(self, canon: str, names: tuple[str, ...]) -> str | None:
        """First of ``names`` hanging below ``canon`` with no joint mapped in both between, in both."""
        for tp in (self.target_tpose, self.source_tpose):
            common = {tp.joints[c] for c in self.common}
            names = tuple(n for n in names if n in self.common)
            hit = _first_below(tp.skeleton, tp.joints, tp.joints[canon], names, common)
            names = (hit,) if hit else ()
        return names[0] if names else None

    def _long(self, vector: Callable[[TPose], np.ndarray]) -> bool:
        """Whether a rest vector is long enough in both skeletons to have a direction."""
        return all(np.linalg.norm(vector(tp)) > 1e-3 * tp.leg_length()
                   for tp in (self.source_tpose, self.target_tpose))

    def _drive(self, canon: str) -> _Drive:
        src, tgt = self.source_tpose, self.target_tpose
        end = self._below(canon, _BONE_DIRECTIONS[canon][0]) if canon in _BONE_DIRECTIONS else None
        if end and not self._long(lambda tp: tp.vector(canon, end)):
            end = None
        pair = _LATERAL.get(canon)
        if not (pair and end and all(self._below(canon, (x,)) for x in pair)
                and self._long(lambda tp: tp.vector(canon, pair[0]) - tp.vector(canon, pair[1]))):
            pair = None
        return _Drive(
            canon,
            rot.multiply(rot.conjugate(src.rotations[src.joints[canon]]), tgt.rotations[tgt.joints[canon]]),
            end,
            tgt.vector(canon, end) if end else None,
            pair,
            tgt.vector(canon, pair[0]) - tgt.vector(canon, pair[1]) if pair else None,
        )

    def __call__(self, motion: Motion) -> Motion:
        """``motion`` (on the source skeleton) on the target skeleton, same frames and rate."""
        if motion.skeleton.names != self.source.names:
            raise MotionStyleError(
                f"motion has joints {', '.join(motion.skeleton.names[:4])}...; this retargeter was "
                f"built for {', '.join(self.source.names[:4])}..."
            )
        s_rot, s_pos = motion.global_transforms()
        src_j, tgt = self.source_tpose.joints, self.target
        n_frames = motion.n_frames
        rest_local = self.target_tpose.local_rotations
        g_rot = np.empty((n_frames, tgt.n_joints, 4))
        for j, p in enumerate(tgt.parents):
            drive = self._drives.get(j)
            if drive is None:
                g_rot[:, j] = rest_local[j] if p < 0 else rot.multiply(g_rot[:, p], rest_local[j])
                continue
            s = src_j[drive.canon]
            if drive.lateral:
                left, right = (s_pos[:, src_j[x]] for x in drive.lateral)
                world = _frame(s_pos[:, src_j[drive.end]] - s_pos[:, s], left - right)
                g_rot[:, j] = rot.from_matrix(world @ _frame(drive.end_vector, drive.lateral_vector).T)
                continue
            guess = rot.multiply(s_rot[:, s], drive.align)
            if drive.end:
                bone = s_pos[:, src_j[drive.end]] - s_pos[:, s]
                guess = rot.multiply(rot.between(rot.rotate(guess, drive.end_vector), bone), guess)
            g_rot[:, j] = guess
        local = local_from_global(tgt, g_rot)

        # Pelvis: put the hip centre at the source's, scaled by the leg-length ratio.
        tgt_j = self.target_tpose.joints
        positions = np.broadcast_to(tgt.offsets, (n_frames, tgt.n_joints, 3)).copy()
        _, t_pos = forward_kinematics(tgt, local, positions)
        pelvis = tgt_j["Hips"]
        world = t_pos[:, pelvis] + self.scale * _hip_centre(s_pos, src_j) - _hip_centre(t_pos, tgt_j)
        parent = tgt.parents[pelvis]
        if parent >= 0:
            world = rot.rotate(rot.conjugate(g_rot[:, parent]), world - t_pos[:, parent])
        positions[:, pelvis] = world
        return Motion(tgt, local, positions, motion.fps)


def _hip_centre(positions: np.ndarray, joints: dict[str, int]) -> np.ndarray:
    return 0.5 * (positions[:, joints["UpperLeg_L"]] + positions[:, joints["UpperLeg_R"]])


def retarget(motion: Motion, target: Skeleton, source_map: BoneMap | None = None,
             target_map: BoneMap | None = None) -> Motion:
    """``motion`` on ``target``; the bone maps are found from the joint names when not given."""
    return Retargeter(motion.skeleton, target, source_map, target_map)(motion)


def bone_direction_errors(source: Motion, result: Motion, source_map: BoneMap | None = None,
                          result_map: BoneMap | None = None) -> tuple[list[str], np.ndarray]:
    """Angle in degrees between each mapped bone's world direction in ``source`` and ``result``.

    A bone runs from a mapped joint to the nearest mapped joint below it (in both skeletons);
    bones of zero length in either are left out. Returns bone labels (``"Chest->Neck"``) and a
    ``(T, bones)`` array.
    """
    src_j = (source_map or find_map(source.skeleton)).resolve(source.skeleton)
    res_j = (result_map or find_map(result.skeleton)).resolve(result.skeleton)
    common = [c for c in CANONICAL_JOINTS if c in src_j and c in res_j]
    src_common, res_common = {src_j[c] for c in common}, {res_j[c] for c in common}
    src_pos, res_pos = source.global_positions(), result.global_positions()
    labels, errors = [], []
    for b in common:
        a = next((c for c in reversed(common[: common.index(b)])
                  if _first_below(source.skeleton, src_j, src_j[c], (b,), src_common)
                  and _first_below(result.skeleton, res_j, res_j[c], (b,), res_common)), None)
        if a is None:
            continue
        u = src_pos[:, src_j[b]] - src_pos[:, src_j[a]]
        v = res_pos[:, res_j[b]] - res_pos[:, res_j[a]]
        nu, nv = np.linalg.norm(u, axis=-1), np.linalg.norm(v, axis=-1)
        if nu.min() < 1e-9 or nv.min() < 1e-9:
            continue
        cos = np.sum(u * v, axis=-1) / (nu * nv)
        labels.append(f"{a}->{b}")
        errors.append(np.degrees(np.arccos(np.clip(cos, -1.0, 1.0))))
    return labels, np.stack(errors, axis=-1) if errors else np.zeros((source.n_frames, 0))
