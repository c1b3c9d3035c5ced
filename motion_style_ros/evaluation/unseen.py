"""Stylizers on recordings they never saw: CMU and Xia neutral clips, other rigs and studios.

There is no ground truth for these, so the checks are the failure modes a live user would meet
first: NaN, joints that flip (a local rotation that turns further in one frame than any human
joint does), feet that start sliding (foot skating against the input's own), stretched bones.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np
from tqdm import tqdm

from motion_style_ros.core import rotations as rot
from motion_style_ros.core.conform import ground
from motion_style_ros.core.motion import Motion
from motion_style_ros.core.retarget import retarget
from motion_style_ros.core.skeleton import canonical
from motion_style_ros.evaluation import metrics
from motion_style_ros.io import datasets

Stylizer = Callable[[Motion, str], Motion]

# A local rotation turning further than this between two frames at 30 fps or more is a flip: the
# fastest human joints (a pitcher's elbow) stay under about 40 degrees per 1/30 s.
FLIP_DEGREES = 90.0


def neutral_clips(root: Path | None = None) -> list[tuple[str, Motion]]:
    """Every CMU clip (neutral performances, calibration T-pose dropped) and the Xia neutral clips,
    retargeted to the canonical skeleton, their planted ankles at the training data's height (the
    sessions conform their arm rolls)."""
    infos = datasets.index_cmu(root) + [i for i in datasets.index_xia(root) if i.style == "neutral"]
    stats = datasets.rotation_stats()
    clips = []
    for info in infos:
        motion = datasets.load_clip(info)
        motion = motion[1:] if info.dataset == "cmu" else motion
        canon = ground(retarget(motion, canonical()), stats)
        clips.append((f"{info.dataset} {info.name} ({info.content})", canon))
    return clips


def largest_joint_step(motion: Motion) -> float:
    """The largest angle (degrees) any joint's local rotation turns between consecutive frames."""
    q = motion.rotations
    return float(np.degrees(rot.angle_between(q[1:], q[:-1]).max())) if len(q) > 1 else 0.0


def check(source: Motion, output: Motion) -> dict:
    """The unseen-input checks of one output against its source."""
    finite = bool(np.isfinite(output.rotations).all() and np.isfinite(output.positions).all())
    step_in, step_out = largest_joint_step(source), largest_joint_step(output) if finite else None
    skate_in = metrics.foot_skating(source)
    skate_out = metrics.foot_skating(output) if finite else float("nan")
    return {
        "finite": finite,
        "largest_joint_step_input_deg": step_in,
        "largest_joint_step_deg": step_out,
        "flips": None if step_out is None else int(step_out > FLIP_DEGREES),
        "foot_skating_input": skate_in,
        "foot_skating": skate_out,
        "foot_skating_ratio": skate_out / skate_in if skate_in > 0 else None,
        "bone_length_error": metrics.bone_length_error(output, canonical()) if finite else None,
    }


def evaluate(stylize: Stylizer, styles: list[str], clips: list[tuple[str, Motion]],
             progress: bool = True) -> dict:
    """Every clip into every style; per-output rows and a summary."""
    rows = []
    for title, source in tqdm(clips, desc="unseen clips", disable=not progress):
        for style in styles:
            rows.append({"clip": title, "style": style, **check(source, stylize(source, style))})
    ratios = [r["foot_skating_ratio"] for r in rows if r["foot_skating_ratio"] is not None
              and np.isfinite(r["foot_skating_ratio"])]
    steps = [r["largest_joint_step_deg"] for r in rows if r["largest_joint_step_deg"] is not None]
    summary = {
        "clips": len(clips),
        "outputs": len(rows),
        "non_finite_outputs": sum(not r["finite"] for r in rows),
        "outputs_with_flips": sum(bool(r["flips"]) for r in rows),
        "largest_joint_step_deg": max(steps) if steps else None,
        "largest_joint_step_input_deg": max(r["largest_joint_step_input_deg"] for r in rows),
        "foot_skating_ratio_median": float(np.median(ratios)) if ratios else None,
        "foot_skating_ratio_max": float(np.max(ratios)) if ratios else None,
        "outputs_skating_over_1.5x": sum(r > 1.5 for r in ratios),
        "bone_length_error_max": max((r["bone_length_error"] for r in rows
                                      if r["bone_length_error"] is not None), default=None),
    }
    return {"summary": summary, "rows": rows}
