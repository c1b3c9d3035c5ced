"""``motion-style eval``: score a stylizer beside the identity and oracle baselines on held-out takes."""

BASELINES = ("identity", "oracle")


def add_parser(subparsers):
    p = subparsers.add_parser(
        "eval", help="score a stylizer and the baselines on held-out takes",
        description="Restyle Bandai dataset-2 test takes into every other style and score the "
                    "outputs with the shipped style and content judges and motion metrics (style "
                    "and content accuracy, FMD, content consistency, foot skating, jerk, bone "
                    "lengths), always beside the identity and oracle baselines. Writes "
                    "report.json and report.png and prints a table.",
    )
    p.add_argument("--stylizer", choices=BASELINES, default=None,
                   help="highlight one system as the one under test (default: none; trained "
                        "stylizers join this list as they land)")
    p.add_argument("--out", default="out/eval", help="output folder (default: out/eval)")
    p.add_argument("--pairs-per-cell", type=int, default=2, metavar="K",
                   help="test takes per (content, style) cell, each paired with every other "
                        "style (default: 2)")
    p.add_argument("--seed", type=int, default=0, help="seed of the take choice (default: 0)")
    p.add_argument("--threads", type=int, default=1, help="ONNX Runtime threads (default: 1)")
    p.add_argument("--quiet", action="store_true", help="no progress bars")
    p.set_defaults(func=run)


def run(args) -> int:
    from pathlib import Path

    from motion_style_ros.evaluation import harness
    from motion_style_ros.evaluation.judges import Judge

    judges = Judge("style", args.threads), Judge("content", args.threads)
    clips = harness.held_out_clips(progress=not args.quiet)
    pairs = harness.make_pairs([info for info, _ in clips], args.pairs_per_cell, args.seed)
    # A stylizer under test goes first: {name: callable, **baselines}; the baselines always run.
    stylizers = harness.baselines(clips, args.seed)
    report = harness.evaluate(stylizers, clips, pairs, *judges, progress=not args.quiet,
                              settings={"pairs_per_cell": args.pairs_per_cell, "seed": args.seed})
    json_path, png_path = harness.write(report, Path(args.out), model=args.stylizer)
    print(harness.format_table(report, model=args.stylizer))
    for name, system in report["systems"].items():
        if system["skipped"]:
            print(f"{name}: {len(system['skipped'])} pairs skipped "
                  f"(e.g. {system['skipped'][0]['reason']})")
    print(f"wrote {json_path} and {png_path}")
    return 0
