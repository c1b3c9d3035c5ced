"""Complete VMC frames from a stream of messages, however the sender bundles them."""

from __future__ import annotations

import struct
from collections import Counter
from collections.abc import Sequence

import numpy as np
from pythonosc import osc_message

from motion_style_ros.io.vmc.osc import BUNDLE_PREFIX, build_message, osc_messages
from motion_style_ros.io.vmc.protocol import (
    APPLY_ADDRESS,
    BLEND_ADDRESS,
    BONE_ADDRESS,
    HUMAN_BONES,
    IDENTITY_XYZW,
    MAX_TIME,
    MAX_VALUE,
    OK_ADDRESS,
    REQUIRED_BONES,
    ROOT_ADDRESS,
    TIME_ADDRESS,
    VmcFrame,
    VmcMessageError,
    check_transform,
    is_value,
    root_extension,
)


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
        self.root: tuple[np.ndarray, np.ndarray] = (np.zeros(3), IDENTITY_XYZW)
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
            check_transform(args, (0,))
            return ("bone", args[0]) if args[0] in HUMAN_BONES else None
        if address == ROOT_ADDRESS:
            check_transform(args, (0, 6))
            root_extension(args)
            return ("root",)
        if address == TIME_ADDRESS:
            if len(args) != 1 or not is_value(args[0], MAX_TIME):
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
            if len(args) != 2 or not isinstance(args[0], str) or not is_value(args[1]):
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
            self.root_scale, self.root_offset = root_extension(args)
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
        whole = data.startswith(BUNDLE_PREFIX) and all(b in names for b in self.required)
        frames = []
        self._bundle_keys = set()
        for m in messages:
            frames += self.feed(m.address, m.params, m, whole=whole)
        if whole and self._pending and (self.last_key is None or self.last_key in self._bundle_keys):
            self.last_key = self._previous_key
            frames.append(self.end_frame())
        self._bundle_keys = None
        return [f for f in frames if f is not None]
