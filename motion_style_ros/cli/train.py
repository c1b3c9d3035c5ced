"""``motion-style train``: train the models this package ships, on the Bandai data or a user's labelled
BVH folder (``--data``), on any device, in one process or several under ``torchrun`` (needs torch:
``pip install '.[train]'``; see docs/training.md)."""

from __future__ import annotations

from typing import NamedTuple


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
    judges.add_argument("--panel", choices=("1", "2", "both"), default="both",
                        help="which panel to train (default: both)")
    judges.add_argument("--epochs", type=int, default=None,
                        help="training epochs (default: the panel's, 15 and 8)")
    judges.add_argument("--seed", type=int, default=None, help="random seed (default: the panel's, 0 and 1)")
    judges.add_argument("--threads", type=int, default=2,
                        help="torch CPU threads (default: 2)")
    judges.add_argument("--out", default=None,
                        help="folder for the ONNX files and cards (default: the shipped models/)")
    _run_flags(judges)
    judges.set_defaults(func=run_judges)
    pairs = targets.add_parser(
        "pairs", help="pseudo-pairs from other capture setups, for 'train recurrent --distil'",
        description="Stylize clips from other capture setups into every style with every candidate "
                    "backend; of the outputs judge panel 1 recognises as the target (and whose action its "
                    "content judge still reads as the input's), keep the most confident as a regression "
                    "target. Panel 2 never looks. 'eval --unseen' leaves these clips out of a model "
                    "trained on them.")
    pairs.add_argument("--clips", required=True, metavar="SPEC,SPEC",
                       help="cmu:SUBJECT, cmu:SUBJECT_TRIAL, a BVH file or a folder of them, any rig")
    pairs.add_argument("--candidates", default="recurrent,stgcn,most,saae:saae_model1.onnx,saae",
                       metavar="BACKEND[:MODEL],...",
                       help="the stylizers whose outputs may become targets (default: every shipped model)")
    pairs.add_argument("--styles", default="", metavar="NAME,NAME",
                       help="target styles (default: those of the shipped recurrent model)")
    pairs.add_argument("--speeds", default="", metavar="S,S",
                       help="also every clip played at these speeds, e.g. 0.8,1.25 (default: none)")
    pairs.add_argument("--mirror", action="store_true", help="also every clip mirrored left-right")
    pairs.add_argument("--threads", type=int, default=1, help="ONNX Runtime threads (default: 1)")
    pairs.add_argument("--out", required=True, help="the pairs file to write (.npz)")
    pairs.set_defaults(func=run_pairs)
    from motion_style_ros.runtime.backends import BACKENDS

    for name in BACKENDS:
        trainer = TRAINERS.get(name)
        if trainer is None:  # a backend with no trainer here (one a test registers)
            continue
        parser = targets.add_parser(name, help=trainer.help, description=trainer.description + " "
                                    + _RESUMABLE.format(trainer.checkpoints or name))
        _own_flags(parser, trainer, "first")
        _budget_flags(parser, trainer.minutes)
        _own_flags(parser, trainer, "middle")
        _output_flags(parser, trainer.files, trainer.checkpoint_of)
        _own_flags(parser, trainer, "last")
        parser.set_defaults(func=globals()[f"run_{name}"])


_DATA_DEFAULTS = {"datasets": "2", "speeds": "", "balance": "0", "exclude_styles": "", "neutral": "normal",
                  "unlabelled": "", "distil": ""}
_RESUMABLE = ("Checkpoints every few minutes to ~/.cache/motion_style_ros/checkpoints/{}_<seed>/ (with "
              "losses.jsonl); --resume continues a stopped run, and the time and iteration budgets count "
              "over all resumed runs, so the same command finishes the job.")


class Trainer(NamedTuple):
    """What one backend's ``train`` subcommand differs by: its help and description (the note on
    resuming follows, naming the checkpoint folder ``checkpoints``, default: the backend's name), its
    time budget in minutes, the files it writes, its own flags (``--flag``, add_argument's keywords) and
    where they stand: ``first``, ``middle`` (between the budgets and the output flags) or ``last``; its
    run function is ``run_<backend>``."""
    help: str
    description: str
    minutes: float
    files: str
    flags: tuple = ()
    place: str = "last"
    checkpoint_of: str = "this seed"
    checkpoints: str | None = None


TRAINERS = {
    "recurrent": Trainer(
        "the Style-ERD online stylizer (models/style_erd.onnx)",
        "Train the Style-ERD generator with its FT-Att discriminator and content network on Bandai dataset-2 "
        "train takes, then export the streaming step to ONNX with its model card.",
        110.0, "style_erd.onnx and its card", place="middle", flags=(
            ("--foot-weight", dict(type=float, default=None, metavar="W",
                                   help="weight of the foot-contact loss (default: the trainer's Config, off)")),
            ("--style-adversary", dict(
                type=float, default=None, metavar="W",
                help="weight of a style adversary on the neutral stack's output (the generator learns to leave "
                     "the input's style out of it; not in the paper; default: the trainer's Config, off)")))),
    "stgcn": Trainer(
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
                                   "output channels, uncapped)")))),
    "saae": Trainer(
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
                                 help="Model2's style code size, 2 to 5 in the paper (default: 5)")))),
    "most": Trainer(
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
                                     "(not in the paper; default: the trainer's Config, off)")))),
}


def _own_flags(parser, trainer: Trainer, place: str) -> None:
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


def _output(args):
    """The model folder: --out, else the shipped models/ (not for a model of the user's own data)."""
    from pathlib import Path

    from motion_style_ros.errors import MotionStyleError
    from motion_style_ros.runtime.onnx_model import models_dir

    if args.data and not args.out:
        raise MotionStyleError("--data needs --out: a model of your own data would replace the shipped one")
    if args.licence and not args.data:
        raise MotionStyleError("--licence states the licence of a model of your own data: give --data")
    return Path(args.out) if args.out else models_dir()


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
    parser.add_argument("--distil", default="", metavar="PAIRS",
                        help="also hold the model to the targets of a pseudo-pairs file ('motion-style train "
                             "pairs'): other capture setups' clips in the style panel 1 recognised; 'eval "
                             "--unseen' then leaves those clips out (default: none)")


def _data_fields(args) -> tuple[dict, str]:
    """The config fields of the data flags, and the flags as they would be typed again."""
    import shlex

    from motion_style_ros.errors import MotionStyleError

    try:
        fields = {"datasets": tuple(int(n) for n in args.datasets.split(",")),
                  "speeds": tuple(float(v) for v in args.speeds.split(",") if v),
                  "balance": args.balance, "mirror": args.mirror,
                  "exclude": tuple(n for n in args.exclude_styles.split(",") if n),
                  "data": args.data or "", "neutral": args.neutral,
                  "unlabelled": tuple(n for n in args.unlabelled.split(",") if n), "distil": args.distil}
    except ValueError:
        raise MotionStyleError("--datasets takes set numbers (1,2) and --speeds numbers (0.8,1.25)") from None
    if not fields["datasets"] or not set(fields["datasets"]) <= {1, 2} or any(v <= 0 for v in fields["speeds"]):
        raise MotionStyleError("--datasets takes 1 and/or 2; --speeds positive numbers")
    given = {"datasets": args.datasets, "speeds": args.speeds, "balance": f"{args.balance:g}",
             "exclude_styles": args.exclude_styles, "neutral": args.neutral, "unlabelled": args.unlabelled,
             "distil": args.distil}
    flags = "".join(f" --{k.replace('_', '-')} {v}" for k, v in given.items() if v != _DATA_DEFAULTS[k])
    user = "".join(f" --{k} {shlex.quote(v)}" for k, v in (("data", args.data), ("out", args.out),
                                                            ("licence", args.licence)) if v and args.data)
    return fields, flags + (" --mirror" if args.mirror else "") + user


def _training(module: str):
    """``motion_style_ros.training.<module>``, or a clear error where torch is missing."""
    import importlib

    from motion_style_ros.errors import MotionStyleError

    try:
        return importlib.import_module(f"motion_style_ros.training.{module}")
    except ModuleNotFoundError as exc:
        if exc.name != "torch":
            raise
        raise MotionStyleError("training needs torch: pip install '.[train]'") from None


def run_judges(args) -> int:
    from motion_style_ros.errors import MotionStyleError
    from motion_style_ros.evaluation.judges import KINDS

    judges = _training("judges")

    if args.epochs is not None and args.epochs < 1:
        raise MotionStyleError(f"--epochs must be at least 1, got {args.epochs}")
    out = _output(args)
    hardware = _training("hardware")
    changes = {k: v for k, v in (("epochs", args.epochs), ("seed", args.seed)) if v is not None}
    changes["data"] = args.data or ""
    with hardware.session(args.threads, args.device):  # one device and process group for every judge
        with hardware.rank_zero_first():
            clips = judges.encode_clips(not hardware.rank(), changes["data"])
        for panel in (1, 2) if args.panel == "both" else (int(args.panel),):
            for kind in KINDS if args.kind == "both" else (args.kind,):
                cfg = (judges.Config(kind=kind, **changes) if panel == 1
                       else judges.second_panel(kind, **changes))
                _report_judge(judges.train(cfg, out, clips, threads=args.threads, device=args.device,
                                           licence=args.licence), out)
    return 0


def run_pairs(args) -> int:
    from pathlib import Path

    from motion_style_ros.errors import MotionStyleError
    from motion_style_ros.runtime.backends import backend
    from motion_style_ros.runtime.onnx_model import model_path, read_card
    from motion_style_ros.training import pseudo_pairs
    from motion_style_ros.training.data import FPS

    candidates = [pseudo_pairs.Candidate.parse(c) for c in args.candidates.split(",") if c]
    for c in candidates:
        backend(c.backend)  # an unknown name: one line naming the backends
    styles = ([s for s in args.styles.split(",") if s]
              or read_card(model_path(backend("recurrent").default_model))["styles"])
    try:
        speeds = tuple(float(v) for v in args.speeds.split(",") if v)
    except ValueError:
        speeds = (0.0,)
    if any(not v > 0 for v in speeds):
        raise MotionStyleError(f"--speeds takes positive numbers (0.8,1.25), got {args.speeds}")
    pairs = pseudo_pairs.make(tuple(c for c in args.clips.split(",") if c), candidates, styles, FPS, args.threads,
                              speeds=speeds, mirror=args.mirror)
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    pseudo_pairs.save(pairs, out)
    made = {m: pairs.made_by.count(m) for m in pairs.meta["candidates"]}
    print(f"{pairs.meta['kept']} of {pairs.meta['tried']} clip-style pairs kept "
          f"({', '.join(f'{m} {n}' for m, n in made.items())}) -> {out}")
    return 0


def _report_judge(card: dict | None, out) -> None:
    """A trained judge's figures (rank 0; None elsewhere under torchrun)."""
    if card is not None:
        acc = card["accuracy"]
        print(f"{card['name']}: test accuracy {acc['test_clip']:.3f} per clip "
              f"({acc['test_clips']} clips), {acc['test_window']:.3f} per "
              f"{acc['test_window_frames']}-frame window; {card['training']['wall_time_s']:.0f} s "
              f"-> {out / card['name']}.onnx")


def _stylizer_run(args, module: str, unlabelled: str | None = None, check=None):
    """What every stylizer trainer's command does before training: ``training.<module>``, the
    budgets checked (then ``check()``, the trainer's own flags), the model folder, the data
    fields and their flags (:func:`_data_fields`); ``unlabelled``: why the trainer refuses
    --unlabelled, if it does."""
    from motion_style_ros.errors import MotionStyleError

    trainer = _training(module)
    if args.minutes <= 0 or (args.iterations is not None and args.iterations < 1):
        raise MotionStyleError("--minutes must be positive and --iterations at least 1")
    if check is not None:
        check()
    out = _output(args)
    fields, recipe = _data_fields(args)
    if unlabelled and fields["unlabelled"]:
        raise MotionStyleError(f"--unlabelled: {unlabelled}; 'train recurrent' does")
    if module != "recurrent" and fields["distil"]:
        raise MotionStyleError("--distil: only 'train recurrent' learns from pseudo-pairs so far")
    return trainer, out, fields, recipe


def _run_settings(args, target: str, recipe: str, before: str = "", after: str = "") -> dict:
    """The keyword arguments every trainer's ``train`` takes from the common flags, with the
    command that resumes the run: ``motion-style train <target> <before>--minutes ... --seed ...
    <recipe> [--iterations N]<after> --resume``."""
    command = (f"motion-style train {target} {before}--minutes {args.minutes:g} --seed {args.seed}{recipe}"
               + (f" --iterations {args.iterations}" if args.iterations is not None else "") + after)
    return {"minutes": args.minutes, "iterations": args.iterations, "resume": args.resume,
            "threads": args.threads, "command": command + " --resume", "device": args.device,
            "licence": args.licence}


def _report(card: dict | None, out, figures, name: str | None = None) -> int:
    """A trained stylizer's line (rank 0; ``card`` is None elsewhere under torchrun): ``name``
    (default: the card's), iterations and minutes, ``figures(val)`` of its last validation, the
    ONNX export's difference from torch and its file."""
    if card is None:  # not rank 0 of a torchrun
        return 0
    history = card["training"]["history"]
    print(f"{name or card['name']}: {history['iterations']} iterations in {history['train_seconds'] / 60:.0f} "
          f"min; {figures(history['val'][-1])}; ONNX vs torch {card['training']['onnx_torch_max_abs_diff']:.1e} "
          f"-> {out / card['name']}.onnx")
    return 0


def _reconstruction(val: dict, what: str = "reconstruction") -> str:
    return f"val {what} {val['val_rec']:.3f} ({val['val_rot_deg']:.1f} deg rotation RMS)"


def _model_flags(args, fields: dict[str, str]) -> tuple[dict, str]:
    """A trainer's own flags that were given (``fields``: flag attribute -> config field): the
    config changes and the flags as the resuming command repeats them. Weights (the float flags)
    are checked to be 0 or more."""
    from motion_style_ros.errors import MotionStyleError

    given = {flag: getattr(args, flag) for flag in fields if getattr(args, flag) is not None}
    for flag, value in given.items():
        if isinstance(value, float) and not value >= 0:
            raise MotionStyleError(f"--{flag.replace('_', '-')} must be 0 or more, got {value:g}")
    return ({fields[flag]: value for flag, value in given.items()},
            "".join(f" --{flag.replace('_', '-')}" + ("" if value is True else f" {value:g}")
                    for flag, value in given.items()))


def run_recurrent(args) -> int:
    flags = {"foot_weight": "w_foot", "style_adversary": "w_style_adversary"}
    recurrent, out, fields, recipe = _stylizer_run(args, "recurrent", check=lambda: _model_flags(args, flags))
    changes, given = _model_flags(args, flags)
    cfg = recurrent.Config(seed=args.seed, **fields, **changes)
    card = recurrent.train(cfg, out, **_run_settings(args, "recurrent", recipe + given))
    return _report(card, out, _reconstruction, "style_erd")


def run_stgcn(args) -> int:
    stgcn, out, fields, recipe = _stylizer_run(args, "stgcn")
    after = "".join(f" --{flag} {value:g}" if isinstance(value, float) else f" --{flag} {value}"
                    for flag, value in (("init-from", args.init_from), ("ds-cap", args.ds_cap),
                                        ("ds-weight", args.ds_weight)) if value is not None)
    changes = {"ds_cap": args.ds_cap, **({"w_ds": args.ds_weight} if args.ds_weight is not None else {})}
    card = stgcn.train(stgcn.Config(seed=args.seed, **fields, **changes), out,
                       **_run_settings(args, "stgcn", recipe, after=after), init_from=args.init_from)
    return _report(card, out, lambda val: (
        f"{_reconstruction(val, 'identity reconstruction')}, style encoder accuracy {val['val_style_acc']:.2f}, "
        f"transfers recognised {val['val_transfer_style_acc']:.2f}"), "stgcn")


def run_saae(args) -> int:
    from motion_style_ros.errors import MotionStyleError

    def style_dim() -> None:
        if not 1 <= args.style_dim <= 64:
            raise MotionStyleError(f"--style-dim must be 1 to 64 (the paper's are 2 to 5), got {args.style_dim}")

    saae, out, fields, recipe = _stylizer_run(args, "saae", "the SAAE trainer does not use unlabelled clips",
                                              style_dim)
    cfg = saae.Config(seed=args.seed, variant=args.variant, style_dim=args.style_dim, **fields)
    card = saae.train(cfg, out, **_run_settings(args, "saae", recipe,
                                                before=f"--variant {args.variant} --style-dim {args.style_dim} "))
    return _report(card, out, lambda val: _reconstruction(val) + "".join(
        f", {label} {val[key]:.2f}" for key, label in (
            ("val_content_style_acc", "style read from the content code"),
            ("val_style_code_acc", "from the style code"),
            ("val_transfer_style_acc", "transfers recognised")) if key in val))


def run_most(args) -> int:
    from motion_style_ros.errors import MotionStyleError

    flags = {"content_weight": "w_content", "content_net_weight": "w_content_net", "dec_blocks": "dec_blocks",
             "residual": "residual"}

    def checked() -> None:
        _model_flags(args, flags)
        if args.dec_blocks is not None and not 1 <= args.dec_blocks <= 8:
            raise MotionStyleError(f"--dec-blocks must be 1 to 8 (the paper's code: 3), got {args.dec_blocks}")

    most, out, fields, recipe = _stylizer_run(args, "most", "the MoST trainer does not restyle unlabelled clips",
                                              checked)
    changes, after = _model_flags(args, flags)
    card = most.train(most.Config(seed=args.seed, **fields, **changes), out,
                      **_run_settings(args, "most", recipe, after=after))
    return _report(card, out, lambda val: (
        f"{_reconstruction(val)}, disentanglement {val['val_disentangle']:.3f}, transfers nearest their "
        f"style {val['val_transfer_style_acc']:.2f}"), "most")
