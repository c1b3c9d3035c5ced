"""``motion-style train``: train the models this package ships, on the Bandai data or a user's labelled
BVH folder (``--data``), on any device, in one process or several under ``torchrun`` (needs torch:
``pip install '.[train]'``; see docs/training.md)."""

from __future__ import annotations

import argparse

from motion_style_ros.training.command import PAIRS_DEFAULTS


def add_parser(subparsers):
    p = subparsers.add_parser(
        "train", help="train models (needs torch)",
        description="Train a model on the Bandai Namco data (or a labelled BVH folder: --data) and "
                    "write it, with its model card, to models/ (or --out). Stopped runs resume from "
                    "~/.cache/motion_style_ros/checkpoints/. Every model also trains data-parallel "
                    "under torchrun (see docs/training.md).",
    )
    targets = p.add_subparsers(dest="target", metavar="TARGET", required=True)
    judges = targets.add_parser(
        "judges", help="the style and content judges used by 'motion-style eval'",
        description="Train the independent style and content classifiers on real Bandai train "
                    "takes of both sets, export them to ONNX and write their model cards. Panel 1 "
                    "(judge_<kind>, a CNN on positions, best val epoch) may guide training "
                    "choices; panel 2 (judge2_<kind>, a GRU, last epoch) only reports.",
    )
    judges.add_argument("--kind", choices=("style", "content", "both"), default="both",
                        help="which judge to train (default: both)")
    judges.add_argument("--panel", choices=("1", "2", "3", "both"), default="both",
                        help="which panel to train; both: 1 and 2, the evaluation panels; 3 (judge3_<kind>, "
                             "a CNN on velocities, best val epoch) may guide pseudo-pair choices beside "
                             "panel 1 (default: both)")
    judges.add_argument("--epochs", type=int, default=None,
                        help="training epochs (default: the panel's; 15, 8 and 15)")
    judges.add_argument("--seed", type=int, default=None, help="random seed (default: the panel's; 0, 1 and 2)")
    judges.add_argument("--threads", type=int, default=2,
                        help="torch CPU threads (default: 2)")
    judges.add_argument("--out", default=None,
                        help="folder for the ONNX files and cards (default: the shipped models/)")
    _run_flags(judges)
    judges.set_defaults(func=run_judges)
    pairs = targets.add_parser(
        "pairs", help="pseudo-pairs from other capture setups, for 'train <backend> --distil'",
        description="Stylize clips from other capture setups into every style with every candidate "
                    "backend; of the outputs judge panel 1 recognises as the target (and whose action its "
                    "content judge still reads as the input's), keep the most confident as a regression target. "
                    "Panel 2 never looks. 'eval --unseen' leaves these clips out of a model trained on them. "
                    "Each clip's pairs are kept in OUT.parts/ as it is done: the same command, stopped, goes "
                    "on where it stopped.")
    pairs.add_argument("--clips", required=True, metavar="SPEC,SPEC",
                       help="cmu:SUBJECT, cmu:SUBJECT_TRIAL, a BVH file or a folder of them, any rig")
    pairs.add_argument("--candidates", default=PAIRS_DEFAULTS["candidates"],
                       metavar="BACKEND[:MODEL],...",
                       help="the stylizers whose outputs may become targets (default: every shipped model)")
    pairs.add_argument("--styles", default="", metavar="NAME,NAME",
                       help="target styles (default: those of the shipped recurrent model)")
    speeds = ",".join(f"{v:g}" for v in PAIRS_DEFAULTS["speeds"])
    pairs.add_argument("--speeds", default=speeds, metavar="S,S",
                       help=f"also every clip played at these speeds; '' for none (default: {speeds})")
    pairs.add_argument("--mirror", action=argparse.BooleanOptionalAction, default=PAIRS_DEFAULTS["mirror"],
                       help="also every clip (and speed copy) mirrored left-right (default: on)")
    pairs.add_argument("--posture-slack", type=float, default=PAIRS_DEFAULTS["posture_slack"], metavar="DEG",
                       help="also require a target's knee and hip figures within how far its style moves "
                            "Bandai's train-take performers, DEG either way (default: off)")
    pairs.add_argument("--agree", default=",".join(PAIRS_DEFAULTS["agree"]), metavar="JUDGE,JUDGE",
                       help="more style judges (ONNX files or names in models/, such as panel 3's "
                            "judge3_style.onnx) that must recognise a target beside panel 1's; a target is "
                            "then ranked by their mean probability; '' for none (default: %(default)s)")
    pairs.add_argument("--threads", type=int, default=1, help="ONNX Runtime threads (default: 1)")
    pairs.add_argument("--out", required=True, help="the pairs file to write (.npz)")
    pairs.set_defaults(func=run_pairs)
    import importlib
    import importlib.util

    from motion_style_ros.runtime.backends import BACKENDS

    for name in BACKENDS:  # each backend's trainer package declares its command (training/<name>/command.py)
        package = f"motion_style_ros.training.{name}"
        if importlib.util.find_spec(package) is None:  # a backend with no trainer here (one a test registers)
            continue
        command = importlib.import_module(f"{package}.command")
        trainer = command.COMMAND
        parser = targets.add_parser(name, help=trainer.help, description=trainer.description + " "
                                    + _RESUMABLE.format(trainer.checkpoints or name))
        _own_flags(parser, trainer, "first")
        _budget_flags(parser, trainer.minutes)
        _own_flags(parser, trainer, "middle")
        _output_flags(parser, trainer.files, trainer.checkpoint_of)
        _own_flags(parser, trainer, "last")
        parser.set_defaults(func=command.run)


_RESUMABLE = ("Checkpoints every few minutes to ~/.cache/motion_style_ros/checkpoints/{}_<seed>/ (with "
              "losses.jsonl); --resume continues a stopped run, and the time and iteration budgets count "
              "over all resumed runs, so the same command finishes the job.")


def _own_flags(parser, trainer, place: str) -> None:
    """A trainer's own flags, where they stand at ``place``."""
    if trainer.place == place:
        for flag, options in trainer.flags:
            parser.add_argument(flag, **options)


def _budget_flags(parser, minutes: float) -> None:
    """What every resumable stylizer trainer takes first: its budgets (``minutes`` by default),
    seed and threads, then the data flags."""
    parser.add_argument("--minutes", type=float, default=minutes,
                        help=f"training time budget in minutes, over all resumed runs (default: {minutes:g})")
    parser.add_argument("--iterations", type=int, default=None,
                        help="stop after this many iterations in total (default: no limit)")
    parser.add_argument("--seed", type=int, default=0, help="random seed (default: 0)")
    parser.add_argument("--threads", type=int, default=2, help="torch CPU threads (default: 2)")
    _data_flags(parser)


def _output_flags(parser, files: str, checkpoint_of: str = "this seed") -> None:
    """What every resumable stylizer trainer takes last: --resume (the checkpoint of
    ``checkpoint_of``), --out (the folder of ``files``) and :func:`_run_flags`."""
    parser.add_argument("--resume", action="store_true",
                        help=f"continue from the checkpoint of {checkpoint_of} if there is one "
                             "(without it, an earlier run's checkpoint is discarded)")
    parser.add_argument("--out", default=None,
                        help=f"folder for {files} (default: the shipped models/)")
    _run_flags(parser)


def _run_flags(parser) -> None:
    """What every trainer takes: a user's data and its licence, the device."""
    parser.add_argument("--data", default=None, metavar="PATH",
                        help="train on a labelled BVH folder instead of the Bandai data (style folders "
                             "or labels.csv; see docs/training.md); needs --out")
    parser.add_argument("--licence", default=None, metavar="TEXT",
                        help="with --data: the licence the model card states (default: \"as the user's data\")")
    parser.add_argument("--device", default=None, metavar="cpu|cuda|mps",
                        help="where to train (default: the best available)")


def _data_flags(parser) -> None:
    """The data flags both stylizer trainers take (fields of their configs; training.data)."""
    parser.add_argument("--datasets", default="2", metavar="N,N",
                        help="Bandai sets to train on, e.g. 1,2 for every style (default: 2)")
    parser.add_argument("--speeds", default="", metavar="S,S",
                        help="also train on every take played at these speeds, e.g. 0.8,1.25 (default: none)")
    parser.add_argument("--balance", type=float, default=0.0, metavar="B",
                        help="draw windows with weight 1 / style_frames ** B (default: 0)")
    parser.add_argument("--mirror", action="store_true",
                        help="also train on every take mirrored left-right (default: off)")
    parser.add_argument("--exclude-styles", default="", metavar="NAME,NAME",
                        help="leave these styles out, e.g. to enrol one later with 'motion-style style "
                             "add' (default: none)")
    parser.add_argument("--neutral", default="normal", metavar="STYLE",
                        help="the neutral style (of --data; default: normal)")
    parser.add_argument("--unlabelled", default="", metavar="SPEC,SPEC",
                        help="also restyle these clips without style labels in training, so that the "
                             "model holds on other capture setups: cmu:SUBJECT (e.g. cmu:07), a BVH file "
                             "or a folder of them, any rig; 'eval --unseen' then leaves them out "
                             "(default: none)")
    parser.add_argument("--distil", default="", metavar="PAIRS|SPEC,SPEC",
                        help="also hold the model to pseudo-pairs: other capture setups' clips as the shipped "
                             "models stylize them, where panel 1 recognised the style; a file 'motion-style "
                             "train pairs' wrote, or clip specs (cmu:07,cmu:02_01) whose pairs are made as "
                             "'train pairs' makes them, once, into the checkpoint folder; 'eval --unseen' then "
                             "leaves those clips out (default: none)")
    parser.add_argument("--distil-weight", type=float, default=None, metavar="W",
                        help="weight of the pseudo-pairs' term beside the trainer's own losses (with --distil; "
                             "default: the trainer's Config, 1)")


def run_judges(args) -> int:
    from motion_style_ros.errors import MotionStyleError
    from motion_style_ros.evaluation.judges import KINDS
    from motion_style_ros.training.command import output, trainer_module

    judges = trainer_module("judges")

    if args.epochs is not None and args.epochs < 1:
        raise MotionStyleError(f"--epochs must be at least 1, got {args.epochs}")
    out = output(args)
    hardware = trainer_module("hardware")
    changes = {k: v for k, v in (("epochs", args.epochs), ("seed", args.seed)) if v is not None}
    changes["data"] = args.data or ""
    with hardware.session(args.threads, args.device):  # one device and process group for every judge
        with hardware.rank_zero_first():
            clips = judges.encode_clips(not hardware.rank(), changes["data"])
        for panel in (1, 2) if args.panel == "both" else (int(args.panel),):
            for kind in KINDS if args.kind == "both" else (args.kind,):
                cfg = judges.PANELS[panel](kind, **changes)
                _report_judge(judges.train(cfg, out, clips, threads=args.threads, device=args.device,
                                           licence=args.licence), out)
    return 0


def run_pairs(args) -> int:
    from pathlib import Path

    from motion_style_ros.errors import MotionStyleError
    from motion_style_ros.runtime.backends import backend
    from motion_style_ros.training import pseudo_pairs
    from motion_style_ros.training.data import FPS

    candidates = [pseudo_pairs.Candidate.parse(c) for c in args.candidates.split(",") if c]
    for c in candidates:
        backend(c.backend)  # an unknown name: one line naming the backends
    styles = [s for s in args.styles.split(",") if s] or pseudo_pairs.default_styles()
    try:
        speeds = tuple(float(v) for v in args.speeds.split(",") if v)
    except ValueError:
        speeds = (0.0,)
    if any(not v > 0 for v in speeds):
        raise MotionStyleError(f"--speeds takes positive numbers (0.8,1.25), got {args.speeds}")
    if args.posture_slack is not None and not args.posture_slack >= 0:
        raise MotionStyleError(f"--posture-slack takes degrees, 0 or more (e.g. 10), got {args.posture_slack}")
    out = Path(args.out)
    pairs = pseudo_pairs.make(tuple(c for c in args.clips.split(",") if c), candidates, styles, FPS, args.threads,
                              speeds=speeds, mirror=args.mirror, parts=pseudo_pairs.parts_folder(out),
                              posture_slack=args.posture_slack,
                              agree=tuple(j for j in args.agree.split(",") if j))
    pseudo_pairs.save_made(pairs, out)
    print(f"{pairs.meta['kept']} of {pairs.meta['tried']} clip-style pairs kept "
          f"({', '.join(f'{m} {n}' for m, n in pairs.made_counts().items())}) -> {out}")
    return 0


def _report_judge(card: dict | None, out) -> None:
    """A trained judge's figures (rank 0; None elsewhere under torchrun)."""
    if card is not None:
        acc = card["accuracy"]
        print(f"{card['name']}: test accuracy {acc['test_clip']:.3f} per clip "
              f"({acc['test_clips']} clips), {acc['test_window']:.3f} per "
              f"{acc['test_window_frames']}-frame window; {card['training']['wall_time_s']:.0f} s "
              f"-> {out / card['name']}.onnx")
