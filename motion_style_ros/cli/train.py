"""``motion-style train``: train the models this package ships (needs torch: ``pip install '.[train]'``)."""


def add_parser(subparsers):
    p = subparsers.add_parser(
        "train", help="train models (needs torch)",
        description="Train a model on the Bandai Namco data and write it, with its model card, "
                    "to models/. Stopped runs resume from ~/.cache/motion_style_ros/checkpoints/.",
    )
    targets = p.add_subparsers(dest="target", metavar="TARGET", required=True)
    judges = targets.add_parser(
        "judges", help="the style and content judges used by 'motion-style eval'",
        description="Train the independent style and content classifiers on real Bandai "
                    "dataset-2 train takes (selected on val, scored on test takes), export them "
                    "to ONNX and write their model cards.",
    )
    judges.add_argument("--kind", choices=("style", "content", "both"), default="both",
                        help="which judge to train (default: both)")
    judges.add_argument("--epochs", type=int, default=15, help="training epochs (default: 15)")
    judges.add_argument("--seed", type=int, default=0, help="random seed (default: 0)")
    judges.add_argument("--threads", type=int, default=2,
                        help="torch CPU threads (default: 2)")
    judges.add_argument("--out", default=None,
                        help="folder for the ONNX files and cards (default: the shipped models/)")
    judges.set_defaults(func=run_judges)


def run_judges(args) -> int:
    from pathlib import Path

    from motion_style_ros.errors import MotionStyleError

    try:
        from motion_style_ros.training import judges
    except ModuleNotFoundError as exc:
        if exc.name != "torch":
            raise
        raise MotionStyleError("training needs torch: pip install '.[train]'") from None
    from motion_style_ros.runtime.onnx_model import models_dir

    if args.epochs < 1:
        raise MotionStyleError(f"--epochs must be at least 1, got {args.epochs}")
    out = Path(args.out) if args.out else models_dir()
    clips = judges.encode_clips()
    for kind in judges.KINDS if args.kind == "both" else (args.kind,):
        card = judges.train(judges.Config(kind=kind, epochs=args.epochs, seed=args.seed), out,
                            clips, threads=args.threads)
        acc = card["accuracy"]
        print(f"judge_{kind}: test accuracy {acc['test_clip']:.3f} per clip "
              f"({acc['test_clips']} clips), {acc['test_window']:.3f} per {acc['test_window_frames']}-frame "
              f"window; val {acc['val_clip']:.3f}; {card['training']['wall_time_s']:.0f} s "
              f"-> {out / card['name']}.onnx")
    return 0
