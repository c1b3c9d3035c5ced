"""Pseudo-pairs for distillation: motion from other capture setups, each clip into each style by
every shipped backend, the best output kept as a plain regression target.

Labelled Bandai takes never show a model a CMU performer in the style asked for, and adversarial
terms on unlabelled clips only push towards it. Here, for each clip and style, the outputs of the
candidate stylizers that judge panel 1 recognises as the target (among the model's styles) and whose
action its content judge still reads as the input's are ranked by the target's probability, and the
best one becomes the target of a supervised term (``w_distil``). With a posture slack, a candidate
must also keep the input's knee and hip figures within how far the style moves Bandai's train-take
performers, that many degrees either way (the content judge cannot read a CMU bend or crouch; off by
default: at 10 degrees it kept the bends at the cost of most of the style on other setups, see
docs/models.md). Other style judges may be asked to agree (``agree``: panel 3's, which sees how a
body moves but not how it stands), so that a target carries the style for more than one network.
Only panels 1 and 3 and the train takes look here: panel 2 and the test takes never choose
anything, so they can report on the result.

Both sides of a pair are conditioned as a stream session conditions the input (the input's arm
rolls, size and height, :func:`~motion_style_ros.training.unlabelled.conditioning`), at the
training rate, frame for frame.
"""

from __future__ import annotations

import json
import shutil
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from tqdm import tqdm

from motion_style_ros.core.features import encode, feature_layout
from motion_style_ros.core.motion import Motion
from motion_style_ros.core.mirror import mirror as mirror_motion
from motion_style_ros.core.resample import at_speed, resample
from motion_style_ros.errors import MotionStyleError
from motion_style_ros.evaluation import posture
from motion_style_ros.evaluation.judges import Judge
from motion_style_ros.evaluation.unseen import offered_columns
from motion_style_ros.io import files
from motion_style_ros.io.datasets import index_bandai, load_bandai
from motion_style_ros.io.resources import rotation_stats
from motion_style_ros.runtime import offline
from motion_style_ros.training.command import PAIRS_DEFAULTS
from motion_style_ros.training.content import FRAME
from motion_style_ros.training.unlabelled import conditioning, sources

PANEL = 1  # the judges that may guide training; panel 2 only reports
# The content judge knows Bandai's actions only: on a CMU punch or swordplay it spreads its
# probability thin (0.2 at most), and whatever it names changes with any restyling. Its label must
# stay the same only where it reads the input's action with at least this probability (a CMU walk: 0.43).
CONFIDENT_CONTENT = 0.3
VERSION = 1


@dataclass(frozen=True)
class Candidate:
    """A stylizer whose outputs may become targets: a backend and its model (None: the shipped one)."""

    backend: str
    model: str | None = None

    @classmethod
    def parse(cls, spec: str) -> Candidate:
        """``"most"`` or ``"saae:models/saae_model1.onnx"``."""
        backend, _, model = spec.partition(":")
        return cls(backend, model or None)

    def __str__(self) -> str:
        return f"{self.backend}:{self.model}" if self.model else self.backend


@dataclass
class Pairs:
    """Kept pairs, one per (clip, style) at most: inputs ``(T_k, F)`` features, targets ``(T_k, FRAME)``
    ``[root | rot6d]`` frames, the target style, the clip, the candidate that made it and the
    target's panel-1 probability; ``tried``: every (clip, style), kept or not, for the record."""

    inputs: list[np.ndarray]
    targets: list[np.ndarray]
    styles: list[str]
    clips: list[str]
    made_by: list[str]
    probability: list[float]
    tried: list[dict]
    meta: dict

    def extend(self, other: Pairs) -> None:
        """Append ``other``'s pairs and tried rows (the meta stays)."""
        for field in ("inputs", "targets", "styles", "clips", "made_by", "probability", "tried"):
            getattr(self, field).extend(getattr(other, field))

    def made_counts(self) -> dict[str, int]:
        """How many kept pairs each candidate made (every candidate, in order)."""
        return {m: self.made_by.count(m) for m in self.meta["candidates"]}


Stylize = Callable[[Motion, str], Motion]


def _judged(style_judges: list[Judge], content_judge: Judge, offered: list[list[int]], motion: Motion,
            style: str, content: str | None) -> float | None:
    """The target's mean probability over ``style_judges`` where every one of them picks ``style``
    among its ``offered`` columns and the content judge still reads ``content`` (None: any); else None."""
    if not (np.isfinite(motion.rotations).all() and np.isfinite(motion.positions).all()):
        return None
    target = []
    for judge, columns in zip(style_judges, offered):
        p = judge.judge([motion]).probabilities[0]
        column = judge.labels.index(style)
        if columns[int(np.argmax(p[columns]))] != column:
            return None
        target.append(float(p[column]))
    if content is not None and content_judge.judge([motion]).labels[0] != content:
        return None
    return float(np.mean(target))


def variants(motion: Motion, speeds: tuple[float, ...], mirror: bool) -> list[tuple[str, Motion]]:
    """``motion`` as it is, at each of ``speeds`` and, with ``mirror``, each of those mirrored
    left-right, each with what it is (``""``, ``" x0.8"``, ``" x0.8 mirrored"``)."""
    out = [("", motion), *((f" x{v:g}", at_speed(motion, v)) for v in speeds)]
    return out + ([(f"{name} mirrored", mirror_motion(m)) for name, m in out] if mirror else [])


def make(specs: tuple[str, ...], candidates: list[Candidate], styles: list[str], fps: float,
         threads: int = 1, progress: bool = True, stylizers: dict[str, Stylize] | None = None,
         speeds: tuple[float, ...] = (), mirror: bool = False, parts: Path | None = None,
         posture_slack: float | None = None, agree: tuple[str, ...] = ()) -> Pairs:
    """Every clip ``specs`` name (:func:`~motion_style_ros.training.unlabelled.sources`; also at
    ``speeds`` and mirrored, :func:`variants`) into every one of ``styles`` by every candidate, at
    ``fps``; the best recognised output of each kept. ``stylizers``: the candidates' stylizers by
    name (default: their offline sessions). ``parts``: a folder that keeps each clip's pairs as it
    is done, so that a stopped making goes on where it stopped (the caller removes it).
    ``posture_slack``: degrees a target's knee and hip figures may sit beyond its style's real shift
    (None: no posture gate). ``agree``: more style judges (files, such as panel 3's
    ``judge3_style.onnx``; never panel 2's) that must recognise a target too; a target is then
    ranked by the mean of its probabilities."""
    stats = rotation_stats()
    style_judges = [Judge("style", threads, panel=PANEL), *(Judge(path, threads) for path in agree)]
    content_judge = Judge("content", threads, panel=PANEL)
    for judge in style_judges:
        if judge.card.get("panel") == 2:
            raise MotionStyleError(f"{judge.model.path.name} is panel 2's: it reports on the pairs' "
                                   "models, so it may not choose their targets")
        unknown = [s for s in styles if s not in judge.labels]
        if unknown:
            raise MotionStyleError(f"{judge.model.path.name} does not know {', '.join(unknown)}")
    offered = offered_columns(style_judges, styles)
    shifts = train_take_shifts() if posture_slack is not None else {}
    stylizers = stylizers or {str(c): offline.stylizer(c.backend, c.model, threads=threads) for c in candidates}
    clips = [(name, variant, moved) for spec in specs for name, motion in sources(spec, stats)
             for variant, moved in variants(motion, speeds, mirror)]
    meta = {"version": VERSION, "clips": list(specs), "speeds": list(speeds), "mirror": mirror,
            "candidates": list(stylizers), "styles": list(styles),
            "fps": fps, "judges": [j.model.path.name for j in (*style_judges, content_judge)],
            "agree": [j.model.path.name for j in style_judges[1:]],
            "posture_slack": posture_slack, "sources": list(dict.fromkeys(name for name, _, _ in clips))}

    def one_clip(name: str, variant: str, motion: Motion) -> Pairs:
        low = resample(motion, fps)
        condition = conditioning(low, fps, stats)
        features = encode(condition(low))
        read = content_judge.judge([low])
        content = read.labels[0] if read.probabilities[0].max() >= CONFIDENT_CONTENT else None
        stance = posture.posture(low)
        pairs = Pairs([], [], [], [], [], [], [], meta)
        for style in styles:
            scored, bent = [], []
            for made_by, stylize in stylizers.items():
                out = stylize(low, style)
                if out.n_frames != low.n_frames:
                    raise MotionStyleError(f"{made_by} gave {out.n_frames} frames for {name}{variant}'s "
                                           f"{low.n_frames}: a target must match its input frame for frame")
                p = _judged(style_judges, content_judge, offered, out, style, content)
                if p is None:
                    continue
                if posture_slack is None or posture.keeps(stance, out, style, shifts, posture_slack):
                    scored.append((p, made_by, out))
                else:
                    bent.append(made_by)
            best = max(scored, key=lambda s: s[0], default=None)
            pairs.tried.append({"clip": name + variant, "style": style,
                                "recognised_by": sorted([m for _, m, _ in scored] + bent),
                                "posture_refused": sorted(bent), "kept": best[1] if best else None})
            if best is None:
                continue
            pairs.inputs.append(features.astype(np.float32))
            pairs.targets.append(encode(condition(best[2]))[:, :FRAME].astype(np.float32))
            pairs.styles.append(style)
            pairs.clips.append(name)
            pairs.made_by.append(best[1])
            pairs.probability.append(best[0])
        return pairs

    pairs = Pairs([], [], [], [], [], [], [], {})
    for index, (name, variant, motion) in enumerate(tqdm(clips, desc="pseudo-pairs", disable=not progress)):
        part = None if parts is None else parts / f"{index:05d}.npz"
        done = _part(part, meta)
        if done is None:
            done = one_clip(name, variant, motion)
            if part is not None:
                parts.mkdir(parents=True, exist_ok=True)
                written = part.with_name("writing.npz")
                save(done, written)
                written.replace(part)
        pairs.extend(done)
    pairs.meta = {**meta, "kept": len(pairs.styles), "tried": len(pairs.tried)}
    return pairs


def _part(path: Path | None, meta: dict) -> Pairs | None:
    """One clip's pairs kept at ``path`` by a making with the same ``meta``; else None."""
    if path is None or not path.is_file():
        return None
    try:
        done = load(path)
    except MotionStyleError:
        return None
    return done if done.meta == meta else None


def train_take_shifts() -> dict[str, dict[str, float]]:
    """How far each style moves the posture of Bandai dataset-2's train-take performers
    (:func:`~motion_style_ros.evaluation.posture.style_shifts`; the acceptance uses the test takes)."""
    return posture.style_shifts(load_bandai([i for i in index_bandai(datasets=(2,)) if i.split == "train"],
                                            progress=False))


def default_styles() -> list[str]:
    """The styles pairs are made into unless told: the shipped recurrent model's."""
    from motion_style_ros.runtime.backends import backend
    from motion_style_ros.runtime.onnx_model import model_path, read_card

    return read_card(model_path(backend("recurrent").default_model))["styles"]


def for_run(distil: str, folder: Path, fps: float, threads: int = 1, progress: bool = True,
            make_pairs: Callable[..., Pairs] | None = None) -> str:
    """The pairs file a training run distils from (its ``--distil``): the file itself where it names
    one; else clip specs, whose pairs are made once as ``train pairs --clips`` makes them by default
    into the run's checkpoint ``folder`` (``pairs.npz``; a stopped making goes on where it stopped)
    and read again when the run resumes, so that a distilled model's recipe is one resumable command. ``make_pairs``: :func:`make` (tests)."""
    if Path(distil).is_file():
        return distil
    if distil.endswith(".npz"):
        raise MotionStyleError(f"--distil: no pairs file {distil} (give a file 'motion-style train pairs' "
                               "wrote, or clip specs such as cmu:07 to make them for this run)")
    specs = [s for s in distil.split(",") if s]
    path = folder / "pairs.npz"
    if _made_for(path, specs):
        return str(path)
    candidates = [Candidate.parse(c) for c in PAIRS_DEFAULTS["candidates"].split(",")]
    pairs = (make_pairs or make)(tuple(specs), candidates, default_styles(), fps, threads, progress,
                                 speeds=PAIRS_DEFAULTS["speeds"], mirror=PAIRS_DEFAULTS["mirror"],
                                 parts=parts_folder(path), posture_slack=PAIRS_DEFAULTS["posture_slack"],
                                 agree=PAIRS_DEFAULTS["agree"])
    save_made(pairs, path)
    return str(path)


def parts_folder(path: Path) -> Path:
    """Where the making of the pairs file ``path`` keeps each clip's pairs until it is written."""
    return path.with_name(path.name + ".parts")


def save_made(pairs: Pairs, path: Path) -> None:
    """Write a making's pairs to ``path`` and remove its parts (:func:`parts_folder`)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    save(pairs, path)
    shutil.rmtree(parts_folder(path), ignore_errors=True)


def _made_for(path: Path, specs: list[str]) -> bool:
    """Were the pairs in ``path`` made from ``specs`` as this version makes them? Reads the meta
    alone, not the arrays (a run's pairs are 100 MB and more)."""
    try:
        with np.load(path, allow_pickle=False) as z:
            meta = json.loads(str(z["meta"]))
    except (OSError, ValueError, KeyError, EOFError):
        return False
    return ((meta.get("version"), meta.get("clips"), meta.get("posture_slack"), meta.get("agree", []))
            == (VERSION, specs, PAIRS_DEFAULTS["posture_slack"], [Path(j).name for j in PAIRS_DEFAULTS["agree"]]))


def save(pairs: Pairs, path: Path) -> None:
    """One compressed ``.npz`` (arrays only, no pickles)."""
    lengths = np.array([len(x) for x in pairs.inputs], dtype=np.int64)
    np.savez_compressed(
        path, inputs=np.concatenate(pairs.inputs or [np.zeros((0, feature_layout().size), np.float32)]),
        targets=np.concatenate(pairs.targets or [np.zeros((0, FRAME), np.float32)]),
        lengths=lengths, styles=np.array(pairs.styles, dtype=str), clips=np.array(pairs.clips, dtype=str),
        made_by=np.array(pairs.made_by, dtype=str), probability=np.array(pairs.probability),
        meta=np.array(json.dumps(pairs.meta)), tried=np.array(json.dumps(pairs.tried)))


def load(path: str | Path) -> Pairs:
    """A pairs file :func:`save` wrote; one line on anything else."""
    import io

    try:
        with np.load(io.BytesIO(files.read_bytes(path, "arrays")), allow_pickle=False) as z:
            lengths = z["lengths"]
            cuts = np.cumsum(lengths)[:-1]
            meta = json.loads(str(z["meta"]))
            if meta.get("version") != VERSION:
                raise MotionStyleError(f"{path}: pairs of version {meta.get('version')}; this package reads "
                                       f"{VERSION} (make them again with 'motion-style train pairs')")
            inputs, targets = np.split(z["inputs"], cuts), np.split(z["targets"], cuts)
            return Pairs(inputs if len(lengths) else [], targets if len(lengths) else [],
                         [str(s) for s in z["styles"]], [str(c) for c in z["clips"]],
                         [str(m) for m in z["made_by"]], [float(p) for p in z["probability"]],
                         json.loads(str(z["tried"])), meta)
    except (OSError, ValueError, KeyError, EOFError) as e:
        raise MotionStyleError(f"{path}: not a pseudo-pairs file ({e})") from None
