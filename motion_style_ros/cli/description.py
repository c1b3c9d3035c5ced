"""``motion-style description``: the canonical skeleton's URDF, for robot_state_publisher and RViz."""


def add_parser(subparsers):
    p = subparsers.add_parser(
        "description", help="write the canonical skeleton's URDF (robot_state_publisher, RViz)",
        description="Write the URDF robot description of the canonical skeleton: its joints are the "
                    "canonical JointState layout's names, so robot_state_publisher shows a stylized "
                    "stream as it is. The package installs it as share/motion_style_ros/urdf/"
                    "canonical_skeleton.urdf.",
    )
    p.add_argument("--out", default="-", metavar="FILE", help="where to write it (default: stdout)")
    p.set_defaults(func=run)


def run(args) -> int:
    import sys
    from pathlib import Path

    from motion_style_ros.io.description import canonical_urdf

    text = canonical_urdf()
    if args.out == "-":
        sys.stdout.write(text)
    else:
        Path(args.out).write_text(text)
        print(f"wrote {args.out}")
    return 0
