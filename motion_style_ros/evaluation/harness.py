"""The evaluation harness: stylizers restyle real held-out clips, the judges and metrics score them.

A stylizer is any callable ``(source: Motion, target_style: str) -> Motion`` on the canonical
skeleton that leaves its input unchanged. Every evaluation also scores two baselines, which set the
scale the stylizers are read on: ``identity`` (the source unchanged: perfect content, the source's
style) and ``oracle`` (a real test take of the source's content performed in the target style:
what a perfect stylizer could reach).

Pairs come from the test takes of Bandai dataset-2 (or of a user's labelled folder, judged by judges
trained on it): for each (content, source style) cell, up to
``pairs_per_cell`` takes are drawn with the seed, and each is paired with every other style as
target. The FMD of a target style compares the embeddings of every output made for that style with
those of all real test takes of that style. The oracle's outputs are drawn from that same set of
takes, so its FMD is the sampling floor rather than an independent sample.
"""

from __future__ import annotations

import json
import zlib
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from tqdm import tqdm

from motion_style_ros.core.motion import Motion
from motion_style_ros.core.skeleton import canonical
from motion_style_ros.errors import MotionStyleError
from motion_style_ros.evaluation import metrics
from motion_style_ros.evaluation.judges import Judge
from motion_style_ros.io.datasets import ClipInfo, index_bandai, load_bandai
from motion_style_ros.io.user_data import load_folder

Stylizer = Callable[[Motion, str], Motion]
Clip = tuple[ClipInfo, Motion]

# The session settings the models' published figures (their cards' metrics, docs/models.md) were
# measured with, from before the sessions took the node's defaults (runtime.defaults): no
# trajectory following, the windowed backend 16 model frames ahead. The evaluations that reproduce
# those figures pass them (each backend those it takes: Backend.settings); eval --live measures
# the node as it runs, with the defaults.
PUBLISHED = {"follow_seconds": None, "lookahead": 16}

# Aggregated metrics, in report and table order.
METRICS = {
    "style_accuracy": "style accuracy (judge 1)",
    "style_accuracy_2": "style accuracy (judge 2)",
    "content_accuracy": "content accuracy (judge 1)",
    "content_accuracy_2": "content accuracy (judge 2)",
    "fmd": "FMD (mean over styles)",
    "content_consistency": "content consistency CC",
    "foot_skating": "foot skating out (m/s)",
    "foot_skating_input": "foot skating in (m/s)",
    "jerk_ratio": "jerk ratio out/in (geometric mean)",
    "bone_length_error": "bone length error (m)",
}


class SkipPair(MotionStyleError):
    """A stylizer has no output for this pair (the report lists it with the reason)."""


@dataclass(frozen=True)
class Pair:
    source: ClipInfo
    target: str


def known_styles_only(stylize: Stylizer, styles: list[str], model: str) -> Stylizer:
    """``stylize`` with the pairs whose target ``model`` was not trained on skipped, with the
    reason (a model trained with styles left out, on the set whose takes are restyled)."""

    def skipping(source: Motion, target_style: str) -> Motion:
        if target_style not in styles:
            raise SkipPair(f"{model} was not trained on {target_style}")
        return stylize(source, target_style)

    return skipping


def held_out_clips(root: Path | None = None, progress: bool = True, dataset: int = 2,
                   folder: Path | str | None = None) -> list[Clip]:
    """The held-out test takes of one Bandai set (dataset-1's: its second walk takes, and the
    second call, punch and slash takes in ``normal-d1``) or of a user's labelled ``folder``,
    canonical skeleton, 30 fps."""
    if folder is not None:
        user = load_folder(folder, progress)
        return [(info, m) for info, m in zip(user.infos, user.motions) if info.split == "test"]
    infos = [i for i in index_bandai(root, datasets=(dataset,)) if i.split == "test"]
    return load_bandai(infos, progress=progress)


def make_pairs(infos: list[ClipInfo], pairs_per_cell: int = 2, seed: int = 0) -> list[Pair]:
    """Up to ``pairs_per_cell`` seeded takes per (content, style) cell, each with every other style."""
    if pairs_per_cell < 1:
        raise MotionStyleError(f"pairs per cell must be at least 1, got {pairs_per_cell}")
    styles = sorted({i.style for i in infos})
    cells: dict[tuple[str, str], list[ClipInfo]] = {}
    for info in sorted(infos, key=lambda i: i.name):
        cells.setdefault((info.content, info.style), []).append(info)
    rng = np.random.default_rng(seed)
    pairs = []
    for (_, style), takes in sorted(cells.items()):
        chosen = np.sort(rng.choice(len(takes), size=min(pairs_per_cell, len(takes)), replace=False))
        pairs += [Pair(takes[k], t) for k in chosen for t in styles if t != style]
    return pairs


def identity(source: Motion, target_style: str) -> Motion:
    return source


class Oracle:
    """A real test take of the source's content in the target style (another take, as the style
    differs), chosen per pair with the seed; it only knows the test clips it was given."""

    def __init__(self, clips: list[Clip], seed: int = 0) -> None:
        self._info = {id(m): info for info, m in clips}
        self._cells: dict[tuple[str, str], list[Motion]] = {}
        for info, m in sorted(clips, key=lambda c: c[0].name):
            self._cells.setdefault((info.content, info.style), []).append(m)
        self._seed = seed

    def __call__(self, source: Motion, target_style: str) -> Motion:
        info = self._info.get(id(source))
        if info is None:
            raise MotionStyleError("the oracle restyles only the test clips it was built with")
        candidates = self._cells.get((info.content, target_style))
        if not candidates:
            raise SkipPair(f"no test take of {info.content} in style {target_style}")
        rng = np.random.default_rng([self._seed, zlib.crc32(f"{info.name}>{target_style}".encode())])
        return candidates[int(rng.integers(len(candidates)))]


def baselines(clips: list[Clip], seed: int = 0) -> dict[str, Stylizer]:
    return {"identity": identity, "oracle": Oracle(clips, seed)}


@dataclass
class _Scores:
    style: str
    content: str
    style_2: str | None  # the second panel's (None without one)
    content_2: str | None
    style_embedding: np.ndarray
    content_embedding: np.ndarray
    skating: float
    jerk: float
    bone_error: float


class _Scorer:
    """Judges and measures motions, each distinct motion object once per run (baselines hand
    back the same test clips over and over)."""

    def __init__(self, style_judge: Judge, content_judge: Judge,
                 second: tuple[Judge, Judge] | None = None) -> None:
        self.style_judge, self.content_judge, self.second = style_judge, content_judge, second
        self._done: dict[int, tuple[Motion, _Scores]] = {}
        self._skeleton = canonical()

    def __call__(self, motion: Motion) -> _Scores:
        # Keyed by identity: the motion is kept alive in the entry, so its id stays its own.
        if id(motion) in self._done:
            return self._done[id(motion)][1]
        features = [self.style_judge.features(motion)]
        style = self.style_judge.judge_features(features)
        content = self.content_judge.judge_features(features)
        second = [None, None] if self.second is None else [
            j.judge_features(features).labels[0] for j in self.second]
        scores = _Scores(
            style.labels[0], content.labels[0], *second, style.embeddings[0], content.embeddings[0],
            metrics.foot_skating(motion), metrics.jerk(motion),
            metrics.bone_length_error(motion, self._skeleton),
        )
        self._done[id(motion)] = (motion, scores)
        return scores


def evaluate(
    stylizers: dict[str, Stylizer],
    clips: list[Clip],
    pairs: list[Pair],
    style_judge: Judge,
    content_judge: Judge,
    progress: bool = True,
    settings: dict | None = None,
    second: tuple[Judge, Judge] | None = None,
) -> dict:
    """Score every stylizer on every pair; the report as a JSON-ready dict (``settings`` are
    recorded in it, e.g. how the pairs were drawn). ``second``: the second panel's style and
    content judges, for the ``_2`` accuracies."""
    score = _Scorer(style_judge, content_judge, second)
    by_name = {info.name: m for info, m in clips}
    real = [score(m) for _, m in tqdm(clips, desc="judging test clips", disable=not progress)]
    styles = sorted({info.style for info, _ in clips})
    reference = {
        s: np.array([r.style_embedding for (info, _), r in zip(clips, real) if info.style == s])
        for s in styles
    }
    systems = {}
    for name, stylize in stylizers.items():
        rows, skipped, embeddings = [], [], {s: [] for s in styles}
        for pair in tqdm(pairs, desc=name, disable=not progress):
            source = by_name[pair.source.name]
            try:
                output = stylize(source, pair.target)
            except SkipPair as exc:
                skipped.append({"source": pair.source.name, "target": pair.target, "reason": str(exc)})
                continue
            if not isinstance(output, Motion):
                raise MotionStyleError(f"stylizer {name!r} returned {type(output).__name__}, not a Motion")
            src, out = score(source), score(output)
            embeddings[pair.target].append(out.style_embedding)
            rows.append({
                "source": pair.source.name,
                "content": pair.source.content,
                "source_style": pair.source.style,
                "target_style": pair.target,
                "judged_style": out.style,
                "judged_content": out.content,
                "style_accuracy": float(out.style == pair.target),
                "content_accuracy": float(out.content == pair.source.content),
                "style_accuracy_2": None if out.style_2 is None else float(out.style_2 == pair.target),
                "content_accuracy_2": None if out.content_2 is None else float(
                    out.content_2 == pair.source.content),
                "content_consistency": metrics.content_consistency(
                    src.content_embedding, out.content_embedding
                ),
                "foot_skating": _or_none(out.skating),
                "foot_skating_input": _or_none(src.skating),
                "jerk_ratio": out.jerk / src.jerk,
                "bone_length_error": out.bone_error,
            })
        per_style = {}
        for s in styles:
            subset = [r for r in rows if r["target_style"] == s]
            per_style[s] = {**_means(subset), "fmd": _fmd(embeddings[s], reference[s]), "pairs": len(subset)}
        fmds = [v["fmd"] for v in per_style.values() if v["fmd"] is not None]
        overall = {**_means(rows), "fmd": float(np.mean(fmds)) if fmds else None, "pairs": len(rows)}
        systems[name] = {"overall": overall, "per_style": per_style, "skipped": skipped, "pairs": rows}
    return {
        "settings": {
            "data": "Bandai Namco Research Motion Dataset "
                    + ", ".join(sorted({info.dataset.removeprefix("bandai-") for info, _ in clips})) + ", test takes",
            "test_clips": len(clips),
            "pairs": len(pairs),
            "styles": styles,
            "pairing": "up to K seeded test takes per (content, source style) cell, each paired "
                       "with every other style as target",
            "fmd_reference": "per target style: style-judge embeddings of all real test takes of "
                             "that style; the oracle draws its outputs from the same takes",
            "judges": {
                kind: {"file": j.model.path.name, "test_clip_accuracy": j.card["accuracy"]["test_clip"]}
                for kind, j in (("style", style_judge), ("content", content_judge),
                                *((("style_2", second[0]), ("content_2", second[1])) if second else ()))
            },
            **(settings or {}),
        },
        "systems": systems,
    }


def _or_none(value: float) -> float | None:
    """JSON has no NaN: a metric that does not apply (no ground contact) is null."""
    return value if np.isfinite(value) else None


def _means(rows: list[dict]) -> dict[str, float | None]:
    """Means over pairs; the jerk ratio's is geometric, so that halving and doubling cancel."""
    out = {}
    for k in (k for k in METRICS if k != "fmd"):
        values = np.array([r[k] for r in rows], dtype=float)  # null -> NaN
        values = values[np.isfinite(values)]
        if not len(values):
            out[k] = None
        else:
            out[k] = float(np.exp(np.log(values).mean()) if k == "jerk_ratio" else values.mean())
    return out


def _fmd(outputs: list[np.ndarray], reference: np.ndarray) -> float | None:
    if len(outputs) < 2 or len(reference) < 2:
        return None
    return metrics.frechet_distance(np.array(outputs), reference)


def format_table(report: dict, model: str | None = None) -> str:
    """Plain aligned text: one row per metric (then FMD per style), one column per system."""
    names = list(report["systems"])
    heads = [f"{n} (model)" if n == model else n for n in names]
    rows = [(label, [report["systems"][n]["overall"][k] for n in names]) for k, label in METRICS.items()]
    rows += [
        (f"FMD {s}", [report["systems"][n]["per_style"][s]["fmd"] for n in names])
        for s in report["settings"]["styles"]
    ]
    rows.append(("pairs scored", [report["systems"][n]["overall"]["pairs"] for n in names]))
    width = max(len(label) for label, _ in rows)
    col = max(10, *(len(h) for h in heads))

    def cell(v) -> str:
        if v is None:
            return "-".rjust(col)
        return (f"{v:d}" if isinstance(v, int) else f"{v:.4g}").rjust(col)

    lines = [" " * width + "".join("  " + h.rjust(col) for h in heads)]
    lines += [label.ljust(width) + "".join("  " + cell(v) for v in values) for label, values in rows]
    return "\n".join(lines)


def plot(report: dict, path: Path, model: str | None = None) -> None:
    """Grouped bars: the systems on each headline metric, and FMD per target style."""
    from matplotlib.figure import Figure

    names = list(report["systems"])
    styles = report["settings"]["styles"]
    colours = [f"C{i}" for i in range(len(names))]
    overall = {k: [report["systems"][n]["overall"][k] for n in names] for k in METRICS}
    fig = Figure(figsize=(15, 8), layout="constrained")
    grid = fig.add_gridspec(2, 4)
    panels = [(grid[0, 0], "style_accuracy", "higher"), (grid[0, 1], "content_accuracy", "higher"),
              (grid[0, 2], "fmd", "lower"), (grid[0, 3], "content_consistency", "lower"),
              (grid[1, 2], "foot_skating", "lower"), (grid[1, 3], "jerk_ratio", "1: as smooth as the input")]
    for where, key, better in panels:
        ax = fig.add_subplot(where)
        bars = ax.bar(names, _nan(overall[key]), color=colours)
        ax.bar_label(bars, fmt="%.3g")
        ax.margins(y=0.15)
        if key == "fmd" and _positive(overall[key]):
            ax.set_yscale("log")  # the baselines lie orders of magnitude apart
        ax.set_title(f"{METRICS[key]}\n({better}{' is better' if better in ('higher', 'lower') else ''})")
        ax.tick_params(axis="x", rotation=20)
    # The input's skating is a property of the source clips, the same for every system.
    skating_in = next((v for v in overall["foot_skating_input"] if v is not None), None)
    if skating_in is not None:
        fig.axes[4].axhline(skating_in, color="k", linestyle="--", label="input")
        fig.axes[4].legend(loc="lower center")
    ax = fig.add_subplot(grid[1, :2])
    width = 0.8 / len(names)
    for i, n in enumerate(names):
        values = [report["systems"][n]["per_style"][s]["fmd"] for s in styles]
        ax.bar(np.arange(len(styles)) + (i - (len(names) - 1) / 2) * width, _nan(values), width,
               color=colours[i], label=n + (" (model)" if n == model else ""))
    ax.set_xticks(np.arange(len(styles)), styles, rotation=20)
    if _positive([report["systems"][n]["per_style"][s]["fmd"] for n in names for s in styles]):
        ax.set_yscale("log")
    ax.set_title("FMD per target style (lower is better)")
    ax.legend(fontsize="small", ncols=len(names), loc="upper center", bbox_to_anchor=(0.5, -0.15))
    settings = report["settings"]
    fig.suptitle(f"{settings['pairs']} (source clip, target style) pairs from {settings['test_clips']} "
                 + (f"test takes of {settings['dataset']}" if isinstance(settings.get("dataset"), str)
                    else "Bandai dataset-2 test takes"))
    fig.savefig(path, dpi=100)


def _positive(values: list) -> bool:
    """Any value a log axis can show (FMD needs two outputs and two takes of a style; a small
    folder may have none)."""
    return any(v is not None and v > 0 for v in values)


def _nan(values: list) -> list[float]:
    return [np.nan if v is None else v for v in values]


def write(report: dict, out_dir: Path, model: str | None = None) -> tuple[Path, Path]:
    """``report.json`` and ``report.png`` in ``out_dir``."""
    out_dir.mkdir(parents=True, exist_ok=True)
    json_path, png_path = out_dir / "report.json", out_dir / "report.png"
    json_path.write_text(json.dumps({"model": model, **report}, indent=1, allow_nan=False) + "\n")
    plot(report, png_path, model)
    return json_path, png_path
