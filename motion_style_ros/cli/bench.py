"""``motion-style bench``: how fast the stylizers run here, per frame and in performers."""

from motion_style_ros.cli.bench_common import DEFAULT_MODEL, model_file, performer_counts, print_model
from motion_style_ros.runtime.backends import BACKENDS
from motion_style_ros.runtime.defaults import DEFAULTS

MAX_PERFORMERS = 4096  # where the search for the real-time limit stops


def add_parser(subparsers):
    p = subparsers.add_parser(
        "bench", help="latency and throughput of the stylizers",
        description="Time the streaming stylizers on ONNX Runtime (CPU) on this machine.",
    )
    targets = p.add_subparsers(dest="target", metavar="TARGET", required=True)
    recurrent = targets.add_parser(
        "recurrent", help="the Style-ERD streaming session",
        description="Stream a synthetic canonical-skeleton walk through RecurrentSession "
                    "(the code path of the ROS node) and report the time of each step() call "
                    "(p50/p99, microseconds) for several numbers of performers, and the largest "
                    "number of performers whose p99 step time fits one input frame (real time).",
    )
    recurrent.add_argument("--performers", default="1,4,16", metavar="N,N,...",
                           help="performer counts to time (default: 1,4,16)")
    recurrent.add_argument("--seconds", type=float, default=5.0,
                           help="stream time per measurement in seconds (default: 5)")
    recurrent.add_argument("--input-fps", type=float, default=120.0,
                           help="rate of the input stream in Hz (default: 120)")
    recurrent.add_argument("--threads", type=int, default=1, help="ONNX Runtime threads (default: 1)")
    recurrent.add_argument("--checkpoint", default=None,
                           help="training checkpoint whose torch generator is timed against the ONNX "
                                "graph (default: the seed-0 one in ~/.cache/motion_style_ros/"
                                "checkpoints, if there; needs torch)")
    recurrent.add_argument("--record", action="store_true",
                           help="also write the figures into the model card's metrics")
    recurrent.set_defaults(func=run_recurrent)
    for spec in BACKENDS.values():
        if not spec.lookahead:
            continue
        windows = targets.add_parser(
            spec.name, help=f"the windowed {spec.name} session",
            description=f"Time one window of the {spec.name} backend's step ({spec.summary}) on ONNX "
                        "Runtime (1 and 8 performers) and its per-frame amortised cost at each hop, "
                        "then the wall time of the session's step() (the node's code path) streaming "
                        "a clip at each hop.",
        )
        windows.add_argument("--clip", default=None, metavar="CLIP.bvh",
                             help="humanoid BVH to stream (default: a 10 s synthetic walk at 30 Hz)")
        windows.add_argument("--hops", default="1,4,8", metavar="N,N,...",
                             help="hops (model frames between windows) to time (default: 1,4,8)")
        windows.add_argument("--lookahead", type=int, default=DEFAULTS["lookahead"],
                             help=f"model frames each output waits for (default: {DEFAULTS['lookahead']})")
        windows.add_argument("--threads", type=int, default=1, help="ONNX Runtime threads (default: 1)")
        windows.add_argument("--record", action="store_true",
                             help="also write the figures into the model card's metrics")
        windows.add_argument("--model", default=spec.default_model,
                             help=f"the step's model with its card and companions beside it (default: the "
                                  f"shipped {spec.default_model})")
        windows.set_defaults(func=run_windows, backend=spec.name)
    from motion_style_ros.cli import bench_nodes, faults, soak, vmc_flood

    bench_nodes.add_parser(targets)
    soak.add_parser(targets)
    faults.add_parser(targets)
    vmc_flood.add_parser(targets)
    recurrent.add_argument("--model", default=DEFAULT_MODEL,
                           help=f"ONNX model with its card beside it (default: the shipped {DEFAULT_MODEL})")


def run_recurrent(args) -> int:
    import numpy as np

    from motion_style_ros.errors import MotionStyleError

    counts = performer_counts(args.performers)
    if min(counts) < 1 or args.seconds <= 0 or args.input_fps <= 0:
        raise MotionStyleError("--performers, --seconds and --input-fps must be positive")
    path = model_file(args.model)
    budget_us = 1e6 / args.input_fps
    results = {n: _time_steps(path, n, args.seconds, args.input_fps, args.threads) for n in counts}
    session = results[counts[0]][0]
    print_model(path, session.card)
    print(f"input: synthetic {args.input_fps:g} Hz stream, {args.seconds:g} s per measurement; model at "
          f"{session.fps:g} Hz; output latency {1000 * session.latency:.1f} ms; "
          f"ONNX Runtime on {args.threads} thread(s)")
    print("step() wall time per input frame; the model runs on one frame in "
          f"{args.input_fps / session.fps:g}, the others interpolate")
    columns = ("performers", "p50 (us)", "p99 (us)", "max (us)", "mean (us)", "real time")
    print(" ".join(f"{c:>10}" for c in columns))
    for n, (_, micros, _) in results.items():
        p50, p99, worst = np.percentile(micros, [50, 99, 100])
        print(f"{n:>10} {p50:>10.0f} {p99:>10.0f} {worst:>10.0f} {micros.mean():>10.0f} "
              f"{'yes' if p99 < budget_us else 'no':>10}")
    print(f"paced like a live stream (each frame {budget_us:.0f} us after the last), 1 performer: "
          "step() is what each frame waits for; catch_up() runs after it, between frames")
    columns = ("mode", "latency", "step p50", "step p99", "step max", "catch_up p99", "catch_up max")
    print(" ".join(f"{c:>12}" for c in columns))
    paced = {}
    for mode in ("default", "pipelined"):
        live, micros, between = _time_steps(path, 1, args.seconds, args.input_fps, args.threads,
                                            paced=True, pipelined=mode == "pipelined")
        p50, p99, worst = np.percentile(micros, [50, 99, 100])
        late99, late = np.percentile(between, [99, 100])
        paced[mode] = {"latency_ms": round(1000 * live.latency, 1), "step_p50_us": round(p50, 1),
                       "step_p99_us": round(p99, 1), "catch_up_p99_us": round(late99, 1)}
        print(f"{mode:>12} {1000 * live.latency:>9.1f} ms {p50:>9.0f} us {p99:>9.0f} us "
              f"{worst:>9.0f} us {late99:>9.0f} us {late:>9.0f} us")
    best = _largest_real_time(path, args.seconds, args.input_fps, args.threads)
    limit = f"at least {best}" if best == MAX_PERFORMERS else str(best)
    print(f"largest number of performers stylized in real time at {args.input_fps:g} Hz "
          f"(p99 step time under {budget_us:.0f} us): {limit}")
    _, frames, _ = _time_steps(path, 1, args.seconds, session.fps, args.threads)
    frame = dict(zip(("p50_us", "p99_us"), np.percentile(frames, [50, 99]).round(1).tolist()))
    print(f"whole model frame back to back (1 performer, input at the model's {session.fps:g} Hz): "
          f"p50 {frame['p50_us']:.0f} us, p99 {frame['p99_us']:.0f} us")
    contact = _contact_costs(args.seconds)
    print(f"contact handling alone per model frame, 1 performer: foot lock p50 {contact['foot_lock'][0]:.0f} us, "
          f"p99 {contact['foot_lock'][1]:.0f} us; alpha below 1, the blend with the input frame p50 "
          f"{contact['blend'][0]:.0f} us, p99 {contact['blend'][1]:.0f} us")
    calls = _model_calls(path, session.card, args.checkpoint, args.threads, args.seconds)
    for name, (p50, p99) in calls.items():
        print(f"model call alone, 1 performer, {name}: p50 {p50:.0f} us, p99 {p99:.0f} us")
    if "torch" in calls:
        print(f"torch / ONNX Runtime time per model call (p50): "
              f"{calls['torch'][0] / calls['onnxruntime'][0]:.2f}")
    reference = _reference_step()
    if reference:
        print(f"reference Style-ERD generator (Tao et al.'s architecture at its default size, random weights, "
              f"torch on {reference['threads']} threads, state carried frame by frame): p50 {reference['p50_us']:.0f} us, "
              f"p99 {reference['p99_us']:.0f} us; its step / this package's whole model frame (p50): "
              f"{reference['p50_us'] / frame['p50_us']:.1f}x")
    if args.record:
        import os
        import shlex
        import sys

        from motion_style_ros.runtime.onnx_model import record_metrics

        rows = {str(n): dict(zip(("p50_us", "p99_us"), np.percentile(m, [50, 99]).round(1).tolist()))
                for n, (_, m, _) in results.items()}
        figures = {"command": "motion-style " + shlex.join(sys.argv[1:]), "cpus": os.cpu_count(),
                   "load_average": os.getloadavg()[0], "input_fps": args.input_fps,
                   "step_per_performers": rows, "paced_1_performer": paced,
                   "real_time_performers": best, "model_frame_us": frame,
                   "model_call_us": {k: {"p50": round(a, 1), "p99": round(b, 1)}
                                     for k, (a, b) in calls.items()},
                   "reference_step_us": reference}
        print(f"recorded in {record_metrics(path, 'bench', figures)}")
    return 0


def run_windows(args) -> int:
    import os
    import shlex
    import sys

    from motion_style_ros.core.synthetic import synthetic_motion
    from motion_style_ros.errors import MotionStyleError
    from motion_style_ros.evaluation.windowed import bench_report
    from motion_style_ros.io.canonical import canonical_clip
    from motion_style_ros.runtime.onnx_model import model_path, record_metrics

    try:
        hops = tuple(int(h) for h in args.hops.split(","))
    except ValueError:
        raise MotionStyleError(f"--hops takes whole numbers separated by commas, got {args.hops!r}") from None
    clip = canonical_clip(args.clip) if args.clip else synthetic_motion("walk", 30.0, 10.0)
    report, figures = bench_report(clip, args.backend, args.model, hops, args.lookahead, args.threads)
    print(report)
    if args.backend == "stgcn":  # the reference's per-frame cost beside this package's at hop 4
        line, figures["reference_window"] = _reference_window(figures["window_ms_1_performers"]["p50"] / 4)
        print(line)
    if args.record:
        figures = {"command": "motion-style " + shlex.join(sys.argv[1:]), "cpus": os.cpu_count(),
                   "load_average": os.getloadavg()[0], **figures}
        print(f"recorded in {record_metrics(model_path(args.model), 'bench', figures)}")
    return 0


def _reference_window(per_frame_ms: float) -> tuple[str, dict | None]:
    """The bench line and figures of one pass of the reference ST-GCN generator
    (:mod:`motion_style_ros.models.reference_stgcn`) on its default test clip, set against
    ``per_frame_ms``, this package's per-frame amortised cost at hop 4; not timed without torch."""
    try:
        from motion_style_ros.models.reference_stgcn import REFERENCE_THREADS, reference_window_times
    except ModuleNotFoundError:
        return "torch not installed: the reference ST-GCN generator is not timed", None
    p50, p99, frames = reference_window_times(REFERENCE_THREADS)
    ratio = p50 / frames / per_frame_ms
    line = (f"reference ST-GCN generator (Park et al.'s architecture at its default size, random weights, "
            f"torch on {REFERENCE_THREADS} threads, one {frames}-frame clip, offline): p50 {p50:.1f} ms, p99 "
            f"{p99:.1f} ms; per frame {p50 / frames:.3f} ms (p99 {p99 / frames:.3f}); its per-frame cost / this "
            f"package's per-frame amortised at hop 4 (p50): {ratio:.2f}x")
    return line, {"p50_ms": round(p50, 3), "p99_ms": round(p99, 3), "frames": frames,
                  "per_frame_p50_ms": round(p50 / frames, 4), "per_frame_p99_ms": round(p99 / frames, 4),
                  "threads": REFERENCE_THREADS, "ratio_to_hop_4": round(ratio, 2)}


def _reference_step() -> dict | None:
    """p50/p99 (us) of one streaming step of the reference Style-ERD generator
    (:mod:`motion_style_ros.models.reference_erd`), or None without torch."""
    try:
        from motion_style_ros.models.reference_erd import REFERENCE_THREADS, reference_step_times
    except ModuleNotFoundError:
        print("torch not installed: the reference generator is not timed")
        return None
    p50, p99 = reference_step_times(REFERENCE_THREADS)
    return {"p50_us": round(p50, 1), "p99_us": round(p99, 1), "threads": REFERENCE_THREADS}


def _contact_costs(seconds: float) -> dict[str, tuple[float, float]]:
    """p50 and p99 (us) of the foot lock's call and of the intensity blend on one performer's
    model frames (a synthetic walk at 30 Hz, its own ankles as the input's), ``seconds`` each."""
    import time

    import numpy as np

    from motion_style_ros.core.foot_lock import FootLock
    from motion_style_ros.core.intensity import blend
    from motion_style_ros.core.synthetic import synthetic_motion

    walk = synthetic_motion("walk", 30.0, 4.0)
    lock = FootLock(1, walk.fps)
    roots, ankles = walk.root_positions, walk.global_positions()[:, lock.ankles]
    weights, half = np.full((1, walk.skeleton.n_joints), 0.5), np.full(1, 0.5)
    runs = {
        "foot_lock": lambda k: lock(walk.rotations[k:k + 1], roots[k:k + 1], ankles[k:k + 1]),
        "blend": lambda k: blend(walk.rotations[k:k + 1], roots[k:k + 1], walk.rotations[k - 1:k],
                                 roots[k - 1:k], weights, half),
    }
    costs = {}
    for name, run in runs.items():
        times, end = [], time.monotonic() + seconds
        while time.monotonic() < end:
            for k in range(1, walk.n_frames):
                start = time.perf_counter_ns()
                run(k)
                times.append((time.perf_counter_ns() - start) / 1e3)
        costs[name] = tuple(np.percentile(times, [50, 99]))
    return costs


def _model_calls(path, card: dict, checkpoint, threads: int, seconds: float, calls: int = 2000) -> dict:
    """p50/p99 (us) of one streaming model call for one performer on ONNX Runtime back to back and
    a model frame apart for ``seconds`` (the core spinning in between: what a live stream's call
    pays for weights that left the caches), and on torch when a training checkpoint and torch are
    at hand."""
    import time
    from pathlib import Path

    import numpy as np

    from motion_style_ros.runtime.onnx_model import OnnxModel

    rng = np.random.default_rng(0)
    inputs = {"features": rng.normal(size=(1, card["feature_layout"]["contact"][1])).astype(np.float32),
              "style": np.eye(len(card["styles"]), dtype=np.float32)[:1],
              "alpha": np.ones((1, 1), np.float32),
              "state": np.zeros((1, card["state_size"]), np.float32),
              "reset": np.zeros((1, 1), np.float32)}

    def timed(call, gap: float = 0.0, count: int = calls) -> tuple[float, float]:
        micros = []
        for _ in range(count):
            due = time.monotonic() + gap
            while time.monotonic() < due:  # busy, not asleep: only the time between calls differs
                pass
            start = time.perf_counter_ns()
            call()
            micros.append((time.perf_counter_ns() - start) / 1000)
        return tuple(np.percentile(micros, [50, 99]).tolist())

    onnx = OnnxModel(path, threads)
    out = {"onnxruntime": timed(lambda: onnx.run(**inputs))}
    period = 1.0 / card["fps"]
    out[f"onnxruntime, {1000 * period:.0f} ms apart"] = timed(lambda: onnx.run(**inputs), period,
                                                               max(3, round(seconds / period)))
    default = Path.home() / ".cache/motion_style_ros/checkpoints/recurrent_0/checkpoint.pt"
    checkpoint = Path(checkpoint) if checkpoint else default
    try:
        import torch

        from motion_style_ros.models.style_erd import StepGraph
        from motion_style_ros.training.recurrent import load_generator
    except ModuleNotFoundError:
        print("torch not installed: the torch model is not timed")
        return out
    if not checkpoint.is_file():
        print(f"{checkpoint}: no training checkpoint, the torch model is not timed")
        return out
    torch.set_num_threads(threads)
    generator = load_generator(checkpoint)
    if (generator.cfg.state_size, list(generator.cfg.styles)) != (card["state_size"], card["styles"]):
        print(f"{checkpoint}: another model than {path.name}, the torch model is not timed")
        return out
    step = StepGraph(generator)
    tensors = {k: torch.from_numpy(v) for k, v in inputs.items()}
    with torch.inference_mode():
        out["torch"] = timed(lambda: step(**tensors))
    return out


def _time_steps(path, performers: int, seconds: float, input_fps: float, threads: int,
                paced: bool = False, pipelined: bool = DEFAULTS["pipelined"]):
    """The session and the wall time of each of its step() calls (microseconds) over ``seconds``
    of a synthetic walk (each performer at its own phase), so that every part of a step runs:
    features, the model, decoding and foot locking on planted feet. ``paced``: each frame comes
    when a live stream's would (the CPU's caches go cold in between), and the times of the
    catch_up() calls after each step come back too (else none)."""
    import time

    import numpy as np

    from motion_style_ros.core.synthetic import synthetic_motion
    from motion_style_ros.runtime.recurrent import RecurrentSession

    session = RecurrentSession(path, performers, input_fps=input_fps, threads=threads,
                               pipelined=pipelined)
    frames = max(2, round(seconds * input_fps))
    walks = [synthetic_motion("walk", input_fps, frames / input_fps, start=0.37 * k)
             for k in range(performers)]
    rotations = np.stack([w.rotations for w in walks], axis=1)
    roots = np.stack([w.positions[:, w.skeleton.pelvis] + [1.0 * k, 0.0, 0.0]
                      for k, w in enumerate(walks)], axis=1)
    micros, between = [], []
    begin = time.monotonic()
    for k in range(frames):
        if paced:
            time.sleep(max(0.0, begin + k / input_fps - time.monotonic()))
        start = time.perf_counter_ns()
        session.step(rotations[k], roots[k], k / input_fps)
        stepped = time.perf_counter_ns()
        micros.append((stepped - start) / 1000)
        if paced:
            session.catch_up()
            between.append((time.perf_counter_ns() - stepped) / 1000)
    return session, np.array(micros), np.array(between)


def _largest_real_time(path, seconds: float, input_fps: float, threads: int) -> int:
    """The largest performer count (within about 6 %, at most MAX_PERFORMERS) whose p99 step time
    fits one input frame; 0 if not even one performer does."""
    import numpy as np

    def fits(n: int) -> bool:
        micros = _time_steps(path, n, seconds, input_fps, threads)[1]
        return bool(np.percentile(micros, 99) < 1e6 / input_fps)

    if not fits(1):
        return 0
    lo, hi = 1, 2
    while hi <= MAX_PERFORMERS and fits(hi):
        lo, hi = hi, 2 * hi
    if hi > MAX_PERFORMERS:
        return MAX_PERFORMERS
    while hi - lo > max(1, lo // 16):
        mid = (lo + hi) // 2
        lo, hi = (mid, hi) if fits(mid) else (lo, mid)
    return lo
