"""Live streams against whole clips: what a stylizer makes of a clip streamed as a live rig sends
it, beside what ``motion-style stylize`` makes of the same clip.

A live rig sends its own joint frames (retargeted onto the canonical names, not conformed) and its
own proportions, and the session has to condition the stream from the stream itself
(:class:`~motion_style_ros.core.conform.StreamRolls`,
:class:`~motion_style_ros.core.proportions.StreamScale`, grounding). Offline, the same session
conditions the whole clip at once. After a stream's first second the two should agree:
:func:`compare` measures by how much. :func:`proportions` streams the same clips as performers of
other sizes would send them and judges the outputs.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np

from motion_style_ros.core import rotations as rot
from motion_style_ros.core.motion import Motion
from motion_style_ros.core.retarget import retarget
from motion_style_ros.core.skeleton import canonical
from motion_style_ros.evaluation import metrics
from motion_style_ros.io import bvh, datasets

SETTLE_SECONDS = 1.0  # a stream's first second may be rough
STYLES = ("elderly", "youthful", "normal")
SCALES = (0.8, 1.2)


def clip_paths(root: Path | None = None) -> list[Path]:
    """Every CMU and Xia clip in the datasets folder."""
    infos = datasets.index_cmu(root) + datasets.index_xia(root)
    return [Path(info.path) for info in infos]


def live_input(path: Path) -> Motion:
    """A clip as the ``bvh_player`` streams it: retargeted to the canonical skeleton, nothing more."""
    source = bvh.read(path).to_motion().check_finite(str(path))
    return retarget(source, canonical())


def hands_up(motion: Motion) -> float:
    """The fraction of frames with a hand above its shoulder."""
    sk = motion.skeleton
    g = motion.global_positions()
    hands = [sk.index(f"Hand_{s}") for s in "LR"]
    shoulders = [sk.index(f"UpperArm_{s}") for s in "LR"]
    return float((g[:, hands, 1] > g[:, shoulders, 1]).any(axis=1).mean()) if len(g) else float("nan")


def compare(live: Motion, offline: Motion, settle_seconds: float = SETTLE_SECONDS) -> dict:
    """Live against offline output, frame for frame, from ``settle_seconds`` on: mean
    pelvis-relative joint distance (cm), mean local rotation difference (degrees, every joint but
    the static root), and the fraction of frames with a hand above its shoulder in each."""
    n = min(live.n_frames, offline.n_frames)
    start = int(round(settle_seconds * live.fps))
    if n <= start:
        return {"frames": 0}
    a, b = live[start:n], offline[start:n]
    pelvis = live.skeleton.pelvis
    ga, gb = a.global_positions(), b.global_positions()
    rel_a, rel_b = ga - ga[:, pelvis:pelvis + 1], gb - gb[:, pelvis:pelvis + 1]
    joints = [j for j in range(live.skeleton.n_joints) if j != pelvis and live.skeleton.parents[j] >= 0]
    return {
        "frames": n - start,
        "joint_distance_cm": float(100.0 * rot.norm(rel_a - rel_b)[:, joints].mean()),
        "rotation_deg": float(np.degrees(rot.angle_between(a.rotations[:, 1:], b.rotations[:, 1:])).mean()),
        "hands_up_live": hands_up(a),
        "hands_up_offline": hands_up(b),
    }


def stream(session, motion: Motion, style: str) -> Motion:
    """``motion`` through ``session.step`` frame by frame, as a live node streams it (the session
    conditions the stream as it goes; no whole-clip calibration)."""
    session.reset(recalibrate=True)
    session.restart()
    session.set_style(style)
    roots = motion.root_positions
    frames = [session.step(motion.rotations[t], roots[t], t / motion.fps) for t in range(motion.n_frames)]
    return Motion.from_rotations(motion.skeleton, np.stack([q for q, _ in frames]),
                                 np.stack([p for _, p in frames]), motion.fps)


def scaled(motion: Motion, scale: float) -> Motion:
    """``motion`` as a performer ``scale`` times the canonical size streams it: the same rotations,
    the root ``scale`` times as far from the origin and as high."""
    return Motion.from_rotations(motion.skeleton, motion.rotations, motion.root_positions * scale, motion.fps)


def on_performer(motion: Motion, scale: float) -> Motion:
    """A stream's output on the performer's own skeleton (every bone ``scale`` times as long)."""
    skeleton = replace(motion.skeleton, offsets=motion.skeleton.offsets * scale)
    return Motion.from_rotations(skeleton, motion.rotations, motion.root_positions, motion.fps)


def proportions(make_session, clips: list[Motion], styles: list[str], judge,
                scales: tuple[float, ...] = SCALES, progress: bool = True) -> dict:
    """Each clip streamed as performers of ``scales`` (and 1) send it, into every style: the style
    judge's accuracy (on the output brought back to canonical size) and the median foot skating on
    the performer's own skeleton, divided by the scale (m/s at canonical size)."""
    from tqdm import tqdm

    rows = {}
    fps_sessions: dict[float, object] = {}
    todo = [(s, c, st) for s in (1.0, *scales) for c in range(len(clips)) for st in styles]
    results: dict[float, list[tuple[bool, float]]] = {s: [] for s in (1.0, *scales)}
    for scale, c, style in tqdm(todo, disable=not progress, desc="proportions", unit="stream"):
        clip = clips[c]
        if clip.fps not in fps_sessions:
            fps_sessions[clip.fps] = make_session(clip.fps)
        out = stream(fps_sessions[clip.fps], scaled(clip, scale), style)
        canonical_size = Motion.from_rotations(out.skeleton, out.rotations, out.root_positions / scale, out.fps)
        recognised = judge.judge([canonical_size]).labels[0] == style
        skating = metrics.foot_skating(on_performer(out, scale)) / scale
        results[scale].append((recognised, skating))
    for scale, values in results.items():
        recognised, skating = zip(*values)
        rows[f"{scale:g}"] = {"outputs": len(values), "style_accuracy": float(np.mean(recognised)),
                              "foot_skating_median": float(np.nanmedian(skating))}
    base = rows["1"]
    for row in rows.values():
        row["style_accuracy_points_vs_1"] = 100.0 * (row["style_accuracy"] - base["style_accuracy"])
        row["foot_skating_vs_1"] = row["foot_skating_median"] / base["foot_skating_median"]
    return rows
