"""What every ``motion-style train <backend>`` subcommand shares, without torch (the parser is built
on every ``motion-style`` call): the :class:`TrainCommand` each trainer package's ``command`` module
declares, and the steps of a run before and after its trainer (output folder, data flags, budgets,
the resuming command, the report line). Torch is imported only when a run starts
(:func:`trainer_module`)."""

from __future__ import annotations

from typing import NamedTuple

DATA_DEFAULTS = {"datasets": "2", "speeds": "", "balance": "0", "exclude_styles": "", "neutral": "normal",
                 "unlabelled": "", "distil": ""}
# what 'train pairs' and a run's '--distil CLIPS' make (training.pseudo_pairs): every shipped model
# a candidate; every clip also at two speeds, and each of those mirrored; no posture gate; judge
# panel 3 must recognise a target beside panel 1
PAIRS_DEFAULTS = {"candidates": "recurrent,stgcn,most,saae:saae_model1.onnx,saae", "speeds": (0.8, 1.25),
                  "mirror": True, "posture_slack": None, "agree": ("judge3_style.onnx",)}


class TrainCommand(NamedTuple):
    """What one backend's ``train`` subcommand differs by: its help and description (the note on
    resuming follows, naming the checkpoint folder ``checkpoints``, default: the backend's name), its
    time budget in minutes, the files it writes, its own flags (``--flag``, add_argument's keywords) and
    where they stand: ``first``, ``middle`` (between the budgets and the output flags) or ``last``; its
    run is the ``run`` beside it in ``training/<backend>/command.py``."""
    help: str
    description: str
    minutes: float
    files: str
    flags: tuple = ()
    place: str = "last"
    checkpoint_of: str = "this seed"
    checkpoints: str | None = None


def output(args):
    """The model folder: --out, else the shipped models/ (not for a model of the user's own data)."""
    from pathlib import Path

    from motion_style_ros.errors import MotionStyleError
    from motion_style_ros.runtime.onnx_model import models_dir

    if args.data and not args.out:
        raise MotionStyleError("--data needs --out: a model of your own data would replace the shipped one")
    if args.licence and not args.data:
        raise MotionStyleError("--licence states the licence of a model of your own data: give --data")
    return Path(args.out) if args.out else models_dir()


def data_fields(args) -> tuple[dict, str]:
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
    flags = "".join(f" --{k.replace('_', '-')} {v}" for k, v in given.items() if v != DATA_DEFAULTS[k])
    user = "".join(f" --{k} {shlex.quote(v)}" for k, v in (("data", args.data), ("out", args.out),
                                                            ("licence", args.licence)) if v and args.data)
    return fields, flags + (" --mirror" if args.mirror else "") + user


def trainer_module(module: str):
    """``motion_style_ros.training.<module>`` with its torch parts loaded (a trainer package's
    ``trainer``), or a clear error where torch is missing."""
    import importlib

    from motion_style_ros.errors import MotionStyleError

    try:
        loaded = importlib.import_module(f"motion_style_ros.training.{module}")
        if hasattr(loaded, "__path__"):  # a trainer package: it loads its trainer on first use
            importlib.import_module(f"motion_style_ros.training.{module}.trainer")
        return loaded
    except ModuleNotFoundError as exc:
        if exc.name != "torch":
            raise
        raise MotionStyleError("training needs torch: pip install '.[train]'") from None


def stylizer_run(args, module: str, unlabelled: str | None = None, check=None):
    """What every stylizer trainer's command does before training: ``training.<module>``, the
    budgets checked (then ``check()``, the trainer's own flags), the model folder, the data
    fields and their flags (:func:`data_fields`); ``unlabelled``: why the trainer refuses
    --unlabelled, if it does."""
    from motion_style_ros.errors import MotionStyleError

    trainer = trainer_module(module)
    if args.minutes <= 0 or (args.iterations is not None and args.iterations < 1):
        raise MotionStyleError("--minutes must be positive and --iterations at least 1")
    if check is not None:
        check()
    out = output(args)
    fields, recipe = data_fields(args)
    weight, given = model_flags(args, {"distil_weight": "w_distil"})
    if weight and not fields["distil"]:
        raise MotionStyleError("--distil-weight weighs the pairs of --distil: give --distil too")
    fields.update(weight)
    recipe += given
    if unlabelled and fields["unlabelled"]:
        raise MotionStyleError(f"--unlabelled: {unlabelled}; 'train recurrent' does")
    if fields["distil"]:
        fields["distil"] = distil_pairs(args, trainer, fields)
    return trainer, out, fields, recipe


def distil_pairs(args, trainer, fields: dict) -> str:
    """The pairs file of ``--distil``: the file given, or the pairs of the clips given, made into the
    run's checkpoint folder unless they are there (:func:`training.pseudo_pairs.for_run`)."""
    import os

    from motion_style_ros.errors import MotionStyleError
    from motion_style_ros.training import pseudo_pairs
    from motion_style_ros.training.data import FPS
    from motion_style_ros.training.loop import CHECKPOINTS

    if int(os.environ.get("WORLD_SIZE", "1")) > 1 and not os.path.isfile(fields["distil"]):
        raise MotionStyleError("--distil CLIPS under torchrun: make the pairs first ('motion-style train "
                               "pairs --clips CLIPS --out pairs.npz') and give the file")
    folder = trainer.Trainer.folder(CHECKPOINTS, args.seed, fields["data"])
    return pseudo_pairs.for_run(fields["distil"], folder, FPS, threads=args.threads)


def run_settings(args, target: str, recipe: str, before: str = "", after: str = "") -> dict:
    """The keyword arguments every trainer's ``train`` takes from the common flags, with the
    command that resumes the run: ``motion-style train <target> <before>--minutes ... --seed ...
    <recipe> [--iterations N]<after> --resume``."""
    command = (f"motion-style train {target} {before}--minutes {args.minutes:g} --seed {args.seed}{recipe}"
               + (f" --iterations {args.iterations}" if args.iterations is not None else "") + after)
    return {"minutes": args.minutes, "iterations": args.iterations, "resume": args.resume,
            "threads": args.threads, "command": command + " --resume", "device": args.device,
            "licence": args.licence}


def report(card: dict | None, out, figures, name: str | None = None) -> int:
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


def reconstruction(val: dict, what: str = "reconstruction") -> str:
    return f"val {what} {val['val_rec']:.3f} ({val['val_rot_deg']:.1f} deg rotation RMS)"


def model_flags(args, fields: dict[str, str]) -> tuple[dict, str]:
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
