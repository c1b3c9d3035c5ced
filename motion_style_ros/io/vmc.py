"""VMC protocol (Virtual Motion Capture v2.7, OSC over UDP): receive, assemble, convert and send.

A VMC performer (a mocap or face-tracking app) streams to a marionette (an avatar host), by
convention on UDP port 39539; the port 39540 is the convention for the other direction (a
marionette or an assistant talking to the performer) and for a second marionette on the same host.
Per frame a performer sends ``/VMC/Ext/Root/Pos`` (the avatar's root transform; since v2.1 with a
scale and an offset), one ``/VMC/Ext/Bone/Pos`` per Unity HumanBodyBones bone (local position and
rotation relative to its parent; identity is the avatar's rest pose), ``/VMC/Ext/Blend/Val`` per
blendshape then ``/VMC/Ext/Blend/Apply``, ``/VMC/Ext/OK`` (model, calibration and tracking state)
and ``/VMC/Ext/T`` (sender time), in one bundle or in many (:class:`VmcFrameAssembler` decides
where a frame ends). Values are in Unity's frame: left-handed, Y up, Z forward, X right, metres,
quaternions as (x, y, z, w).

The motion core is right-handed, Y up, the character facing +Z with its left towards +X. Both face
+Z with Y up, so the core is Unity mirrored in X: ``p_core = M p_unity`` with ``M = diag(-1, 1, 1)``.
A rotation matrix maps as ``R_core = M R_unity M``; conjugating by a reflection keeps the rotation
angle's magnitude and turns the axis ``a`` into ``M a`` with the sense reversed (det M = -1), so
axis ``(-ax, ay, az)`` with angle ``-t`` = axis ``(ax, -ay, -az)`` with angle ``t``: the Unity
quaternion ``(x, y, z, w)`` is the core quaternion ``(w, x, -y, -z)``. Unity's quaternion maths is
the usual Hamilton formula on these components, which is what the tests check against.

:class:`VmcLink` is what ``vmc_bridge`` does with all this: frames in -> canonical JointStates (the
fingers, eyes and jaw as names of their own, the blendshapes apart), and stylized JointStates back
out on the sender's own rig, with everything the stylizer does not restyle sent as it came.
"""

from __future__ import annotations

import math
import queue
import socket
import struct
import threading
import time
from collections import Counter, deque
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace

import numpy as np
from pythonosc import osc_bundle, osc_message, osc_message_builder

from motion_style_ros.core import rotations as rot
from motion_style_ros.core.motion import Motion
from motion_style_ros.core.retarget import MAPS, Retargeter, find_map, tpose
from motion_style_ros.core.skeleton import Skeleton, canonical
from motion_style_ros.errors import MotionStyleError
from motion_style_ros.io.joint_state import (
    FACE_BONES,
    FINGER_BONES,
    JointStateLayout,
    rotation_names,
    rotation_values,
    rotations_from_values,
)

DEFAULT_HOST = "127.0.0.1"
DEFAULT_PORT = 39539  # a marionette listens here (the bridge, for the performer app)
DEFAULT_SEND_PORT = 39540  # where the bridge sends: a marionette on the same host, by convention
ROOT_ADDRESS = "/VMC/Ext/Root/Pos"
BONE_ADDRESS = "/VMC/Ext/Bone/Pos"
TIME_ADDRESS = "/VMC/Ext/T"
OK_ADDRESS = "/VMC/Ext/OK"
BLEND_ADDRESS = "/VMC/Ext/Blend/Val"
APPLY_ADDRESS = "/VMC/Ext/Blend/Apply"
RECEIVE_BUFFER = 4 * 1024 * 1024  # bytes of socket buffer asked for (the kernel may cap it: rmem_max)
# A datagram that waited longer than this to be parsed is dropped: a live pose that old is stale.
MAX_AGE_S = 0.25
MAX_QUEUED_BYTES = 16 * 1024 * 1024  # datagrams read but not parsed, at most (then the newest are dropped)
STALE_NS = 100_000_000  # an output whose frame is further than this from every kept one: counted
# No performer sends a position (m), quaternion component, scale, offset or blendshape value beyond
# this: such a value is a corrupt one (float32 still holds it: 1e30 passes every finiteness check).
MAX_VALUE = 1e4
MAX_TIME = 1e11  # s: /VMC/Ext/T beyond is no clock's (an epoch time is 1.7e9; 1e300 overflows a stamp)
MAX_NESTING = 8  # bundles within bundles (VMC senders nest none)
_BUNDLE_PREFIX = b"#bundle\x00"

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
_IDENTITY_XYZW = np.array([0.0, 0.0, 0.0, 1.0])


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


def _is_value(x: object, bound: float = MAX_VALUE) -> bool:
    """A finite number within ``bound``."""
    return _is_number(x) and -bound <= x <= bound


def _check_transform(args: Sequence[object], extra: tuple[int, ...]) -> None:
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
    _check_transform(args, extra)
    values = np.asarray(args[1:8], dtype=np.float64)
    return args[0], values[:3], values[3:] / np.linalg.norm(values[3:])


def _root_extension(args: Sequence[object]) -> tuple[np.ndarray | None, np.ndarray | None]:
    """Root/Pos v2.1's scale and offset (None when absent); a scale must not be zero."""
    if len(args) != 14:
        return None, None
    scale, offset = np.asarray(args[8:11], dtype=np.float64), np.asarray(args[11:14], dtype=np.float64)
    if np.any(np.abs(scale) < 1e-9):
        raise VmcMessageError(f"{ROOT_ADDRESS}: zero scale {scale.tolist()}")
    return scale, offset


def build_message(address: str, args: Sequence[object]) -> osc_message.OscMessage:
    """An OSC message; floats go as float32 (``f``), as VMC senders send them."""
    msg = osc_message_builder.OscMessageBuilder(address)
    for a in args:
        msg.add_arg(a)
    return msg.build()


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
    root: tuple[np.ndarray, np.ndarray] = field(default_factory=lambda: (np.zeros(3), _IDENTITY_XYZW))
    time: float | None = None
    root_scale: np.ndarray | None = None
    root_offset: np.ndarray | None = None
    blendshapes: dict[str, float] = field(default_factory=dict)
    apply: bool = False
    ok: tuple[int, ...] | None = None
    raw: dict[str, osc_message.OscMessage] = field(default_factory=dict)
    passthrough: tuple[osc_message.OscMessage, ...] = ()
    received_ns: int | None = None  # time.monotonic_ns() when the datagram completing it arrived


class VmcFrameAssembler:
    """Turns a stream of VMC messages into complete frames, however the sender bundles them.

    Senders bundle differently: one bundle per frame (VSeeFace, vmcp's one-``send()``-per-frame),
    a frame over several bundles (Virtual Motion Capture splits its bones), or one message per
    bundle (vmcp when each message gets its own ``send()``). A bundle end therefore ends a frame
    only when the bundle held every required bone. Otherwise the frame is the run of messages
    between two repetitions of the sender's pattern: each message has a key (Root/Pos, a bone's
    name, Blend/Apply, OK, T; Blend/Val and pass-through messages belong to the frame they arrive
    in), a key that the frame already holds starts the next frame, and the key that came last before
    such a repetition is learnt as the sender's last one: once known, it ends a frame at once, so
    no frame waits for the next one. Keys that arrive after that end and before the sender's first
    key (blendshapes sent in a bundle of their own after a whole-body bundle) show that the last key
    comes later, and it is learnt again. A sender that changes its order is learnt again (a new last
    key is taken when two frames in a row agree on it, so a lost datagram does not unlearn it).
    Frames are never cut by time: a frame whose last message is lost ends with the next frame's
    first one, late but whole.

    Each frame holds the last known value of every bone seen so far, so a frame that misses bones is
    completed from the previous pose; it is emitted once every required bone has been seen (before
    that it is counted as ``incomplete``). A malformed message (values not finite or beyond
    ``MAX_VALUE`` included) is dropped on its own (``malformed``); the rest of its bundle still
    makes a frame. An unparsable datagram is ``malformed`` too, and it makes the assembler learn
    the sender's pattern again (:meth:`forget`), since what came with it may have been no
    sender's. A key that comes twice in one datagram is no frame's: the repeat is dropped
    (``repeated``), so one datagram never makes more than two frames. Messages outside VMC and bone
    names outside HumanBodyBones are ``ignored``.
    """

    def __init__(self, required: Sequence[str] = REQUIRED_BONES) -> None:
        self.required = tuple(required)
        self.counts: Counter[str] = Counter(frames=0, malformed=0, incomplete=0, ignored=0, repeated=0)
        self.bones: dict[str, tuple[np.ndarray, np.ndarray]] = {}
        self.raw: dict[str, osc_message.OscMessage] = {}
        self.root: tuple[np.ndarray, np.ndarray] = (np.zeros(3), _IDENTITY_XYZW)
        self.root_scale: np.ndarray | None = None
        self.root_offset: np.ndarray | None = None
        self.time: float | None = None
        self.ok: tuple[int, ...] | None = None
        self._bundle_keys: set[tuple[str, ...]] | None = None  # the keys of the datagram being fed
        self.forget()

    def forget(self) -> None:
        """Learn the sender's pattern again (after garbage, whose bundling is no sender's); the
        last pose, every value of which was checked, still completes the next frame."""
        self.last_key: tuple[str, ...] | None = None
        self.first_key: tuple[str, ...] | None = None
        self._candidate: tuple[str, ...] | None = None
        self._resync: set[tuple[str, ...]] | None = None  # after a gap: the keys skipped until a frame starts
        self._start_frame()

    def interrupt(self) -> None:
        """The stream has a gap (datagrams dropped as stale): the frame in progress is abandoned,
        and the messages up to the sender's first key with it, so that no frame mixes poses from
        before and after the gap."""
        self._start_frame()
        self._resync: set[tuple[str, ...]] | None = set() if self.first_key is not None else None

    def _start_frame(self) -> None:
        self._keys: set[tuple[str, ...]] = set()
        self._previous_key: tuple[str, ...] | None = None
        self._blend: dict[str, float] = {}
        self._apply = False
        self._passthrough: list[osc_message.OscMessage] = []
        self._pending = False

    def feed(self, address: str, args: Sequence[object],
             message: osc_message.OscMessage | None = None, *, whole: bool = False) -> list[VmcFrame]:
        """Take one message (``message``: the parsed OSC message, kept to send on as it came);
        returns the frames it completed (none, one, or the previous one and a one-message one).
        ``whole``: the message is in a bundle of a whole frame, which its bundle's end ends."""
        try:
            key = self._key(address, args)
        except VmcMessageError:
            self.counts["malformed"] += 1
            return []
        if key is None:  # a message that only rides along, or one that is not ours
            if address.startswith("/VMC/") and address not in (BONE_ADDRESS,):
                self._passthrough.append(message or build_message(address, args))
                self._pending = True
                if address == BLEND_ADDRESS:
                    self._blend[args[0]] = float(args[1])
            else:
                self.counts["ignored"] += 1
            return []
        if self._bundle_keys is not None and key in self._bundle_keys:
            # Twice in one datagram: no sender's frame; the first one stands, and one datagram of
            # repeats never becomes a frame per repeat.
            self.counts["repeated"] += 1
            return []
        if self._resync is not None and key != self.first_key:
            if key not in self._resync:  # the rest of a frame begun before the gap
                self._resync.add(key)
                return []
            self.first_key = key  # a whole cycle without the first key: the pattern starts here now
        self._resync = None
        frames = []
        if self.first_key is None:
            self.first_key = key
        if key in self._keys:  # the pattern starts again: the frame before ended without its last key
            self._learn(self._previous_key)
            frames.append(self.end_frame())
        elif key == self.first_key and self._keys:
            # Keys came after the frame's end and before the next frame's first key: they were the
            # frame's tail (blendshapes in a bundle of their own after the pose, say), so its last
            # key comes later. Learnt from two frames in a row; the tail goes with the next frame.
            self._learn(self._previous_key)
            self._keys = set()
        self._take(key, address, args, message)
        self._keys.add(key)
        if self._bundle_keys is not None:
            self._bundle_keys.add(key)
        self._previous_key = key
        if key == self.last_key and not whole:
            frames.append(self.end_frame())
        return [f for f in frames if f is not None]

    def _key(self, address: str, args: Sequence[object]) -> tuple[str, ...] | None:
        """The message's key in the sender's pattern (None: no key); validates its arguments."""
        if address == BONE_ADDRESS:
            _check_transform(args, (0,))
            return ("bone", args[0]) if args[0] in HUMAN_BONES else None
        if address == ROOT_ADDRESS:
            _check_transform(args, (0, 6))
            _root_extension(args)
            return ("root",)
        if address == TIME_ADDRESS:
            if len(args) != 1 or not _is_value(args[0], MAX_TIME):
                raise VmcMessageError(f"{TIME_ADDRESS} takes one number within {MAX_TIME:g} s, "
                                      f"got {list(args)!r}")
            return ("time",)
        if address == OK_ADDRESS:
            if not 1 <= len(args) <= 4 or not all(isinstance(a, int) and not isinstance(a, bool)
                                                  for a in args):
                raise VmcMessageError(f"{OK_ADDRESS} takes 1 to 4 integers, got {list(args)!r}")
            return ("ok",)
        if address == APPLY_ADDRESS:
            return ("apply",)
        if address == BLEND_ADDRESS:
            if len(args) != 2 or not isinstance(args[0], str) or not _is_value(args[1]):
                raise VmcMessageError(f"{BLEND_ADDRESS} takes a name and a number within "
                                      f"{MAX_VALUE:g}, got {list(args)!r}")
        return None

    def _take(self, key: tuple[str, ...], address: str, args: Sequence[object],
              message: osc_message.OscMessage | None) -> None:
        message = message or build_message(address, args)
        if key[0] == "bone":  # kept as sent (exactly; unit length only to float precision)
            self.bones[key[1]] = (np.asarray(args[1:4], dtype=np.float64),
                                  np.asarray(args[4:8], dtype=np.float64))
            self.raw[key[1]] = message
        elif key[0] == "root":
            self.root = (np.asarray(args[1:4], dtype=np.float64), np.asarray(args[4:8], dtype=np.float64))
            self.root_scale, self.root_offset = _root_extension(args)
            self.raw["root"] = message
        elif key[0] == "time":
            self.time = float(args[0])
        elif key[0] == "ok":
            self.ok = tuple(int(a) for a in args)
            self.raw["ok"] = message
        elif key[0] == "apply":
            self._apply = True
            self._passthrough.append(message)
        self._pending = True

    def _learn(self, key: tuple[str, ...] | None) -> None:
        if key is None or key == self.last_key:
            self._candidate = None
        elif self.last_key is None or key == self._candidate:
            self.last_key, self._candidate = key, None
        else:
            self._candidate = key

    def end_frame(self) -> VmcFrame | None:
        """Close the frame being received; None if nothing came or a required bone is unknown."""
        if not self._pending:
            self._start_frame()
            return None
        if not any(k[0] in ("root", "bone") for k in self._keys):
            # No pose in it (blendshapes, Thru): it rides with the next frame, which is not doubled.
            self._keys = set()
            return None
        blend, apply, passthrough = self._blend, self._apply, tuple(self._passthrough)
        self._start_frame()
        if any(b not in self.bones for b in self.required):
            self.counts["incomplete"] += 1
            return None
        self.counts["frames"] += 1
        return VmcFrame(dict(self.bones), self.root, self.time, self.root_scale, self.root_offset,
                        blend, apply, self.ok, dict(self.raw), passthrough)

    def feed_datagram(self, data: bytes) -> list[VmcFrame]:
        """Take one UDP datagram (an OSC message or bundle); returns the frames it completed."""
        try:
            messages = osc_messages(data)
        except (osc_message.ParseError, ValueError, IndexError, TypeError, struct.error):
            self.counts["malformed"] += 1
            self.forget()
            return []
        names = {m.params[0] for m in messages
                 if m.address == BONE_ADDRESS and m.params and isinstance(m.params[0], str)}
        # A bundle with every required bone is a frame of its own (one bundle per frame) once it
        # also holds the sender's last key (if learnt): it ends there and only there, and its last
        # key is the sender's, so a flood of one bone learnt as the last key cannot split it.
        whole = data.startswith(_BUNDLE_PREFIX) and all(b in names for b in self.required)
        frames = []
        self._bundle_keys = set()
        for m in messages:
            frames += self.feed(m.address, m.params, m, whole=whole)
        if whole and self._pending and (self.last_key is None or self.last_key in self._bundle_keys):
            self.last_key = self._previous_key
            frames.append(self.end_frame())
        self._bundle_keys = None
        return [f for f in frames if f is not None]


def osc_messages(data: bytes, depth: int = 0) -> list[osc_message.OscMessage]:
    """The OSC messages of a datagram in the order sent, nested bundles flattened.

    Stricter than python-osc's ``OscPacket``, which loops for ever on a negative bundle element
    size, takes a size past the end as the rest of the datagram, skips an element it cannot
    identify and recurses without bound (a ``RecursionError``): each of these raises
    :class:`VmcMessageError` here. Messages keep the order sent: time tags are not waited for
    (``OscPacket`` sorts by them), a pose is shown when it comes.
    """
    if not data.startswith(_BUNDLE_PREFIX):
        if not data.startswith(b"/"):
            raise VmcMessageError("neither an OSC message nor a bundle")
        return [osc_message.OscMessage(data)]
    if depth == MAX_NESTING:
        raise VmcMessageError(f"bundles nested deeper than {MAX_NESTING}")
    messages, i = [], len(_BUNDLE_PREFIX) + 8  # after the time tag
    if len(data) < i:
        raise VmcMessageError("bundle without a time tag")
    while i < len(data):
        (size,) = struct.unpack_from(">i", data, i)  # struct.error past the end
        i += 4
        if size <= 0 or size % 4 or i + size > len(data):
            raise VmcMessageError(f"bundle element of {size} bytes at byte {i} of {len(data)}")
        messages += osc_messages(data[i:i + size], depth + 1)
        i += size
    return messages


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




@dataclass(frozen=True)
class Packet:
    """An OSC packet ready to send: its datagram (``dgram``), as python-osc's packets have one."""

    dgram: bytes


_IMMEDIATELY = struct.pack(">Q", 1)  # the OSC time tag "now"


def _bundle(messages: Sequence[osc_message.OscMessage | Packet]) -> Packet:
    """One bundle of ``messages`` (their datagrams as they are: python-osc's builder would parse
    every message it has just written again, which doubled the cost of a frame)."""
    return Packet(_BUNDLE_PREFIX + _IMMEDIATELY + b"".join(
        struct.pack(">i", len(m.dgram)) + m.dgram for m in messages))


def _osc_string(text: str) -> bytes:
    data = text.encode("utf-8") + b"\x00"
    return data + b"\x00" * (-len(data) % 4)


_BONE_HEAD = _osc_string(BONE_ADDRESS) + _osc_string(",sfffffff")


def _bone_message(name: str, p: np.ndarray, q: np.ndarray) -> Packet:
    """A /VMC/Ext/Bone/Pos message, encoded as python-osc's builder encodes it (float32 big-endian
    arguments), at a fraction of its cost: a frame sends one for every bone."""
    return Packet(_BONE_HEAD + _osc_string(name) + struct.pack(">7f", *p, *q))


def _transform_args(name: str, p: np.ndarray, q: np.ndarray) -> list[object]:
    return [name, *map(float, p), *map(float, q)]


def frame_bundle(frame: VmcFrame, time: float) -> Packet:
    """One VMC frame as an OSC bundle: root, bones, blendshapes, OK and time (as performers send it)."""
    root = _transform_args("root", *frame.root)
    if frame.root_scale is not None:
        root += [*map(float, frame.root_scale), *map(float, frame.root_offset)]
    messages = [build_message(ROOT_ADDRESS, root)]
    messages += [_bone_message(b, p, q) for b, (p, q) in frame.bones.items()]
    messages += [build_message(BLEND_ADDRESS, [k, float(v)]) for k, v in frame.blendshapes.items()]
    if frame.apply or frame.blendshapes:
        messages.append(build_message(APPLY_ADDRESS, []))
    messages.append(build_message(OK_ADDRESS, list(frame.ok or (1,))))
    messages.append(build_message(TIME_ADDRESS, [float(time)]))
    return _bundle(messages)


class VmcSender:
    """Streams frames to a VMC marionette (an avatar host) over UDP, one bundle per frame."""

    def __init__(self, host: str, port: int) -> None:
        """Raises OSError for a host that does not resolve (once, here, not with every send)."""
        self._address = socket.getaddrinfo(host, port, socket.AF_INET, socket.SOCK_DGRAM)[0][4]
        self._socket = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)

    def send(self, frame: VmcFrame, time: float) -> None:
        self.send_packet(frame_bundle(frame, time))

    def send_packet(self, packet: Packet | osc_bundle.OscBundle | osc_message.OscMessage) -> None:
        try:
            self._socket.sendto(packet.dgram, self._address)
        except ConnectionRefusedError:  # an ICMP "port unreachable" from an earlier datagram
            pass

    def close(self) -> None:
        self._socket.close()


_SO_RXQ_OVFL = getattr(socket, "SO_RXQ_OVFL", 40)  # Linux: datagrams the kernel dropped, per read


class VmcReceiver:
    """A VMC marionette: listens on UDP, assembles frames and hands each to ``on_frame``.

    One thread only reads datagrams into a queue, so that the socket buffer (``RECEIVE_BUFFER``
    asked for; the kernel caps it at ``net.core.rmem_max``) is drained however long a frame's work
    takes; a second thread parses them (python-osc), assembles frames and calls ``on_frame``.
    python-osc's Dispatcher is not used: it drops packets it cannot parse without a word and hides
    bundle boundaries, both of which this needs. On Linux the kernel's count of datagrams it dropped
    for want of buffer space is read with every datagram (``SO_RXQ_OVFL``) and reported as
    ``kernel_dropped`` in :attr:`counts`; ``backlog_max`` is the most datagrams that waited in the
    queue (the parsing thread behind the reader).

    Live means latest: a datagram that waited more than ``max_age`` seconds is dropped unparsed
    (``stale``), and a frame that is that old by the time it would be handed on gives way to a
    newer one made with it (``superseded``); so after any burst (a sender's backlog, a flood) the
    frames are current again as soon as the queue is drained of what is old, which takes
    microseconds per datagram. The queue never holds more than :data:`MAX_QUEUED_BYTES` (beyond,
    what arrives is dropped: ``overflow``).
    Each frame carries the arrival time of the datagram that completed it (``received_ns``).
    """

    def __init__(self, on_frame: Callable[[VmcFrame], None], host: str = DEFAULT_HOST,
                 port: int = DEFAULT_PORT, buffer_bytes: int = RECEIVE_BUFFER,
                 max_age: float = MAX_AGE_S) -> None:
        self.on_frame = on_frame
        self.max_age_ns = round(max_age * 1e9)
        self.assembler = VmcFrameAssembler()
        self._socket = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            self._socket.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, buffer_bytes)
            self._socket.setsockopt(socket.SOL_SOCKET, _SO_RXQ_OVFL, 1)
        except OSError:
            pass  # not Linux: no drop count
        try:
            self._socket.bind((host, port))
        except OSError:
            self._socket.close()
            raise
        self._socket.settimeout(0.1)  # the reader checks for close() this often
        self.buffer_bytes = self._socket.getsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF)
        self._queue: queue.SimpleQueue[tuple[int, bytes] | None] = queue.SimpleQueue()
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._datagrams = 0
        self._kernel_dropped = 0
        self._backlog = 0  # the most datagrams read but not yet parsed
        self._queued_bytes = 0
        self._stale = 0
        self._superseded = 0
        self._overflow = 0
        self._reader = threading.Thread(target=self._read, name="vmc-reader", daemon=True)
        self._worker = threading.Thread(target=self._work, name="vmc-frames", daemon=True)

    @property
    def address(self) -> tuple[str, int]:
        return self._socket.getsockname()[:2]

    @property
    def counts(self) -> dict[str, int]:
        with self._lock:
            counts = dict(self.assembler.counts)
        counts.update(datagrams=self._datagrams, kernel_dropped=self._kernel_dropped,
                      backlog_max=self._backlog, stale=self._stale, superseded=self._superseded,
                      overflow=self._overflow)
        return counts

    def start(self) -> VmcReceiver:
        self._worker.start()
        self._reader.start()
        return self

    def _read(self) -> None:
        space = socket.CMSG_SPACE(4)
        while not self._stop.is_set():
            try:
                data, ancillary, _, _ = self._socket.recvmsg(65535, space)
            except TimeoutError:
                continue
            except OSError:
                break
            for level, kind, value in ancillary:
                if level == socket.SOL_SOCKET and kind == _SO_RXQ_OVFL and len(value) >= 4:
                    self._kernel_dropped = struct.unpack("=I", value[:4])[0]
            self._datagrams += 1
            with self._lock:
                if self._queued_bytes + len(data) > MAX_QUEUED_BYTES:
                    self._overflow += 1
                    continue
                self._queued_bytes += len(data)
            self._queue.put((time.monotonic_ns(), data))
        self._queue.put(None)

    def _work(self) -> None:
        """Takes what is queued at once: what waited too long is dropped unparsed, the rest made
        into frames, and of those every one still fresh is handed on, and the newest in any case."""
        running = True
        while running:
            batch = [self._queue.get()]
            while batch[-1] is not None and not self._queue.empty():
                batch.append(self._queue.get())
            running = batch[-1] is not None
            batch = [item for item in batch if item is not None]
            self._backlog = max(self._backlog, len(batch) - 1)
            frames = []
            with self._lock:
                for arrived, data in batch:
                    self._queued_bytes -= len(data)
                    if time.monotonic_ns() - arrived > self.max_age_ns:
                        self._stale += 1
                        self.assembler.interrupt()
                        continue
                    frames += [(arrived, f) for f in self.assembler.feed_datagram(data)]
            for i, (arrived, f) in enumerate(frames):
                if i < len(frames) - 1 and time.monotonic_ns() - arrived > self.max_age_ns:
                    self._superseded += 1
                    continue
                self.on_frame(replace(f, received_ns=arrived))

    def close(self) -> None:
        self._stop.set()
        if self._reader.is_alive():
            self._reader.join()
        else:
            self._queue.put(None)
        if self._worker.is_alive():
            self._worker.join(timeout=5.0)
        self._socket.close()


class SenderClock:
    """Stamps for a sender's frames: its own ``/VMC/Ext/T`` when that advances, else arrival time.

    A sender's clock spaces its frames as it made them, so stamps taken from it keep the stream's
    rhythm however the network, the sender or a scheduler hold up and bunch the datagrams. The stamp
    is the sender's time plus an offset that follows the least delayed arrivals (the lower envelope
    of arrival minus sender time), and the offset only ever slews, so stamps keep their spacing to
    within a fraction: it drops to a less delayed arrival by at most half a frame step at a time,
    creeps up by ``drift`` (1000 ppm) of the time that passed so a slow sender clock is followed,
    and once frames have trailed their arrival by more than ``tolerance`` seconds for ``patience``
    seconds of sender time (a sender that fell behind and stays behind; a sender held up for a
    moment that then sends its backlog keeps its stamps) it catches up at ``catch_up`` (10 %: frame
    steps 1.1 times longer) until they trail by less. A time that does not advance (an epoch time sent as float32 moves in 128 s
    steps) stamps the frame with its arrival time, and one that would stamp a frame more than
    ``jump`` (1 s) after its arrival (a time that jumped ahead) anchors the clock at that arrival
    again; less than that (a sender that was behind catching up) is slewed down like any less
    delayed arrival. Stamps always increase, by at least half the sender's frame step.
    """

    def __init__(self, tolerance: float = 0.1, drift: float = 1e-3, catch_up: float = 0.1,
                 patience: float = 0.5, jump: float = 1.0) -> None:
        self.tolerance_ns = round(tolerance * 1e9)
        self.jump_ns = round(jump * 1e9)
        self.drift = drift
        self.catch_up = catch_up
        self.patience = patience
        self._late_since: float | None = None
        self._offset: int | None = None
        self._time: float | None = None
        self._now = 0
        self._last = 0

    def stamp(self, sender_time: float | None, now_ns: int) -> int:
        """The stamp (ns) of a frame with ``sender_time`` (seconds, or None) that completed at
        ``now_ns``."""
        stamp = now_ns
        if sender_time is None or self._time is None or sender_time <= self._time:
            self._offset = None  # no time, or one that does not advance: arrival time
        if sender_time is not None:
            t_ns = round(sender_time * 1e9)
            arrival = now_ns - t_ns  # the offset that would stamp this frame on arrival
            if self._offset is None or self._offset - arrival > self.jump_ns:
                self._offset = arrival
            else:
                step = (sender_time - self._time) * 1e9
                if arrival < self._offset:  # less delayed than any before: slew down to it
                    self._offset = max(arrival, self._offset - round(0.5 * step))
                else:
                    late = arrival - self._offset > self.tolerance_ns
                    self._late_since = (self._late_since if self._late_since is not None
                                        else sender_time) if late else None
                    behind = late and sender_time - self._late_since > self.patience
                    up = self.catch_up * step if behind else self.drift * max(step, now_ns - self._now)
                    self._offset = min(arrival, self._offset + round(up))
            stamp = t_ns + self._offset
            self._time = sender_time
        self._now = now_ns
        self._last = max(stamp, self._last + 1)
        return self._last


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


@dataclass(frozen=True)
class _Received:
    """What the link published for one frame, kept to send the frame's stylized pose back."""

    stamp_ns: int
    frame: VmcFrame
    retarget: Retargeter  # sender rig -> canonical, as used for this frame
    canonical_rotations: np.ndarray  # (22, 4) global, core frame
    canonical_hips: np.ndarray  # (3,) hip centre
    rig_rotations: np.ndarray  # (J, 4) the sender rig's global rotations, root folded in
    rig_local: np.ndarray  # (J, 4) its local rotations (the root folded into the hips)
    rig_hips: np.ndarray  # (3,) its hip centre
    rig_pelvis: np.ndarray  # (3,) its Hips joint
    extras: dict[str, np.ndarray]  # pass-through bone -> the 3 JointState values published for it


def _hip_centre(positions: np.ndarray, joints: dict[str, int]) -> np.ndarray:
    return 0.5 * (positions[joints["UpperLeg_L"]] + positions[joints["UpperLeg_R"]])


class VmcLink:
    """VMC frames -> canonical JointState values, and stylized ones back to VMC on the sender's rig.

    :meth:`receive` converts a frame (:class:`VmcDecoder`) and keeps it with the stamp it was
    published under. :meth:`send` takes a stylized JointState, picks the kept frame whose pose that
    output shows (stamp nearest ``stamp - delay``, the stylizer's latency), and sends the stylized
    pose as a change of that frame: each body bone mapped to a canonical joint turns in the world
    as the canonical joint turned (stylized global times input global inverse), the sender's other
    body bones (e.g. Chest between Spine and UpperChest) keep their local rotations, the hip
    centre moves as the canonical one did (over the leg-length ratio), and bone local positions,
    the root transform (with its scale and offset), fingers, eyes, jaw, blendshapes, OK and every
    pass-through message are that frame's, as they came. So a stylizer that changes nothing
    returns the sender's frame (to float32), and a stylized pose keeps the sender's rest pose and
    proportions. A finger, eye or jaw whose JointState values come back changed (a node between
    changed them) goes out as they came back. ``/VMC/Ext/T`` goes out as the time given to
    :meth:`send`. Before any frame was
    received, stylized states go out on a T-posed rig of canonical proportions (:class:`VmcEncoder`).
    """

    def __init__(self, keep_seconds: float = 2.0) -> None:
        self.layout = JointStateLayout.canonical()
        self.decoder = VmcDecoder()
        self.counts: Counter[str] = Counter()
        self.keep_ns = round(keep_seconds * 1e9)
        self._received: deque[_Received] = deque()
        self._lock = threading.Lock()
        self._calibration: int | None = None
        self._fallback: VmcEncoder | None = None
        self._names: dict[tuple[str, ...], list[str]] = {}

    def reset(self) -> None:
        """Forget the rig and the kept frames (the next frame builds the rig again)."""
        self.decoder.reset()
        with self._lock:
            self._received.clear()

    def receive(self, frame: VmcFrame, stamp_ns: int) -> tuple[list[str], np.ndarray] | None:
        """The JointState names and values for ``frame``, or None when its OK state says the pose
        is not the performer's (counted by reason). Raises MotionStyleError when no rig can be
        built or the values are not finite (the rig is then built anew from the next frame)."""
        reason = usable(frame)
        calibration = frame.ok[1] if frame.ok is not None and len(frame.ok) >= 2 else None
        if calibration != self._calibration:
            if calibration == CALIBRATED and self._calibration is not None:
                self.decoder.reset()  # a new calibration: rest pose and proportions may differ
            self._calibration = calibration
        if reason:
            self.counts[reason] += 1
            return None
        try:
            motion = self.decoder([frame])
            values = self.layout.encode(motion.rotations[0], motion.root_positions[0])
            extras = tuple(b for b in EXTRA_BONES if b in frame.bones)
            if extras:
                quats = unity_to_core_rotation(np.stack([frame.bones[b][1] for b in extras]))
                values = np.concatenate([values, rotation_values(quats)])
            if not np.isfinite(values).all():
                raise MotionStyleError("VMC frame gave non-finite joint values")
        except MotionStyleError:
            self.decoder.reset()
            raise
        retarget = self.decoder._retarget
        canon_rot, canon_pos = motion.global_transforms()
        rig = self.decoder.rig
        rig_m = rig_motion(rig, [frame], self.decoder.fps)
        rig_rot, rig_pos = rig_m.global_transforms()
        kept = _Received(stamp_ns, frame, retarget, canon_rot[0],
                         _hip_centre(canon_pos[0], retarget.target_tpose.joints), rig_rot[0],
                         rig_m.rotations[0],
                         _hip_centre(rig_pos[0], retarget.source_tpose.joints), rig_pos[0, 0],
                         {b: values[len(values) - 3 * len(extras) + 3 * i:][:3]
                          for i, b in enumerate(extras)})
        with self._lock:
            self._received.append(kept)
            while stamp_ns - self._received[0].stamp_ns > self.keep_ns or \
                    stamp_ns < self._received[0].stamp_ns:
                self._received.popleft()
        if extras not in self._names:
            self._names[extras] = self.layout.names + rotation_names(extras)
        return self._names[extras], values

    @staticmethod
    def blendshapes(frame: VmcFrame) -> tuple[list[str], np.ndarray]:
        """The frame's blendshape names and values (its Val messages), as received."""
        return list(frame.blendshapes), np.array(list(frame.blendshapes.values()), dtype=np.float64)

    def _shown(self, stamp_ns: int) -> _Received | None:
        with self._lock:
            if not self._received:
                return None
            # The nearest frame, the older one on a tie (as FrameDelay picks pass-through names).
            return min(self._received, key=lambda r: abs(r.stamp_ns - stamp_ns))

    def send(self, names: Sequence[str], positions: Sequence[float], stamp_ns: int,
             delay_ns: int, time: float) -> Packet:
        """The VMC bundle for one stylized JointState stamped ``stamp_ns`` whose pose shows the
        input of ``stamp_ns - delay_ns``. Raises MotionStyleError for names or values the layout
        cannot decode, and for values beyond ``MAX_VALUE`` (no pose has them; past float32's range
        they could not even be sent)."""
        rotations, root = self.layout.decode(names, positions)
        if np.abs(np.asarray(positions, dtype=np.float64)).max() > MAX_VALUE:
            raise MotionStyleError(f"JointState values beyond {MAX_VALUE:g} (m or rad): not a pose")
        shown = self._shown(stamp_ns - delay_ns)
        if shown is None:
            self._fallback = self._fallback or VmcEncoder()
            motion = Motion.from_rotations(canonical(), rotations[None], root[None], 30.0)
            return frame_bundle(self._fallback(motion)[0], time)
        if abs(shown.stamp_ns - (stamp_ns - delay_ns)) > STALE_NS:
            self.counts["sent_stale_frame"] += 1
        where = {n: i for i, n in enumerate(names)}
        extras = {b: np.asarray([positions[where[n]] for n in rotation_names([b])], dtype=np.float64)
                  for b in shown.extras if all(n in where for n in rotation_names([b]))}
        return self._bundle(shown, rotations, root, time, extras)

    def _bundle(self, shown: _Received, rotations: np.ndarray, root: np.ndarray, time: float,
                extras: dict[str, np.ndarray] | None = None) -> Packet:
        """``extras``: pass-through bones' JointState values as they came back; one that differs
        from what was published for the frame (a node changed it on the way) is sent as it came
        back, the others as the sender sent them."""
        ret, frame = shown.retarget, shown.frame
        rig = ret.source
        out = Motion.from_rotations(canonical(), rotations[None], root[None], 30.0)
        out_rot, out_pos = (a[0] for a in out.global_transforms())
        canon_j, rig_j = ret.target_tpose.joints, ret.source_tpose.joints
        turn = {rig_j[c]: rot.multiply(out_rot[canon_j[c]],
                                       rot.conjugate(shown.canonical_rotations[canon_j[c]]))
                for c in ret.common}
        g = np.empty_like(shown.rig_rotations)
        for j, p in enumerate(rig.parents):
            if j in turn:
                g[j] = rot.multiply(turn[j], shown.rig_rotations[j])
            else:
                g[j] = shown.rig_rotations[j] if p < 0 else rot.multiply(g[p], shown.rig_local[j])
        hips = shown.rig_hips + (_hip_centre(out_pos, canon_j) - shown.canonical_hips) / ret.scale
        pelvis = hips - rot.rotate(g[0], rot.rotate(rot.conjugate(shown.rig_rotations[0]),
                                                    shown.rig_hips - shown.rig_pelvis))
        root_p, root_q = root_transform(frame)
        local = np.empty_like(g)
        local[0] = rot.multiply(rot.conjugate(root_q), g[0])
        for j in range(1, rig.n_joints):
            local[j] = rot.multiply(rot.conjugate(g[rig.parents[j]]), g[j])
        local_q = core_to_unity_rotation(rot.normalize(local))
        hips_p = core_to_unity_position(rot.rotate(rot.conjugate(root_q), pelvis - root_p))
        messages = [frame.raw.get("root") or build_message(ROOT_ADDRESS, _transform_args("root", *frame.root))]
        for j, b in enumerate(rig.names):
            messages.append(_bone_message(b, hips_p if j == 0 else frame.bones[b][0], local_q[j]))
        for b in EXTRA_BONES:
            if b not in frame.bones:
                continue
            back = (extras or {}).get(b)
            if back is not None and not np.array_equal(back, shown.extras[b]) and np.isfinite(back).all():
                q = core_to_unity_rotation(rotations_from_values(back)[0])
                messages.append(_bone_message(b, frame.bones[b][0], q))
            else:
                messages.append(frame.raw.get(b) or _bone_message(b, *frame.bones[b]))
        if frame.passthrough:
            messages += list(frame.passthrough)
        else:  # a frame made, not received
            messages += [build_message(BLEND_ADDRESS, [k, float(v)]) for k, v in frame.blendshapes.items()]
            messages += [build_message(APPLY_ADDRESS, [])] if frame.apply else []
        messages.append(frame.raw.get("ok") or build_message(OK_ADDRESS, [1]))
        messages.append(build_message(TIME_ADDRESS, [float(time)]))
        return _bundle(messages)
