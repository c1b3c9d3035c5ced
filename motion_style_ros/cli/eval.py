"""``motion-style eval``: score stylizers beside the identity and oracle baselines on held-out takes."""

from __future__ import annotations

import argparse

from motion_style_ros.cli import eval_modes
from motion_style_ros.runtime.defaults import DEFAULTS


def _stylizers():
    from motion_style_ros.runtime.backends import BACKENDS

    return tuple(BACKENDS)


def add_parser(subparsers):
    p = subparsers.add_parser(
        "eval", help="score a stylizer and the baselines on held-out takes",
        description="Restyle Bandai test takes (dataset 2 unless --dataset 1) into every other "
                    "style and score the outputs with both panels of style and content judges and "
                    "motion metrics (style and content accuracy, FMD, content consistency, foot "
                    "skating, jerk, bone lengths), always beside the identity and oracle "
                    "baselines. Writes report.json and report.png and prints a table.",
    )
    p.add_argument("--stylizer", choices=_stylizers(), action="append", default=None,
                   help="a trained stylizer to score (repeat for several; default: the baselines only)")
    p.add_argument("--model", default=None,
                   help="model file of the stylizer (default: the shipped one)")
    p.add_argument("--alpha", type=float, default=DEFAULTS["alpha"],
                   help=f"style strength in [0, 1] (default: {DEFAULTS['alpha']:g})")
    p.add_argument("--out", default="out/eval", help="output folder (default: out/eval)")
    p.add_argument("--pairs-per-cell", type=int, default=2, metavar="K",
                   help="test takes per (content, style) cell, each paired with every other "
                        "style (default: 2)")
    p.add_argument("--seed", type=int, default=0, help="seed of the take choice (default: 0)")
    p.add_argument("--dataset", type=int, choices=(1, 2), default=2,
                   help="the Bandai set whose test takes are restyled into its own other styles "
                        "(default: 2; 1: its 18 held-out takes into its 15 styles; --record "
                        "writes it as eval_dataset1)")
    p.add_argument("--data", default=None, metavar="PATH",
                   help="instead of Bandai's: the test takes of a labelled BVH folder (its split, "
                        "written when it was indexed), restyled into its other styles; needs --judges")
    p.add_argument("--judges", default=None, metavar="DIR",
                   help="--data: the folder of judges trained on it ('motion-style train judges --data "
                        "PATH --out DIR'; the second panel where DIR has it)")
    p.add_argument("--threads", type=int, default=1, help="ONNX Runtime threads (default: 1)")
    p.add_argument("--quiet", action="store_true", help="no progress bars")
    p.add_argument("--record", action="store_true",
                   help="also write the results into the model card's metrics (one --stylizer)")
    p.add_argument("--unseen", action="store_true",
                   help="instead: stylize the CMU and Xia neutral clips (other rigs and studios, "
                        "retargeted) into every style and check for NaN, joint flips, foot skating "
                        "against the input's and bone lengths; writes unseen.json and pictures")
    p.add_argument("--posture", action="store_true",
                   help="with --unseen: the knee and hip flexion of every output against its input's, "
                        "per style, beside how far each style moves real performers (Bandai test "
                        "takes against normal's), with foot skating and the floor; writes posture.json")
    p.add_argument("--seed-spread", type=float, default=None, metavar="S",
                   help="stgcn: seeds' codes spread S times as far from their style's mean code "
                        "(default: 1, as trained); --record writes it as eval_seed_spread_S")
    p.add_argument("--reference-codes", action="store_true",
                   help="backends that take reference clips: take each pair's style from a test "
                        "take of the target style and another content (through the style encoder) "
                        "instead of the style's own; --record writes it as eval_reference_codes")
    p.add_argument("--same-content", action="store_true",
                   help="--reference-codes: references of the input's content (another take); "
                        "--record writes it as eval_reference_codes_same_content")
    p.add_argument("--consistency", action="store_true",
                   help="--reference-codes: also MoST's content and style consistencies (CC, "
                        "SC++; local joint positions, m) with references of the same and of another "
                        "content, on one seeded pair per test take")
    p.add_argument("--enrol", default=None, metavar="STYLE",
                   help="instead (stgcn, most): enrol STYLE, a Bandai style the model was not trained on, "
                        "into a style bank from --enrol-clips of its train takes, and score how "
                        "often both judge panels recognise it in dataset-2 test takes and CMU/Xia "
                        "clips restyled into it; writes enrolment.json (--record: as enrolment)")
    p.add_argument("--enrol-clips", type=int, default=4, metavar="K",
                   help="--enrol: clips to enrol from (default: 4)")
    p.add_argument("--enrol-head", default=None, metavar="HEAD",
                   help="--enrol, stgcn: the encoder head to read (a style, or mix; default: the closest)")
    p.add_argument("--controls", action="store_true",
                   help="instead (stgcn): the cost of each lookahead (0, 8, 16, 32), the "
                        "diversity of latent seeds against styles, on one test take per (content, "
                        "style); writes controls.json")
    p.add_argument("--live", action="store_true",
                   help="instead: stream every CMU and Xia clip through real nodes (bvh_player -> "
                        "stylizer per style, over DDS; the clip retargeted, not conformed, as a live "
                        "rig sends it) and compare with the offline output after the first second; "
                        "then the same clips from performers 0.8 and 1.2 times the size; writes "
                        "live_<stylizer>.json")
    p.add_argument("--live-styles", default="elderly,youthful,normal", metavar="A,B",
                   help="--live: the styles (one stylizer node each; default: elderly,youthful,normal)")
    p.add_argument("--live-clips", default="", metavar="NAME,...",
                   help="--live: only clips whose file names contain one of these (default: all)")
    p.add_argument("--no-proportions", action="store_true",
                   help="--live: skip the performer-size part")
    p.add_argument("--performer", action="store_true",
                   help="instead (saae): the learned performer, --performer-minutes of new motion per "
                        "style against the Bandai test takes: seams, foot skating, both judges on "
                        "4 s windows; writes performer.json and a picture (--record: as learned_performer)")
    p.add_argument("--performer-minutes", type=float, default=10.0, metavar="M",
                   help="--performer: minutes of stream per style (default: 10)")
    p.add_argument("--generative", default=None, nargs="*", metavar="MODEL",
                   help="instead: the SAAE paper's Table 1 (Parzen log-likelihood, G2T, T2G) for these "
                        "SAAE model files (default: every saae_*.onnx shipped); --record writes each "
                        "row into its model's card as generative")
    p.add_argument("--no-foot-lock", action="store_true",
                   help="stream without the package's foot locking (the node's foot_lock:=false; --record "
                        "adds _no_foot_lock to the key), to measure what it adds to a backend")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Check the flags every mode shares, then run the first mode a flag picks (:data:`MODES`), else
    the judged comparison."""
    from motion_style_ros.errors import MotionStyleError
    from motion_style_ros.runtime.backends import backend, with_feature

    names = args.stylizer or []
    if args.reference_codes and (not names or not all(backend(n).reference_clips for n in names)):
        raise MotionStyleError("--reference-codes scores backends that take reference clips: give "
                               f"--stylizer {' and/or '.join(with_feature('reference_clips'))}")
    if (args.same_content or args.consistency) and not args.reference_codes:
        raise MotionStyleError("--same-content and --consistency go with --reference-codes")
    if args.reference_codes and args.model and len(names) > 1:
        raise MotionStyleError("--model names one stylizer's model: give one --stylizer with it")
    if bool(args.data) != bool(args.judges):
        raise MotionStyleError("--data and --judges go together: the shipped judges know the Bandai styles "
                               "only (train them on the folder with 'motion-style train judges --data PATH "
                               "--out DIR')")
    if args.data and (args.unseen or args.controls or args.enrol or args.live or args.reference_codes):
        raise MotionStyleError("--data scores the folder's held-out takes; --unseen, --controls, --enrol, "
                               "--live and --reference-codes use the Bandai data")
    for picked, mode in MODES:
        if picked(args):
            return mode(args)
    return run_judged(args)


# The modes other than the judged comparison, in the order they take precedence when several flags are
# given: (whether the flags pick it, the function that runs it).
MODES = (
    (lambda args: args.live, eval_modes.run_live),
    (lambda args: args.posture, eval_modes.run_posture),
    (lambda args: args.unseen, eval_modes.run_unseen),
    (lambda args: args.controls, eval_modes.run_controls),
    (lambda args: args.performer, eval_modes.run_performer),
    (lambda args: args.generative is not None, eval_modes.run_generative),
    (lambda args: bool(args.enrol), eval_modes.run_enrolment),
)


def run_judged(args: argparse.Namespace) -> int:
    """Bandai's (or --data's) test takes restyled by every --stylizer and the baselines, judged by both
    panels."""
    from pathlib import Path

    from motion_style_ros.evaluation import harness
    from motion_style_ros.runtime.offline import default_model
    from motion_style_ros.runtime.onnx_model import model_path

    names = args.stylizer or []
    stylizers = eval_modes.build_stylizers(args)  # before the slow part
    judges, second = _judges(args)
    clips = harness.held_out_clips(progress=not args.quiet, dataset=args.dataset, folder=args.data)
    if args.reference_codes:
        from motion_style_ros.evaluation.references import ReferenceStylizer

        stylizers = {name: ReferenceStylizer(clips, name, args.model, args.alpha, args.threads, args.seed,
                                             args.same_content, eval_modes.session_overrides(args))
                     for name in names}
    references = dict(stylizers)  # unwrapped: the consistencies switch their same_content
    for name in names:
        path = model_path(args.model or default_model(name))
        stylizers[name] = harness.known_styles_only(stylizers[name], _styles_offered(path), path.name)
    pairs = harness.make_pairs([info for info, _ in clips], args.pairs_per_cell, args.seed)
    consistencies = _consistency(args, references, clips, pairs) if args.consistency else None
    stylizers.update(harness.baselines(clips, args.seed))
    settings = {"pairs_per_cell": args.pairs_per_cell, "seed": args.seed, "alpha": args.alpha,
                "dataset": args.data or args.dataset,
                **({"data": f"the user's labelled BVH folder {args.data}, test takes"} if args.data else {}),
                **({"foot_lock": False} if args.no_foot_lock else {}),
                **({} if args.seed_spread is None else {"seed_spread": args.seed_spread})}
    if args.reference_codes:
        settings["references"] = (f"a test take of the target style and {'the same' if args.same_content else 'another'} "
                                  "content as the input's, per pair")
    report = harness.evaluate(stylizers, clips, pairs, *judges, progress=not args.quiet,
                              settings=settings, second=second)
    if consistencies is not None:
        from dataclasses import asdict

        report["consistency"] = {name: asdict(c) for name, c in consistencies.items()}
    model = names[0] if names else None
    json_path, png_path = harness.write(report, Path(args.out), model=model)
    print(harness.format_table(report, model=model))
    if consistencies is not None:
        from motion_style_ros.evaluation.references import format_consistency

        print(format_consistency(consistencies))
    if args.record:
        summary = {name: {**system["overall"], "fmd_per_style": {
                       s: v["fmd"] for s, v in system["per_style"].items()}}
                   for name, system in report["systems"].items()}
        key = ("eval_reference_codes" + ("_same_content" if args.same_content else "") if args.reference_codes
               else f"eval_seed_spread_{args.seed_spread:g}" if args.seed_spread is not None
               else "eval" if args.dataset == 2 or args.data else f"eval_dataset{args.dataset}")
        key += "_no_foot_lock" if args.no_foot_lock else ""
        eval_modes.record(args, key, {"settings": report["settings"], "systems": summary,
                                      **({"consistency": report["consistency"]} if consistencies else {})})
    for name, system in report["systems"].items():
        if system["skipped"]:
            print(f"{name}: {len(system['skipped'])} pairs skipped "
                  f"(e.g. {system['skipped'][0]['reason']})")
    print(f"wrote {json_path} and {png_path}")
    return 0


def _styles_offered(path) -> list[str]:
    """The styles a model's sessions offer: its card's and those of the style bank beside it,
    which the sessions load by default."""
    from motion_style_ros.runtime.onnx_model import read_card
    from motion_style_ros.runtime.style_bank import names_beside

    return [*read_card(path)["styles"], *names_beside(path)]


def _consistency(args: argparse.Namespace, stylizers: dict, clips: list, pairs: list) -> dict:
    """MoST's CC and SC++ of the reference stylizers on one seeded pair per test take, against
    the train takes of the same Bandai set."""
    import numpy as np

    from motion_style_ros.evaluation.references import consistency
    from motion_style_ros.io.datasets import index_bandai, load_bandai

    rng = np.random.default_rng(args.seed)
    by_source: dict[str, list] = {}
    for pair in pairs:
        by_source.setdefault(pair.source.name, []).append(pair)
    chosen = [group[int(rng.integers(len(group)))] for _, group in sorted(by_source.items())]
    wanted = {(p.source.content, p.target) for p in chosen}
    train = [i for i in index_bandai(datasets=(args.dataset,))
             if i.split == "train" and (i.content, i.style) in wanted]
    return consistency(stylizers, clips, chosen, load_bandai(train, progress=not args.quiet),
                       progress=not args.quiet)


def _judges(args: argparse.Namespace) -> tuple[tuple, tuple | None]:
    """Both panels' style and content judges: the shipped ones, or those in --judges for --data
    (the second panel where the folder has it)."""
    from pathlib import Path

    from motion_style_ros.evaluation.judges import KINDS, Judge, judge_file

    if not args.data:
        return ((Judge("style", args.threads), Judge("content", args.threads)),
                (Judge("style", args.threads, panel=2), Judge("content", args.threads, panel=2)))
    panels = [[Path(args.judges) / judge_file(kind, panel) for kind in KINDS] for panel in (1, 2)]
    first = tuple(Judge(path, args.threads) for path in panels[0])
    second = tuple(Judge(path, args.threads) for path in panels[1]) if all(p.is_file() for p in panels[1]) else None
    return first, second
