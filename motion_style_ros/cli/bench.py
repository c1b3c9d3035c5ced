"""``motion-style bench``: how fast the stylizers run here, per frame and in performers."""

DEFAULT_MODEL = "style_erd.onnx"
MAX_PERFORMERS = 4096  # where the search for the real-time limit stops


def add_parser(subparsers):
    p = subparsers.add_parser(
        "bench", help="latency and throughput of the stylizers",
        description="Time the streaming stylizers on ONNX Runtime (CPU) on this machine.",
    )
    targets = p.add_subparsers(dest="target", metavar="TARGET", required=True)
    recurrent = targets.add_parser(
        "recurrent", help="the Style-ERD streaming session",
        description="Stream a synthetic canonical-skeleton performance through RecurrentSession "
                    "(the code path of the ROS node) and report the time of each step() call "
                    "(p50/p99, microseconds) for several numbers of performers, and the largest "
                    "number of performers whose p99 step time fits one input frame (real time).",
    )
    recurrent.add_argument("--model", default=DEFAULT_MODEL,
                           help="ONNX model with its card beside it "
                                f"(default: the shipped {DEFAULT_MODEL})")
    recurrent.add_argument("--performers", default="1,4,16", metavar="N,N,...",
                           help="performer counts to time (default: 1,4,16)")
    recurrent.add_argument("--seconds", type=float, default=5.0,
                           help="stream time per measurement in seconds (default: 5)")
    recurrent.add_argument("--input-fps", type=float, default=120.0,
                           help="rate of the input stream in Hz (default: 120)")
    recurrent.add_argument("--threads", type=int, default=1, help="ONNX Runtime threads (default: 1)")
    recurrent.set_defaults(func=run_recurrent)


def run_recurrent(args) -> int:
    import numpy as np

    from motion_style_ros.errors import MotionStyleError
    from motion_style_ros.runtime.onnx_model import model_path, models_dir

    try:
        counts = [int(n) for n in args.performers.split(",")]
    except ValueError:
        raise MotionStyleError(
            f"--performers takes whole numbers separated by commas, got {args.performers!r}"
        ) from None
    if min(counts) < 1 or args.seconds <= 0 or args.input_fps <= 0:
        raise MotionStyleError("--performers, --seconds and --input-fps must be positive")
    try:
        path = model_path(args.model)
    except MotionStyleError as exc:
        if args.model != DEFAULT_MODEL:
            raise
        raise MotionStyleError(
            f"{exc}; train it with 'motion-style train recurrent', or time another model with "
            "--model (e.g. a random-weight one from "
            "motion_style_ros.training.recurrent.export_random_model)"
        ) from None

    budget_us = 1e6 / args.input_fps
    results = {n: _time_steps(path, n, args.seconds, args.input_fps, args.threads) for n in counts}
    session = results[counts[0]][0]
    trained = session.card.get("training", {}).get("data", "unknown data")
    print(f"model: {path} ({session.card.get('name', path.stem)}, trained on: {trained})")
    if "random" in str(trained):
        shipped = ("" if (models_dir() / DEFAULT_MODEL).is_file()
                   else f" (models/{DEFAULT_MODEL} does not exist yet)")
        print(f"note: a random-weight model{shipped}: the timings hold for a model of its size only")
    print(f"input: synthetic {args.input_fps:g} Hz stream, {args.seconds:g} s per measurement; model at "
          f"{session.fps:g} Hz; output latency {1000 * session.latency:.1f} ms; "
          f"ONNX Runtime on {args.threads} thread(s)")
    print("step() wall time per input frame; the model runs on one frame in "
          f"{args.input_fps / session.fps:g}, the others interpolate")
    columns = ("performers", "p50 (us)", "p99 (us)", "max (us)", "mean (us)", "real time")
    print(" ".join(f"{c:>10}" for c in columns))
    for n, (_, micros) in results.items():
        p50, p99, worst = np.percentile(micros, [50, 99, 100])
        print(f"{n:>10} {p50:>10.0f} {p99:>10.0f} {worst:>10.0f} {micros.mean():>10.0f} "
              f"{'yes' if p99 < budget_us else 'no':>10}")
    best = _largest_real_time(path, args.seconds, args.input_fps, args.threads)
    limit = f"at least {best}" if best == MAX_PERFORMERS else str(best)
    print(f"largest number of performers stylized in real time at {args.input_fps:g} Hz "
          f"(p99 step time under {budget_us:.0f} us): {limit}")
    return 0


def _time_steps(path, performers: int, seconds: float, input_fps: float, threads: int):
    """The session and the wall time of each of its step() calls (microseconds) over ``seconds``
    of a synthetic stream: every joint swinging about its own axis, the pelvis walking forward."""
    import time

    import numpy as np

    from motion_style_ros.core import rotations as rot
    from motion_style_ros.runtime.session import RecurrentSession

    session = RecurrentSession(path, performers, input_fps=input_fps, threads=threads)
    rng = np.random.default_rng(0)
    axes = rng.normal(size=(performers, 22, 3))
    phase = rng.uniform(0, 2 * np.pi, size=(performers, 22))
    micros = []
    for k in range(max(2, round(seconds * input_fps))):
        t = k / input_fps
        q = rot.from_axis_angle(axes, 0.4 * np.sin(2 * np.pi * t + phase))
        root = np.stack([np.arange(performers), np.full(performers, 0.9), np.full(performers, 1.2 * t)],
                        axis=-1)
        start = time.perf_counter_ns()
        session.step(q, root, t)
        micros.append((time.perf_counter_ns() - start) / 1000)
    return session, np.array(micros)


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
