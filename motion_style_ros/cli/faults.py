"""``motion-style bench faults`` (registered by ``cli/bench.py``): performer -> stylizer -> recorder,
the performer and then the stylizer killed (SIGKILL) and started again mid-stream, timed from this
side; then the recorded bag read back to show what the faults cost the recording."""

from __future__ import annotations

import numpy as np

from motion_style_ros.cli import pipeline


def add_parser(targets) -> None:
    faults = targets.add_parser(
        "faults", help="kill and restart the performer, then the stylizer: recovery times and the bag",
        description="Start synthetic_performer (at --rate), the stylizer and a recorder of both "
                    "streams as processes over DDS. --cycles times: kill the performer, start it "
                    "again --pause seconds later and time its first frame and the first stylized "
                    "frame of it, from that frame's stamp (the stylizer is not touched); then kill the stylizer, start it "
                    "again --pause seconds later and time its first stylized frame. At the end, "
                    "read the recorded bag back: the input frames seen here that it lacks (and "
                    "how many of them while the stylizer was down), and every stylized stamp "
                    "checked against an input frame's.",
    )
    pipeline.add_arguments(faults, "out/faults")
    faults.add_argument("--cycles", type=int, default=3, help="kill/restart cycles (default: 3)")
    faults.add_argument("--pause", type=float, default=1.0,
                        help="seconds between a kill and the restart (default: 1)")
    faults.set_defaults(func=run)


def longest_step(stamps_ns: np.ndarray) -> float:
    """The longest step (s) between consecutive stamps."""
    return float(np.diff(np.sort(stamps_ns)).max(initial=0)) / 1e9


def run(args) -> int:
    import json
    import signal
    import time

    from rclpy.qos import qos_profile_sensor_data
    from sensor_msgs.msg import JointState

    from motion_style_ros.cli.live import STARTUP_SECONDS, LiveGraph, stamp_ns
    from motion_style_ros.errors import MotionStyleError
    from motion_style_ros.io import bags

    if args.cycles < 1 or args.pause < 0:
        raise MotionStyleError("--cycles must be at least 1 and --pause not negative")
    out, bag = pipeline.prepare(args)
    inputs: list[tuple[int, int]] = []  # (stamp, arrival) of every input frame seen here
    outputs: list[tuple[int, int]] = []  # and of every stylized frame
    rows = []
    stylizer_down: list[tuple[int, int]] = []  # from each kill of the stylizer to its first frame back
    # stamps of a (re)started performer's frames before this process discovered it
    unseen: list[tuple[int, int]] = []
    with LiveGraph("motion_style_faults", out / "logs") as graph:

        def restart(name: str, **params) -> tuple[int, int]:
            """Kill ``name``, wait --pause, start it again; the times (ns) it was killed and started."""
            killed = time.time_ns()
            proc = graph.processes.pop(name)
            proc.send_signal(signal.SIGKILL)
            proc.wait(STARTUP_SECONDS)
            graph.spin_for(args.pause)
            started = time.time_ns()
            graph.start(name, **params)
            return killed, started

        def first_after(seen: list[tuple[int, int]], stamp: int, what: str) -> tuple[int, int]:
            """The first (stamp, arrival) in ``seen`` stamped at or after ``stamp``, waited for."""
            found: list[tuple[int, int]] = []

            def check() -> bool:
                found[:] = [x for x in seen[-4 * int(args.rate):] if x[0] >= stamp][:1]
                return bool(found)

            graph.spin_until(check, what, STARTUP_SECONDS)
            return found[0]

        pipeline.start(graph, args, bag)
        node = graph.node
        for topic, seen in (("joint_states", inputs), ("stylized/joint_states", outputs)):
            node.create_subscription(
                JointState, topic, lambda msg, info, seen=seen: seen.append(
                    (stamp_ns(msg.header.stamp), info["received_timestamp"])), qos_profile_sensor_data)
        # both subscriptions matched: this process can discover the stylizer's publisher before the
        # performer's (a clean clone's CI saw outputs and no input yet)
        graph.spin_until(lambda: len(outputs) > args.rate and inputs, "the input and stylized streams",
                         STARTUP_SECONDS)
        unseen.append((0, inputs[0][0]))
        print(f"{args.rate:g} Hz, {args.backend}; each fault: SIGKILL, {args.pause:g} s, the process "
              "started again; times from its start (ms)")
        for cycle in range(1, args.cycles + 1):
            graph.spin_for(2.0)
            _, started = restart("synthetic_performer", **pipeline.performer_params(args))
            first_in = first_after(inputs, started, "the restarted performer's first frame")
            unseen.append((started, first_in[0]))
            first_out = first_after(outputs, first_in[0], "a stylized frame of the restarted performer")
            graph.spin_for(2.0)
            killed, started_stylizer = restart("stylizer", **pipeline.stylizer_params(args))
            back = first_after(outputs, started_stylizer, "the restarted stylizer's first frame")
            stylizer_down.append((killed, back[1]))
            row = {"cycle": cycle,
                   "performer_first_frame_ms": round((first_in[1] - started) / 1e6, 1),
                   # from the first input's stamp (its publication): the stylizer's output may
                   # arrive here before this process's own copy of that input does
                   "then_first_stylized_ms": round((first_out[1] - first_in[0]) / 1e6, 2),
                   "stylizer_first_stylized_ms": round((back[1] - started_stylizer) / 1e6, 1)}
            rows.append(row)
            print(" ".join(f"{k} {v}" for k, v in row.items()), flush=True)
        graph.spin_for(1.0)
    recorded = np.array([r.stamp_ns for r in bags.read_joint_states(bag, ["/joint_states"])])
    stylized = np.array([r.stamp_ns for r in bags.read_joint_states(bag, ["/stylized/joint_states"])])
    seen = np.array([stamp for stamp, _ in inputs])
    missing = ~np.isin(seen, recorded)
    # a stylized stamp must be an input frame's, unless its input came before anyone here heard it
    invented = ~np.isin(stylized, np.union1d(recorded, seen))
    for a, b in unseen:
        invented &= ~((stylized >= a) & (stylized < b))
    summary = {
        "rate_hz": args.rate, "cycles": rows,
        "bag": {"input_frames": len(recorded), "input_frames_seen_here": len(seen),
                "seen_here_not_in_bag": int(missing.sum()),
                "of_them_while_the_stylizer_was_down": int(sum(
                    (missing & (seen >= a) & (seen <= b)).sum() for a, b in stylizer_down)),
                "longest_input_step_s": round(longest_step(recorded), 3), "stylized_frames": len(stylized),
                "stylized_stamps_not_an_input_stamp": int(invented.sum())},
    }
    (out / "faults.json").write_text(json.dumps(summary, indent=1) + "\n")
    b = summary["bag"]
    print(f"bag {bag}: {b['input_frames']} input frames, {b['seen_here_not_in_bag']} of the "
          f"{b['input_frames_seen_here']} seen here missing ({b['of_them_while_the_stylizer_was_down']} "
          f"while the stylizer was down; the rest while the recorder discovered a restarted "
          f"performer), longest step {b['longest_input_step_s']:g} s "
          f"(the performer's own restarts: {args.pause:g} s and its start-up); {b['stylized_frames']} "
          f"stylized frames, {b['stylized_stamps_not_an_input_stamp']} of them not stamped as an input "
          f"frame; wrote {out / 'faults.json'}")
    return 0
