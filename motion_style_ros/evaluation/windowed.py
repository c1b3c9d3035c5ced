"""How the windowed stylizers do on this machine and on real clips: what one window costs on ONNX
Runtime and per frame at each hop (every windowed backend), what each lookahead costs in quality (seams, style,
foot skating, distance from the most-context output), and how diverse its latent seeds are.
``bench_report`` is what ``motion-style bench stgcn`` (``most``, ``saae``) prints."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from motion_style_ros.core.motion import Motion
from motion_style_ros.errors import MotionStyleError
from motion_style_ros.evaluation.harness import PUBLISHED, Clip
from motion_style_ros.evaluation.judges import Judge
from motion_style_ros.evaluation.metrics import foot_skating, largest_jump
from motion_style_ros.runtime import backends
from motion_style_ros.runtime.defaults import DEFAULTS
from motion_style_ros.runtime.onnx_model import model_path, read_card
from motion_style_ros.runtime.stgcn import DEFAULT_MODEL, StgcnSession
from motion_style_ros.runtime.windows import WindowsSession

LOOKAHEADS = (0, 8, 16, 32)
SPREADS = (1.0, 2.0, 2.5, 3.0)
DIVERSITY_STYLES = ["elderly", "youthful", "exhausted"]  # styles the seeds' diversity is measured in


def window_times(backend: str, model: str | Path | None = None, performers: int = 1, repeats: int = 200,
                 threads: int = 1) -> np.ndarray:
    """Wall time (ms) of each of ``repeats`` runs of a windowed backend's step on one window of
    ``performers`` (its model calls on the history, at the first style)."""
    spec = backends.backend(backend)
    session = spec.open_session(model, performers=performers, threads=threads)
    step = session.windows
    style = np.zeros((performers, len(session.styles)))
    style[:, 0] = 1.0
    step.run_window(style)  # warm-up
    times = []
    for _ in range(repeats):
        start = time.perf_counter_ns()
        step.run_window(style)
        times.append((time.perf_counter_ns() - start) / 1e6)
    return np.array(times)


def step_times(session: WindowsSession, motion: Motion, style: str) -> np.ndarray:
    """Wall time (ms) of each ``step()`` call streaming ``motion`` (at its own rate) through
    ``session``, everything included (features, windows, overlap-add, decoding, foot locking)."""
    session.set_style(style)
    session.restart()
    roots = motion.root_positions
    times = []
    for t in range(motion.n_frames):
        start = time.perf_counter_ns()
        session.step(motion.rotations[t], roots[t], t / motion.fps)
        times.append((time.perf_counter_ns() - start) / 1e6)
    return np.array(times)


def _local(motion: Motion) -> np.ndarray:
    """Joint positions relative to the pelvis (the root trajectory left out)."""
    return motion.global_positions() - motion.root_positions[:, None]


def lookahead_costs(pairs: list[tuple[Motion, str]], model: str | Path = DEFAULT_MODEL,
                    lookaheads: tuple[int, ...] = LOOKAHEADS, hop: int = DEFAULTS["hop"],
                    judge: Judge | None = None) -> list[dict]:
    """One row per lookahead over ``(source clip, target style)`` pairs (30 fps canonical clips):
    the largest joint jump between consecutive output frames over the input's own (a style that
    moves faster raises it too) and over the output's with the most lookahead (the window minus
    one frame: as much context as a window gives; seams show as a ratio above 1), the style
    judge's accuracy, foot skating (m/s) of output and input, and the mean pelvis-relative joint
    distance (m) from the output with the most lookahead."""
    judge = judge or Judge("style")
    window = int(read_card(model_path(str(model)))["window"])

    def stylize(lookahead: int) -> list[Motion]:
        session = StgcnSession(model, lookahead=lookahead, hop=min(hop, lookahead + 1),
                                  follow_seconds=PUBLISHED["follow_seconds"])
        return [session.run(source, style) for source, style in pairs]

    most = stylize(window - 1)
    rows = []
    for lookahead in lookaheads:
        outs = stylize(lookahead)
        labels = judge.judge(outs).labels
        rows.append({
            "lookahead": lookahead,
            "latency_ms": round(1000 * lookahead / 30.0, 1),
            "jump_ratio_max": round(max(largest_jump(o) / largest_jump(s) for o, (s, _) in zip(outs, pairs)), 3),
            "jump_over_most_lookahead_max": round(max(largest_jump(o) / largest_jump(m)
                                                      for o, m in zip(outs, most)), 3),
            "style_accuracy": round(float(np.mean([lab == st for lab, (_, st) in zip(labels, pairs)])), 3),
            "foot_skating": round(float(np.nanmean([foot_skating(o) for o in outs])), 4),
            "input_foot_skating": round(float(np.nanmean([foot_skating(s) for s, _ in pairs])), 4),
            "distance_from_most_lookahead_m": round(float(np.mean(
                [np.linalg.norm(_local(o) - _local(m), axis=-1).mean() for o, m in zip(outs, most)])), 4),
        })
    return rows


def diversity(sources: list[Motion], styles: list[str], model: str | Path = DEFAULT_MODEL,
              seeds: tuple[int, ...] = (0, 1, 2, 3), spread: float = 1.0) -> dict:
    """Mean pelvis-relative joint distance (m) between outputs of one source and style under two
    seeds, against the distance between outputs of one source and seed under two styles (at
    seed spread ``spread``)."""
    outs = {}
    for seed in seeds:
        session = StgcnSession(model, latent_seed=seed, seed_spread=spread, **PUBLISHED)
        for i, source in enumerate(sources):
            for style in styles:
                outs[i, style, seed] = _local(session.run(source, style))

    def mean_distance(pairs) -> float:
        return float(np.mean([np.linalg.norm(outs[a] - outs[b], axis=-1).mean() for a, b in pairs]))

    n = range(len(sources))
    between_seeds = [((i, s, a), (i, s, b)) for i in n for s in styles for a in seeds for b in seeds if a < b]
    between_styles = [((i, a, k), (i, b, k)) for i in n for k in seeds for a in styles for b in styles if a < b]
    return {"between_seeds_m": round(mean_distance(between_seeds), 4),
            "between_styles_m": round(mean_distance(between_styles), 4),
            "seeds": list(seeds), "styles": list(styles), "sources": len(sources)}


def seed_spread_costs(pairs: list[tuple[Motion, str]], sources: list[Motion], styles: list[str],
                      model: str | Path = DEFAULT_MODEL, spreads: tuple[float, ...] = SPREADS,
                      judge: Judge | None = None) -> list[dict]:
    """One row per seed spread: the seeds' :func:`diversity` on ``sources`` into ``styles``, and
    the style judge's accuracy on ``pairs`` under seeds 0 and 1 (what more diverse seeds cost)."""
    judge = judge or Judge("style")
    rows = []
    for spread in spreads:
        outs, wanted = [], []
        for seed in (0, 1):
            session = StgcnSession(model, latent_seed=seed, seed_spread=spread, **PUBLISHED)
            outs += [session.run(source, style) for source, style in pairs]
            wanted += [style for _, style in pairs]
        labels = judge.judge(outs).labels
        spread_div = diversity(sources, styles, model, spread=spread)
        rows.append({"seed_spread": spread, "between_seeds_m": spread_div["between_seeds_m"],
                     "between_styles_m": spread_div["between_styles_m"],
                     "style_accuracy": round(float(np.mean([a == b for a, b in zip(labels, wanted)])), 3)})
    return rows


def control_pairs(clips: list[Clip], seed: int = 0) -> list[tuple[Motion, str]]:
    """One seeded test take per (content, style) cell, each with the next style in order."""
    from motion_style_ros.evaluation.harness import make_pairs

    motions = {info.name: (info, motion) for info, motion in clips}
    styles = sorted({info.style for info, _ in clips})
    takes = dict.fromkeys(pair.source.name for pair in make_pairs([i for i, _ in clips], 1, seed))
    return [(motions[name][1], styles[(styles.index(motions[name][0].style) + 1) % len(styles)])
            for name in takes]


def bench_report(motion: Motion, backend: str = "stgcn", model: str | Path | None = None,
                 hops: tuple[int, ...] = (1, 4, 8), lookahead: int = DEFAULTS["lookahead"], threads: int = 1) -> tuple[str, dict]:
    """What ``motion-style bench stgcn`` (or ``most``, ``saae``) prints, and the figures in it: one
    window on ONNX Runtime (1 and 8 performers) and the per-frame amortised cost at each hop, then
    the wall time of a session's ``step()`` streaming ``motion`` (at its rate) at each hop with
    ``lookahead``."""
    spec = backends.backend(backend)
    path = model_path(str(model or spec.default_model))
    card = read_card(path)
    lines = [(f"model: {path} ({card['window']}-frame windows, {card['fps']:g} fps; trained on: "
             f"{card.get('training', {}).get('data', 'unknown data')}); ONNX Runtime on {threads} thread(s)")]
    figures: dict = {"lookahead": lookahead, "latency_ms": round(1000 * lookahead / card["fps"], 1),
                     "clip_frames": motion.n_frames, "clip_fps": motion.fps}
    for performers in (1, 8):
        ms = window_times(backend, path, performers, threads=threads)
        p50, p99 = np.percentile(ms, [50, 99])
        amortised = ", ".join(f"hop {h}: {p50 / h:.3f} ms (p99 {p99 / h:.3f})" for h in hops)
        lines.append(f"one window, {performers} performer(s): p50 {p50:.2f} ms, p99 {p99:.2f} ms; "
                     f"per frame amortised {amortised}")
        figures[f"window_ms_{performers}_performers"] = {"p50": round(p50, 3), "p99": round(p99, 3)}
        if performers == 1:
            figures["per_frame_amortised_ms"] = {f"hop {h}": round(p50 / h, 3) for h in hops}
            figures["per_frame_amortised_p99_ms"] = {f"hop {h}": round(p99 / h, 3) for h in hops}
    lines.append(f"step() per input frame, {motion.n_frames} frames at {motion.fps:g} Hz, "
                 f"lookahead {lookahead} ({figures['latency_ms']:.0f} ms):")
    figures["step_ms"] = {}
    for h in hops:
        session = spec.open_session(path, hop=h, lookahead=lookahead, threads=threads, input_fps=motion.fps)
        ms = step_times(session, motion, session.styles[0])
        p50, p99, worst = np.percentile(ms, [50, 99, 100])
        lines.append(f"  hop {h}: p50 {p50:.2f} ms, p99 {p99:.2f} ms, max {worst:.2f} ms, mean {ms.mean():.2f} ms")
        figures["step_ms"][f"hop {h}"] = {"p50": round(p50, 3), "p99": round(p99, 3), "max": round(worst, 3)}
    return "\n".join(lines), figures


def enrolment(style: str, out_dir: Path, model: str | Path | None = None, clips: int = 4, seed: int = 0,
              judges: list[Judge] | None = None, root: Path | None = None, progress: bool = True,
              head: str | None = None, backend: str = "stgcn") -> dict:
    """A style the model does not know, enrolled into a style bank from ``clips`` of its Bandai
    train takes (distinct contents, chosen with ``seed``), then asked of every dataset-2 test take
    (one per content and style) and every CMU and Xia neutral clip: how often each judge panel
    recognises it, and how much the style's probability rose from the source's. ``backend``: one
    with a style bank (stgcn, most), run with the published settings."""
    from motion_style_ros.evaluation.harness import held_out_clips
    from motion_style_ros.evaluation.unseen import _recognition, neutral_clips, offered_columns
    from motion_style_ros.io.datasets import index_bandai, load_bandai
    from motion_style_ros.runtime import style_bank
    from motion_style_ros.runtime.offline import stylizer

    made_by = backends.backend(backend)
    if not made_by.style_bank:
        raise MotionStyleError("--enrol needs a backend with a style bank: "
                               + " or ".join(backends.with_feature("style_bank")))
    model = model or made_by.default_model
    session = made_by.open_session(model, **PUBLISHED)
    if style in session.styles[: len(session.card["styles"])]:
        raise MotionStyleError(f"{style!r} is a style the model was trained on; enrol one it has not seen")
    takes = sorted((i for i in index_bandai(root) if i.style == style and i.split == "train"),
                   key=lambda i: i.name)
    by_content = {i.content: i for i in takes}
    if len(by_content) < clips:
        raise MotionStyleError(f"style {style!r} has {len(by_content)} train contents, fewer than {clips} clips")
    rng = np.random.default_rng(seed)
    chosen = [by_content[c] for c in sorted(rng.choice(sorted(by_content), clips, replace=False))]
    entry = session.enrol([m for _, m in load_bandai(chosen, progress=False)], [i.name for i in chosen], head)
    out_dir.mkdir(parents=True, exist_ok=True)
    bank = out_dir / f"enrolled_{style}.json"
    style_bank.write(bank, {style: entry}, session.card["name"], session.model_digest)
    enrolled = stylizer(backend, str(model), bank=bank, **PUBLISHED)  # a session per input rate
    test = held_out_clips(root, progress=progress)
    one_per_cell = {(i.content, i.style): m for i, m in sorted(test, key=lambda c: c[0].name)}
    sources = {"bandai2_test": list(one_per_cell.values()),
               "unseen": [m for _, m in neutral_clips(root)]}
    judges = judges or []
    offered = offered_columns(judges, [*session.card["styles"], style])  # the model's and the enrolled
    report = {"style": style, "enrolled_from": list(entry.clips), "head": entry.head,
              "closest_known": entry.probabilities, "bank": str(bank)}
    for name, motions in sources.items():
        rows = []
        for source in motions:
            before = [judge.judge([source]).probabilities[0] for judge in judges]
            rows.append(_recognition(judges, before, enrolled(source, style), style, offered))
        report[name] = {"outputs": len(rows), **{
            key: float(np.mean([r[f"recognised_{k}"] for r in rows])) if key.startswith("recog")
            else float(np.median([r[f"target_gain_{k}"] for r in rows]))
            for k in range(1, len(judges) + 1) for key in (f"recognised_{k}", f"target_gain_median_{k}")}}
    return report
