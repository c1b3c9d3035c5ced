"""``motion-style demo``: what the foundation does, on real recordings, in under a minute.

Reads an unseen CMU walk and a Xia walk (other capture setups and skeletons), retargets both onto
the canonical skeleton, asks the shipped judges what they see, and renders the source, the
retargeted motion and a real Bandai walk in the "elderly" style side by side. The live ROS demo
(synthetic performer -> stylizer node) replaces this once the stylizer lands.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path


def add_parser(subparsers) -> None:
    p = subparsers.add_parser(
        "demo",
        help="run the built-in demo",
        description="Retarget unseen CMU/Xia recordings to the canonical skeleton, judge their "
        "style and content, and render them beside a real stylized Bandai walk.",
    )
    p.add_argument("--out", type=Path, default=Path("out/demo"), help="output folder (default: out/demo)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from motion_style_ros.core.retarget import bone_direction_errors, retarget
    from motion_style_ros.core.skeleton import canonical
    from motion_style_ros.evaluation.judges import Judge
    from motion_style_ros.io import datasets
    from motion_style_ros.io.render import render_gif, render_png

    start = time.perf_counter()
    root = datasets.datasets_root()
    cmu = next(i for i in datasets.index_cmu(root) if i.name == "02_01")
    xia = next(i for i in datasets.index_xia(root) if i.name == "strutting_01_000")
    elderly = next(
        i for i in datasets.index_bandai(root, datasets=(2,))
        if i.split == "test" and i.content == "walk" and i.style == "elderly"
    )
    style, content = Judge("style"), Judge("content")

    sources = {
        "CMU 02_01 walk": datasets.load_clip(cmu)[1:],  # frame 0 is the calibration T-pose
        "Xia strutting walk": datasets.load_clip(xia),
    }
    print(f"{'clip':22s} {'frames':>6s} {'fps':>4s} {'bone dir. err. mean/max':>24s}  judged as")
    rows = []
    for title, motion in sources.items():
        canon = retarget(motion, canonical())
        _, err = bone_direction_errors(motion, canon)
        s, c = style.judge([canon]), content.judge([canon])
        print(
            f"{title:22s} {motion.n_frames:6d} {motion.fps:4.0f} {err.mean():10.2f} / {err.max():6.2f} deg"
            f"   {c.labels[0]} ({c.probabilities.max():.0%}), style {s.labels[0]} ({s.probabilities.max():.0%})"
        )
        rows.append((title, motion, canon))
    real = datasets.load_clip(elderly)
    s = style.judge([real])
    print(f"{'Bandai ' + elderly.name:22s} {real.n_frames:6d} {real.fps:4.0f} {'(canonical)':>24s}   "
          f"style {s.labels[0]} ({s.probabilities.max():.0%})")

    args.out.mkdir(parents=True, exist_ok=True)
    title, motion, canon = rows[0]
    motions = [motion, canon, real]
    titles = [title, "retargeted (canonical)", "real Bandai walk, elderly"]
    render_png(motions, titles, args.out / "demo.png")
    render_gif(motions, titles, args.out / "demo.gif", seconds=4.0)
    print(f"wrote {args.out / 'demo.png'} and {args.out / 'demo.gif'} in {time.perf_counter() - start:.1f} s")
    return 0
