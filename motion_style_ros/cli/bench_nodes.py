"""``motion-style bench nodes`` (registered by ``cli/bench.py``): the stylizer node as its own
process over DDS, end to end: latency from the input's stamp to the stylized frame's arrival, dropped
frames and the node's CPU, each stylizer row after a relay row (this machine's floor)."""

from __future__ import annotations

from motion_style_ros.cli.bench_common import model_file, performer_counts, print_model
from motion_style_ros.cli.proc import cpu_seconds, load_average
from motion_style_ros.runtime.backends import BACKENDS
from motion_style_ros.runtime.defaults import DEFAULTS


def add_parser(targets) -> None:
    nodes = targets.add_parser(
        "nodes", help="the stylizer node over DDS, end to end",
        description="Start the stylizer node as its own process (reliable QoS) and stream synthetic "
                    "walk frames to it from this command's rclpy node, header.stamp = the publish "
                    "time; report the end-to-end latency (stamp -> arrival of the stylized frame in "
                    "this node's DDS reader, p50/p99 in ms), the dropped frames, and the stylizer "
                    "process's CPU use (utime + stime from /proc, in %% of one core) for each input "
                    "rate with one performer and at the highest rate with several performers. "
                    "Before each stylizer row, a relay node that republishes the frames as they "
                    "came measures the same path with no stylizing: this machine's floor.",
    )
    nodes.add_argument("--rates", default="30,60,120", metavar="HZ,HZ,...",
                       help="input rates with one performer (default: 30,60,120)")
    nodes.add_argument("--performers", default="4", metavar="N,N,...",
                       help="performers at the highest rate, each on its own topics; with several counts, "
                            "a row pair for each and the largest count the stylizer held (default: 4)")
    nodes.add_argument("--seconds", type=float, default=10.0,
                       help="measured stream time per row in seconds (default: 10)")
    nodes.add_argument("--backend", default="recurrent", choices=tuple(BACKENDS),
                       help="the node's backend (default: recurrent)")
    nodes.add_argument("--lookahead", type=int, default=DEFAULTS["lookahead"],
                       help=f"windowed backends: model frames each output waits for (default: {DEFAULTS['lookahead']})")
    nodes.add_argument("--pipelined", action="store_true",
                       help="the node's pipelined mode: each frame is published before the model "
                            "frames it does not need run (one input frame more latency)")
    nodes.add_argument("--reference", default=None, metavar="CLIP.bvh",
                       help="stgcn, most, saae: set the reference parameter to this clip and back every 2 s "
                            "while streaming, and report the longest gap between two outputs of a "
                            "performer against the longest gap between two inputs (the clip is read "
                            "off the streams' thread)")
    nodes.add_argument("--workers", type=int, default=1, metavar="N",
                       help="also stream each several-performer row's performers through N stylizer "
                            "processes, shared out round robin as the launch file's workers:=N does, in "
                            "a row of its own beside the one-process row (default: 1, none)")
    nodes.add_argument("--model", default=None,
                       help="ONNX model with its card beside it (default: the backend's shipped one)")
    nodes.set_defaults(func=run)


def run(args) -> int:
    import os
    import tempfile
    from pathlib import Path

    import numpy as np

    from motion_style_ros.cli.live import LiveGraph
    from motion_style_ros.errors import MotionStyleError
    from motion_style_ros.nodes.process import EXECUTOR_VARIABLE, executor_choice
    from motion_style_ros.runtime.backends import backend, with_feature
    from motion_style_ros.runtime.onnx_model import read_card

    try:
        rates = [float(r) for r in args.rates.split(",")]
    except ValueError:
        raise MotionStyleError(f"--rates takes numbers separated by commas, got {args.rates!r}") from None
    counts = performer_counts(args.performers)
    if min(rates) <= 0 or args.seconds <= 0 or min(counts) < 1 or args.workers < 1:
        raise MotionStyleError("--rates, --seconds, --performers and --workers must be positive")
    if args.workers > 1 and args.reference:
        raise MotionStyleError("--workers and --reference go one at a time (the reference is set on one node)")
    spec = backend(args.backend)
    if args.reference and not spec.reference_clips:
        raise MotionStyleError(f"--reference needs --backend {' or '.join(with_feature('reference_clips'))} "
                               "(its style encoder reads the clip)")
    from motion_style_ros.runtime.offline import default_model

    path = model_file(args.model or default_model(args.backend)).resolve()
    card = read_card(path)
    print_model(path, card)
    settings = {"backend": args.backend, "pipelined": args.pipelined}
    if spec.lookahead:
        settings["lookahead"] = args.lookahead
        print(f"{args.backend} with lookahead {args.lookahead}: each output shows the motion of "
              f"{1000 * args.lookahead / card['fps']:.0f} ms earlier (not in the latencies below, "
              "which run from the input's stamp to the output's arrival)")
    rows = [(node, rate, 1, 1) for rate in rates for node in ("relay", "stylizer")]
    for n in (n for n in counts if n > 1):  # the relay for as many streams: rclpy's share of the stylizer's row
        rows += [("relay", max(rates), n, 1), ("stylizer", max(rates), n, 1)]
        if args.workers > 1:
            rows.append(("stylizer", max(rates), n, min(args.workers, n)))
    if args.reference:  # the reference changes at the highest rate, with the most performers
        rows = [("relay", max(rates), 1, 1), ("stylizer", max(rates), max(counts), 1),
                ("stylizer+reference", max(rates), max(counts), 1)]
    delays = {rate: 1000 * _output_delay(path, args, rate) for rate in rates}  # ms, the stylizer's
    logs = Path(tempfile.mkdtemp(prefix="motion_style_bench_"))
    print(f"machine: {os.cpu_count()} cores, load average {load_average()} (before); node logs in {logs}; the nodes "
          f"spin in rclpy's {executor_choice()} executor ({EXECUTOR_VARIABLE})")
    print(f"each row: a node process (reliable QoS) <- synthetic walk frames from this process, "
          f"{NODE_WARMUP:g} s warm-up, {args.seconds:g} s measured; the relay republishes each "
          "frame as it came (what DDS and an rclpy node cost here), the stylizer stylizes it")
    columns = ("node", "processes", "rate (Hz)", "performers", "frames", "p50 (ms)", "p99 (ms)", "max (ms)",
               "dropped", "node p99", "CPU (%)", "bench CPU", "delay (ms)")
    print(" ".join(f"{c:>10}" for c in columns))
    held = []  # performer counts the stylizer held at the highest rate
    with LiveGraph("motion_style_bench", logs) as graph:
        for node, rate, performers, workers in rows:
            latency_ms, sent, node_p99, cpu, own, gaps = _stream_nodes(
                graph, node.split("+")[0], rate, performers, args.seconds,
                {"model": str(path), **settings} if node.startswith("stylizer") else {},
                reference=args.reference if node.endswith("+reference") else None, workers=workers)
            p50, p99, worst = np.percentile(latency_ms, [50, 99, 100]) if len(latency_ms) else [np.nan] * 3
            delay = delays[rate] if node.startswith("stylizer") else 0.0
            print(f"{node.split('+')[0]:>10} {workers:>10} {rate:>10g} {performers:>10} {sent:>10} {p50:>10.2f} {p99:>10.2f} "
                  f"{worst:>10.2f} {sent - len(latency_ms):>10} {node_p99:>10.2f} {cpu:>10.0f} "
                  f"{own:>10.0f} {delay:>10.1f}")
            if (node == "stylizer" and workers == 1 and rate == max(rates) and sent == len(latency_ms)
                    and p99 <= HELD_P99_MS):
                held.append(performers)
            if args.reference:
                print(f"{'':>10} longest gap between two outputs of a performer {gaps['output_ms']:.1f} ms "
                      f"({gaps['output_ms'] * rate / 1000:.2f} input periods), between two inputs sent "
                      f"{gaps['input_ms']:.1f} ms; added by the node {gaps['stall_ms']:.1f} ms "
                      f"({gaps['stall_ms'] * rate / 1000:.2f} periods); reference changes {gaps['changes']}"
                      + (" (the clip read and encoded on the node's worker thread)" if gaps["changes"] else ""))
    if len(counts) > 1 and not args.reference:
        print(f"the stylizer held (no frame dropped, p99 <= {HELD_P99_MS:g} ms) at {max(rates):g} Hz: "
              + (f"{max(held)} performers" if held else "none of the counts")
              + f" of {', '.join(map(str, sorted({1, *counts})))} tried")
    print(f"load average {load_average()} (after); node p99: the stylizer's own p99 (ms, worst performer) "
          "from a message's arrival in its DDS reader to the stylized frame's publication, from its "
          "/diagnostics; CPU: the node processes together, % of one core; bench CPU: this process's "
          "(publishing and receiving every frame), which shares the cores; delay: how much earlier "
          "than its stamp the motion an output shows is (the session's latency), on top of p50/p99")
    return 0


def _output_delay(path, args, rate: float) -> float:
    """The stylizer's own output latency (s) at ``rate``, as its session works it out."""
    from motion_style_ros.runtime.backends import backend

    spec = backend(args.backend)
    return spec.open_session(path, input_fps=rate, pipelined=args.pipelined, lookahead=args.lookahead).latency


HELD_P99_MS = 10.0  # a node holds a count of performers when none drops and p99 stays within this
NODE_WARMUP = 2.0  # s of streaming before measuring: ONNX Runtime's first runs, DDS settling
NODE_DRAIN = 1.0  # s after the last frame for its output to arrive


def _stream_nodes(graph, name: str, rate: float, performers: int, seconds: float, settings: dict,
                  reference: str | None = None, workers: int = 1):
    """One row: a fresh node ``name`` (stylizer or relay, with ``settings``) for ``performers``
    performers at ``rate`` Hz; returns the latency (ms) of every measured frame that came back, how
    many were sent, the node's own p99 (ms, its last diagnostics, worst performer; NaN without),
    and the CPU use of the node and of this process (% of one core) over the measured interval, and
    the longest gaps (ms) between two outputs of a performer and two inputs sent; with
    ``reference``, the stylizer's reference parameter goes to that clip and back every 2 s; with
    ``workers`` > 1, the performers are shared out round robin over that many node processes."""
    import os
    import time

    import numpy as np
    from diagnostic_msgs.msg import DiagnosticArray
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    from sensor_msgs.msg import JointState

    from motion_style_ros.cli.live import STARTUP_SECONDS, stamp_ns
    from motion_style_ros.core.synthetic import synthetic_motion
    from motion_style_ros.io.joint_state import JointStateLayout

    node = graph.node
    prefixes = [""] if performers == 1 else [f"performer{k}" for k in range(performers)]
    if name == "stylizer":
        settings = {**settings, "input_fps": float(rate)}
    names = [name] if workers == 1 else [f"{name}_{k}" for k in range(workers)]
    procs = [graph.start(name, name=n, qos_reliability="reliable", qos_depth=100,
                         performers=prefixes[k::workers], **settings) for k, n in enumerate(names)]
    reliable = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE)
    topics = [f"{p}/" if p else "" for p in prefixes]
    publishers = [node.create_publisher(JointState, f"{t}joint_states", reliable) for t in topics]
    arrivals: list[dict[int, int]] = [{} for _ in topics]  # per performer: stamp -> arrival
    subscriptions = [
        node.create_subscription(
            JointState, f"{t}stylized/joint_states",
            lambda msg, info, got=got: got.__setitem__(stamp_ns(msg.header.stamp),
                                                       info["received_timestamp"]),
            reliable)
        for t, got in zip(topics, arrivals)]
    node_p99: dict[str, float] = {}  # per performer, from the stylizer's last diagnostics
    diagnostics = node.create_subscription(
        DiagnosticArray, "/diagnostics",
        lambda msg: node_p99.update({s.name: float(next(v.value for v in s.values
                                                        if v.key == "latency_p99_ms"))
                                     for s in msg.status}), 10)
    graph.spin_until(lambda: all(p.get_subscription_count() >= 1 for p in publishers)
                     and all(s.get_publisher_count() >= 1 for s in subscriptions),
                     f"the {name} for {performers} performer(s) to start", STARTUP_SECONDS)

    layout = JointStateLayout.canonical()
    # one walk for the whole stream: a looped clip would jump back, which the stylizer drops
    frames = layout.encode_motion(synthetic_motion("walk", rate, NODE_WARMUP + seconds + 10.0)).tolist()
    clock = node.get_clock()
    sent: list[list[int]] = [[] for _ in topics]  # per performer: stamps sent while measuring
    start = time.monotonic()
    measure_from, end = start + NODE_WARMUP, start + NODE_WARMUP + seconds
    cpu_from: list[tuple[float, float, float]] = []  # stylizer's and own CPU s, wall s at the start
    count = 0
    changes = []
    if reference:
        from rclpy.parameter import Parameter
        from rclpy.parameter_client import AsyncParameterClient

        client = AsyncParameterClient(node, "stylizer")
        client.wait_for_services(STARTUP_SECONDS)

    def publish() -> None:
        nonlocal count
        now = time.monotonic()
        if now >= end:
            return
        if reference and now >= measure_from + 2.0 * len(changes):
            changes.append(client.set_parameters([Parameter("reference", value=reference if len(changes) % 2 == 0
                                                            else "")]))
        if now >= measure_from and not cpu_from:
            cpu_from.append((sum(cpu_seconds(p.pid) for p in procs), cpu_seconds(os.getpid()), now))
        for publisher, stamps in zip(publishers, sent):
            msg = JointState(name=layout.names, position=frames[count % len(frames)])
            msg.header.stamp = clock.now().to_msg()
            publisher.publish(msg)
            if now >= measure_from:
                stamps.append(stamp_ns(msg.header.stamp))
        count += 1

    timer = node.create_timer(1.0 / rate, publish)
    graph.spin_until(lambda: time.monotonic() >= end, "the stream", seconds + NODE_WARMUP + 60)
    stylizer_cpu, own_cpu, wall = cpu_from[0]
    wall = time.monotonic() - wall
    cpu = 100 * (sum(cpu_seconds(p.pid) for p in procs) - stylizer_cpu) / wall
    own = 100 * (cpu_seconds(os.getpid()) - own_cpu) / wall
    node_p99.clear()  # the diagnostics of the measured stream, not of the warm-up
    graph.spin_for(NODE_DRAIN + 1.0)  # the last frames' outputs, and the next diagnostics
    node.destroy_timer(timer)
    node.destroy_subscription(diagnostics)
    for publisher in publishers:
        node.destroy_publisher(publisher)
    for subscription in subscriptions:
        node.destroy_subscription(subscription)
    for n in names:
        graph.stop(n)
    latency = [got[s] - s for stamps, got in zip(sent, arrivals) for s in stamps if s in got]
    output_gap = max((np.diff(sorted(got[s] for s in stamps if s in got)).max(initial=0)
                      for stamps, got in zip(sent, arrivals)), default=0)
    input_gap = max((np.diff(stamps).max(initial=0) for stamps in sent), default=0)
    # What the node adds to a gap: how much later than the one before a frame came back, beyond how
    # much later it was sent (a stall in the node delays every frame queued behind it by as much).
    stall = max((np.diff([got[s] - s for s in stamps if s in got]).max(initial=0)
                 for stamps, got in zip(sent, arrivals)), default=0)
    gaps = {"output_ms": output_gap / 1e6, "input_ms": input_gap / 1e6, "stall_ms": stall / 1e6,
            "changes": sum(f.done() and all(r.successful for r in f.result().results) for f in changes)}
    return (np.array(latency) / 1e6, sum(map(len, sent)), max(node_p99.values(), default=np.nan),
            cpu, own, gaps)
