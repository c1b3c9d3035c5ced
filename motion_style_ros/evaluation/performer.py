"""The learned performer (an SAAE's prior decoded into endless motion, ``runtime.saae.Sampler``)
measured against real motion, per style:

- **seams**: the largest distance any joint moves between two frames of the stream, against the
  largest of every real Bandai test take of that dataset (a seam is a jump no real motion makes);
- **feet**: foot skating (m/s, ``metrics.foot_skating``) against the median of the real takes of
  the style;
- **style**: the stream cut into windows of ``WINDOW_SECONDS``, each judged by both judge panels:
  the share recognised as the chosen style.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from tqdm import tqdm

from motion_style_ros.core.motion import Motion
from motion_style_ros.evaluation import metrics
from motion_style_ros.evaluation.metrics import joint_jumps, largest_jump
from motion_style_ros.evaluation.judges import Judge

WINDOW_SECONDS = 4.0  # the stream is judged in windows this long


def windows(motion: Motion, seconds: float = WINDOW_SECONDS) -> list[Motion]:
    """``motion`` cut into consecutive clips of ``seconds`` (a shorter tail dropped)."""
    n = max(round(seconds * motion.fps), 2)
    return [motion[s : s + n] for s in range(0, motion.n_frames - n + 1, n)]


def evaluate(model: str | Path, real: list[tuple[str, Motion]], judges: list[Judge], minutes: float = 10.0,
             styles: list[str] | None = None, seed: int = 0, progress: bool = True) -> dict:
    """``minutes`` of stream per style (default: every style of the model) against the ``real``
    takes ``(style, motion)``; per style and overall."""
    from motion_style_ros.runtime.saae import Sampler

    sampler = Sampler(model, seed=seed)
    real_jump = max(largest_jump(m) for _, m in real)
    rows = {}
    for style in tqdm(styles or sampler.styles, desc="learned performer", disable=not progress):
        sampler.set_style(style)
        sampler.restart()
        stream = sampler.motion(60.0 * minutes)
        jumps = joint_jumps(stream)  # one FK of the whole stream
        skating = [metrics.foot_skating(m) for s, m in real if s == style]
        judged = [j.judge(windows(stream)) for j in judges]
        rows[style] = {
            "frames": stream.n_frames,
            "finite": bool(np.isfinite(jumps).all()),
            "largest_jump_m": float(jumps.max()),
            "seams_over_real": int((jumps > real_jump).sum()),
            "foot_skating": metrics.foot_skating(stream),
            "foot_skating_real_median": float(np.median(skating)) if skating else None,
            **{f"recognised_{k}": float(np.mean([label == style for label in j.labels]))
               for k, j in enumerate(judged, start=1)},
        }
    ratios = [r["foot_skating"] / r["foot_skating_real_median"] for r in rows.values()
              if r["foot_skating_real_median"]]
    overall = {
        "minutes_per_style": minutes,
        "window_seconds": WINDOW_SECONDS,
        "real_largest_jump_m": real_jump,
        "largest_jump_m": max(r["largest_jump_m"] for r in rows.values()),
        "seams_over_real": sum(r["seams_over_real"] for r in rows.values()),
        "all_finite": all(r["finite"] for r in rows.values()),
        **{f"recognised_{k}": float(np.mean([r[f"recognised_{k}"] for r in rows.values()]))
           for k in range(1, len(judges) + 1)},
        "foot_skating_ratio_median": float(np.median(ratios)) if ratios else None,
    }
    return {"summary": overall, "styles": rows}
