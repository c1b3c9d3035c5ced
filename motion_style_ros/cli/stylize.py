"""``motion-style stylize``: restyle a BVH clip offline, through the same streaming session a node runs."""

from __future__ import annotations

import argparse

from motion_style_ros.runtime.backends import BACKENDS
from motion_style_ros.runtime.defaults import DEFAULTS


def add_parser(subparsers) -> None:
    p = subparsers.add_parser(
        "stylize", help="restyle a BVH clip into one or more styles",
        description="Read a humanoid BVH clip (canonical Bandai/Unity names, CMU or Unity "
                    "HumanBodyBones; retargeted to the canonical skeleton when needed, its joint "
                    "frames turned to the training data's conventions), stream it "
                    "frame by frame through a stylizer as the ROS node would, and write the "
                    "stylized clip as a canonical-skeleton BVH (centimetres). With several "
                    "--style, OUT gets the style name appended.",
    )
    p.add_argument("input", metavar="IN.bvh", help="source clip")
    p.add_argument("-o", "--output", required=True, metavar="OUT.bvh", help="stylized clip to write")
    p.add_argument("--style", action="append", default=None,
                   help="target style (repeat for several); see the model card's 'styles'")
    p.add_argument("--reference", metavar="CLIP.bvh", default=None,
                   help="stgcn, most, saae backends: move like this clip (its style read by the "
                        "backend's style encoder; the target style is the one the clip is "
                        "recognised as, unless --style names it)")
    p.add_argument("--seed", type=int, default=0,
                   help="stgcn backend: latent seed of the style codes (default: 0)")
    p.add_argument("--seed-spread", type=float, default=DEFAULTS["seed_spread"], metavar="S",
                   help="stgcn backend: how much seeds differ, 0 to 4 (default: 1, as trained)")
    p.add_argument("--alpha", type=float, default=DEFAULTS["alpha"],
                   help=f"style strength in [0, 1] (default: {DEFAULTS['alpha']:g})")
    p.add_argument("--backend", default="recurrent", choices=tuple(BACKENDS),
                   help="stylizer backend (default: recurrent)")
    p.add_argument("--model", default=None, help="model file (default: the backend's shipped model)")
    p.add_argument("--render", metavar="OUT.png|OUT.gif", default=None,
                   help="also draw the input beside every output")
    p.add_argument("--threads", type=int, default=1, help="ONNX Runtime threads (default: 1)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from pathlib import Path

    from motion_style_ros.errors import MotionStyleError
    from motion_style_ros.io import bvh, render
    from motion_style_ros.io.canonical import canonical_clip
    from motion_style_ros.runtime.backends import backend, with_feature
    from motion_style_ros.runtime.offline import with_reference

    if args.render and Path(args.render).suffix.lower() not in (".png", ".gif"):
        raise MotionStyleError(f"{args.render}: --render must end in .png or .gif")
    spec = backend(args.backend)
    if args.reference and not spec.reference_clips:
        raise MotionStyleError(f"--reference needs --backend {' or '.join(with_feature('reference_clips'))} "
                               f"(the {args.backend} backend takes no reference clip)")
    if not spec.latent_seeds and (args.seed or args.seed_spread != DEFAULTS["seed_spread"]):
        raise MotionStyleError(f"--seed and --seed-spread need --backend {' or '.join(with_feature('latent_seeds'))} "
                               f"(the {args.backend} backend has no latent seeds)")
    if not args.style and not args.reference:
        raise MotionStyleError("give a target --style (or, with a backend that takes them, a --reference clip)")
    source = canonical_clip(args.input)
    reference = canonical_clip(args.reference) if args.reference else None
    seeds = {"seed": args.seed, "seed_spread": args.seed_spread} if spec.latent_seeds else {}
    stylize, recognised = with_reference(args.backend, args.model, args.alpha, args.threads, reference,
                                         (args.style or [None])[0], **seeds)
    if reference is not None:
        print(f"{args.reference}: style read as {recognised!r}")
        args.style = args.style or [recognised]
    output = Path(args.output)
    outputs = []
    for style in args.style:
        result = stylize(source, style)
        path = output if len(args.style) == 1 else output.with_name(f"{output.stem}_{style}{output.suffix}")
        bvh.write(path, bvh.BvhClip.from_motion(result, scale=100.0), precision=6)
        print(f"wrote {path}: {result.n_frames} frames at {result.fps:g} fps, style {style}, "
              f"alpha {args.alpha:g}")
        outputs.append(result)
    if args.render:
        motions, titles = [source, *outputs], [Path(args.input).stem, *args.style]
        draw = render.render_png if args.render.lower().endswith(".png") else render.render_gif
        draw(motions, titles, args.render)
        print(f"wrote {args.render}")
    return 0
