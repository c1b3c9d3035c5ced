"""Stylizers on recordings they never saw: CMU and Xia neutral clips, other rigs and studios.

There is no ground truth for these, so the checks are whether the style arrives (both judge
panels: is the target recognised, and is its probability higher than on the input) and the failure
modes a live user would meet first: NaN, joints that flip (a local rotation that turns further in
one frame than any human joint does), feet that start sliding (foot skating against the input's
own), stretched bones, and jerk against the input's at each input rate (30, 60 and the clips' own
120 Hz: the output between model frames must stay smooth).
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np
from tqdm import tqdm

from motion_style_ros.core import rotations as rot
from motion_style_ros.core.conform import ground
from motion_style_ros.core.motion import Motion
from motion_style_ros.core.resample import resample
from motion_style_ros.core.retarget import retarget
from motion_style_ros.core.skeleton import canonical
from motion_style_ros.evaluation import metrics
from motion_style_ros.evaluation.judges import Judge
from motion_style_ros.io import datasets
from motion_style_ros.io.resources import rotation_stats

Stylizer = Callable[[Motion, str], Motion]

# A local rotation turning further than this between two frames at 30 fps or more is a flip: the
# fastest human joints (a pitcher's elbow) stay under about 40 degrees per 1/30 s.
FLIP_DEGREES = 90.0


def neutral_clips(root: Path | None = None, leave_out: tuple[str, ...] = ()) -> list[tuple[str, Motion]]:
    """Every CMU clip (neutral performances) and the Xia neutral clips (:func:`canonical_unseen`),
    titled ``"cmu 02_01 (walk)"``. ``leave_out``: clips a model trained on (its card's
    ``training.clips.unlabelled``, named by :func:`clip_name`)."""
    infos = datasets.index_cmu(root) + [i for i in datasets.index_xia(root) if i.style == "neutral"]
    stats = rotation_stats()
    return [(f"{clip_name(info)} ({info.content})", canonical_unseen(info, stats))
            for info in infos if clip_name(info) not in leave_out]


def clip_name(info: datasets.ClipInfo) -> str:
    """How cards and reports name a CMU or Xia clip: ``"cmu 02_01"``."""
    return f"{info.dataset} {info.name}"


def canonical_unseen(info: datasets.ClipInfo, stats: dict[str, np.ndarray]) -> Motion:
    """A CMU or Xia clip on the canonical skeleton (a CMU file's calibration T-pose dropped), its
    planted ankles at the training data's height (the sessions conform its arm rolls)."""
    motion = datasets.load_clip(info)
    motion = motion[1:] if info.dataset == "cmu" else motion
    return ground(retarget(motion, canonical()), stats)


def capture_setup(title: str) -> str:
    """The capture setup of a clip titled by :func:`neutral_clips`: ``"cmu 02"`` (a CMU subject)
    or ``"xia"``."""
    dataset, name = title.split()[:2]
    return f"{dataset} {name.split('_')[0]}" if dataset == "cmu" else dataset


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


def offered_columns(judges: list[Judge], styles: list[str]) -> list[list[int]]:
    """Per judge, its columns of ``styles`` (the ones it knows): what a stylizer's user can ask for."""
    return [[judge.labels.index(s) for s in styles if s in judge.labels] for judge in judges]


def _recognition(judges: list[Judge], source: np.ndarray, output: Motion, style: str,
                 offered: list[list[int]]) -> dict:
    """Per judge panel: the judged style of ``output``, whether it is the target (among every
    style the judge knows, and among the stylizer's styles only, the judge's columns ``offered``:
    the choice its user has), and how much the target's probability rose from the source's
    (``source``: its probabilities per judge)."""
    row = {}
    for k, (judge, before, offered) in enumerate(zip(judges, source, offered), start=1):
        if style not in judge.labels:
            continue
        column = judge.labels.index(style)
        result = judge.judge([output])
        row[f"judged_style_{k}"] = result.labels[0]
        row[f"recognised_{k}"] = result.labels[0] == style
        row[f"recognised_{k}_among_styles"] = bool(offered[result.probabilities[0, offered].argmax()] == column)
        row[f"target_gain_{k}"] = float(result.probabilities[0, column] - before[column])
    return row


def evaluate(stylize: Stylizer, styles: list[str], clips: list[tuple[str, Motion]],
             judges: list[Judge] | None = None, rates: tuple[float, ...] = (30.0, 60.0),
             rate_styles: int = 3, progress: bool = True) -> dict:
    """Every clip into every style (at the clips' own rate); per-output rows and a summary. Each
    clip also goes into ``rate_styles`` of the styles (spread over the list) at each of ``rates``
    for the jerk ratio there."""
    judges = judges or []
    rows, jerks = [], {}
    offered = offered_columns(judges, styles)
    spread = [styles[round(i * (len(styles) - 1) / max(rate_styles - 1, 1))] for i in range(rate_styles)]
    for title, source in tqdm(clips, desc="unseen clips", disable=not progress):
        before = [judge.judge([source]).probabilities[0] for judge in judges]
        for style in styles:
            output = stylize(source, style)
            row = {"clip": title, "style": style, **check(source, output)}
            if row["finite"]:
                row.update(_recognition(judges, before, output, style, offered))
                row["jerk_ratio"] = metrics.jerk(output) / metrics.jerk(source)
                jerks.setdefault(float(source.fps), []).append(row["jerk_ratio"])
            rows.append(row)
        for rate in rates:
            low = resample(source, rate)
            for style in dict.fromkeys(spread):
                out = stylize(low, style)
                if np.isfinite(out.positions).all():
                    jerks.setdefault(float(rate), []).append(metrics.jerk(out) / metrics.jerk(low))
    ratios = [r["foot_skating_ratio"] for r in rows if r["foot_skating_ratio"] is not None
              and np.isfinite(r["foot_skating_ratio"])]
    steps = [r["largest_joint_step_deg"] for r in rows if r["largest_joint_step_deg"] is not None]
    summary = {
        "clips": len(clips),
        "outputs": len(rows),
        "non_finite_outputs": sum(not r["finite"] for r in rows),
        "outputs_with_flips": sum(bool(r["flips"]) for r in rows),
    }
    for k in range(1, len(judges) + 1):
        judged = [r for r in rows if f"recognised_{k}" in r]
        if judged:
            summary[f"style_recognised_{k}"] = float(np.mean([r[f"recognised_{k}"] for r in judged]))
            summary[f"style_recognised_{k}_among_styles"] = float(
                np.mean([r[f"recognised_{k}_among_styles"] for r in judged]))
            summary[f"target_raised_{k}"] = float(np.mean([r[f"target_gain_{k}"] > 0 for r in judged]))
            summary[f"target_gain_median_{k}"] = float(np.median([r[f"target_gain_{k}"] for r in judged]))
            groups = sorted({capture_setup(r["clip"]) for r in judged})
            summary[f"style_recognised_{k}_by_source"] = {
                g: float(np.mean([r[f"recognised_{k}"] for r in judged if capture_setup(r["clip"]) == g])) for g in groups}
    summary.update({
        "largest_joint_step_deg": max(steps) if steps else None,
        "largest_joint_step_input_deg": max(r["largest_joint_step_input_deg"] for r in rows),
        "foot_skating_ratio_median": float(np.median(ratios)) if ratios else None,
        "foot_skating_ratio_max": float(np.max(ratios)) if ratios else None,
        "outputs_skating_over_1.5x": sum(r > 1.5 for r in ratios),
        "bone_length_error_max": max((r["bone_length_error"] for r in rows
                                      if r["bone_length_error"] is not None), default=None),
        **{f"jerk_ratio_median_{rate:g}hz": float(np.median(v)) for rate, v in sorted(jerks.items()) if v},
    })
    return {"summary": summary, "rows": rows, "rate_styles": list(dict.fromkeys(spread))}
