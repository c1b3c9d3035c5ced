"""``motion-style train stgcn``: the flags of the windowed ST-GCN stylizer and what a run does with
them (torch is imported when it runs)."""

from __future__ import annotations

from motion_style_ros.training.command import TrainCommand, reconstruction, report, run_settings, stylizer_run

COMMAND = TrainCommand(
    "the windowed ST-GCN stylizer (models/stgcn*.onnx)",
    "Train the ST-GCN generator, mapping network, style encoder and discriminator (Park et al. 2021) on "
    "Bandai dataset-2 train takes, then export the first three to ONNX with the model card.",
    100.0, "stgcn*.onnx and the card", flags=(
        ("--init-from", dict(type=int, default=None, metavar="SEED",
                             help="a new run continues this seed's checkpoint (weights, optimisers, "
                                  "iterations and time) under this run's settings")),
        ("--ds-weight", dict(type=float, default=None, metavar="W",
                             help="weight of the diversity loss at iteration 0, decaying linearly to 0 "
                                  "(default: 4)")),
        ("--ds-cap", dict(type=float, default=None, metavar="M",
                          help="diversity loss on the pelvis-relative pose, pushing two seeds apart until "
                               "their joints differ by M metres on average (default: on the normalised "
                               "output channels, uncapped)"))))


def run(args) -> int:
    stgcn, out, fields, recipe = stylizer_run(args, "stgcn")
    after = "".join(f" --{flag} {value:g}" if isinstance(value, float) else f" --{flag} {value}"
                    for flag, value in (("init-from", args.init_from), ("ds-cap", args.ds_cap),
                                        ("ds-weight", args.ds_weight)) if value is not None)
    changes = {"ds_cap": args.ds_cap, **({"w_ds": args.ds_weight} if args.ds_weight is not None else {})}
    card = stgcn.train(stgcn.Config(seed=args.seed, **fields, **changes), out,
                       **run_settings(args, "stgcn", recipe, after=after), init_from=args.init_from)
    return report(card, out, lambda val: (
        f"{reconstruction(val, 'identity reconstruction')}, style encoder accuracy {val['val_style_acc']:.2f}, "
        f"transfers recognised {val['val_transfer_style_acc']:.2f}"), "stgcn")
