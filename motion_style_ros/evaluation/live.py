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
from motion_style_ros.core.features import facing_yaw
from motion_style_ros.core.motion import Motion
from motion_style_ros.core.retarget import retarget
from motion_style_ros.core.skeleton import canonical
from motion_style_ros.evaluation import metrics
from motion_style_ros.io import bvh, datasets

SETTLE_SECONDS = 1.0  # a stream's first second may be rough
SCALES = (0.8, 1.2)


def clip_paths(root: Path | None = None) -> list[Path]:
    """Every CMU and Xia clip in the datasets folder."""
    infos = datasets.index_cmu(root) + datasets.index_xia(root)
    return [Path(info.path) for info in infos]


def start_frame(path: Path) -> int:
    """The clip's first frame of motion: CMU files begin with a calibration T-pose at the origin,
    a couple of metres from where the motion starts (no rig streams that)."""
    return 1 if "cmu" in Path(path).parts else 0


def live_input(path: Path) -> Motion:
    """A clip as the ``bvh_player`` streams it (from :func:`start_frame`): retargeted to the
    canonical skeleton, nothing more."""
    source = bvh.read(path).to_motion().check_finite(str(path))
    return retarget(source, canonical())[start_frame(path):]


def hands_up(motion: Motion) -> float:
    """The fraction of frames with a hand above its shoulder."""
    sk = motion.skeleton
    g = motion.global_positions()
    hands = [sk.index(f"Hand_{s}") for s in "LR"]
    shoulders = [sk.index(f"UpperArm_{s}") for s in "LR"]
    return float((g[:, hands, 1] > g[:, shoulders, 1]).any(axis=1).mean()) if len(g) else float("nan")


def compare(live: Motion, offline: Motion, settle_seconds: float = SETTLE_SECONDS) -> dict:
    """Live against offline output, frame for frame, from ``settle_seconds`` on. The pose: mean
    joint distance (cm) in each frame's own pelvis-centred, facing-aligned frame, and mean local
    rotation difference (degrees; every joint but the static root, the pelvis's without its
    heading); the trajectory apart: mean heading difference (degrees) and root distance (cm); and
    the fraction of frames with a hand above its shoulder in each."""
    n = min(live.n_frames, offline.n_frames)
    start = int(round(settle_seconds * live.fps))
    if n <= start:
        return {"frames": 0}
    sk = live.skeleton
    posed, headings = [], []
    for m in (live[start:n], offline[start:n]):
        g = m.global_positions()
        yaw = facing_yaw(g, sk)
        unturn = rot.from_yaw(-yaw)
        rel = rot.rotate(unturn[:, None], g - g[:, sk.pelvis:sk.pelvis + 1])
        q = m.rotations.copy()
        q[:, sk.pelvis] = rot.multiply(unturn, q[:, sk.pelvis])
        posed.append((rel, q, m.root_positions))
        headings.append(yaw)
    (rel_a, q_a, root_a), (rel_b, q_b, root_b) = posed
    joints = [j for j in range(sk.n_joints) if j != sk.pelvis and sk.parents[j] >= 0]
    return {
        "frames": n - start,
        "joint_distance_cm": float(100.0 * rot.norm(rel_a - rel_b)[:, joints].mean()),
        "rotation_deg": float(np.degrees(rot.angle_between(q_a[:, 1:], q_b[:, 1:])).mean()),
        "heading_deg": float(np.degrees(np.abs(np.angle(np.exp(1j * (headings[0] - headings[1]))))).mean()),
        "root_distance_cm": float(100.0 * rot.norm(root_a - root_b).mean()),
        "hands_up_live": hands_up(live[start:n]),
        "hands_up_offline": hands_up(offline[start:n]),
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
    the performer's own skeleton, divided by the scale (m/s at canonical size), over the whole
    stream and after its first second (clips of at least two seconds)."""
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
        canonical_size = Motion.from_rotations(out.skeleton, out.rotations, out.root_positions / scale,
                                               out.fps)
        recognised = judge.judge([canonical_size]).labels[0] == style
        performer = on_performer(out, scale)
        settled = performer[int(round(SETTLE_SECONDS * clip.fps)):]
        skating = metrics.foot_skating(performer) / scale
        late = metrics.foot_skating(settled) / scale if settled.n_frames >= clip.fps else float("nan")
        results[scale].append((recognised, skating, late))
    for scale, values in results.items():
        recognised, skating, late = zip(*values)
        rows[f"{scale:g}"] = {"outputs": len(values), "style_accuracy": float(np.mean(recognised)),
                              "foot_skating_median": float(np.nanmedian(skating)),
                              "foot_skating_median_after_1s": float(np.nanmedian(late))}
    base = rows["1"]
    for row in rows.values():
        row["style_accuracy_points_vs_1"] = 100.0 * (row["style_accuracy"] - base["style_accuracy"])
        row["foot_skating_vs_1"] = row["foot_skating_median"] / base["foot_skating_median"]
        row["foot_skating_after_1s_vs_1"] = (row["foot_skating_median_after_1s"]
                                             / base["foot_skating_median_after_1s"])
    return rows
