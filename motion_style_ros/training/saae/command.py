"""``motion-style train saae``: the flags of the sequence adversarial autoencoder and what a run does
with them (torch is imported when it runs)."""

from __future__ import annotations

from motion_style_ros.training.command import TrainCommand, reconstruction, report, run_settings, stylizer_run

COMMAND = TrainCommand(
    "the sequence adversarial autoencoder: plain SAAE, Model1, Model2 (models/saae_*.onnx)",
    "Train the sequence adversarial autoencoder of the ESANN 2018 seed on Bandai dataset-2 "
    "train takes: a GRU encoder and decoder whose content codes a discriminator pushes towards N(0, I); "
    "Model1's decoder takes the style label, Model2's a style code of --style-dim dims from the encoder; "
    "both hide the style from the content code through a reversed-gradient style discriminator. Exports "
    "the decoder, encoder (and Model2's style encoder) to ONNX with the card, as saae_plain, saae_model1 "
    "or saae_model2_<d>d.",
    110.0, "saae_*.onnx and the card", place="first", checkpoint_of="this variant and seed",
    checkpoints="<that name>", flags=(
        ("--variant", dict(choices=("saae", "model1", "model2"), default="model2",
                           help="saae: the plain baseline (no style input); model1: decoder takes the "
                                "style label; model2: a style code (default: model2)")),
        ("--style-dim", dict(type=int, default=5, metavar="D",
                             help="Model2's style code size, 2 to 5 in the paper (default: 5)"))))


def run(args) -> int:
    from motion_style_ros.errors import MotionStyleError

    def style_dim() -> None:
        if not 1 <= args.style_dim <= 64:
            raise MotionStyleError(f"--style-dim must be 1 to 64 (the paper's are 2 to 5), got {args.style_dim}")

    saae, out, fields, recipe = stylizer_run(args, "saae", "the SAAE trainer does not use unlabelled clips",
                                              style_dim)
    cfg = saae.Config(seed=args.seed, variant=args.variant, style_dim=args.style_dim, **fields)
    card = saae.train(cfg, out, **run_settings(args, "saae", recipe,
                                                before=f"--variant {args.variant} --style-dim {args.style_dim} "))
    return report(card, out, lambda val: reconstruction(val) + "".join(
        f", {label} {val[key]:.2f}" for key, label in (
            ("val_content_style_acc", "style read from the content code"),
            ("val_style_code_acc", "from the style code"),
            ("val_transfer_style_acc", "transfers recognised")) if key in val))
