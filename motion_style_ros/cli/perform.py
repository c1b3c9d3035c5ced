"""``motion-style perform``: new motion of a chosen style sampled from an SAAE's prior, to a BVH file
(what the ``learned_performer`` node streams, offline)."""


def add_parser(subparsers):
    p = subparsers.add_parser(
        "perform", help="sample new motion of a style from an SAAE into a BVH file",
        description="Decode content codes drawn from the prior of a sequence adversarial autoencoder "
                    "('motion-style train saae') with a style's input into a seamless clip "
                    "on the canonical skeleton (written in centimetres), as the learned_performer "
                    "node streams it: the same model, style, seed and rate give the same motion.",
    )
    p.add_argument("--style", required=True, metavar="NAME", help="one of the model card's styles")
    p.add_argument("--seconds", type=float, required=True, metavar="S", help="length of the clip")
    p.add_argument("--out", required=True, metavar="CLIP.bvh", help="where to write the clip")
    p.add_argument("--model", default=None, metavar="M",
                   help="the SAAE: a shipped model's file name or a path (default: the saae backend's "
                        "shipped model)")
    p.add_argument("--seed", type=int, default=0, metavar="N", help="seed of the prior samples (default 0)")
    p.add_argument("--spread", type=float, default=None, metavar="X",
                   help="how far the style inputs lie from their style's mean in its stds, 0..4 (default: "
                        "the node's, each style's mean; 1: as trained)")
    p.add_argument("--no-foot-lock", action="store_true",
                   help="leave the sampled feet as the model gives them (the node's foot_lock:=false)")
    p.add_argument("--fps", type=float, default=60.0, metavar="F", help="frame rate of the clip (default 60)")
    p.set_defaults(func=run)


def run(args) -> int:
    from motion_style_ros.errors import MotionStyleError
    from motion_style_ros.io import bvh
    from motion_style_ros.runtime.learned_performer import LearnedStream

    if not args.style:
        raise MotionStyleError("--style is empty; give one of the model card's styles")
    spread = {} if args.spread is None else {"spread": args.spread}
    stream = LearnedStream(args.model, args.style, args.seed, fps=args.fps, foot_lock=not args.no_foot_lock, **spread)
    motion = stream.motion(args.seconds)
    bvh.write(args.out, bvh.BvhClip.from_motion(motion, scale=100.0), precision=6)
    print(f"wrote {args.out}: {motion.n_frames} frames at {motion.fps:g} fps, style {stream.style} sampled "
          f"from {stream.sampler.path.name} (seed {args.seed})")
    return 0
