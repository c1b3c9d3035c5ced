"""``motion-style eval --live``: every CMU and Xia clip streamed through real nodes (``bvh_player``
-> one ``stylizer`` per style, separate processes over DDS, the player sending the clip retargeted
but not conformed, as a live rig would), against ``motion-style stylize`` of the same clip; then
the same clips as performers of other sizes stream them, through the same session in-process.

Imported from ``eval``'s ``run()`` only (it imports rclpy).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

SETTLE_SECONDS = 2.0  # after the stylizers' subscriptions match, before the player starts
QUEUE_DEPTH = 500


def stream_clip(graph, path: Path, styles: list[str], backend: str, fps: float) -> tuple[list, dict]:
    """Play one clip through one stylizer per style; the input frames' stamps in arrival order
    and, per style, ``{stamp: (names, positions)}`` of the stylized frames."""
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    from sensor_msgs.msg import JointState

    from motion_style_ros.cli.live import STARTUP_SECONDS, stamp_ns
    from motion_style_ros.evaluation import live

    # Reliable from end to end: the figures compare stylized frames, and a frame lost on a busy
    # machine would only thin them (the live rig's best-effort transport is not what is measured).
    qos = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE)
    inputs: list[int] = []
    outputs: dict[str, dict[int, tuple[list[str], np.ndarray]]] = {s: {} for s in styles}
    subscriptions = [graph.node.create_subscription(
        JointState, "/clip/joint_states", lambda m: inputs.append(stamp_ns(m.header.stamp)), qos)]
    for style in styles:
        def keep(msg, style=style):
            outputs[style][stamp_ns(msg.header.stamp)] = (list(msg.name), np.array(msg.position))
        subscriptions.append(graph.node.create_subscription(JointState, f"/{style}/joint_states", keep, qos))
        # A deep queue: a stylizer still warming up (its first model calls) loses no frame.
        graph.start("stylizer", name=f"stylizer_{style}", backend=backend, target_style=style,
                    input_fps=float(fps), qos_reliability="reliable", qos_depth=QUEUE_DEPTH,
                    remaps={"joint_states": "/clip/joint_states",
                            "stylized/joint_states": f"/{style}/joint_states",
                            "stylized/trajectory": f"/{style}/trajectory"})
    try:
        graph.spin_until(lambda: graph.node.count_publishers("/clip/joint_states") == 0
                         and graph.node.count_subscribers("/clip/joint_states") >= len(styles) + 1
                         and all(graph.node.count_publishers(f"/{s}/joint_states") for s in styles),
                         "the stylizers to start", STARTUP_SECONDS)
        graph.spin_for(SETTLE_SECONDS)
        player = graph.start("bvh_player", file=str(path), topic="/clip/joint_states",
                             qos_reliability="reliable", qos_depth=QUEUE_DEPTH,
                             wait_for_subscribers=len(styles) + 1, start_frame=live.start_frame(path))
        graph.spin_until(lambda: player.poll() is not None, f"{path.name} to play", STARTUP_SECONDS + 120.0)
        graph.spin_for(1.0)  # frames still in flight
        graph.processes.pop("bvh_player")
    finally:
        for style in styles:
            if f"stylizer_{style}" in graph.processes:
                graph.stop(f"stylizer_{style}")
        for sub in subscriptions:
            graph.node.destroy_subscription(sub)
    return inputs, outputs


def run(args: argparse.Namespace, backend: str) -> int:
    from motion_style_ros.cli.live import LiveGraph
    from motion_style_ros.core.motion import Motion
    from motion_style_ros.core.skeleton import canonical
    from motion_style_ros.errors import MotionStyleError
    from motion_style_ros.evaluation import live
    from motion_style_ros.evaluation.judges import Judge
    from motion_style_ros.io.canonical import canonical_clip
    from motion_style_ros.io.joint_state import JointStateLayout
    from motion_style_ros.runtime.backends import backend as spec
    from motion_style_ros.runtime.defaults import DEFAULTS
    from motion_style_ros.runtime.offline import stylizer

    styles = args.live_styles.split(",")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    paths = live.clip_paths()
    if args.live_clips:
        paths = [p for p in paths if any(k in p.name for k in args.live_clips.split(","))]
    if not paths:
        raise MotionStyleError("no CMU or Xia clips found (unpack the datasets: "
                               "../shared/datasets/unpack.sh)")
    # the node's session settings, written into the report; the style strength is --alpha
    settings = {k: v for k, v in spec(backend).settings(DEFAULTS).items() if k != "alpha"}
    offline = stylizer(backend, args.model, args.alpha, args.threads, **settings)
    layout = JointStateLayout.canonical()
    sk = canonical()
    rows = []
    delays: dict[float, int] = {}
    with LiveGraph("motion_style_eval_live", out / "logs") as graph:
        for path in paths:
            source = live.live_input(path)
            inputs, outputs = stream_clip(graph, path, styles, backend, source.fps)
            index = {stamp: k for k, stamp in enumerate(inputs)}
            reference = canonical_clip(str(path))[live.start_frame(path):]
            if source.fps not in delays:
                delays[source.fps] = _delay(backend, source.fps)
            delay = delays[source.fps]
            for style in styles:
                frames = sorted((index[s], v) for s, v in outputs[style].items() if s in index)
                row = {"clip": path.name, "style": style, "frames_in": source.n_frames,
                       "frames_received": len(inputs), "frames_out": len(frames)}
                # Frames the stream lost are left out; the rest are compared index for index (the
                # offline output is aligned with its input, the live one trails it).
                start = delay + int(round(live.SETTLE_SECONDS * source.fps))
                kept = [(k, v) for k, v in frames if k >= start and k - delay < reference.n_frames]
                if kept and len(inputs) == source.n_frames:
                    ks = np.array([k for k, _ in kept])
                    q, p = zip(*(layout.decode(*v) for _, v in kept))
                    got = Motion.from_rotations(sk, np.stack(q), np.stack(p), source.fps)
                    want = offline(reference, style)
                    at = ks - delay
                    want = Motion.from_rotations(sk, want.rotations[at], want.root_positions[at], source.fps)
                    row.update(live.compare(got, want, settle_seconds=0.0))
                else:
                    row["frames"] = 0
                rows.append(row)
                print(_line(row), flush=True)
    report = {"settings": {"backend": backend, "styles": styles, "settle_seconds": live.SETTLE_SECONDS,
                           **settings},
              "clips": rows, "summary": _summary(rows)}
    if not args.no_proportions:
        clips = [live.live_input(p) for p in paths]
        report["proportions"] = live.proportions(
            lambda fps: spec(backend).open_session(args.model, input_fps=fps, threads=args.threads, **settings),
            clips, Judge("style").labels, Judge("style", args.threads), progress=not args.quiet)
        for scale, row in report["proportions"].items():
            print(f"scale {scale}: " + ", ".join(f"{k} {v:.3g}" for k, v in row.items()))
    print("summary: " + ", ".join(f"{k} {v:.3g}" if isinstance(v, float) else f"{k} {v}"
                                  for k, v in report["summary"].items()))
    path = out / f"live_{backend}.json"
    path.write_text(json.dumps(report, indent=1) + "\n")
    print(f"wrote {path}")
    return 0


def _delay(backend: str, fps: float) -> int:
    """Input frames by which the node's output trails the offline output of the same clip."""
    from motion_style_ros.runtime.backends import backend as spec
    session = spec(backend).open_session(input_fps=fps)
    return int(round(session.latency * fps))


def _line(row: dict) -> str:
    frames = (f"frames in {row['frames_in']}, received {row['frames_received']}, "
              f"out {row['frames_out']}")
    if not row["frames"]:
        return f"{row['clip']:<22} {row['style']:<9} {frames}: not compared (no frame after the first second)"
    return (f"{row['clip']:<22} {row['style']:<9} joints {row['joint_distance_cm']:.2f} cm, rotations "
            f"{row['rotation_deg']:.2f} deg, hands up {100 * row['hands_up_live']:.0f}% live / "
            f"{100 * row['hands_up_offline']:.0f}% offline ({frames})")


def _summary(rows: list[dict]) -> dict:
    done = [r for r in rows if r.get("frames")]
    if not done:
        return {"compared": 0, "streams": len(rows)}
    dist = np.array([r["joint_distance_cm"] for r in done])
    ang = np.array([r["rotation_deg"] for r in done])
    hands = np.array([100 * abs(r["hands_up_live"] - r["hands_up_offline"]) for r in done])
    return {"streams": len(rows), "compared": len(done),
            "frames_lost": int(sum(r["frames_in"] - r["frames_out"] for r in rows)),
            "joint_distance_cm_mean": float(dist.mean()), "joint_distance_cm_max": float(dist.max()),
            "over_3cm": int((dist > 3.0).sum()),
            "rotation_deg_mean": float(ang.mean()), "rotation_deg_max": float(ang.max()),
            "over_5deg": int((ang > 5.0).sum()),
            "hands_up_points_max": float(hands.max()), "hands_up_over_2_points": int((hands > 2.0).sum())}
