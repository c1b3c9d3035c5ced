"""``motion-style train most``: the flags of the MoST reference-clip stylizer and what a run does with
them (torch is imported when it runs)."""

from __future__ import annotations

from motion_style_ros.training.command import TrainCommand, model_flags, reconstruction, report, run_settings, stylizer_run

COMMAND = TrainCommand(
    "the MoST reference-clip stylizer (models/most*.onnx)",
    "Train MoST (Kim et al. 2024: Siamese transformer encoder, part-attentive style modulator, AdaIN "
    "transformer generator, discriminator) on Bandai dataset-2 train takes, then export the streamed "
    "step and the reference style encoder to ONNX with every style's mean features and the model card.",
    100.0, "most*.onnx, the style means and the card", place="first", flags=(
        ("--content-weight", dict(
            type=float, default=None, metavar="W",
            help="weight of the content term (the transfer's frame content features against the input's; "
                 "not in the paper; default: the trainer's Config)")),
        ("--content-net-weight", dict(
            type=float, default=None, metavar="W",
            help="weight of a content classifier's cross-entropy on the transfer against the input's "
                 "content label (a content network trained on the train takes first; not in the paper; "
                 "default: the trainer's Config, off)")),
        ("--dec-blocks", dict(type=int, default=None, metavar="N",
                              help="generator blocks (the paper's code: 3; default: the trainer's Config)")),
        ("--residual", dict(action="store_const", const=True, default=None,
                            help="the generator gives a change to the input's own frames, starting at none "
                                 "(not in the paper; default: the trainer's Config, off)"))))


def run(args) -> int:
    from motion_style_ros.errors import MotionStyleError

    flags = {"content_weight": "w_content", "content_net_weight": "w_content_net", "dec_blocks": "dec_blocks",
             "residual": "residual"}

    def checked() -> None:
        model_flags(args, flags)
        if args.dec_blocks is not None and not 1 <= args.dec_blocks <= 8:
            raise MotionStyleError(f"--dec-blocks must be 1 to 8 (the paper's code: 3), got {args.dec_blocks}")

    most, out, fields, recipe = stylizer_run(args, "most", "the MoST trainer does not restyle unlabelled clips",
                                              checked)
    changes, after = model_flags(args, flags)
    card = most.train(most.Config(seed=args.seed, **fields, **changes), out,
                      **run_settings(args, "most", recipe, after=after))
    return report(card, out, lambda val: (
        f"{reconstruction(val)}, disentanglement {val['val_disentangle']:.3f}, transfers nearest their "
        f"style {val['val_transfer_style_acc']:.2f}"), "most")
