"""Training data for every trainer: Bandai takes (or a user's labelled BVH folder,
:mod:`motion_style_ros.io.user_data`) as encoded feature clips with style and content indices,
their augmentation (speeds, mirroring), windows drawn from them (of any style, or one of each style
asked for) with the targets of a transfer, and the feature normalisation. Which takes
and augmentations a run uses is its config's ``datasets`` (or ``data``), ``neutral``, ``speeds``,
``balance``, ``mirror`` and ``exclude`` fields (:class:`DataConfig`, :func:`load_for`)."""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
import torch
from tqdm import tqdm

from motion_style_ros.core.features import encode
from motion_style_ros.core.mirror import mirror as mirror_motion
from motion_style_ros.core.resample import at_speed
from motion_style_ros.errors import MotionStyleError
from motion_style_ros.io.datasets import BANDAI_FPS, index_bandai, load_bandai
from motion_style_ros.io.user_data import MIN_TAKES, folder_id, load_folder
from motion_style_ros.training.unlabelled import load_unlabelled

NEUTRAL = "normal"
USER_LICENCE = "as the user's data"  # a model trained on a user's folder, unless they state its licence
FPS = BANDAI_FPS  # the rate of every training take, so of every model trained on them


@dataclass(frozen=True)
class DataConfig:
    """The fields every stylizer's config starts with: the run's seed and the takes it trains on
    (:func:`load_for`; :func:`recipe` describes them on the card)."""

    seed: int = 0
    datasets: tuple[int, ...] = (2,)
    # Every train take can also be used played slower and faster (other performers walk at other
    # paces); windows are drawn with weight frames / style_frames ** balance, so that dataset-1's
    # styles (one take per content) come up more often than their share of frames. The shipped
    # models use neither; the 22-style Style-ERD run of the models-v2 issue used (0.8, 1.25) and 0.5.
    speeds: tuple[float, ...] = ()
    balance: float = 0.0
    mirror: bool = False  # also every train take mirrored left-right (load_data)
    exclude: tuple[str, ...] = ()  # styles left out (to enrol them later through a style bank)
    data: str = ""  # a user's labelled BVH folder instead of the Bandai sets ``datasets``
    neutral: str = NEUTRAL  # the style of the neutral branch (and the card's neutral style)
    # clips without style labels (``cmu:SUBJECT``, BVH files or folders) restyled in training but
    # never reconstructed nor shown to a critic as real (:mod:`motion_style_ros.training.unlabelled`)
    unlabelled: tuple[str, ...] = ()
    # a pseudo-pairs file (``motion-style train pairs``): clips of other capture setups with a
    # stylized target for a style each (:mod:`motion_style_ros.training.pseudo_pairs`)
    distil: str = ""


@dataclass
class Clips:
    features: list[np.ndarray]  # (T, F) float32 per take
    styles: np.ndarray  # index into the model's styles
    contents: np.ndarray  # index into the content labels
    weights: np.ndarray | None = None  # per take, relative chance of a frame (None: all alike)


@dataclass
class Data:
    styles: tuple[str, ...]
    contents: tuple[str, ...]
    splits: dict[str, Clips]  # "train", "val"
    unlabelled: Clips | None = None  # styles and contents -1 (DataConfig.unlabelled)
    unlabelled_names: tuple[str, ...] = ()  # the clips it holds, for the card and eval --unseen
    # DataConfig.distil's pairs: features are each input's encode() features and its target's
    # [root | rot6d] frames side by side (split at the input's width); contents -1
    pairs: Clips | None = None
    pairs_record: dict | None = None  # how they were made, for the card


def load_data(datasets: tuple[int, ...] = (2,), progress: bool = True, root: Path | None = None,
              takes_per_cell: int | None = None, speeds: tuple[float, ...] = (),
              balance: float = 0.0, mirror: bool = False, exclude: tuple[str, ...] = (),
              folder: Path | str | None = None, neutral: str = NEUTRAL) -> Data:
    """Encoded train and val takes with style and content indices (every style of the sets, or of
    the user's ``folder``, but ``exclude``; Bandai labels from
    :func:`motion_style_ros.io.datasets.style_label`); ``neutral`` must be among them. Train takes are
    added again at each of ``speeds`` and, with ``mirror``, mirrored left-right (at each speed too;
    a left content becomes its right mate). ``takes_per_cell`` keeps only the first takes of each
    split, style and content (tests)."""
    if folder is None:
        indexed = [i for i in index_bandai(root, datasets=tuple(sorted(datasets))) if i.split in ("train", "val")]
    else:
        user = load_folder(folder, progress)
        short = {s: n for s, n in user.too_few().items() if s not in exclude}
        if short:
            raise MotionStyleError(
                f"{folder}: too few takes in style(s) {', '.join(f'{s} ({n})' for s, n in short.items())}; "
                f"each needs at least {MIN_TAKES} (train, val, test): add takes or --exclude-styles them")
        motions = {i: m for i, m in zip(user.infos, user.motions) if i.split in ("train", "val")}
        indexed = list(motions)
    unknown = sorted(set(exclude) - {i.style for i in indexed})
    if unknown or neutral in exclude:
        raise MotionStyleError(f"cannot leave out {', '.join(unknown) or neutral}: the styles to leave out "
                               f"are among {', '.join(sorted({i.style for i in indexed} - {neutral}))}")
    infos = [i for i in indexed if i.style not in exclude]
    if takes_per_cell is not None:
        seen: dict[tuple[str, str, str], int] = {}
        kept = []
        for i in infos:
            seen[i.split, i.style, i.content] = seen.get((i.split, i.style, i.content), 0) + 1
            if seen[i.split, i.style, i.content] <= takes_per_cell:
                kept.append(i)
        infos = kept
    styles = tuple(sorted({i.style for i in infos}))
    contents = tuple(sorted({i.content for i in infos}))
    if neutral not in styles:
        raise MotionStyleError(f"no '{neutral}' takes among the data: the neutral branch needs them (the "
                               f"styles are {', '.join(styles)}; --neutral names another)")
    loaded = load_bandai(infos, progress=progress) if folder is None else [(i, motions[i]) for i in infos]
    encoded = []
    for info, m in tqdm(loaded, desc="features", disable=not progress):
        encoded.append((info, encode(m)))
        if info.split != "train":
            continue
        variants = [(info, at_speed(m, v)) for v in speeds]
        if mirror:
            mirrored = replace(info, content=_mirrored_content(info.content, contents))
            variants += [(mirrored, mirror_motion(v)) for _, v in [(info, m), *variants]]
        encoded += [(i, encode(v)) for i, v in variants]
    splits = {}
    for split in ("train", "val"):
        chosen = [(i, f) for i, f in encoded if i.split == split]
        style_index = np.array([styles.index(i.style) for i, _ in chosen])
        frames = np.bincount(style_index, [len(f) for _, f in chosen], len(styles))
        splits[split] = Clips([f for _, f in chosen], style_index,
                              np.array([contents.index(i.content) for i, _ in chosen]),
                              1.0 / np.maximum(frames[style_index], 1.0) ** balance if balance else None)
    return Data(styles, contents, splits)


def _mirrored_content(content: str, contents: tuple[str, ...]) -> str:
    """The content a mirrored take shows: ``walk-turn-left`` -> ``walk-turn-right``."""
    words = content.split("-")
    swapped = "-".join({"left": "right", "right": "left"}.get(w, w) for w in words)
    return swapped if swapped in contents else content


def windows(clips: Clips, length: int, count: int, rng: np.random.Generator
            ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """``count`` random ``length``-frame windows (over the frames of the takes long enough, by the
    takes' weights):
    features ``(count, length, F)``, style and content indices ``(count,)``."""
    spans = np.array([max(len(f) - length + 1, 0) for f in clips.features], dtype=float)
    if spans.sum() == 0:
        raise MotionStyleError(f"no take has the {length} frames a training window needs")
    chance = spans if clips.weights is None else spans * clips.weights
    idx = rng.choice(len(spans), size=count, p=chance / chance.sum())
    starts = rng.integers(0, spans[idx].astype(int))
    x = np.stack([clips.features[i][s : s + length] for i, s in zip(idx, starts)])
    return (torch.from_numpy(x), torch.from_numpy(clips.styles[idx]),
            torch.from_numpy(clips.contents[idx]))


def style_windows(clips: Clips, length: int, styles: np.ndarray, rng: np.random.Generator
                  ) -> torch.Tensor:
    """One random ``length``-frame window of a take of each requested style: ``(len(styles),
    length, F)``."""
    spans = np.array([max(len(f) - length + 1, 0) for f in clips.features], dtype=float)
    out = []
    for style in styles:
        p = spans * (clips.styles == style)
        if p.sum() == 0:
            raise MotionStyleError(f"no take of style {style} has the {length} frames a window needs")
        i = rng.choice(len(p), p=p / p.sum())
        s = rng.integers(0, int(spans[i]))
        out.append(clips.features[i][s : s + length])
    return torch.from_numpy(np.stack(out))


def other_styles(style: torch.Tensor, n_styles: int, rng: np.random.Generator) -> torch.Tensor:
    """A random style index other than each row's own (the targets of a transfer)."""
    return (style + torch.from_numpy(rng.integers(1, n_styles, len(style))).to(style.device)) % n_styles


def load_for(cfg: DataConfig, progress: bool = True) -> Data:
    """:func:`load_data` with a trainer config's data fields, and its unlabelled clips."""
    data = load_data(cfg.datasets, progress, speeds=cfg.speeds, balance=cfg.balance, mirror=cfg.mirror,
                     exclude=cfg.exclude, folder=cfg.data or None, neutral=cfg.neutral)
    if cfg.unlabelled:
        features, names = load_unlabelled(cfg.unlabelled, FPS, cfg.speeds, cfg.mirror, progress)
        unknown = np.full(len(features), -1)
        data = replace(data, unlabelled=Clips(features, unknown, unknown), unlabelled_names=tuple(names))
    if cfg.distil:
        data = with_pairs(data, cfg.distil)
    return data


def with_pairs(data: Data, path: str) -> Data:
    """``data`` with the pseudo-pairs of the file at ``path``; their clips join the unlabelled ones
    (``eval --unseen`` leaves them out)."""
    from motion_style_ros.training import pseudo_pairs

    pairs = pseudo_pairs.load(path)
    unknown = sorted(set(pairs.styles) - set(data.styles))
    if unknown:
        raise MotionStyleError(f"{path}: pairs into {', '.join(unknown)}, which the model does not have "
                               f"(its styles: {', '.join(data.styles)})")
    if not pairs.styles:
        raise MotionStyleError(f"{path}: no pairs were kept; nothing to distil")
    styles = np.array([data.styles.index(s) for s in pairs.styles])
    clips = Clips([np.concatenate([x, y], axis=1) for x, y in zip(pairs.inputs, pairs.targets)], styles,
                  np.full(len(styles), -1))
    record = {**{k: pairs.meta[k] for k in ("clips", "judges", "kept", "tried")}, "made_by": pairs.made_counts(),
              "posture_slack": pairs.meta.get("posture_slack")}
    # every clip the pairs were made from, kept or not: panel 1 looked at each ('eval --unseen' leaves them out)
    names = tuple(dict.fromkeys((*data.unlabelled_names, *pairs.meta.get("sources", pairs.clips))))
    return replace(data, pairs=clips, pairs_record=record, unlabelled_names=names)


def data_tag(data: str) -> str:
    """What a run on a user's folder ``data`` adds to its checkpoint names, so that it never
    replaces a Bandai run's checkpoint (nor another folder's)."""
    return f"_{folder_id(data)}" if data else ""


def recipe(cfg: DataConfig, licence: str | None = None) -> dict:
    """The card's account of a config's data fields; for a user's folder, with the ``licence``
    they give their model (the card's licence fields, :func:`motion_style_ros.training.export.licence_fields`)."""
    aug = [f"every train take also at speeds {list(cfg.speeds)}"] if cfg.speeds else []
    if cfg.mirror:
        aug.append("every train take (and speed copy) also mirrored left-right, left/right contents swapped")
    if cfg.balance:
        aug.append(f"windows weighted frames / style_frames ** {cfg.balance}")
    unlabelled = ({"unlabelled": f"clips without style labels, restyled into every style in training "
                                 f"(never reconstructed nor shown as real): {', '.join(cfg.unlabelled)}"}
                  if cfg.unlabelled else {})
    if cfg.distil:
        unlabelled["distilled"] = ("a supervised term towards pseudo-pairs: clips of other capture setups "
                                   "stylized by the shipped backends, the best output that the style judges of "
                                   "clips.pairs.judges (panel 1's, and panel 3's where asked to agree) "
                                   "recognise as the target kept (motion-style train pairs)")
    if cfg.data:
        return {"data": f"the user's labelled BVH folder {cfg.data}: 'train' takes (val takes for the val "
                        "figures; test takes never seen; split in its motion_style_split.csv)",
                "styles": "every style of the folder" + (f" but {', '.join(cfg.exclude)} (left out)"
                                                          if cfg.exclude else "") + f"; neutral {cfg.neutral}",
                "augmentation": "; ".join(aug) or "none", **unlabelled, "licence": licence or USER_LICENCE}
    return {
        "data": f"Bandai Namco Research Motion Dataset(s) {', '.join(map(str, cfg.datasets))}: 'train' "
                "takes (val takes for the val figures; test takes never seen)",
        "styles": ("every style of the sets" + (f" but {', '.join(cfg.exclude)} (left out)" if cfg.exclude else "")
                   + "; dataset-1 styles named like a dataset-2 style are their own styles with the "
                   "suffix -d1 (motion_style_ros.io.datasets.style_label)"),
        "augmentation": "; ".join(aug) or "none",
        **unlabelled,
    }


def normalisation(features: list[np.ndarray], floor: float) -> tuple[np.ndarray, np.ndarray]:
    """Mean and std per feature over the frames of the train clips ``features`` (std floored:
    near-constant features stay small)."""
    frames = np.concatenate(features)
    return frames.mean(axis=0), np.maximum(frames.std(axis=0), floor)
