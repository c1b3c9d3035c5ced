"""``motion-style style``: enrol a style of your own from a few clips into a model's style bank."""


# Said wherever enrolment is offered (``style --help`` and ``style add --help``); the figures are
# docs/models.md's "Styles enrolled from a few clips".
EXPERIMENTAL = ("Experimental: no shipped model renders a style it was not trained on from a few clips "
                "yet ('proud', left out of training and enrolled from 4 takes, was recognised on 0-10 % "
                "of outputs by both judge panels, where its real takes are recognised; motion-style eval "
                "--stylizer stgcn --enrol proud; docs/models.md).")


def add_parser(subparsers):
    p = subparsers.add_parser(
        "style", help="enrol, list and remove your own styles (stgcn and most style banks)",
        description="A style bank holds styles enrolled from a few clips, without retraining, for a "
                    "model with a style encoder: stgcn (the encoder's code of the clips) or most "
                    "(the clips' own style features), averaged over the clips. It is a JSON file "
                    "beside the model (stgcn_styles.json, most_styles.json) that the sessions and "
                    "the stylizer node read, so target_style accepts the new name. Clips are BVH "
                    "files of any humanoid rig the package retargets. " + EXPERIMENTAL,
    )
    actions = p.add_subparsers(dest="action", metavar="ACTION", required=True)
    add = actions.add_parser("add", help="enrol a style from clips of it (experimental)",
                             description="Enrol NAME from the clips (3-5 clips of a few seconds each; "
                                         "every clip must show the style). " + EXPERIMENTAL)
    add.add_argument("name", metavar="NAME", help="the new style's name (lowercase letters, digits, - and _)")
    add.add_argument("clips", metavar="CLIP.bvh", nargs="+", help="clips of the style")
    add.add_argument("--head", default=None, metavar="STYLE",
                     help="stgcn: read the codes under this known style's head, or 'mix': every "
                          "head's code weighted by the classifier's probabilities (default: the style "
                          "the clips are closest to, by the encoder's classifier)")
    add.add_argument("--replace", action="store_true", help="replace NAME if the bank has it")
    listing = actions.add_parser("list", help="the styles of a model and its bank")
    remove = actions.add_parser("remove", help="remove an enrolled style")
    remove.add_argument("name", metavar="NAME")
    for sub in (add, listing, remove):
        sub.add_argument("--model", default="stgcn.onnx",
                         help="the model, stgcn or most: a shipped file name or a path (default: stgcn.onnx)")
        sub.add_argument("--bank", default=None, metavar="FILE",
                         help="the style bank file (default: <model>_styles.json beside the model)")
        sub.set_defaults(func=run)


def run(args) -> int:
    from pathlib import Path

    from motion_style_ros.errors import MotionStyleError
    from motion_style_ros.runtime import style_bank
    from motion_style_ros.runtime.backends import BACKENDS, with_feature
    from motion_style_ros.runtime.onnx_model import model_path, read_card

    path = model_path(args.model)
    kind = read_card(path).get("kind")  # a card's kind is its backend's name
    if kind not in BACKENDS or not BACKENDS[kind].style_bank:
        raise MotionStyleError(f"{path.name}: a {kind} model; a style bank needs a "
                               f"{' or '.join(with_feature('style_bank'))} model (a style encoder)")
    bank = Path(args.bank) if args.bank else style_bank.path_beside(path)
    session = BACKENDS[kind].open_session(path, lookahead=0, bank=bank if bank.exists() else None)  # its encoder only
    known = session.styles[: len(session.card["styles"])]
    entries = dict(session.bank)
    if args.action == "list":
        print(f"{session.card['name']}: {', '.join(known)}")
        for name, e in entries.items():
            print(f"{name}: {len(e.clips)} clips, {e.frames} frames, read under {e.head!r} "
                  f"(closest: {', '.join(f'{k} {v:.2f}' for k, v in e.probabilities.items())})")
        if not entries:
            print(f"no enrolled styles ({bank})")
        return 0
    if args.action == "remove":
        if args.name not in entries:
            raise MotionStyleError(f"{bank} has no style {args.name!r}"
                                   + (f"; it has {', '.join(entries)}" if entries else ""))
        del entries[args.name]
    else:
        name = style_bank.check_name(args.name, known)
        if name in entries and not args.replace:
            raise MotionStyleError(f"{bank} has a style {name!r} already; --replace to enrol it again")
        files, clips = _usable(session, args.clips)
        entries[name] = entry = session.enrol(clips, files, args.head)
        print(f"{name}: {len(clips)} clips, {entry.frames} frames at {session.fps:g} fps, read under "
              f"{entry.head!r} (closest: {', '.join(f'{k} {v:.2f}' for k, v in entry.probabilities.items())})")
    style_bank.write(bank, entries, session.card["name"], session.model_digest)
    print(f"wrote {bank}: {len(entries)} enrolled styles")
    return 0


def _usable(session, paths: list[str]) -> tuple[list[str], list]:
    """The clips that can serve as references, by file name; the others are left out with a
    warning that says why (too short for the model's window, not finite), so that one short
    take among a user's clips does not stop the enrolment. A file that cannot be read stops it."""
    import sys
    from pathlib import Path

    from motion_style_ros.cli.main import PROG
    from motion_style_ros.errors import MotionStyleError
    from motion_style_ros.io.canonical import canonical_clip

    files, clips, skipped = [], [], []
    for path in paths:
        clip = canonical_clip(path)
        try:
            session.reference_clip(clip, session.window)
        except MotionStyleError as exc:
            skipped.append(f"{Path(path).name}: {exc}")
            continue
        files.append(Path(path).name)
        clips.append(clip)
    for line in skipped:
        print(f"{PROG} style: warning: left out {line}", file=sys.stderr)
    if not clips:
        raise MotionStyleError(f"none of the {len(paths)} clips can serve: {skipped[0]}"
                               + (f" (and {len(skipped) - 1} more)" if len(skipped) > 1 else ""))
    return files, clips
