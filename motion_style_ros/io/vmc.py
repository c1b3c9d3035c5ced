"""VMC protocol (Virtual Motion Capture, OSC over UDP): receive, assemble, convert and send.

A VMC performer streams, per frame and usually in one OSC bundle, ``/VMC/Ext/Root/Pos`` (the
avatar's root transform), one ``/VMC/Ext/Bone/Pos`` per Unity HumanBodyBones bone (local position
and rotation relative to its parent), ``/VMC/Ext/OK`` and ``/VMC/Ext/T`` (sender time). A frame ends
with its bundle or with ``/VMC/Ext/T``. Values are in Unity's frame: left-handed, Y up, Z forward,
X right, metres, quaternions as (x, y, z, w).

The motion core is right-handed, Y up, the character facing +Z with its left towards +X. Both face
+Z with Y up, so the core is Unity mirrored in X: ``p_core = M p_unity`` with ``M = diag(-1, 1, 1)``.
A rotation matrix maps as ``R_core = M R_unity M``; conjugating by a reflection keeps the rotation
angle's magnitude and turns the axis ``a`` into ``M a`` with the sense reversed (det M = -1), so
axis ``(-ax, ay, az)`` with angle ``-t`` = axis ``(ax, -ay, -az)`` with angle ``t``: the Unity
quaternion ``(x, y, z, w)`` is the core quaternion ``(w, x, -y, -z)``. Unity's quaternion maths is
the usual Hamilton formula on these components, which is what the tests check against.
"""

from __future__ import annotations

import socketserver
import struct
import threading
from collections import Counter
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np
from pythonosc import osc_bundle_builder, osc_message_builder, osc_packet
from pythonosc.udp_client import UDPClient

from motion_style_ros.core import rotations as rot
from motion_style_ros.core.motion import Motion
from motion_style_ros.core.retarget import MAPS, Retargeter, find_map, tpose
from motion_style_ros.core.skeleton import Skeleton, canonical
from motion_style_ros.errors import MotionStyleError

DEFAULT_HOST = "127.0.0.1"
DEFAULT_PORT = 39539
ROOT_ADDRESS = "/VMC/Ext/Root/Pos"
BONE_ADDRESS = "/VMC/Ext/Bone/Pos"
TIME_ADDRESS = "/VMC/Ext/T"
OK_ADDRESS = "/VMC/Ext/OK"

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


def parse_transform(
    args: Sequence[object], extra: tuple[int, ...] = (0,)
) -> tuple[str, np.ndarray, np.ndarray]:
    """``(name, position (3,), rotation (x, y, z, w))`` from Root/Pos or Bone/Pos arguments.

    ``extra`` lists how many numbers may follow the quaternion (Root/Pos v2.1 adds scale and offset).
    Raises :class:`VmcMessageError` for wrong counts or types, non-finite values or a zero quaternion.
    """
    if len(args) - 8 not in extra:
        raise VmcMessageError(f"expected {[8 + e for e in extra]} arguments, got {len(args)}")
    name, *numbers = args
    if not isinstance(name, str) or not name:
        raise VmcMessageError(f"first argument must be a bone name, got {name!r}")
    if not all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in numbers):
        raise VmcMessageError(f"{name}: non-numeric values {numbers!r}")
    values = np.asarray(numbers[:7], dtype=np.float64)
    if not np.isfinite(values).all():
        raise VmcMessageError(f"{name}: non-finite values")
    norm = np.linalg.norm(values[3:])
    if norm < 1e-6:
        raise VmcMessageError(f"{name}: zero quaternion")
    return name, values[:3], values[3:] / norm


@dataclass(frozen=True)
class VmcFrame:
    """One complete pose as received, in Unity's frame: bone -> (local position, (x, y, z, w))."""

    bones: dict[str, tuple[np.ndarray, np.ndarray]]
    root: tuple[np.ndarray, np.ndarray] = field(default_factory=lambda: (np.zeros(3), _IDENTITY_XYZW))
    time: float | None = None


class VmcFrameAssembler:
    """Turns a stream of VMC messages into complete frames.

    Each frame holds the last known value of every bone seen so far, so a frame that misses bones is
    completed from the previous pose. Frames end at a bundle's end or at ``/VMC/Ext/T``; a frame is
    emitted only once every required bone has been seen (before that it is counted as dropped).
    A malformed message is dropped on its own; the rest of its bundle still makes a frame.
    ``counts``: frames, malformed (unparsable packets, bad arguments), dropped (frames before every
    required bone was known), ignored (other addresses, non-body bones such as fingers).
    """

    def __init__(self, required: Sequence[str] = REQUIRED_BONES) -> None:
        self.required = tuple(required)
        self.bones: dict[str, tuple[np.ndarray, np.ndarray]] = {}
        self.root: tuple[np.ndarray, np.ndarray] = (np.zeros(3), _IDENTITY_XYZW)
        self.time: float | None = None
        self.counts: Counter[str] = Counter(frames=0, malformed=0, dropped=0, ignored=0)
        self._pending = False

    def feed(self, address: str, args: Sequence[object]) -> VmcFrame | None:
        """Take one message; returns a frame when the message ends one."""
        try:
            if address == BONE_ADDRESS:
                name, p, q = parse_transform(args)
                if name not in UNITY_PARENTS:  # fingers, eyes, jaw: valid, but not ours
                    self.counts["ignored"] += 1
                    return None
                self.bones[name] = (p, q)
                self._pending = True
            elif address == ROOT_ADDRESS:
                _, p, q = parse_transform(args, extra=(0, 6))
                self.root = (p, q)
                self._pending = True
            elif address == TIME_ADDRESS:
                if len(args) != 1 or isinstance(args[0], bool) or not isinstance(args[0], (int, float)):
                    raise VmcMessageError(f"{TIME_ADDRESS} takes one number, got {list(args)!r}")
                self.time = float(args[0])
                return self.end_frame()
            elif address == OK_ADDRESS:
                if not args or not all(isinstance(a, int) and not isinstance(a, bool) for a in args):
                    raise VmcMessageError(f"{OK_ADDRESS} takes integers, got {list(args)!r}")
            else:
                self.counts["ignored"] += 1
        except VmcMessageError:
            self.counts["malformed"] += 1
        return None

    def end_frame(self) -> VmcFrame | None:
        """Close the frame being received (a bundle ended); None if nothing changed or incomplete."""
        if not self._pending:
            return None
        self._pending = False
        if any(b not in self.bones for b in self.required):
            self.counts["dropped"] += 1
            return None
        self.counts["frames"] += 1
        return VmcFrame(dict(self.bones), self.root, self.time)

    def feed_datagram(self, data: bytes) -> list[VmcFrame]:
        """Take one UDP datagram (an OSC message or bundle); returns the frames it completed."""
        try:
            packet = osc_packet.OscPacket(data)
        except (osc_packet.ParseError, ValueError, IndexError, TypeError, struct.error):
            self.counts["malformed"] += 1
            return []
        frames = [self.feed(m.message.address, m.message.params) for m in packet.messages]
        if data.startswith(b"#bundle"):
            frames.append(self.end_frame())
        return [f for f in frames if f is not None]


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


def rig_motion(rig: Skeleton, frames: Sequence[VmcFrame], fps: float) -> Motion:
    """Frames on ``rig`` in the core frame; the root transform is folded into the hips."""
    pos = unity_to_core_position([[f.bones[b][0] for b in rig.names] for f in frames])
    q = unity_to_core_rotation([[f.bones[b][1] for b in rig.names] for f in frames])
    root_p = unity_to_core_position([f.root[0] for f in frames])
    root_q = unity_to_core_rotation([f.root[1] for f in frames])
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

    The sender's rig is built from the first frame and retargeted by bone names and T-pose; its
    rest pose (identity local rotations) is taken as a T-pose, as on a normalised VRM avatar.
    :meth:`reset` forgets it, so that the next frame builds it again (another avatar).
    """

    def __init__(self, target: Skeleton | None = None, fps: float = 30.0) -> None:
        self.target = target or canonical()
        self.fps = fps
        self.rig: Skeleton | None = None
        self._retarget: Retargeter | None = None

    def reset(self) -> None:
        self.rig = self._retarget = None

    def __call__(self, frames: Sequence[VmcFrame]) -> Motion:
        if self.rig is None:
            rig = unity_rig(frames[0])
            lengths = [np.linalg.norm(rig.offsets[rig.index(b)])
                       for b in ("LeftLowerLeg", "LeftFoot", "RightLowerLeg", "RightFoot")]
            if min(lengths) < 1e-6:
                raise MotionStyleError("VMC frame has zero-length legs; no rig can be built from it")
            self._retarget = Retargeter(rig, self.target, MAPS["unity"], find_map(self.target))
            self.rig = rig
        return self._retarget(rig_motion(self.rig, frames, self.fps))


class VmcEncoder:
    """Motion on ``source`` (canonical by default) -> VMC frames for a T-posed Unity rig."""

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


def frame_bundle(frame: VmcFrame, time: float) -> osc_bundle_builder.osc_bundle.OscBundle:
    """One VMC frame as an OSC bundle: root, bones, OK and time (as performers send it)."""
    bundle = osc_bundle_builder.OscBundleBuilder(osc_bundle_builder.IMMEDIATELY)

    def add(address: str, args: Sequence[object]) -> None:
        msg = osc_message_builder.OscMessageBuilder(address)
        for a in args:
            msg.add_arg(a)
        bundle.add_content(msg.build())

    for address, name, (p, q) in [(ROOT_ADDRESS, "root", frame.root)] + [
        (BONE_ADDRESS, b, v) for b, v in frame.bones.items()
    ]:
        add(address, [name, *map(float, p), *map(float, q)])
    add(OK_ADDRESS, [1])
    add(TIME_ADDRESS, [float(time)])
    return bundle.build()


class VmcSender:
    """Streams frames to a VMC marionette (an avatar host) over UDP, one bundle per frame."""

    def __init__(self, host: str, port: int) -> None:
        self._client = UDPClient(host, port)

    def send(self, frame: VmcFrame, time: float) -> None:
        self._client.send(frame_bundle(frame, time))


class _Handler(socketserver.BaseRequestHandler):
    def handle(self) -> None:
        server: _Server = self.server  # type: ignore[assignment]
        with server.lock:
            frames = server.assembler.feed_datagram(self.request[0])
        for f in frames:
            server.on_frame(f)


class _Server(socketserver.UDPServer):
    max_packet_size = 65535  # a bundle of every bone can exceed socketserver's 8 KiB default

    def __init__(self, address: tuple[str, int], on_frame: Callable[[VmcFrame], None]) -> None:
        super().__init__(address, _Handler)
        self.assembler = VmcFrameAssembler()
        self.lock = threading.Lock()
        self.on_frame = on_frame


class VmcReceiver:
    """A VMC marionette: listens on UDP, assembles frames and hands each to ``on_frame``.

    python-osc parses the packets; its Dispatcher is not used because it silently drops packets it
    cannot parse and hides bundle boundaries, both of which this needs. ``on_frame`` runs on the
    receiver's thread.
    """

    def __init__(self, on_frame: Callable[[VmcFrame], None], host: str = DEFAULT_HOST,
                 port: int = DEFAULT_PORT) -> None:
        self._server = _Server((host, port), on_frame)
        self._thread = threading.Thread(target=self._server.serve_forever, daemon=True)

    @property
    def address(self) -> tuple[str, int]:
        return self._server.server_address[:2]

    @property
    def counts(self) -> dict[str, int]:
        with self._server.lock:
            return dict(self._server.assembler.counts)

    def start(self) -> VmcReceiver:
        self._thread.start()
        return self

    def close(self) -> None:
        if self._thread.is_alive():
            self._server.shutdown()
        self._server.server_close()
