"""``motion-style demo``: the built-in demo (placeholder until the runtime and nodes land)."""

PLAN = """\
motion-style demo (placeholder: the demo itself is not written yet)

It will show, with nothing but this package installed:
  1. a synthetic performer streaming a canonical 22-joint humanoid as sensor_msgs/JointState,
  2. the stylizer restyling it live with a shipped ONNX model (style, alpha and seed switched
     while it runs),
  3. the output as JointState / JointTrajectory, a skeleton MarkerArray, and a plot of the
     original and stylized motion, with the measured latency.
"""


def add_parser(subparsers):
    p = subparsers.add_parser("demo", help="run the built-in demo",
                              description="Run the built-in demo: a synthetic performer, "
                                          "restyled live.")
    p.set_defaults(func=run)


def run(args):
    print(PLAN, end="")
    return 0
