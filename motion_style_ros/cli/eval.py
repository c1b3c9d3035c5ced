"""``motion-style eval``: score stylizers beside the identity and oracle baselines on held-out takes."""

from __future__ import annotations

import argparse


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
    p.add_argument("--alpha", type=float, default=1.0, help="style strength in [0, 1] (default: 1)")
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
    from pathlib import Path

    from motion_style_ros.errors import MotionStyleError
    from motion_style_ros.evaluation import harness
    from motion_style_ros.runtime.backends import backend, with_feature
    from motion_style_ros.runtime.offline import default_model, stylizer
    from motion_style_ros.runtime.onnx_model import model_path

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
    # Build the stylizers first: a missing model fails here in one line, before the slow part.
    stylizers = {name: stylizer(name, args.model, args.alpha, args.threads, args.seed_spread,
                                **backend(name).settings(harness.PUBLISHED), **_overrides(args))
                 for name in names}
    if args.live:
        from motion_style_ros.cli import eval_live

        if len(names) != 1:
            raise MotionStyleError("--live streams one stylizer: give one --stylizer")
        return eval_live.run(args, names[0])
    if args.posture:
        if not args.unseen or args.reference_codes:
            raise MotionStyleError("--posture goes with --unseen (the CMU and Xia clips), without --reference-codes")
        return run_posture(args, stylizers)
    if args.unseen:
        if args.reference_codes:  # references: Bandai test takes of the target style
            from motion_style_ros.evaluation.references import ReferenceStylizer

            clips = harness.held_out_clips(progress=not args.quiet, dataset=args.dataset)
            stylizers = {name: ReferenceStylizer(clips, name, args.model, args.alpha, args.threads, args.seed,
                                                 session=_overrides(args))
                         for name in names}
        return run_unseen(args, stylizers)
    if args.controls:
        return run_controls(args)
    if args.performer:
        return run_performer(args)
    if args.generative is not None:
        return run_generative(args)
    if args.enrol:
        return run_enrolment(args)
    judges, second = _judges(args)
    clips = harness.held_out_clips(progress=not args.quiet, dataset=args.dataset, folder=args.data)
    if args.reference_codes:
        from motion_style_ros.evaluation.references import ReferenceStylizer

        stylizers = {name: ReferenceStylizer(clips, name, args.model, args.alpha, args.threads, args.seed,
                                             args.same_content, _overrides(args)) for name in names}
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
        _record(args, key, {"settings": report["settings"], "systems": summary,
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


def _overrides(args: argparse.Namespace) -> dict:
    """Session settings the flags change from the published ones."""
    return {"foot_lock": False} if args.no_foot_lock else {}


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


def run_unseen(args: argparse.Namespace, stylizers: dict) -> int:
    import json
    from pathlib import Path

    from motion_style_ros.errors import MotionStyleError
    from motion_style_ros.evaluation import unseen
    from motion_style_ros.evaluation.judges import Judge
    from motion_style_ros.io.render import render_gif, render_png
    from motion_style_ros.runtime.offline import default_model
    from motion_style_ros.runtime.onnx_model import model_path, read_card

    if not stylizers:
        raise MotionStyleError("--unseen checks trained stylizers: name one with --stylizer")
    judges = [Judge("style", args.threads), Judge("style", args.threads, panel=2)]
    cards = {name: read_card(model_path(args.model or default_model(name))) for name in stylizers}
    # clips any of the models trained on (train --unlabelled) are not unseen: every model is
    # measured on the same others
    trained = tuple(sorted({c for card in cards.values() for c in card["training"].get("clips", {}).get("unlabelled", [])}))
    clips = unseen.neutral_clips(leave_out=trained)
    if trained:
        print(f"left out {len(trained)} clips a model trained on: {', '.join(trained)}")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    reports = {}
    for name, stylize in stylizers.items():
        styles = cards[name]["styles"]
        reports[name] = unseen.evaluate(stylize, styles, clips, judges, progress=not args.quiet)
        print(f"{name}: " + ", ".join(f"{k} {_fmt(v)}" for k, v in reports[name]["summary"].items()))
        # Pictures: the input beside two contrasting styles, for a walk of each studio.
        for title, source in (clips[0], clips[-1]):
            motions, titles = [source], [title]
            for style in ("elderly", "youthful"):
                motions.append(stylize(source, style))
                titles.append(f"{name}: {style}")
                if getattr(stylize, "last_reference", None):  # the reference clip beside its output
                    reference, motion = stylize.last_reference
                    motions.insert(-1, motion)
                    titles.insert(-1, f"reference {reference.removeprefix('dataset-2_')}")
            stem = out / f"unseen_{name}_{title.split()[1]}"
            render_png(motions, titles, stem.with_suffix(".png"))
            render_gif(motions, titles, stem.with_suffix(".gif"), seconds=6.0)
            print(f"wrote {stem}.png and {stem}.gif")
    path = out / "unseen.json"
    settings = {"alpha": args.alpha, "judges": [j.model.path.name for j in judges], "left_out": list(trained),
                **({"foot_lock": False} if args.no_foot_lock else {}),
                **({"references": f"Bandai dataset-{args.dataset} test takes of the target style"}
                   if args.reference_codes else {})}
    path.write_text(json.dumps({"settings": settings, **reports}, indent=1) + "\n")
    print(f"wrote {path}")
    if args.record:
        key = ("unseen_reference_codes" if args.reference_codes else "unseen") + (
            "_no_foot_lock" if args.no_foot_lock else "")
        _record(args, key, {"alpha": args.alpha, **reports[args.stylizer[0]]["summary"]})
    return 0


def run_posture(args: argparse.Namespace, stylizers: dict) -> int:
    import json
    from pathlib import Path

    from motion_style_ros.errors import MotionStyleError
    from motion_style_ros.evaluation import harness, posture, unseen
    from motion_style_ros.runtime.offline import default_model
    from motion_style_ros.runtime.onnx_model import model_path, read_card

    if not stylizers:
        raise MotionStyleError("--posture checks trained stylizers: name one with --stylizer")
    shifts = posture.style_shifts(harness.held_out_clips(progress=not args.quiet))
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    reports = {}
    for name, stylize in stylizers.items():
        card = read_card(model_path(args.model or default_model(name)))
        # clips the model trained on (train --unlabelled) are left out, as --unseen leaves them out
        clips = unseen.neutral_clips(leave_out=tuple(card["training"].get("clips", {}).get("unlabelled", [])))
        reports[name] = {"clips": len(clips), **posture.evaluate(stylize, card["styles"], clips, shifts)}
        print(f"{name} ({len(clips)} clips): " + posture.format_table(name, reports[name]).split(": ", 1)[1])
    path = out / "posture.json"
    settings = {"alpha": args.alpha, **({"foot_lock": False} if args.no_foot_lock else {})}
    path.write_text(json.dumps({"settings": settings, "bandai_shifts": shifts, **reports}, indent=1) + "\n")
    print(f"wrote {path}")
    return 0


def run_controls(args: argparse.Namespace) -> int:
    import json
    from pathlib import Path

    from motion_style_ros.errors import MotionStyleError
    from motion_style_ros.evaluation import harness, windowed

    if args.stylizer != ["stgcn"]:
        raise MotionStyleError("--controls measures the windowed stylizer's controls: give --stylizer stgcn")
    model = args.model or windowed.DEFAULT_MODEL
    pairs = windowed.control_pairs(harness.held_out_clips(progress=not args.quiet), args.seed)
    sources = [source for source, _ in pairs[::len(pairs) // 4]][:4]
    report = {
        "lookahead_costs": {"pairs": f"{len(pairs)} test takes, one per (content, style), each into "
                                     "the next style; hop 4 (lookahead 0: hop 1)",
                            "rows": windowed.lookahead_costs(pairs, model)},
        "diversity": {**windowed.diversity(sources, windowed.DIVERSITY_STYLES, model),
                      "meaning": "mean pelvis-relative joint distance between outputs of one source "
                                 "under two latent seeds vs under two styles"},
        "seed_spread": {"pairs": f"style accuracy on the same {len(pairs)} takes under seeds 0 and 1; "
                                 "diversity as above",
                        "rows": windowed.seed_spread_costs(pairs, sources, windowed.DIVERSITY_STYLES,
                                                           model)},
    }
    for row in report["lookahead_costs"]["rows"]:
        print("lookahead " + ", ".join(f"{k} {_fmt(v)}" for k, v in row.items() if k != "lookahead")
              + f" (lookahead {row['lookahead']})")
    for row in report["seed_spread"]["rows"]:
        print("seed spread " + ", ".join(f"{k} {_fmt(v)}" for k, v in row.items()))
    print("diversity: " + ", ".join(f"{k} {_fmt(v)}" for k, v in report["diversity"].items() if k != "meaning"))
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "controls.json").write_text(json.dumps(report, indent=1) + "\n")
    print(f"wrote {out / 'controls.json'}")
    if args.record:
        for key, metrics in report.items():
            _record(args, key, metrics)
    return 0


def run_performer(args: argparse.Namespace) -> int:
    import json
    from pathlib import Path

    from motion_style_ros.errors import MotionStyleError
    from motion_style_ros.evaluation import harness, performer
    from motion_style_ros.evaluation.judges import Judge
    from motion_style_ros.io.render import render_png
    from motion_style_ros.runtime.offline import default_model
    from motion_style_ros.runtime.saae import Sampler

    if args.stylizer != ["saae"]:
        raise MotionStyleError("--performer measures the SAAE's learned performer: give --stylizer saae")
    model = args.model or default_model("saae")
    real = [(info.style, m) for info, m in harness.held_out_clips(progress=not args.quiet, dataset=args.dataset)]
    judges = [Judge("style", args.threads), Judge("style", args.threads, panel=2)]
    report = performer.evaluate(model, real, judges, args.performer_minutes, seed=args.seed,
                                progress=not args.quiet)
    print("learned performer: " + ", ".join(f"{k} {_fmt(v)}" for k, v in report["summary"].items()))
    for style, row in report["styles"].items():
        print(f"  {style}: " + ", ".join(f"{k} {_fmt(v)}" for k, v in row.items()))
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    sampler = Sampler(model, seed=args.seed)
    shown = [s for s in ("elderly", "youthful", "exhausted") if s in sampler.styles] or sampler.styles[:3]
    clips = []
    for style in shown:
        sampler.set_style(style)
        sampler.restart()
        clips.append(sampler.motion(6.0))
    render_png(clips, [f"learned performer: {s}" for s in shown], out / "performer.png")
    (out / "performer.json").write_text(json.dumps(report, indent=1) + "\n")
    print(f"wrote {out / 'performer.json'} and {out / 'performer.png'}")
    if args.record:
        _record(args, "learned_performer", report)
    return 0


def run_generative(args: argparse.Namespace) -> int:
    import json
    import shlex
    import sys
    from pathlib import Path

    from motion_style_ros.errors import MotionStyleError
    from motion_style_ros.evaluation import generative
    from motion_style_ros.runtime.onnx_model import model_path, models_dir, record_metrics

    models = args.generative or sorted(str(p) for p in models_dir().glob("saae_*.onnx")
                                       if p.with_suffix(".json").is_file())
    if not models:
        raise MotionStyleError("--generative found no SAAE model: train one (motion-style train saae) or name its file")
    table = generative.table(models, seed=args.seed, threads=args.threads)
    print(f"{'model':24s} {'Parzen LL':>12s} {'+-':>8s} {'G2T':>8s} {'T2G':>8s}")
    for name, row in table.items():
        print(f"{name:24s} {row['parzen_log_likelihood']:12.1f} {row['parzen_sem']:8.1f} {row['g2t']:8.3f} {row['t2g']:8.3f}")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "generative.json").write_text(json.dumps(table, indent=1) + "\n")
    print(f"wrote {out / 'generative.json'}")
    if args.record:
        command = "motion-style " + shlex.join(sys.argv[1:])
        for model in models:
            path = model_path(str(model))
            print(f"recorded in {record_metrics(path, 'generative', {'command': command, **table[path.stem]})}")
    return 0


def run_enrolment(args: argparse.Namespace) -> int:
    import json
    from pathlib import Path

    from motion_style_ros.errors import MotionStyleError
    from motion_style_ros.evaluation import windowed
    from motion_style_ros.evaluation.judges import Judge

    if len(args.stylizer) != 1:
        raise MotionStyleError("--enrol scores one backend: give --stylizer stgcn or --stylizer most")
    out = Path(args.out)
    judges = [Judge("style", args.threads), Judge("style", args.threads, panel=2)]
    report = windowed.enrolment(args.enrol, out, args.model, args.enrol_clips, args.seed, judges,
                                progress=not args.quiet, head=args.enrol_head, backend=args.stylizer[0])
    print(f"{args.enrol}: enrolled from {', '.join(report['enrolled_from'])} under {report['head']!r}")
    for key in ("bandai2_test", "unseen"):
        print(f"{key}: " + ", ".join(f"{k} {_fmt(v)}" for k, v in report[key].items()))
    (out / "enrolment.json").write_text(json.dumps(report, indent=1) + "\n")
    print(f"wrote {out / 'enrolment.json'}")
    if args.record:
        _record(args, "enrolment", {k: v for k, v in report.items() if k != "bank"})
    return 0


def _record(args: argparse.Namespace, key: str, metrics: dict) -> None:
    """Write ``metrics`` into the card of the one stylizer's model, with the command line."""
    import shlex
    import sys

    from motion_style_ros.errors import MotionStyleError
    from motion_style_ros.runtime.offline import default_model
    from motion_style_ros.runtime.onnx_model import model_path, record_metrics

    if len(args.stylizer or []) != 1:
        raise MotionStyleError("--record writes into one model's card: give one --stylizer")
    command = "motion-style " + shlex.join(sys.argv[1:])
    path = record_metrics(model_path(args.model or default_model(args.stylizer[0])), key,
                          {"command": command, **metrics})
    print(f"recorded in {path}")


def _fmt(value) -> str:
    if isinstance(value, dict):
        return "{" + ", ".join(f"{k}: {_fmt(v)}" for k, v in value.items()) + "}"
    return f"{value:.3g}" if isinstance(value, float) else str(value)
