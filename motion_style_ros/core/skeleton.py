"""Skeleton topology and rest geometry.

The motion core works in a right-handed, Y-up frame in metres with the character facing +Z and its
left side towards +X at rest (the BVH/animation convention). Conversion to ROS' REP-103 frame
(X forward, Z up) happens at the ROS boundary, not here.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from motion_style_ros.errors import MotionStyleError


@dataclass(frozen=True, eq=False)
class Skeleton:
    """A joint tree: ``parents[j] < j`` for every non-root joint (depth-first BVH order)."""

    names: tuple[str, ...]
    parents: tuple[int, ...]
    offsets: np.ndarray  # (J, 3) rest translation of each joint in its parent's frame
    end_sites: dict[int, np.ndarray] = field(default_factory=dict)  # joint -> End Site offset
    parts: dict[str, tuple[int, ...]] = field(default_factory=dict)  # body part -> joints
    feet: tuple[int, ...] = ()  # joints used for foot contact (heel/ankle and toe, both sides)
    pelvis: int = 0  # the joint that carries the root trajectory

    def __post_init__(self) -> None:
        n = len(self.names)
        if len(self.parents) != n or np.shape(self.offsets) != (n, 3):
            raise MotionStyleError(
                f"skeleton has {n} names, {len(self.parents)} parents and offsets of shape "
                f"{np.shape(self.offsets)}; they must agree"
            )
        if len(set(self.names)) != n:
            dup = sorted({x for x in self.names if self.names.count(x) > 1})
            raise MotionStyleError(f"skeleton has duplicate joint names: {', '.join(dup)}")
        for j, p in enumerate(self.parents):
            if (j == 0) != (p < 0) or p >= j:
                raise MotionStyleError(
                    f"joint {self.names[j]!r} has parent index {p}; joints must follow their parents"
                )

    @property
    def n_joints(self) -> int:
        return len(self.names)

    def index(self, name: str) -> int:
        try:
            return self.names.index(name)
        except ValueError:
            raise MotionStyleError(
                f"unknown joint {name!r}; this skeleton has: {', '.join(self.names)}"
            ) from None

    def children(self, joint: int) -> list[int]:
        return [j for j, p in enumerate(self.parents) if p == joint]

    def bone_lengths(self) -> np.ndarray:
        """Length of the bone from each joint's parent to the joint (0 for the root)."""
        lengths = np.linalg.norm(self.offsets, axis=-1)
        lengths[0] = 0.0
        return lengths

    def scaled(self, factor: float) -> "Skeleton":
        return Skeleton(
            self.names,
            self.parents,
            self.offsets * factor,
            {j: o * factor for j, o in self.end_sites.items()},
            self.parts,
            self.feet,
            self.pelvis,
        )


def _build(
    spec: list[tuple[str, str | None, tuple[float, float, float]]],
    scale: float,
    parts: dict[str, tuple[str, ...]],
    feet: tuple[str, ...],
    pelvis: str,
) -> Skeleton:
    names = tuple(n for n, _, _ in spec)
    parents = tuple(-1 if p is None else names.index(p) for _, p, _ in spec)
    offsets = np.array([o for _, _, o in spec], dtype=np.float64) * scale
    return Skeleton(
        names,
        parents,
        offsets,
        parts={k: tuple(names.index(n) for n in v) for k, v in parts.items()},
        feet=tuple(names.index(n) for n in feet),
        pelvis=names.index(pelvis),
    )


# The Bandai Namco research skeleton (rest offsets in cm, bones along local X), whose bone names are
# Unity's humanoid bones; VMC streams use the same names.
_CANONICAL = [
    ("joint_Root", None, (0.0, 0.0, 0.0)),
    ("Hips", "joint_Root", (0.0, 93.3139, 0.0)),
    ("Spine", "Hips", (15.7357, 0.0, 0.0)),
    ("Chest", "Spine", (8.98455, -0.406207, 0.0)),
    ("Neck", "Chest", (16.3773, 0.0, 0.0)),
    ("Head", "Neck", (6.45672, 0.0, 0.0)),
    ("Shoulder_L", "Chest", (12.9942, -0.242716, 4.98039)),
    ("UpperArm_L", "Shoulder_L", (5.34809, 0.0, 0.0)),
    ("LowerArm_L", "UpperArm_L", (24.3286, 0.0, 0.0)),
    ("Hand_L", "LowerArm_L", (22.2916, 0.0, 0.0)),
    ("Shoulder_R", "Chest", (12.9945, -0.242716, -4.98039)),
    ("UpperArm_R", "Shoulder_R", (-5.34813, 0.0, 0.0)),
    ("LowerArm_R", "UpperArm_R", (-24.3289, 0.0, 0.0)),
    ("Hand_R", "LowerArm_R", (-22.2915, 0.0, 0.0)),
    ("UpperLeg_L", "Hips", (-2.19248, -6.46944, 0.0)),
    ("LowerLeg_L", "UpperLeg_L", (39.0811, 0.0, 0.0)),
    ("Foot_L", "LowerLeg_L", (40.9854, 0.0, 0.0)),
    ("Toes_L", "Foot_L", (11.7543, 0.0, 0.0)),
    ("UpperLeg_R", "Hips", (-2.19251, 6.46944, 0.0)),
    ("LowerLeg_R", "UpperLeg_R", (-39.0811, 0.0, 0.0)),
    ("Foot_R", "LowerLeg_R", (-40.9854, 0.0, 0.0)),
    ("Toes_R", "Foot_R", (-11.7543, 0.0, 0.0)),
]

_CANONICAL_PARTS = {
    "torso": ("Hips", "Spine", "Chest", "Neck", "Head"),
    "arm_l": ("Shoulder_L", "UpperArm_L", "LowerArm_L", "Hand_L"),
    "arm_r": ("Shoulder_R", "UpperArm_R", "LowerArm_R", "Hand_R"),
    "leg_l": ("UpperLeg_L", "LowerLeg_L", "Foot_L", "Toes_L"),
    "leg_r": ("UpperLeg_R", "LowerLeg_R", "Foot_R", "Toes_R"),
}

# CMU Graphics Lab skeleton as converted to BVH by cgspeed (subject 02's proportions, BVH units).
_CMU31 = [
    ("Hips", None, (0.0, 0.0, 0.0)),
    ("LHipJoint", "Hips", (0.0, 0.0, 0.0)),
    ("LeftUpLeg", "LHipJoint", (1.65674, -1.80282, 0.62477)),
    ("LeftLeg", "LeftUpLeg", (2.59720, -7.13576, 0.0)),
    ("LeftFoot", "LeftLeg", (2.49236, -6.84770, 0.0)),
    ("LeftToeBase", "LeftFoot", (0.19704, -0.54136, 2.14581)),
    ("RHipJoint", "Hips", (0.0, 0.0, 0.0)),
    ("RightUpLeg", "RHipJoint", (-1.61070, -1.80282, 0.62476)),
    ("RightLeg", "RightUpLeg", (-2.59502, -7.12977, 0.0)),
    ("RightFoot", "RightLeg", (-2.46780, -6.78024, 0.0)),
    ("RightToeBase", "RightFoot", (-0.23024, -0.63258, 2.13368)),
    ("LowerBack", "Hips", (0.0, 0.0, 0.0)),
    ("Spine", "LowerBack", (0.01961, 2.05450, -0.14112)),
    ("Spine1", "Spine", (0.01021, 2.06436, -0.05921)),
    ("Neck", "Spine1", (0.0, 0.0, 0.0)),
    ("Neck1", "Neck", (0.00713, 1.56711, 0.14968)),
    ("Head", "Neck1", (0.03429, 1.56041, -0.10006)),
    ("LeftShoulder", "Spine1", (0.0, 0.0, 0.0)),
    ("LeftArm", "LeftShoulder", (3.54205, 0.90436, -0.17364)),
    ("LeftForeArm", "LeftArm", (4.86513, 0.0, 0.0)),
    ("LeftHand", "LeftForeArm", (3.35554, 0.0, 0.0)),
    ("LeftFingerBase", "LeftHand", (0.0, 0.0, 0.0)),
    ("LeftHandIndex1", "LeftFingerBase", (0.66117, 0.0, 0.0)),
    ("LThumb", "LeftHand", (0.0, 0.0, 0.0)),
    ("RightShoulder", "Spine1", (0.0, 0.0, 0.0)),
    ("RightArm", "RightShoulder", (-3.49802, 0.75994, -0.32616)),
    ("RightForeArm", "RightArm", (-5.02649, 0.0, 0.0)),
    ("RightHand", "RightForeArm", (-3.36431, 0.0, 0.0)),
    ("RightFingerBase", "RightHand", (0.0, 0.0, 0.0)),
    ("RightHandIndex1", "RightFingerBase", (-0.73041, 0.0, 0.0)),
    ("RThumb", "RightHand", (0.0, 0.0, 0.0)),
]

_CMU_PARTS = {
    "torso": ("Hips", "LowerBack", "Spine", "Spine1", "Neck", "Neck1", "Head"),
    "arm_l": ("LeftShoulder", "LeftArm", "LeftForeArm", "LeftHand", "LeftFingerBase",
              "LeftHandIndex1", "LThumb"),
    "arm_r": ("RightShoulder", "RightArm", "RightForeArm", "RightHand", "RightFingerBase",
              "RightHandIndex1", "RThumb"),
    "leg_l": ("LHipJoint", "LeftUpLeg", "LeftLeg", "LeftFoot", "LeftToeBase"),
    "leg_r": ("RHipJoint", "RightUpLeg", "RightLeg", "RightFoot", "RightToeBase"),
}

_CMU_FEET = ("LeftFoot", "LeftToeBase", "RightFoot", "RightToeBase")

# The 21-joint subset used by Holden et al. and most style-transfer work on CMU/Xia data.
CMU21_JOINTS = (
    "Hips", "LeftUpLeg", "LeftLeg", "LeftFoot", "LeftToeBase", "RightUpLeg", "RightLeg",
    "RightFoot", "RightToeBase", "Spine", "Spine1", "Neck1", "Head", "LeftArm", "LeftForeArm",
    "LeftHand", "LeftHandIndex1", "RightArm", "RightForeArm", "RightHand", "RightHandIndex1",
)


def canonical() -> Skeleton:
    """The 22-joint canonical humanoid (Bandai Namco / Unity humanoid names), in metres."""
    return _build(
        _CANONICAL, 0.01, _CANONICAL_PARTS, ("Foot_L", "Toes_L", "Foot_R", "Toes_R"), "Hips"
    )


def cmu31() -> Skeleton:
    """The 31-joint CMU skeleton (cgspeed BVH), in BVH units (about 5.6 cm each)."""
    return _build(_CMU31, 1.0, _CMU_PARTS, _CMU_FEET, "Hips")


def subset(skeleton: Skeleton, keep: tuple[str, ...] | list[str]) -> tuple[Skeleton, np.ndarray]:
    """The skeleton restricted to ``keep`` (which must contain the root), and the kept indices.

    A dropped joint's rest offset is folded into its kept descendants, so rest positions of the
    kept joints are unchanged. Motions follow with :func:`motion_style_ros.core.motion.subset`.
    """
    idx = sorted(skeleton.index(n) for n in keep)
    if idx[0] != 0:
        raise MotionStyleError(f"a subset must keep the root joint {skeleton.names[0]!r}")
    kept = set(idx)
    parents, offsets = [], []
    for j in idx:
        off = skeleton.offsets[j].copy()
        p = skeleton.parents[j]
        while p >= 0 and p not in kept:
            off += skeleton.offsets[p]
            p = skeleton.parents[p]
        parents.append(idx.index(p) if p >= 0 else -1)
        offsets.append(off)
    remap = {old: new for new, old in enumerate(idx)}
    return (
        Skeleton(
            tuple(skeleton.names[j] for j in idx),
            tuple(parents),
            np.array(offsets),
            {remap[j]: o for j, o in skeleton.end_sites.items() if j in kept},
            {k: tuple(remap[j] for j in v if j in kept) for k, v in skeleton.parts.items()},
            tuple(remap[j] for j in skeleton.feet if j in kept),
            remap.get(skeleton.pelvis, 0),
        ),
        np.array(idx),
    )


def cmu21() -> Skeleton:
    return subset(cmu31(), CMU21_JOINTS)[0]
