"""``motion-style bench soak`` (registered by ``cli/bench.py``): performer -> stylizer -> recorder
for a long time, with the stylizer's memory and CPU sampled every minute, and the dropped frames and
latency percentiles of each minute; then the recorded bag read back."""

from __future__ import annotations

from motion_style_ros.cli import pipeline


def add_parser(targets) -> None:
    soak = targets.add_parser(
        "soak", help="a long run: memory, CPU, drops and latency each minute",
        description="Start synthetic_performer (at --rate), the stylizer and a recorder of both "
                    "streams as processes over DDS and let them run for --minutes. Every minute, "
                    "print the stylizer's resident memory (RSS from /proc) and CPU use, the frames "
                    "in and out and dropped in that minute (from its /diagnostics) and this "
                    "process's end-to-end latency percentiles (stamp -> arrival of the stylized "
                    "frame); at the end, the memory growth after the first minute (warm-up) and "
                    "the frames in the recorded bag.",
    )
    soak.add_argument("--minutes", type=float, default=60.0, help="how long (default: 60)")
    pipeline.add_arguments(soak, "out/soak")
    soak.set_defaults(func=run)


def run(args) -> int:
    import json
    import time

    import numpy as np
    from diagnostic_msgs.msg import DiagnosticArray
    from rclpy.qos import qos_profile_sensor_data
    from sensor_msgs.msg import JointState

    from motion_style_ros.cli.live import STARTUP_SECONDS, LiveGraph, stamp_ns
    from motion_style_ros.cli.proc import cpu_seconds, rss_mb
    from motion_style_ros.errors import MotionStyleError
    from motion_style_ros.io import bags

    if args.minutes <= 0:
        raise MotionStyleError(f"--minutes must be positive, got {args.minutes:g}")
    out, bag = pipeline.prepare(args)
    rows = []
    with LiveGraph("motion_style_soak", out / "logs") as graph:
        stylizer = pipeline.start(graph, args, bag)
        node = graph.node
        latencies: list[int] = []
        node.create_subscription(JointState, "stylized/joint_states",
                                 lambda msg, info: latencies.append(info["received_timestamp"]
                                                                    - stamp_ns(msg.header.stamp)),
                                 qos_profile_sensor_data)
        status: dict[str, str] = {}
        node.create_subscription(DiagnosticArray, "/diagnostics", lambda msg: status.update(
            {kv.key: kv.value for s in msg.status if s.name.startswith("stylizer") for kv in s.values}), 10)
        graph.spin_until(lambda: len(latencies) > args.rate, "the stylized stream", STARTUP_SECONDS)
        print(f"{args.rate:g} Hz, {args.backend}; per minute: stylizer RSS (MB), CPU (% of one core), "
              "frames in / out / dropped in that minute, end-to-end latency p50 / p99 / max (ms)")
        start, last = time.monotonic(), None
        cpu0 = (cpu_seconds(stylizer.pid), start)
        every: list[np.ndarray] = []  # each minute's latencies (ms), for the whole run's percentiles
        for minute in range(1, int(np.ceil(args.minutes)) + 1):
            latencies.clear()
            graph.spin_for(min(60.0, args.minutes * 60 - (minute - 1) * 60))
            now = time.monotonic()
            cpu = 100 * (cpu_seconds(stylizer.pid) - cpu0[0]) / (now - cpu0[1])
            cpu0 = (cpu_seconds(stylizer.pid), now)
            counts = {k: int(status.get(k, 0)) for k in ("frames_in", "frames_out", "dropped")}
            delta = {k: counts[k] - (last or {}).get(k, 0) for k in counts} if last else counts
            last = counts
            ms = np.array(latencies) / 1e6
            every.append(ms)
            p50, p99, worst = np.percentile(ms, [50, 99, 100]) if len(ms) else [np.nan] * 3
            row = {"minute": minute, "rss_mb": round(rss_mb(stylizer.pid), 1), "cpu_percent": round(cpu, 1),
                   **delta, "latency_p50_ms": round(p50, 2), "latency_p99_ms": round(p99, 2),
                   "latency_max_ms": round(worst, 2)}
            rows.append(row)
            print(" ".join(f"{k} {v}" for k, v in row.items()), flush=True)
    growth = rows[-1]["rss_mb"] - rows[0]["rss_mb"]
    ms = np.concatenate(every)
    whole = {"frames_in": last["frames_in"], "frames_out": last["frames_out"], "dropped": last["dropped"],
             "cpu_percent_mean": round(float(np.mean([r["cpu_percent"] for r in rows])), 1),
             **{f"latency_{k}_ms": round(float(v), 2) if len(ms) else None
                for k, v in zip(("p50", "p99", "p999", "max"),
                                np.percentile(ms, [50, 99, 99.9, 100]) if len(ms) else [0] * 4)}}
    print("whole run: " + " ".join(f"{k} {v}" for k, v in whole.items()))
    print(f"memory growth after the first minute: {growth:+.1f} MB")
    summary = {"minutes": args.minutes, "rate_hz": args.rate, "rss_growth_after_minute_1_mb": round(growth, 1),
               "whole_run": whole, "rows": rows}
    try:  # the figures above are kept whatever the bag holds
        summary["bag_frames"] = {t: len(bags.read_joint_states(bag, [t]))
                                 for t in ("/joint_states", "/stylized/joint_states")}
    except MotionStyleError as exc:
        summary["bag_error"] = str(exc)
    (out / "soak.json").write_text(json.dumps(summary, indent=1) + "\n")
    if "bag_error" in summary:
        print(f"bag {bag}: {summary['bag_error']}; wrote {out / 'soak.json'}")
        return 1
    print(f"bag {bag}: {summary['bag_frames']['/joint_states']} input and "
          f"{summary['bag_frames']['/stylized/joint_states']} stylized frames; wrote {out / 'soak.json'}")
    return 0
