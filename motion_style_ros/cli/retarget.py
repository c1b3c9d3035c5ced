"""``motion-style retarget``: put a humanoid BVH clip on the canonical (or CMU) skeleton."""

TARGETS = ("canonical", "cmu")


def add_parser(subparsers):
    p = subparsers.add_parser(
        "retarget", help="retarget a humanoid BVH file to the canonical or CMU skeleton",
        description="Retarget a BVH clip of any known humanoid skeleton (canonical Bandai/Unity "
                    "names, CMU, Unity HumanBodyBones; found from the joint names) onto the "
                    "canonical skeleton (written in centimetres) or the CMU one, and print how far "
                    "the mapped bones' directions stray from the source's.",
    )
    p.add_argument("input", metavar="IN.bvh", help="source clip")
    p.add_argument("output", metavar="OUT.bvh", help="where to write the retargeted clip")
    p.add_argument("--to", choices=TARGETS, default="canonical",
                   help="target skeleton (default: canonical)")
    p.add_argument("--report", action="store_true",
                   help="also print the direction error of every mapped bone")
    p.set_defaults(func=run)


def run(args) -> int:
    from motion_style_ros.core import skeleton
    from motion_style_ros.core.retarget import Retargeter, bone_direction_errors, find_map
    from motion_style_ros.io import bvh

    clip = bvh.read(args.input)
    source = clip.to_motion()
    target, scale, unit = {
        "canonical": (skeleton.canonical(), 100.0, "cm"),
        "cmu": (skeleton.cmu31(), 1.0, "CMU units"),
    }[args.to]
    retargeter = Retargeter(source.skeleton, target, find_map(source.skeleton, args.input))
    result = retargeter(source).check_finite(args.input)
    bvh.write(args.output, bvh.BvhClip.from_motion(result, scale=scale), precision=6)

    labels, errors = bone_direction_errors(source, result)
    print(f"wrote {args.output}: {result.n_frames} frames at {result.fps:g} fps, {args.to} skeleton "
          f"({unit})")
    if args.report:
        width = max(len(label) for label in labels)
        print(f"{'bone':<{width}}  mean deg  max deg")
        for label, e in zip(labels, errors.T):
            print(f"{label:<{width}}  {e.mean():8.2f}  {e.max():7.2f}")
    print(f"bone directions vs source: mean {errors.mean():.2f} deg, max {errors.max():.2f} deg "
          f"over {len(labels)} mapped bones")
    return 0
