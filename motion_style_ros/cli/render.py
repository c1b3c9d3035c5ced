"""``motion-style render``: stick-figure pictures (PNG strip) or animations (GIF) of BVH clips."""


def add_parser(subparsers):
    p = subparsers.add_parser(
        "render", help="draw BVH clips side by side as a PNG strip or a GIF",
        description="Draw one or more BVH clips as stick figures side by side: a PNG with a row of "
                    "poses per clip, or an animated GIF. With --retarget each clip is shown next "
                    "to its retargeted canonical version.",
    )
    p.add_argument("inputs", nargs="+", metavar="IN.bvh", help="clips to draw")
    p.add_argument("-o", "--output", required=True, metavar="OUT.png|OUT.gif",
                   help="picture to write; the suffix picks PNG strip or GIF animation")
    p.add_argument("--retarget", action="store_true",
                   help="also draw each clip retargeted to the canonical skeleton")
    p.add_argument("--frames", type=int, default=6, help="poses per clip in a PNG (default: 6)")
    p.add_argument("--fps", type=float, default=15.0, help="GIF frame rate (default: 15)")
    p.add_argument("--seconds", type=float, help="GIF length (default: the longest clip)")
    p.set_defaults(func=run)


def run(args) -> int:
    from pathlib import Path

    from motion_style_ros.core import skeleton
    from motion_style_ros.core.retarget import Retargeter, find_map
    from motion_style_ros.errors import MotionStyleError
    from motion_style_ros.io import bvh, render

    suffix = Path(args.output).suffix.lower()
    if suffix not in (".png", ".gif"):
        raise MotionStyleError(f"{args.output}: output must end in .png or .gif")
    motions, titles = [], []
    for path in args.inputs:
        motion = bvh.read(path).to_motion()
        motions.append(motion)
        titles.append(Path(path).stem)
        if args.retarget:
            target = skeleton.canonical()
            motions.append(Retargeter(motion.skeleton, target, find_map(motion.skeleton, path))(motion))
            titles.append(f"{Path(path).stem} -> canonical")
    if suffix == ".png":
        render.render_png(motions, titles, args.output, frames=args.frames)
    else:
        render.render_gif(motions, titles, args.output, fps=args.fps, seconds=args.seconds)
    print(f"wrote {args.output}")
    return 0
