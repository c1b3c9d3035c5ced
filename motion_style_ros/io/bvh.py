"""BVH files: any channel order, 3 or 6 channels per joint, End Sites; lossless to file precision.

:class:`BvhClip` holds the file as written (header plus the raw channel matrix), so reading and
writing a file reproduces its numbers exactly; :meth:`BvhClip.to_motion` and
:meth:`BvhClip.from_motion` convert to and from the motion core.
"""

from __future__ import annotations

import io
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from motion_style_ros.core import rotations as rot
from motion_style_ros.core.motion import Motion
from motion_style_ros.core.skeleton import Skeleton
from motion_style_ros.errors import MotionStyleError
from motion_style_ros.io import files

_POSITION = ("Xposition", "Yposition", "Zposition")
_ROTATION = ("Xrotation", "Yrotation", "Zrotation")
_NUMBER_BYTES = b"0123456789.+-eE \t\n\r\f\v"  # digits, signs, exponents, whitespace
# what a value may hold before it is converted: a number's characters, and NaN's and infinity's
# (those are then reported as non-finite)
_NOT_NUMBER_OR_NAN = re.compile(r"[^0-9.+\-eEnNaAiIfFtTyY]", re.ASCII)
MAX_DEPTH = 200  # joints nested deeper are no body (and would exhaust the reader's recursion)
MIN_FRAME_TIME = 1e-5  # s: 100 kHz, far beyond any capture (and 1 / 5e-324 is no rate)
MAX_VALUE = 1e9  # no channel of a capture holds more (cm: 10,000 km; degrees: 2.8 million turns)


class BvhError(MotionStyleError):
    """A BVH file that cannot be read; the message names the file and the problem."""


@dataclass(eq=False)
class BvhClip:
    skeleton: Skeleton  # in file units
    channels: tuple[tuple[str, ...], ...]  # per joint, as listed in the header
    data: np.ndarray  # (T, C) channel values in header order, degrees and file units
    frame_time: float

    @property
    def n_frames(self) -> int:
        return self.data.shape[0]

    @property
    def fps(self) -> float:
        """Frames per second; files store a rounded frame time (0.0333333), so snap to whole rates."""
        fps = 1.0 / self.frame_time
        return float(round(fps)) if abs(fps - round(fps)) < 1e-4 * fps else fps

    def to_motion(self, scale: float = 1.0) -> Motion:
        """The clip as a :class:`Motion`; ``scale`` converts file units (for example cm -> m: 0.01)."""
        sk = self.skeleton
        t = self.n_frames
        rotations = np.empty((t, sk.n_joints, 4))
        positions = np.broadcast_to(sk.offsets, (t, sk.n_joints, 3)).copy()
        col = 0
        for j, chans in enumerate(self.channels):
            block = self.data[:, col : col + len(chans)]
            col += len(chans)
            rot_idx = [i for i, c in enumerate(chans) if c in _ROTATION]
            if rot_idx:
                order = "".join(chans[i][0] for i in rot_idx)
                rotations[:, j] = rot.from_euler(block[:, rot_idx], order, degrees=True)
            else:
                rotations[:, j] = rot.identity()
            for i, c in enumerate(chans):
                if c in _POSITION:
                    positions[:, j, _POSITION.index(c)] = block[:, i]
        return Motion(sk.scaled(scale), rotations, positions * scale, fps=self.fps)

    @classmethod
    def from_motion(
        cls,
        motion: Motion,
        scale: float = 1.0,
        channels: tuple[tuple[str, ...], ...] | None = None,
    ) -> "BvhClip":
        """A clip for ``motion`` in file units (``scale`` multiplies lengths, e.g. m -> cm: 100).

        Without ``channels``, the root and any joint whose translation changes get
        ``Xposition Yposition Zposition Zrotation Yrotation Xrotation`` and the others the three
        rotation channels.
        """
        sk = motion.skeleton.scaled(scale)
        positions = motion.positions * scale
        if channels is None:
            moving = np.ptp(positions, axis=0).max(axis=-1) > 1e-9
            moving |= np.abs(positions[0] - sk.offsets).max(axis=-1) > 1e-9
            moving[0] = True
            rot_chans = ("Zrotation", "Yrotation", "Xrotation")
            channels = tuple(_POSITION + rot_chans if m else rot_chans for m in moving)
        if len(channels) != sk.n_joints:
            raise MotionStyleError(f"{len(channels)} channel lists for {sk.n_joints} joints")
        columns = []
        for j, chans in enumerate(channels):
            rot_idx = [i for i, c in enumerate(chans) if c in _ROTATION]
            euler = (
                rot.to_euler(motion.rotations[:, j], "".join(chans[i][0] for i in rot_idx), degrees=True)
                if rot_idx
                else None
            )
            for c in chans:
                if c in _POSITION:
                    columns.append(positions[:, j, _POSITION.index(c)])
                elif c in _ROTATION:
                    columns.append(euler[:, rot_idx.index(chans.index(c))])
                else:
                    raise MotionStyleError(f"unknown BVH channel {c!r}")
        data = np.stack(columns, axis=1) if columns else np.zeros((motion.n_frames, 0))
        return cls(sk, tuple(tuple(c) for c in channels), data, 1.0 / motion.fps)


class _Tokens:
    def __init__(self, text: str, path: str) -> None:
        self.words = text.split()
        self.i = 0
        self.path = path

    def next(self, what: str) -> str:
        if self.i >= len(self.words):
            raise BvhError(f"{self.path}: file ends early, expected {what}")
        w = self.words[self.i]
        self.i += 1
        return w

    def expect(self, word: str) -> None:
        got = self.next(repr(word))
        if got != word:
            raise BvhError(f"{self.path}: expected {word!r}, found {got!r}")

    def number(self, what: str) -> float:
        w = self.next(what)
        try:
            return float(w)
        except ValueError:
            raise BvhError(f"{self.path}: expected a number for {what}, found {w!r}") from None


def read(path: str | Path) -> BvhClip:
    """Read a BVH file; raises :class:`BvhError` naming the file and the problem."""
    path = str(path)
    try:
        text = files.read_text(path, "bvh")
    except MotionStyleError as e:
        raise BvhError(str(e)) from None
    head, sep, body = text.partition("MOTION")
    if not sep:
        raise BvhError(f"{path}: no MOTION section (not a BVH file, or truncated)")
    tok = _Tokens(head, path)
    tok.expect("HIERARCHY")
    if tok.next("ROOT") != "ROOT":
        raise BvhError(f"{path}: expected ROOT after HIERARCHY")

    names: list[str] = []
    parents: list[int] = []
    offsets: list[list[float]] = []
    channels: list[tuple[str, ...]] = []
    end_sites: dict[int, np.ndarray] = {}

    def joint(parent: int, depth: int) -> None:
        if depth > MAX_DEPTH:
            raise BvhError(f"{path}: joints nested over {MAX_DEPTH} deep (a body is under 30)")
        name = tok.next("joint name")
        j = len(names)
        names.append(name)
        parents.append(parent)
        tok.expect("{")
        tok.expect("OFFSET")
        offsets.append([tok.number(f"OFFSET of {name}") for _ in range(3)])
        tok.expect("CHANNELS")
        n = tok.number(f"CHANNELS count of {name}")
        if n not in (0, 3, 6):
            raise BvhError(f"{path}: joint {name!r} has {n:g} channels; 0, 3 or 6 are supported")
        chans = tuple(tok.next(f"channel of {name}") for _ in range(int(n)))
        for c in chans:
            if c not in _POSITION + _ROTATION:
                raise BvhError(f"{path}: joint {name!r} has unknown channel {c!r}")
        channels.append(chans)
        while True:
            w = tok.next(f"'}}' closing {name}")
            if w == "}":
                return
            if w == "JOINT":
                joint(j, depth + 1)
            elif w == "End":
                tok.expect("Site")
                tok.expect("{")
                tok.expect("OFFSET")
                end_sites[j] = np.array([tok.number(f"End Site of {name}") for _ in range(3)])
                tok.expect("}")
            else:
                raise BvhError(f"{path}: unexpected {w!r} inside joint {name!r}")

    joint(-1, 1)
    if tok.i != len(tok.words):
        raise BvhError(f"{path}: unexpected {tok.words[tok.i]!r} after the hierarchy (several ROOTs?)")
    for j, offset in [*enumerate(offsets), *end_sites.items()]:
        if not (np.abs(offset) <= MAX_VALUE).all():  # NaN too
            raise BvhError(f"{path}: joint {names[j]!r} has an OFFSET of {np.asarray(offset).tolist()} "
                           f"(beyond +-{MAX_VALUE:g}: a corrupt file)")

    mt = _Tokens(body, path)
    mt.expect("Frames:")
    n_frames = mt.number("frame count")
    mt.expect("Frame")
    mt.expect("Time:")
    frame_time = mt.number("frame time")
    if not (np.isfinite(n_frames) and n_frames >= 1 and n_frames == int(n_frames)):
        raise BvhError(f"{path}: has {n_frames:g} frames; a clip needs a whole number, at least one")
    if not (np.isfinite(frame_time) and frame_time >= MIN_FRAME_TIME):
        raise BvhError(f"{path}: frame time must be at least {MIN_FRAME_TIME:g} s, found {frame_time:g}")
    n_channels = sum(len(c) for c in channels)
    if not n_channels:
        raise BvhError(f"{path}: no joint has channels; a clip needs at least the root's")
    values = mt.words[mt.i :]
    expected = int(n_frames) * n_channels
    if len(values) != expected:
        found = len(values) / max(n_channels, 1)
        raise BvhError(
            f"{path}: header says {int(n_frames)} frames of {n_channels} channels, "
            f"but the file holds {found:.2f} frames ({'truncated' if len(values) < expected else 'extra values'})"
        )
    # Python and numpy also take '1_0' and other scripts' digits, which no BVH writer writes (and
    # check() refuses)
    if _NOT_NUMBER_OR_NAN.search("".join(values)):
        bad = next(v for v in values if _NOT_NUMBER_OR_NAN.search(v))
        raise BvhError(f"{path}: motion data holds a non-number {bad[:20]!r}")
    try:
        data = np.array(values, dtype=np.float64).reshape(int(n_frames), n_channels)
    except ValueError:  # '1.2.3', '+-1', 'e5'
        bad = next((v for v in values if not _is_number(v)), "")
        raise BvhError(f"{path}: motion data holds a non-number {bad[:20]!r}") from None
    bad = ~(np.abs(data) <= MAX_VALUE)  # NaN too
    if bad.any():
        f, c = np.argwhere(bad)[0]
        what = "non-finite value" if not np.isfinite(data[f, c]) else f"value {data[f, c]:g} (a corrupt file)"
        raise BvhError(f"{path}: {what} at frame {f}, channel {c}")

    # The pelvis carries the trajectory: the first joint whose position channels move (Bandai files
    # keep a static joint_Root above the Hips).
    pelvis, col = 0, 0
    for j, chans in enumerate(channels):
        pos = [col + i for i, c in enumerate(chans) if c in _POSITION]
        if pos and np.ptp(data[:, pos], axis=0).max() > 0:
            pelvis = j
            break
        col += len(chans)
    try:
        skeleton = Skeleton(tuple(names), tuple(parents), np.array(offsets), end_sites, pelvis=pelvis)
    except MotionStyleError as e:
        raise BvhError(f"{path}: {e}") from None
    return BvhClip(skeleton, tuple(channels), data, frame_time)


def _is_number(word: str) -> bool:
    try:
        float(word)
        return True
    except ValueError:
        return False


def write(path: str | Path, clip: BvhClip, precision: int | None = None) -> None:
    """Write ``clip``; numbers read from a file are written back exactly.

    Without ``precision`` each value is written as the shortest text that reads back to the same
    float; with it, motion data get that many decimals (smaller files for generated motion).
    """
    out = io.StringIO()
    sk = clip.skeleton
    out.write("HIERARCHY\n")

    def num(v: float) -> str:
        return repr(float(v)) if v != 0 else "0.0"

    def joint(j: int, depth: int) -> None:
        ind = "\t" * depth
        out.write(f"{ind}{'ROOT' if depth == 0 else 'JOINT'} {sk.names[j]}\n{ind}{{\n")
        out.write(f"{ind}\tOFFSET {' '.join(num(v) for v in sk.offsets[j])}\n")
        out.write(f"{ind}\tCHANNELS {len(clip.channels[j])} {' '.join(clip.channels[j])}\n")
        for c in sk.children(j):
            joint(c, depth + 1)
        if j in sk.end_sites:
            out.write(f"{ind}\tEnd Site\n{ind}\t{{\n")
            out.write(f"{ind}\t\tOFFSET {' '.join(num(v) for v in sk.end_sites[j])}\n{ind}\t}}\n")
        out.write(f"{ind}}}\n")

    joint(0, 0)
    out.write(f"MOTION\nFrames: {clip.n_frames}\nFrame Time: {clip.frame_time!r}\n")
    if precision is None:
        out.writelines(" ".join(map(repr, row)) + "\n" for row in clip.data.tolist())
    else:
        np.savetxt(out, clip.data, fmt=f"%.{precision}f", delimiter=" ")
    Path(path).write_text(out.getvalue(), encoding="utf-8")


def header(path: str | Path, joints: tuple[str, ...] | None = None) -> tuple[int, float]:
    """``(frames, frame time in s)`` of a file :func:`read` would take, found in one read without
    converting the numbers, or a one-line :class:`MotionStyleError` naming the first problem.

    For indexing thousands of files quickly, and for checking a file a user names before it is
    read; ``joints`` are the expected joint names in order (None: any). Checks the joint names, the
    frame count and time, non-numeric text (NaN, inf, garbage) and the number of values, in about
    0.2 ms per file; :func:`read` at load time re-checks everything.
    """
    data = files.read_bytes(path, "bvh")

    def refuse(problem: str) -> MotionStyleError:
        return MotionStyleError(f"{path}: {problem}")

    head, sep, body = data.partition(b"MOTION")
    if not sep or not head.lstrip().startswith(b"HIERARCHY"):
        raise refuse("not a BVH file (no HIERARCHY and MOTION sections), or truncated")
    if head.count(b"{") != head.count(b"}"):
        raise refuse("hierarchy braces do not match (malformed or truncated header)")
    names = tuple(n.decode(errors="replace") for n in re.findall(rb"\b(?:ROOT|JOINT)\s+(\S+)", head))
    if joints is not None and names != joints:
        raise refuse(f"joints {_first_difference(names, joints)}; not the expected {len(joints)}-joint skeleton")
    m = re.match(rb"\s*Frames:\s*([0-9+-]+)\s+Frame\s+Time:\s*(\S+)", body)
    try:
        frames, frame_time = int(m[1]), float(m[2])
    except (TypeError, ValueError):  # no match; not a number (or an int of over 4300 digits)
        raise refuse("no valid 'Frames:' and 'Frame Time:' after MOTION") from None
    if frames < 1:
        raise refuse(f"has {frames} frames; a clip needs at least one")
    if not (np.isfinite(frame_time) and frame_time >= MIN_FRAME_TIME):
        raise refuse(f"frame time must be at least {MIN_FRAME_TIME:g} s, found {frame_time:g}")
    values = body[m.end() :].strip()
    if values.translate(None, _NUMBER_BYTES):
        bad = re.search(rb"\S*[^0-9.+\-eE\s]\S*", values)[0].decode(errors="replace")
        raise refuse(f"motion data holds a non-number {bad[:20]!r}")
    counts = re.findall(rb"CHANNELS\s+(\d+)", head)
    if any(len(n) > 1 for n in counts):  # not 0, 3 or 6 (and an int of 4300 digits is a ValueError)
        raise refuse("a joint's CHANNELS count is not 0, 3 or 6")
    n_channels = sum(int(n) for n in counts)
    # One frame per line is how every writer lays BVH out: count lines, fall back to counting values.
    lines = values.count(b"\n") + 1 if values else 0
    if lines == frames and len(values[values.rfind(b"\n") + 1 :].split()) == n_channels:
        return frames, frame_time
    found = len(values.split()) / max(n_channels, 1)
    if found != frames:
        raise refuse(f"header says {frames} frames of {n_channels} channels, but the file holds {found:.2f} "
                     f"frames ({'truncated' if found < frames else 'extra values'})")
    return frames, frame_time


def check(path: Path, joints: tuple[str, ...] | None = None) -> str | None:
    """The first problem :func:`read` would report (:func:`header`), without the path; None if none."""
    try:
        header(path, joints)
    except MotionStyleError as e:
        return str(e).removeprefix(f"{path}: ")
    return None


def _first_difference(names: tuple[str, ...], expected: tuple[str, ...]) -> str:
    i = next((i for i, (a, b) in enumerate(zip(names, expected)) if a != b), min(len(names), len(expected)))
    found = repr(names[i]) if i < len(names) else "nothing"
    wanted = repr(expected[i]) if i < len(expected) else "nothing"
    return f"differ at joint {i}: {found} where {wanted} was expected"
