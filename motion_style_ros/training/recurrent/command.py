"""``motion-style train recurrent``: the flags of Style-ERD (the recurrent online stylizer) and what a
run does with them (torch is imported when it runs)."""

from __future__ import annotations

from motion_style_ros.training.command import TrainCommand, model_flags, reconstruction, report, run_settings, stylizer_run

COMMAND = TrainCommand(
    "the Style-ERD online stylizer (models/style_erd.onnx)",
    "Train the Style-ERD generator with its FT-Att discriminator and content network on Bandai dataset-2 "
    "train takes, then export the streaming step to ONNX with its model card.",
    110.0, "style_erd.onnx and its card", place="middle", flags=(
        ("--foot-weight", dict(type=float, default=None, metavar="W",
                               help="weight of the foot-contact loss (default: the trainer's Config, off)")),
        ("--style-adversary", dict(
            type=float, default=None, metavar="W",
            help="weight of a style adversary on the neutral stack's output (the generator learns to leave "
                 "the input's style out of it; not in the paper; default: the trainer's Config, off)"))))


def run(args) -> int:
    flags = {"foot_weight": "w_foot", "style_adversary": "w_style_adversary"}
    recurrent, out, fields, recipe = stylizer_run(args, "recurrent", check=lambda: model_flags(args, flags))
    changes, given = model_flags(args, flags)
    cfg = recurrent.Config(seed=args.seed, **fields, **changes)
    card = recurrent.train(cfg, out, **run_settings(args, "recurrent", recipe + given))
    return report(card, out, reconstruction, "style_erd")
