"""``motion-style bench vmc-flood`` (registered by ``cli/bench.py``): a VMC stream, a flood of
garbage datagrams to ``vmc_bridge``'s port, then the stream again; how soon the bridge publishes the
stream again and how current its frames are, with its own counts of what it dropped and why."""

from __future__ import annotations

import json
import struct
import threading
import time
from pathlib import Path

import numpy as np

NESTING = 400  # bundles within bundles in one flood datagram (the receiver refuses beyond 8)


def add_parser(targets) -> None:
    flood = targets.add_parser(
        "vmc-flood", help="flood vmc_bridge's port with garbage between two good VMC streams",
        description="Start vmc_bridge as a process; send it a good 60 Hz VMC stream (one bundle per "
                    "frame) for --before seconds, then --seconds of garbage at --rate datagrams a "
                    "second (random bytes, truncated and deeply nested bundles, bundles of one bone "
                    "repeated, well-formed bones of random values), then the good stream again for "
                    "--after seconds. Prints when the first frame of the stream after the flood was "
                    "published, from the flood's end, how far every later frame's publication "
                    "trailed its stamp, and the bridge's counts (/diagnostics).")
    flood.add_argument("--seconds", type=float, default=10.0, help="flood duration (default: 10)")
    flood.add_argument("--rate", type=float, default=20_000.0, help="flood datagrams a second (default: 20000)")
    flood.add_argument("--before", type=float, default=1.0, help="good stream before (s, default: 1)")
    flood.add_argument("--after", type=float, default=5.0, help="good stream after (s, default: 5)")
    flood.add_argument("--out", type=Path, default=Path("out/vmc_flood"), help="logs (default: out/vmc_flood)")
    flood.set_defaults(func=run)


def _bundle(elements: list[bytes]) -> bytes:
    return b"#bundle\x00" + bytes(8) + b"".join(struct.pack(">i", len(e)) + e for e in elements)


def garbage(count: int, seed: int = 0) -> list[bytes]:
    """Datagrams no VMC sender sends, of every kind the receiver must survive."""
    from motion_style_ros.io.vmc import BONE_ADDRESS, REQUIRED_BONES, build_message

    rng = np.random.default_rng(seed)

    def bone(name: str) -> bytes:
        return build_message(BONE_ADDRESS, [name, *map(float, rng.uniform(-1, 1, 7))]).dgram

    def nested() -> bytes:
        data = bone("Hips")
        for _ in range(NESTING):
            data = _bundle([data])
        return data

    kinds = [
        lambda: bytes(rng.integers(0, 256, int(rng.integers(1, 1500)), dtype=np.uint8)),
        lambda: _bundle([bone(b) for b in REQUIRED_BONES])[: int(rng.integers(20, 900))],
        nested,
        lambda: _bundle([bone("LeftHand")] * 700),
        lambda: _bundle([bone(b) for b in rng.choice(REQUIRED_BONES, 5)]),
        lambda: BONE_ADDRESS.encode() + bytes(rng.integers(0, 256, 40, dtype=np.uint8)),
    ]
    return [kinds[k % len(kinds)]() for k in range(count)]


def run(args) -> int:
    import socket

    from diagnostic_msgs.msg import DiagnosticArray
    from rclpy.qos import qos_profile_sensor_data
    from sensor_msgs.msg import JointState

    from motion_style_ros.cli.live import STARTUP_SECONDS, LiveGraph, stamp_ns
    from motion_style_ros.core.synthetic import synthetic_motion
    from motion_style_ros.errors import MotionStyleError
    from motion_style_ros.io import vmc

    if min(args.seconds, args.rate, args.before, args.after) <= 0:
        raise MotionStyleError("--seconds, --rate, --before and --after must be positive")
    fps = 60.0
    good = vmc.VmcEncoder()(synthetic_motion("walk", fps, 4.0))
    pool = garbage(600)
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    received: list[tuple[int, int]] = []  # (stamp, arrival) ns of every published frame
    with LiveGraph("motion_style_vmc_flood", args.out / "logs") as graph:
        graph.start("vmc_bridge", osc_port=port, send_port=0)
        diagnostics = []
        graph.node.create_subscription(
            JointState, "joint_states",
            lambda m: received.append((stamp_ns(m.header.stamp), graph.node.get_clock().now().nanoseconds)),
            qos_profile_sensor_data)
        graph.node.create_subscription(DiagnosticArray, "/diagnostics", diagnostics.append, 10)
        sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        address = ("127.0.0.1", port)

        def stream(seconds: float, start_frame: int) -> None:
            t0 = time.monotonic()
            for k in range(int(seconds * fps)):
                time.sleep(max(0.0, t0 + k / fps - time.monotonic()))
                frame = good[(start_frame + k) % len(good)]
                sock.sendto(vmc.frame_bundle(frame, (start_frame + k) / fps).dgram, address)

        # The bridge is up once a frame of the good stream comes out.
        deadline = time.monotonic() + STARTUP_SECONDS
        while not received:
            if time.monotonic() > deadline:
                raise MotionStyleError("vmc_bridge published nothing of the good stream")
            sock.sendto(vmc.frame_bundle(good[0], 0.0).dgram, address)
            graph.spin_for(0.1)
        times: dict[str, int] = {}
        sent = {"flood": 0}

        def play() -> None:
            stream(args.before, 0)
            times["flood_start"] = graph.node.get_clock().now().nanoseconds
            t0 = time.monotonic()
            while (elapsed := time.monotonic() - t0) < args.seconds:
                due = int(elapsed * args.rate)
                while sent["flood"] < due:
                    sock.sendto(pool[sent["flood"] % len(pool)], address)
                    sent["flood"] += 1
                time.sleep(0.0005)
            times["flood_end"] = graph.node.get_clock().now().nanoseconds
            stream(args.after, int(args.before * fps))

        player = threading.Thread(target=play, daemon=True)
        player.start()
        while player.is_alive():
            graph.spin_for(0.05)
        graph.spin_for(1.5)  # the last frames and a /diagnostics message
        sock.close()
        counts = {kv.key: kv.value for kv in diagnostics[-1].status[0].values} if diagnostics else {}
    end = times["flood_end"]
    after = [(s, a) for s, a in received if s >= end]
    first = (after[0][1] - end) / 1e9 if after else None
    settled = [(a - s) / 1e6 for s, a in after if a >= end + 1e9]
    result = {
        "flood_seconds": args.seconds, "flood_datagrams": sent["flood"],
        "flood_rate": round(sent["flood"] / args.seconds), "after_seconds": args.after,
        "first_frame_after_flood_s": first,
        "frames_after_flood": len(after), "frames_expected_after_flood": int(args.after * fps),
        "lag_ms_after_first_second": {"p50": float(np.median(settled)) if settled else None,
                                      "max": max(settled) if settled else None},
        "frames_during_flood": sum(1 for s, _ in received if times["flood_start"] <= s < end),
        "bridge": {k: counts.get(k) for k in ("datagrams", "frames", "malformed", "repeated", "stale",
                                              "superseded", "overflow", "kernel_dropped", "backlog_max")},
    }
    print(json.dumps(result))
    lag = result["lag_ms_after_first_second"]["max"]
    print(f"flood of {sent['flood']} datagrams in {args.seconds:g} s: the good stream's first frame "
          f"published {'never' if first is None else f'{first:.3f} s'} after the flood ended; after "
          f"that second, frames trailed their stamps by {'-' if lag is None else f'{lag:.1f}'} ms at "
          f"most ({len(after)} of {int(args.after * fps)} frames published)")
    return 0
