"""Files that must never be taken as a clip, and the reason each is refused with (shared by the node
tests of every backend that takes a reference clip)."""

import os

from motion_style_ros.core.synthetic import synthetic_motion
from motion_style_ros.io import bvh


def unusable_clips(folder, fps: float) -> list[tuple[str, str]]:
    """``(path, part of the reason)`` for each kind of file a ``reference`` set must refuse at once."""
    clip = bvh.BvhClip.from_motion(synthetic_motion("walk", fps, 4.0), scale=100.0)
    good = folder / "good.bvh"
    bvh.write(good, clip)
    text = good.read_bytes()
    truncated = folder / "truncated.bvh"
    truncated.write_bytes(text[: len(text) * 2 // 3])
    nan = folder / "nan.bvh"
    head, body = text.split(b"MOTION")
    lines = body.split(b"\n")
    lines[10] = b" ".join([b"nan"] + lines[10].split()[1:])
    nan.write_bytes(head + b"MOTION" + b"\n".join(lines))
    notes = folder / "notes.bvh"
    notes.write_text("not a motion\n")
    short = folder / "short.bvh"
    bvh.write(short, bvh.BvhClip.from_motion(synthetic_motion("walk", fps, 0.5), scale=100.0))
    fifo = folder / "fifo.bvh"
    os.mkfifo(fifo)
    sparse = folder / "sparse.bvh"
    with open(sparse, "wb") as f:
        f.truncate(2 * 2**30)
    return [(str(folder / "missing.bvh"), "cannot read"), (str(notes), "not a BVH file"),
            (str(truncated), "truncated"), (str(nan), "non-number 'nan'"), (str(short), "too short"),
            ("/dev/zero", "is a device"), (str(fifo), "is a FIFO"), (str(folder), "is a directory"),
            (str(sparse), "over the 256 MiB limit for a bvh")]


def unretargetable_clip(folder) -> str:
    """A well-formed BVH of one joint: it passes every check at once, and the worker that
    retargets it finds it is no humanoid."""
    path = folder / "one_joint.bvh"
    path.write_text("HIERARCHY\nROOT Hips\n{\nOFFSET 0 0 0\nCHANNELS 6 Xposition Yposition Zposition "
                    "Zrotation Xrotation Yrotation\nEnd Site\n{\nOFFSET 0 10 0\n}\n}\nMOTION\nFrames: 120\n"
                    "Frame Time: 0.0333333\n" + "0 90 0 0 0 0\n" * 120)
    return str(path)
