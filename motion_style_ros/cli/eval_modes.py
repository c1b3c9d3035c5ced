"""The modes of ``motion-style eval`` other than the judged comparison (``cli/eval.py``), each a function
of the parsed arguments that builds only what it needs, and what every mode shares: the stylizers of
--stylizer, the session settings the flags change, --record. Light at import time."""

from __future__ import annotations

import argparse


def session_overrides(args: argparse.Namespace) -> dict:
    """Session settings the flags change from the published ones."""
    return {"foot_lock": False} if args.no_foot_lock else {}


def build_stylizers(args: argparse.Namespace) -> dict:
    """The offline stylizer of every --stylizer, at the published settings with the flags' changes; a
    missing model fails here in one line, before the slow part."""
    from motion_style_ros.evaluation.harness import PUBLISHED
    from motion_style_ros.runtime.offline import stylizer

    return {name: stylizer(name, args.model, args.alpha, args.threads, args.seed_spread,
                           **PUBLISHED, **session_overrides(args))
            for name in args.stylizer or []}


def run_live(args: argparse.Namespace) -> int:
    from motion_style_ros.cli import eval_live
    from motion_style_ros.errors import MotionStyleError

    if len(args.stylizer or []) != 1:
        raise MotionStyleError("--live streams one stylizer: give one --stylizer")
    return eval_live.run(args, args.stylizer[0])


def run_unseen(args: argparse.Namespace) -> int:
    import json
    from pathlib import Path

    from motion_style_ros.errors import MotionStyleError
    from motion_style_ros.evaluation import harness, unseen
    from motion_style_ros.evaluation.judges import Judge
    from motion_style_ros.io.render import render_gif, render_png
    from motion_style_ros.runtime.offline import default_model
    from motion_style_ros.runtime.onnx_model import model_path, read_card

    if args.reference_codes:  # references: Bandai test takes of the target style
        from motion_style_ros.evaluation.references import ReferenceStylizer

        build_stylizers(args)  # a missing model fails before the test takes load
        clips = harness.held_out_clips(progress=not args.quiet, dataset=args.dataset)
        stylizers = {name: ReferenceStylizer(clips, name, args.model, args.alpha, args.threads, args.seed,
                                             session=session_overrides(args))
                     for name in args.stylizer or []}
    else:
        stylizers = build_stylizers(args)
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
        print(f"{name}: " + ", ".join(f"{k} {fmt(v)}" for k, v in reports[name]["summary"].items()))
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
        record(args, key, {"alpha": args.alpha, **reports[args.stylizer[0]]["summary"]})
    return 0


def run_posture(args: argparse.Namespace) -> int:
    import json
    from pathlib import Path

    from motion_style_ros.errors import MotionStyleError
    from motion_style_ros.evaluation import harness, posture, unseen
    from motion_style_ros.runtime.offline import default_model
    from motion_style_ros.runtime.onnx_model import model_path, read_card

    if not args.unseen or args.reference_codes:
        raise MotionStyleError("--posture goes with --unseen (the CMU and Xia clips), without --reference-codes")
    stylizers = build_stylizers(args)
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
        print("lookahead " + ", ".join(f"{k} {fmt(v)}" for k, v in row.items() if k != "lookahead")
              + f" (lookahead {row['lookahead']})")
    for row in report["seed_spread"]["rows"]:
        print("seed spread " + ", ".join(f"{k} {fmt(v)}" for k, v in row.items()))
    print("diversity: " + ", ".join(f"{k} {fmt(v)}" for k, v in report["diversity"].items() if k != "meaning"))
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "controls.json").write_text(json.dumps(report, indent=1) + "\n")
    print(f"wrote {out / 'controls.json'}")
    if args.record:
        for key, metrics in report.items():
            record(args, key, metrics)
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
    print("learned performer: " + ", ".join(f"{k} {fmt(v)}" for k, v in report["summary"].items()))
    for style, row in report["styles"].items():
        print(f"  {style}: " + ", ".join(f"{k} {fmt(v)}" for k, v in row.items()))
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
        record(args, "learned_performer", report)
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
        print(f"{key}: " + ", ".join(f"{k} {fmt(v)}" for k, v in report[key].items()))
    (out / "enrolment.json").write_text(json.dumps(report, indent=1) + "\n")
    print(f"wrote {out / 'enrolment.json'}")
    if args.record:
        record(args, "enrolment", {k: v for k, v in report.items() if k != "bank"})
    return 0


def record(args: argparse.Namespace, key: str, metrics: dict) -> None:
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


def fmt(value) -> str:
    if isinstance(value, dict):
        return "{" + ", ".join(f"{k}: {fmt(v)}" for k, v in value.items()) + "}"
    return f"{value:.3g}" if isinstance(value, float) else str(value)
