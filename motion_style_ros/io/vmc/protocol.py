"""The VMC protocol's messages and frames (Virtual Motion Capture v2.7, OSC over UDP), and Unity's
frame in the motion core's.

Per frame a performer sends ``/VMC/Ext/Root/Pos`` (the avatar's root transform; since v2.1 with a
scale and an offset), one ``/VMC/Ext/Bone/Pos`` per Unity HumanBodyBones bone (local position and
rotation relative to its parent; identity is the avatar's rest pose), ``/VMC/Ext/Blend/Val`` per
blendshape then ``/VMC/Ext/Blend/Apply``, ``/VMC/Ext/OK`` (model, calibration and tracking state)
and ``/VMC/Ext/T`` (sender time). Values are in Unity's frame: left-handed, Y up, Z forward, X right,
metres, quaternions as (x, y, z, w).

The motion core is right-handed, Y up, the character facing +Z with its left towards +X. Both face
+Z with Y up, so the core is Unity mirrored in X: ``p_core = M p_unity`` with ``M = diag(-1, 1, 1)``.
A rotation matrix maps as ``R_core = M R_unity M``; conjugating by a reflection keeps the rotation
angle's magnitude and turns the axis ``a`` into ``M a`` with the sense reversed (det M = -1), so
axis ``(-ax, ay, az)`` with angle ``-t`` = axis ``(ax, -ay, -az)`` with angle ``t``: the Unity
quaternion ``(x, y, z, w)`` is the core quaternion ``(w, x, -y, -z)``. Unity's quaternion maths is
the usual Hamilton formula on these components, which is what the tests check against.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from pythonosc import osc_message

from motion_style_ros.core.retarget import MAPS
from motion_style_ros.io.joint_state import FACE_BONES, FINGER_BONES

ROOT_ADDRESS = "/VMC/Ext/Root/Pos"
BONE_ADDRESS = "/VMC/Ext/Bone/Pos"
TIME_ADDRESS = "/VMC/Ext/T"
OK_ADDRESS = "/VMC/Ext/OK"
BLEND_ADDRESS = "/VMC/Ext/Blend/Val"
APPLY_ADDRESS = "/VMC/Ext/Blend/Apply"
# No performer sends a position (m), quaternion component, scale, offset or blendshape value beyond
# this: such a value is a corrupt one (float32 still holds it: 1e30 passes every finiteness check).
MAX_VALUE = 1e4
MAX_TIME = 1e11  # s: /VMC/Ext/T beyond is no clock's (an epoch time is 1.7e9; 1e300 overflows a stamp)

# Unity's humanoid body bones, parents first; optional bones hang off their nearest present ancestor.
UNITY_PARENTS: dict[str, str | None] = {
    "Hips": None, "Spine": "Hips", "Chest": "Spine", "UpperChest": "Chest",
    "Neck": "UpperChest", "Head": "Neck",
}
for _side in ("Left", "Right"):
    UNITY_PARENTS.update({
        f"{_side}Shoulder": "UpperChest", f"{_side}UpperArm": f"{_side}Shoulder",
        f"{_side}LowerArm": f"{_side}UpperArm", f"{_side}Hand": f"{_side}LowerArm",
    })
for _side in ("Left", "Right"):
    UNITY_PARENTS.update({
        f"{_side}UpperLeg": "Hips", f"{_side}LowerLeg": f"{_side}UpperLeg",
        f"{_side}Foot": f"{_side}LowerLeg", f"{_side}Toes": f"{_side}Foot",
    })
# The other HumanBodyBones: not restyled, passed through. Fingers hang off the hands, eyes and jaw
# off the head.
EXTRA_PARENTS: dict[str, str] = {
    **{b: f"{b[:4] if b.startswith('Left') else b[:5]}Hand" for b in FINGER_BONES},
    **{b: "Head" for b in FACE_BONES},
}
EXTRA_BONES = tuple(EXTRA_PARENTS)
HUMAN_BONES = frozenset(UNITY_PARENTS) | frozenset(EXTRA_PARENTS)
# /VMC/Ext/OK: model state, then (v2.5) calibration state and mode, then (v2.7) tracking state.
CALIBRATING = (1, 2)  # waiting for calibration, calibrating: the pose means nothing yet
CALIBRATED = 3
# Bones a frame must have before it can drive a skeleton (Unity's required humanoid bones).
REQUIRED_BONES = tuple(
    MAPS["unity"].joints[c][0]
    for c in ("Hips", "Spine", "Head", "UpperArm_L", "LowerArm_L", "Hand_L", "UpperArm_R",
              "LowerArm_R", "Hand_R", "UpperLeg_L", "LowerLeg_L", "Foot_L", "UpperLeg_R",
              "LowerLeg_R", "Foot_R")
)

_MIRROR = np.array([-1.0, 1.0, 1.0])
IDENTITY_XYZW = np.array([0.0, 0.0, 0.0, 1.0])


def unity_to_core_position(p: np.ndarray) -> np.ndarray:
    """Unity (left-handed) positions ``(..., 3)`` in the core's right-handed frame, and back."""
    return np.asarray(p, dtype=np.float64) * _MIRROR


core_to_unity_position = unity_to_core_position


def unity_to_core_rotation(q_xyzw: np.ndarray) -> np.ndarray:
    """Unity quaternions ``(..., 4)`` as (x, y, z, w) -> core quaternions (w, x, y, z)."""
    q = np.asarray(q_xyzw, dtype=np.float64)
    return np.stack([q[..., 3], q[..., 0], -q[..., 1], -q[..., 2]], axis=-1)


def core_to_unity_rotation(q_wxyz: np.ndarray) -> np.ndarray:
    """Core quaternions (w, x, y, z) -> Unity quaternions (x, y, z, w)."""
    q = np.asarray(q_wxyz, dtype=np.float64)
    return np.stack([q[..., 1], -q[..., 2], -q[..., 3], q[..., 0]], axis=-1)




class VmcMessageError(ValueError):
    """A VMC message whose arguments do not fit its address."""


def _is_number(x: object) -> bool:
    return isinstance(x, (int, float)) and not isinstance(x, bool)


def is_value(x: object, bound: float = MAX_VALUE) -> bool:
    """A finite number within ``bound``."""
    return _is_number(x) and -bound <= x <= bound


def check_transform(args: Sequence[object], extra: tuple[int, ...]) -> None:
    """Raises :class:`VmcMessageError` unless ``args`` are a name, 7 numbers within ``MAX_VALUE``
    with a non-zero quaternion, and ``extra`` more (plain Python: this runs for every bone of every
    frame)."""
    if len(args) - 8 not in extra:
        raise VmcMessageError(f"expected {[8 + e for e in extra]} arguments, got {len(args)}")
    name = args[0]
    if not isinstance(name, str) or not name:
        raise VmcMessageError(f"first argument must be a bone name, got {name!r}")
    numbers = args[1:]
    if not all(_is_number(x) for x in numbers):
        raise VmcMessageError(f"{name}: non-numeric values {list(numbers)!r}")
    if not all(-MAX_VALUE <= x <= MAX_VALUE for x in numbers):  # NaN fails both
        raise VmcMessageError(f"{name}: values not finite or beyond {MAX_VALUE:g}")
    if math.hypot(*numbers[3:7]) < 1e-6:
        raise VmcMessageError(f"{name}: zero quaternion")


def parse_transform(
    args: Sequence[object], extra: tuple[int, ...] = (0,)
) -> tuple[str, np.ndarray, np.ndarray]:
    """``(name, position (3,), rotation (x, y, z, w))`` from Root/Pos or Bone/Pos arguments.

    ``extra`` lists how many numbers may follow the quaternion (Root/Pos v2.1 adds scale and offset).
    Raises :class:`VmcMessageError` for wrong counts or types, non-finite values or a zero quaternion.
    """
    check_transform(args, extra)
    values = np.asarray(args[1:8], dtype=np.float64)
    return args[0], values[:3], values[3:] / np.linalg.norm(values[3:])


def root_extension(args: Sequence[object]) -> tuple[np.ndarray | None, np.ndarray | None]:
    """Root/Pos v2.1's scale and offset (None when absent); a scale must not be zero."""
    if len(args) != 14:
        return None, None
    scale, offset = np.asarray(args[8:11], dtype=np.float64), np.asarray(args[11:14], dtype=np.float64)
    if np.any(np.abs(scale) < 1e-9):
        raise VmcMessageError(f"{ROOT_ADDRESS}: zero scale {scale.tolist()}")
    return scale, offset


@dataclass(frozen=True)
class VmcFrame:
    """One complete pose as received, in Unity's frame.

    ``bones``: every HumanBodyBones bone known, name -> (local position, (x, y, z, w)) as sent (unit
    length to the sender's precision); ``root``
    and its v2.1 ``root_scale``/``root_offset``; ``blendshapes`` (the Val messages of this frame) and
    whether it ended them with ``apply``; ``ok`` (the last /VMC/Ext/OK arguments); ``time`` (the last
    /VMC/Ext/T). ``raw`` keeps the messages as they came (bone names, ``"root"``, ``"ok"``), and
    ``passthrough`` this frame's Val, Apply, /VMC/Thru/* and other messages in arrival order, so that
    what is not restyled can be sent on bit for bit.
    """

    bones: dict[str, tuple[np.ndarray, np.ndarray]]
    root: tuple[np.ndarray, np.ndarray] = field(default_factory=lambda: (np.zeros(3), IDENTITY_XYZW))
    time: float | None = None
    root_scale: np.ndarray | None = None
    root_offset: np.ndarray | None = None
    blendshapes: dict[str, float] = field(default_factory=dict)
    apply: bool = False
    ok: tuple[int, ...] | None = None
    raw: dict[str, osc_message.OscMessage] = field(default_factory=dict)
    passthrough: tuple[osc_message.OscMessage, ...] = ()
    received_ns: int | None = None  # time.monotonic_ns() when the datagram completing it arrived


def usable(frame: VmcFrame) -> str | None:
    """Why a frame's pose is not to be stylized (its ``/VMC/Ext/OK`` says so), or None.

    ``not_loaded``: no avatar (model state 0); ``calibrating``: waiting for or in calibration
    (v2.5 calibration state 1 or 2), the pose is the calibration's, not the performer's;
    ``tracking_lost``: v2.7 tracking state 0. Uncalibrated (0) and calibrated (3) streams are used.
    """
    ok = frame.ok
    if ok is None:
        return None
    if ok[0] == 0:
        return "not_loaded"
    if len(ok) >= 2 and ok[1] in CALIBRATING:
        return "calibrating"
    if len(ok) >= 4 and ok[3] == 0:
        return "tracking_lost"
    return None
