"""``motion-style eval``: score stylizers beside the identity and oracle baselines on held-out takes."""

from __future__ import annotations

import argparse

BASELINES = ("identity", "oracle")


def recurrent(args: argparse.Namespace):
    """The recurrent (Style-ERD) session streaming each clip frame by frame, as a node would."""
    from motion_style_ros.runtime.session import RecurrentSession

    sessions: dict[float, RecurrentSession] = {}

    def stylize(source, target_style: str):
        if source.fps not in sessions:
            sessions[source.fps] = RecurrentSession(args.model or "style_erd.onnx",
                                                    input_fps=source.fps, threads=args.threads)
        return sessions[source.fps].run(source, target_style, args.alpha)

    return stylize


# Trained stylizers by name: a factory taking the parsed arguments and returning
# ``(source Motion, target style) -> Motion``. Backends register here as they land.
STYLIZERS = {"recurrent": recurrent}


def add_parser(subparsers):
    p = subparsers.add_parser(
        "eval", help="score a stylizer and the baselines on held-out takes",
        description="Restyle Bandai dataset-2 test takes into every other style and score the "
                    "outputs with the shipped style and content judges and motion metrics (style "
                    "and content accuracy, FMD, content consistency, foot skating, jerk, bone "
                    "lengths), always beside the identity and oracle baselines. Writes "
                    "report.json and report.png and prints a table.",
    )
    p.add_argument("--stylizer", choices=tuple(STYLIZERS), action="append", default=None,
                   help="a trained stylizer to score (repeat for several; default: the baselines only)")
    p.add_argument("--model", default=None,
                   help="model file of the stylizer (default: the shipped one)")
    p.add_argument("--alpha", type=float, default=1.0, help="style strength in [0, 1] (default: 1)")
    p.add_argument("--out", default="out/eval", help="output folder (default: out/eval)")
    p.add_argument("--pairs-per-cell", type=int, default=2, metavar="K",
                   help="test takes per (content, style) cell, each paired with every other "
                        "style (default: 2)")
    p.add_argument("--seed", type=int, default=0, help="seed of the take choice (default: 0)")
    p.add_argument("--threads", type=int, default=1, help="ONNX Runtime threads (default: 1)")
    p.add_argument("--quiet", action="store_true", help="no progress bars")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from pathlib import Path

    from motion_style_ros.evaluation import harness
    from motion_style_ros.evaluation.judges import Judge

    names = args.stylizer or []
    # Build the stylizers first: a missing model fails here in one line, before the slow part.
    stylizers = {name: STYLIZERS[name](args) for name in names}
    judges = Judge("style", args.threads), Judge("content", args.threads)
    clips = harness.held_out_clips(progress=not args.quiet)
    pairs = harness.make_pairs([info for info, _ in clips], args.pairs_per_cell, args.seed)
    stylizers.update(harness.baselines(clips, args.seed))
    settings = {"pairs_per_cell": args.pairs_per_cell, "seed": args.seed, "alpha": args.alpha}
    report = harness.evaluate(stylizers, clips, pairs, *judges, progress=not args.quiet,
                              settings=settings)
    model = names[0] if names else None
    json_path, png_path = harness.write(report, Path(args.out), model=model)
    print(harness.format_table(report, model=model))
    for name, system in report["systems"].items():
        if system["skipped"]:
            print(f"{name}: {len(system['skipped'])} pairs skipped "
                  f"(e.g. {system['skipped'][0]['reason']})")
    print(f"wrote {json_path} and {png_path}")
    return 0
