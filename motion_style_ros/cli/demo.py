"""``motion-style demo``: the live product in ~15 s, with nothing but this package installed.

Starts three node processes, the synthetic performer (a procedural walk at 60 Hz), the stylizer
(the shipped model) and the recorder (an MCAP bag of input and output), and drives the stylizer
from its own rclpy node the way a user would, through the stylizer's standard
``~/set_parameters`` service: the first style with alpha ramping 0 -> 1, then the second style.
Then it renders input and output side by side (PNG and GIF) from the bag, and prints the
end-to-end latency it measured: the stylized frame's arrival here minus its input stamp, both on
the system clock, so it holds the transport both ways and the stylizer's work.
"""

from __future__ import annotations

import argparse
import shutil
from pathlib import Path

DEFAULT_MODEL = "style_erd.onnx"
INPUT, OUTPUT = "joint_states", "stylized/joint_states"
FPS = 60
CONTROL_PERIOD = 0.25  # s between two alpha steps of the ramp (the stylizer blends each step)
SETTLE_SECONDS = 2.0


def add_parser(subparsers) -> None:
    p = subparsers.add_parser(
        "demo",
        help="run the built-in live demo",
        description="Stream a synthetic walk through the stylizer node live (separate processes "
        "over DDS), change style and alpha through ROS parameters, record input and output to an "
        "MCAP bag, render them side by side and print the measured end-to-end latency.",
    )
    p.add_argument("--out", type=Path, default=Path("out/demo"), help="output folder (default: out/demo)")
    p.add_argument("--model", default=DEFAULT_MODEL,
                   help=f"stylizer ONNX model with its card beside it (default: the shipped {DEFAULT_MODEL})")
    p.add_argument("--styles", default="elderly,youthful", metavar="FIRST,SECOND",
                   help="the two styles, one after the other (default: elderly,youthful)")
    p.add_argument("--seconds", type=float, default=12.0,
                   help="how long to stream (default: 12): the first style with alpha ramping "
                        "0 -> 1 for half of it, then the second style")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from motion_style_ros.errors import MotionStyleError
    from motion_style_ros.runtime.onnx_model import model_path, read_card

    styles = args.styles.split(",")
    if args.seconds < 2:
        raise MotionStyleError(f"--seconds must be at least 2, got {args.seconds:g}")
    try:
        model = model_path(args.model).resolve()
    except MotionStyleError as exc:
        if args.model != DEFAULT_MODEL:
            raise
        raise MotionStyleError(f"{exc}; train it with 'motion-style train recurrent' or pass "
                               "another model with --model") from None
    known = read_card(model).get("styles", [])
    if len(styles) != 2 or not set(styles) <= set(known):
        raise MotionStyleError(f"--styles takes two of {', '.join(known)} separated by a comma, "
                               f"got {args.styles!r}")
    out: Path = args.out
    out.mkdir(parents=True, exist_ok=True)
    for old in (out / "bag", out / "logs"):
        shutil.rmtree(old, ignore_errors=True)

    timeline = _timeline(styles, args.seconds)
    print(f"model: {model}")
    print(f"streaming {args.seconds:g} s: synthetic_performer (walk, {FPS} Hz) -> stylizer -> "
          f"recorder, controls through /stylizer/set_parameters:")
    for begin, end, style, alpha in _segments(styles, args.seconds):
        print(f"  {begin:g}-{end:g} s: {style}, alpha {alpha}")
    start, inputs, outputs = _stream(model, timeline, args.seconds, out)
    _report(inputs, outputs)
    _render(out / "bag", start, styles, args.seconds, out)
    print(f"wrote {out / 'bag'}, {out / 'demo.png'} and {out / 'demo.gif'}")
    return 0


def _timeline(styles: list[str], seconds: float) -> list[tuple[float, str, float]]:
    """(time after the first frame in s, style, alpha) of each control change: the first style
    with alpha stepping 0 -> 1 over the first half, then the second style at alpha 1."""
    half = seconds / 2
    steps = max(2, round(half / CONTROL_PERIOD))
    ramp = [(k * half / steps, styles[0], k / (steps - 1)) for k in range(steps)]
    return ramp + [(half, styles[1], 1.0)]


def _segments(styles: list[str], seconds: float) -> list[tuple[float, float, str, str]]:
    """(from s, to s, style, alpha) of the two halves of the timeline, to describe it."""
    return [(0.0, seconds / 2, styles[0], "0 -> 1"), (seconds / 2, seconds, styles[1], "1")]


def _stream(model: Path, timeline, seconds: float, out: Path):
    """Run the three nodes and the controls; the timeline's start (ns), the input stamps seen and
    (stamp, arrival) of each output from then on."""
    from rclpy.parameter import Parameter
    from rclpy.parameter_client import AsyncParameterClient
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    from sensor_msgs.msg import JointState

    from motion_style_ros.cli.live import STARTUP_SECONDS, LiveGraph, stamp_ns
    from motion_style_ros.errors import MotionStyleError

    first_style, first_alpha = timeline[0][1], timeline[0][2]
    inputs: list[int] = []
    outputs: list[tuple[int, int]] = []
    with LiveGraph("motion_style_demo", out / "logs") as graph:
        clock = graph.node.get_clock()
        listen = QoSProfile(depth=200, reliability=ReliabilityPolicy.BEST_EFFORT)
        graph.node.create_subscription(JointState, INPUT,
                                       lambda m: inputs.append(stamp_ns(m.header.stamp)), listen)
        # Arrival = when this node's DDS reader received the frame (not when the executor got
        # round to its callback): the pipeline's latency, not this process's.
        graph.node.create_subscription(
            JointState, OUTPUT,
            lambda m, info: outputs.append((stamp_ns(m.header.stamp), info["received_timestamp"])),
            listen)
        # best_effort: the recorder matches the performer's sensor-data publisher too.
        graph.start("recorder", topics=[INPUT, OUTPUT], bag=str(out / "bag"), qos_reliability="best_effort")
        # The stylizer keeps its default sensor-data QoS (best effort): a reliable subscription
        # would not match the performer's best-effort publisher.
        graph.start("stylizer", model=str(model), target_style=first_style, alpha=float(first_alpha),
                    input_fps=float(FPS))
        client = AsyncParameterClient(graph.node, "stylizer")
        graph.spin_until(
            lambda: (client.services_are_ready() and graph.node.count_subscribers(INPUT) >= 3
                     and graph.node.count_subscribers(OUTPUT) >= 2
                     and graph.node.count_publishers(OUTPUT) >= 1),
            "the stylizer and the recorder to start", STARTUP_SECONDS)
        graph.start("synthetic_performer", motion="walk", fps=FPS)
        graph.spin_until(lambda: inputs and outputs, "the first stylized frame", STARTUP_SECONDS)
        # Discovery on a busy machine can match a subscriber to the new performer a second or two
        # after another: the timeline starts once it has settled.
        graph.spin_for(SETTLE_SECONDS)
        start = clock.now().nanoseconds
        pending, changes = list(timeline[1:]), []
        style = first_style
        while (clock.now().nanoseconds - start) * 1e-9 < seconds:
            graph.check()
            now = (clock.now().nanoseconds - start) * 1e-9
            while pending and pending[0][0] <= now:
                _, new_style, alpha = pending.pop(0)
                params = [Parameter("alpha", value=float(alpha))]
                if new_style != style:
                    params.insert(0, Parameter("target_style", value=new_style))
                    style = new_style
                changes.append(client.set_parameters(params))
            graph.spin_for(0.005)
        graph.stop("synthetic_performer")
        graph.spin_for(1.0)  # frames still in flight
        graph.spin_until(lambda: all(f.done() for f in changes), "the parameter changes to answer", 10.0)
        refused = [r.reason for f in changes for r in f.result().results if not r.successful]
        if refused:
            raise MotionStyleError(f"the stylizer refused a parameter change: {refused[0]}")
        graph.stop("stylizer")
        if graph.stop("recorder") != 0:
            raise MotionStyleError(f"the recorder did not finish its bag (log: {out / 'logs'})")
    return start, [s for s in inputs if s >= start], [(s, t) for s, t in outputs if s >= start]


def _report(inputs: list[int], outputs: list[tuple[int, int]]) -> None:
    import numpy as np

    latency_ms = np.array([t - s for s, t in outputs]) / 1e6
    stylized = {s for s, _ in outputs}
    dropped = sum(1 for s in inputs if s not in stylized)
    p50, p99, worst = np.percentile(latency_ms, [50, 99, 100])
    print(f"frames: {len(inputs)} in, {len(outputs)} out, {dropped} dropped")
    print(f"end-to-end latency (input stamp -> stylized frame received here, {len(outputs)} frames): "
          f"p50 {p50:.2f} ms, p99 {p99:.2f} ms, max {worst:.2f} ms")


def _render(bag: Path, start: int, styles: list[str], seconds: float, out: Path) -> None:
    """Input and output from the bag from stamp ``start`` on, frame by frame where both were
    recorded."""
    import numpy as np

    from motion_style_ros.core.motion import Motion
    from motion_style_ros.core.skeleton import canonical
    from motion_style_ros.errors import MotionStyleError
    from motion_style_ros.io.bags import read_joint_states
    from motion_style_ros.io.joint_state import JointStateLayout
    from motion_style_ros.io.render import render_gif, render_png

    recorded = {topic: {r.stamp_ns: r for r in read_joint_states(bag, [topic])}
                for topic in (INPUT, OUTPUT)}
    stamps = sorted(s for s in set(recorded[INPUT]) & set(recorded[OUTPUT]) if s >= start)
    if len(stamps) < 2:
        raise MotionStyleError(f"{bag}: fewer than 2 frames recorded on both {INPUT} and {OUTPUT}")
    layout = JointStateLayout.canonical()
    fps = 1e9 / float(np.median(np.diff(stamps)))

    def motion(topic: str) -> Motion:
        frames = [layout.decode(recorded[topic][s].names, recorded[topic][s].positions) for s in stamps]
        return Motion.from_rotations(canonical(), np.stack([q for q, _ in frames]),
                                     np.stack([p for _, p in frames]), fps)

    motions = [motion(INPUT), motion(OUTPUT)]
    # Short enough for one panel; the console and the column times say when the style changes.
    timeline = ", ".join(f"{style} α {alpha}".replace(" -> ", "→")
                         for _, _, style, alpha in _segments(styles, seconds))
    titles = [f"input: synthetic walk, {fps:.0f} Hz", timeline]
    render_png(motions, titles, out / "demo.png", frames=8)
    render_gif(motions, titles, out / "demo.gif", fps=10.0)
