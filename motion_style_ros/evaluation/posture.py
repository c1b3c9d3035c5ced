"""Does a stylized performer keep their stature? Knee and hip flexion, feet on the floor.

A style judge's score can rise while a person sees a crouch, so the posture of the legs is
measured beside it: the knee's flexion (the angle between thigh and shank, 0 = straight) and the
hip's (the angle between thigh and the trunk's downward axis, chest to pelvis, 0 = standing), each
as a mean and a 10th percentile over both legs and every frame. An output into the neutral style
should keep the input's; an output into another style may move as far as that style moves real
performers, which :func:`style_shifts` measures on the Bandai test takes (each style's mean
against ``normal``'s, content by content). The floor check is how far the output's planted ankles
rest from the input's (:func:`~motion_style_ros.core.conform.planted_ankle_height`).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np

from motion_style_ros.core.conform import planted_ankle_height
from motion_style_ros.core.motion import Motion
from motion_style_ros.evaluation import metrics

ANGLES = ("knee", "hip")
STATS = ("mean", "p10")
SLACK_DEGREES = 5.0  # how far an output's posture may sit beyond what the acceptance allows
NEUTRAL = "normal"


def leg_angles(motion: Motion) -> dict[str, np.ndarray]:
    """Knee and hip flexion in degrees, ``(T * 2,)`` each (left leg's frames, then right's)."""
    sk, g = motion.skeleton, motion.global_positions()
    down = g[:, sk.pelvis] - g[:, sk.index("Chest")]
    angles: dict[str, list[np.ndarray]] = {"knee": [], "hip": []}
    for side in "LR":
        hip, knee, ankle = (g[:, sk.index(f"{name}_{side}")] for name in ("UpperLeg", "LowerLeg", "Foot"))
        angles["knee"].append(_angle(knee - hip, ankle - knee))
        angles["hip"].append(_angle(down, knee - hip))
    return {k: np.concatenate(v) for k, v in angles.items()}


def posture(motion: Motion) -> dict[str, float]:
    """``knee_mean``, ``knee_p10``, ``hip_mean``, ``hip_p10`` (degrees)."""
    out = {}
    for name, values in leg_angles(motion).items():
        out[f"{name}_mean"] = float(values.mean())
        out[f"{name}_p10"] = float(np.percentile(values, 10))
    return out


def compare(source: Motion, output: Motion) -> dict[str, float]:
    """One output against its source: each posture figure's shift (output minus input, degrees),
    the floor's offset (cm) and the foot skating ratio."""
    before, after = posture(source), posture(output)
    skate_in = metrics.foot_skating(source)
    row = {f"{k}_shift": after[k] - before[k] for k in before}
    row["floor_offset_cm"] = 100.0 * (planted_ankle_height(output) - planted_ankle_height(source))
    row["foot_skating_ratio"] = metrics.foot_skating(output) / skate_in if skate_in > 0 else float("nan")
    return row


def style_shifts(clips: Sequence[tuple[object, Motion]]) -> dict[str, dict[str, float]]:
    """Per style, how far its real takes' posture sits from ``normal``'s: the mean over contents
    of (the style's mean figure - normal's) for every content both have. ``clips``: (info with
    ``content`` and ``style``, motion) pairs, e.g. the Bandai test takes."""
    cells: dict[tuple[str, str], list[dict[str, float]]] = {}
    for info, motion in clips:
        cells.setdefault((info.content, info.style), []).append(posture(motion))
    mean = {cell: {k: float(np.mean([p[k] for p in rows])) for k in rows[0]} for cell, rows in cells.items()}
    shifts: dict[str, dict[str, float]] = {}
    for style in sorted({s for _, s in mean}):
        contents = [c for c, s in mean if s == style and (c, NEUTRAL) in mean]
        if contents:
            shifts[style] = {k: float(np.mean([mean[(c, style)][k] - mean[(c, NEUTRAL)][k] for c in contents]))
                             for k in mean[(contents[0], style)]}
    return shifts


def evaluate(stylize: Callable[[Motion, str], Motion], styles: Sequence[str],
             clips: Sequence[tuple[str, Motion]], shifts: dict[str, dict[str, float]]) -> dict:
    """Every clip into every style: per-output rows, and per style the mean shifts, the allowed
    shift (the real takes' for that style, 0 for ``normal``, plus :data:`SLACK_DEGREES` either
    way) and whether each figure keeps within it, with the feet's figures."""
    rows = []
    for title, source in clips:
        for style in styles:
            rows.append({"clip": title, "style": style, **compare(source, stylize(source, style))})
    per_style = {}
    for style in styles:
        mine = [r for r in rows if r["style"] == style]
        entry: dict[str, float | bool] = {}
        for angle in ANGLES:
            for stat in STATS:
                key = f"{angle}_{stat}"
                shift = float(np.mean([r[f"{key}_shift"] for r in mine]))
                real = allowed(style, key, shifts)
                entry[f"{key}_shift"] = shift
                entry[f"{key}_allowed"] = real
                entry[f"{key}_ok"] = within(shift, real)
        ratios = np.array([r["foot_skating_ratio"] for r in mine], dtype=float)
        ratios = ratios[np.isfinite(ratios)]
        entry["foot_skating_ratio_median"] = float(np.median(ratios)) if len(ratios) else float("nan")
        entry["outputs_skating_over_1.5x"] = float(np.mean(ratios > 1.5)) if len(ratios) else float("nan")
        entry["floor_offset_cm_max"] = float(np.max(np.abs([r["floor_offset_cm"] for r in mine])))
        per_style[style] = entry
    return {"per_style": per_style, "rows": rows}


def format_table(name: str, report: dict) -> str:
    """One line per style: each figure's shift from the input against what is allowed (deg), the
    feet's figures; a ``*`` marks a figure beyond its allowance."""
    head = (f"{name}: shift from the input, degrees (allowed: the real takes' shift from normal "
            f"+- {SLACK_DEGREES:g}; * beyond it)")
    cols = [f"{a} {s}" for a in ANGLES for s in STATS]
    lines = [head, f"  {'style':<11}" + "".join(f"{c:>18}" for c in cols)
             + f"{'skate med':>11}{'>1.5x':>8}{'floor cm':>10}"]
    for style, e in report["per_style"].items():
        cells = "".join(
            f"{e[f'{a}_{s}_shift']:>+8.1f} ({e[f'{a}_{s}_allowed']:>+5.1f}){' ' if e[f'{a}_{s}_ok'] else '*'} "
            for a in ANGLES for s in STATS)
        lines.append(f"  {style:<11}{cells}{e['foot_skating_ratio_median']:>11.2f}"
                     f"{e['outputs_skating_over_1.5x']:>8.0%}{e['floor_offset_cm_max']:>10.1f}")
    return "\n".join(lines)


def allowed(style: str, key: str, shifts: dict[str, dict[str, float]]) -> float:
    """How far ``style`` moves real performers' figure ``key`` from ``normal``'s (0 for ``normal``
    and for a style ``shifts`` lacks)."""
    return 0.0 if style == NEUTRAL else shifts.get(style, {}).get(key, 0.0)


def within(shift: float, real: float, slack: float = SLACK_DEGREES) -> bool:
    """A shift is within a real style's shift ``real`` and ``slack`` degrees: no further from 0
    than that style moves real performers, in either direction."""
    return bool(min(0.0, real) - slack <= shift <= max(0.0, real) + slack)


def keeps(source: dict[str, float], output: Motion, style: str, shifts: dict[str, dict[str, float]],
          slack: float) -> bool:
    """Does ``output``, ``source`` (its input's :func:`posture`) into ``style``, keep every posture
    figure within what the style allows (:func:`allowed`) and ``slack``?"""
    after = posture(output)
    return all(within(after[k] - source[k], allowed(style, k, shifts), slack) for k in source)


def _angle(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Degrees between rows of vectors ``(..., 3)``."""
    cos = (a * b).sum(-1) / np.maximum(np.linalg.norm(a, axis=-1) * np.linalg.norm(b, axis=-1), 1e-12)
    return np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))
