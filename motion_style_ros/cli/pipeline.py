"""The recorded pipeline the long benches run (``bench soak``, ``bench faults``):
synthetic_performer -> stylizer -> recorder of both streams, as processes over DDS. Its arguments
are added at parse time (nothing heavy imported); :func:`start` runs in a command's ``run()``."""

from __future__ import annotations

from pathlib import Path


def add_arguments(parser, out: str) -> None:
    """--rate, --backend, --model and --out (default ``out``)."""
    parser.add_argument("--rate", type=float, default=120.0, help="the performer's rate in Hz (default: 120)")
    parser.add_argument("--backend", default="recurrent", help="the stylizer's backend (default: recurrent)")
    parser.add_argument("--model", default=None,
                        help="ONNX model with its card beside it (default: the backend's shipped one)")
    parser.add_argument("--out", default=out, help=f"folder for the bag and the logs (default: {out})")


# A recording keeps every frame, as ros2 bag record does with reliable publishers: a machine busy
# with a node's start delays the recording rather than thinning it.
RELIABLE = {"qos_reliability": "reliable"}


def stylizer_params(args) -> dict:
    """The stylizer's parameters from the arguments (a restart passes the same ones)."""
    return {"backend": args.backend, "input_fps": float(args.rate), **RELIABLE,
            **({"model": args.model} if args.model else {})}


def performer_params(args) -> dict:
    """The synthetic performer's parameters (a restart passes the same ones)."""
    return {"fps": int(args.rate), **RELIABLE}


def prepare(args) -> tuple[Path, Path]:
    """Check the arguments; the output folder (made) and the bag folder to record to."""
    import time

    from motion_style_ros.errors import MotionStyleError
    from motion_style_ros.runtime.backends import backend

    if args.rate <= 0:
        raise MotionStyleError(f"--rate must be positive, got {args.rate:g}")
    backend(args.backend)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    return out, out / f"bag_{time.strftime('%Y%m%d_%H%M%S')}"


def start(graph, args, bag: Path):
    """Start the stylizer, the recorder and the performer in ``graph``; the stylizer's process."""
    stylizer = graph.start("stylizer", **stylizer_params(args))
    graph.start("recorder", bag=str(bag), topics=["joint_states", "stylized/joint_states"], **RELIABLE)
    graph.start("synthetic_performer", **performer_params(args))
    return stylizer
