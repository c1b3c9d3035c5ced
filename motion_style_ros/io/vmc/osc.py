"""OSC datagrams of VMC: read (stricter than python-osc's packet parser) and written (as python-osc's
builder writes them, at a fraction of its cost)."""

from __future__ import annotations

import struct
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from pythonosc import osc_message, osc_message_builder

from motion_style_ros.io.vmc.protocol import (
    APPLY_ADDRESS,
    BLEND_ADDRESS,
    BONE_ADDRESS,
    OK_ADDRESS,
    ROOT_ADDRESS,
    TIME_ADDRESS,
    VmcFrame,
    VmcMessageError,
)

MAX_NESTING = 8  # bundles within bundles (VMC senders nest none)
BUNDLE_PREFIX = b"#bundle\x00"


def build_message(address: str, args: Sequence[object]) -> osc_message.OscMessage:
    """An OSC message; floats go as float32 (``f``), as VMC senders send them."""
    msg = osc_message_builder.OscMessageBuilder(address)
    for a in args:
        msg.add_arg(a)
    return msg.build()



def osc_messages(data: bytes, depth: int = 0) -> list[osc_message.OscMessage]:
    """The OSC messages of a datagram in the order sent, nested bundles flattened.

    Stricter than python-osc's ``OscPacket``, which loops for ever on a negative bundle element
    size, takes a size past the end as the rest of the datagram, skips an element it cannot
    identify and recurses without bound (a ``RecursionError``): each of these raises
    :class:`VmcMessageError` here. Messages keep the order sent: time tags are not waited for
    (``OscPacket`` sorts by them), a pose is shown when it comes.
    """
    if not data.startswith(BUNDLE_PREFIX):
        if not data.startswith(b"/"):
            raise VmcMessageError("neither an OSC message nor a bundle")
        return [osc_message.OscMessage(data)]
    if depth == MAX_NESTING:
        raise VmcMessageError(f"bundles nested deeper than {MAX_NESTING}")
    messages, i = [], len(BUNDLE_PREFIX) + 8  # after the time tag
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


@dataclass(frozen=True)
class Packet:
    """An OSC packet ready to send: its datagram (``dgram``), as python-osc's packets have one."""

    dgram: bytes


_IMMEDIATELY = struct.pack(">Q", 1)  # the OSC time tag "now"


def bundle(messages: Sequence[osc_message.OscMessage | Packet]) -> Packet:
    """One bundle of ``messages`` (their datagrams as they are: python-osc's builder would parse
    every message it has just written again, which doubled the cost of a frame)."""
    return Packet(BUNDLE_PREFIX + _IMMEDIATELY + b"".join(
        struct.pack(">i", len(m.dgram)) + m.dgram for m in messages))


def _osc_string(text: str) -> bytes:
    data = text.encode("utf-8") + b"\x00"
    return data + b"\x00" * (-len(data) % 4)


_BONE_HEAD = _osc_string(BONE_ADDRESS) + _osc_string(",sfffffff")


def bone_message(name: str, p: np.ndarray, q: np.ndarray) -> Packet:
    """A /VMC/Ext/Bone/Pos message, encoded as python-osc's builder encodes it (float32 big-endian
    arguments), at a fraction of its cost: a frame sends one for every bone."""
    return Packet(_BONE_HEAD + _osc_string(name) + struct.pack(">7f", *p, *q))


def transform_args(name: str, p: np.ndarray, q: np.ndarray) -> list[object]:
    return [name, *map(float, p), *map(float, q)]


def frame_bundle(frame: VmcFrame, time: float) -> Packet:
    """One VMC frame as an OSC bundle: root, bones, blendshapes, OK and time (as performers send it)."""
    root = transform_args("root", *frame.root)
    if frame.root_scale is not None:
        root += [*map(float, frame.root_scale), *map(float, frame.root_offset)]
    messages = [build_message(ROOT_ADDRESS, root)]
    messages += [bone_message(b, p, q) for b, (p, q) in frame.bones.items()]
    messages += [build_message(BLEND_ADDRESS, [k, float(v)]) for k, v in frame.blendshapes.items()]
    if frame.apply or frame.blendshapes:
        messages.append(build_message(APPLY_ADDRESS, []))
    messages.append(build_message(OK_ADDRESS, list(frame.ok or (1,))))
    messages.append(build_message(TIME_ADDRESS, [float(time)]))
    return bundle(messages)
