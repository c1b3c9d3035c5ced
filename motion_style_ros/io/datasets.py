"""Indexes of the motion capture datasets, the fixed Bandai train/val/test split, cached Bandai loading.

Layout under :func:`datasets_root` (what ``../shared/datasets/unpack.sh`` creates)::

    bandai-namco/Bandai-Namco-Research-Motiondataset-{1,2}/data/dataset-N_<content>_<style>_<take>.bvh
        (+ .json beside each: content and style indices into cfg/content_label.txt, style_label.txt)
    cmu/data/<subject>/<subject>_<trial>.bvh, cmu/labels.csv (category -> content)
    xia-test/<style>_<content id>_<take>.bvh

Split (``motion_style_ros/resources/bandai_split.csv``, columns ``name,split``, one row per Bandai
clip; ``motion-style data split --write`` regenerates it from the rule below, ``--check`` compares).
Every Bandai file is one take, so a split by file never puts frames of one take in two splits:

- dataset-2 (10 contents x 7 styles, 17-104 takes per cell): with ``t`` the take number,
  ``t % 20`` in {1, 8, 15} -> test, in {4, 11} -> val, anything else -> train. That holds out 15 %
  (test) and 10 % (val) of each cell's takes, spread over the whole recording session rather than its
  end, gives every cell at least 3 test takes (the smallest cell has 17), and depends on the take
  number only, so adding or losing a file never moves another one.
- dataset-1 (one take per content x style cell, except walk in every style and call, punch, slash in
  ``normal``, which have two): second and later takes -> test, everything else -> train. Holding
  out a single-take cell would remove that content/style pair from training altogether, so only
  repeated takes are held out, and there is no val split.
- Style labels: dataset-1's styles were acted by other performers in another session. Only its
  ``feminine`` takes read as dataset-2's ``feminine`` to a dataset-2 style judge (7 of 7 walks and
  runs); its ``active`` 3 of 7, its ``normal`` 1 of 7 (5 of 7 read ``feminine``: the performer, not the
  style). So no dataset-1 style is merged into a dataset-2 one: the three names both sets use get
  the suffix ``-d1`` (``active-d1``, ``feminine-d1``, ``normal-d1``), the other twelve keep their names.
- CMU and Xia clips are ``unseen``: other capture setups and skeletons, only ever used as inputs at
  evaluation time. Xia (Aberman et al.'s retarget) is licensed for research use only: never train
  shipped models on it.

Bad input never crashes indexing and never loads silently: a file that is unreadable, truncated,
malformed, has no frames, holds NaN or other non-numbers, has the wrong joints, or whose JSON
disagrees with its name is skipped with a one-line warning naming the file and the problem (logger
``motion_style_ros.io.datasets``). Indexing does not convert the motion numbers (that costs as much as
loading); loading re-checks everything, including bone lengths against the canonical skeleton, and
skips a failing clip with the same kind of warning.
"""

from __future__ import annotations

import csv
import io
import json
import logging
import os
import re
import time
from collections.abc import Callable, Iterable
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, replace
from functools import cache as memoize
from importlib import resources
from pathlib import Path

import numpy as np
from tqdm import tqdm

from motion_style_ros.core.motion import Motion
from motion_style_ros.core.skeleton import canonical, cmu31
from motion_style_ros.errors import MotionStyleError
from motion_style_ros.io import bvh, cache
from motion_style_ros.io.canonical import canonical_arrays

log = logging.getLogger(__name__)

BANDAI_FPS = 30.0
BANDAI_DATASETS = (1, 2)
DATASET2_STYLES = ("active", "elderly", "exhausted", "feminine", "masculine", "normal", "youthful")
DATASET1_SUFFIX = "-d1"  # dataset-1 styles named like a dataset-2 style (see the module docstring)
XIA_CONTENTS = {"01": "walk", "13": "run", "16": "jump", "18": "punch"}
SPLITS = ("train", "val", "test", "unseen")
SPLIT_FILE = "resources/bandai_split.csv"  # inside the motion_style_ros package

CACHE_VERSION = 2  # bump when the cached arrays change meaning (2: style labels, style_label)

_BANDAI_NAME = re.compile(r"dataset-(\d+)_([^_]+)_([^_]+)_(\d+)")
_CMU_NAME = re.compile(r"(\d+)_(\d+)")
_XIA_NAME = re.compile(r"([a-z]+)_(\d+)_(\d+)")


@dataclass(frozen=True)
class ClipInfo:
    dataset: str  # "bandai-1", "bandai-2", "cmu", "xia"
    path: Path
    name: str  # file stem, unique within a dataset
    content: str  # "walk", "raise-up-both-hands"; CMU: the category in labels.csv
    style: str  # "elderly"; "neutral" for CMU; Xia's style word
    take: str  # "001"; CMU: trial number; Xia: take
    split: str  # "train" | "val" | "test" for Bandai; "unseen" for CMU and Xia


def datasets_root() -> Path:
    """Where the datasets are unpacked: ``$MOTION_STYLE_DATASETS``, else ``~/.cache/motion-datasets``."""
    root = Path(os.environ.get("MOTION_STYLE_DATASETS") or Path.home() / ".cache" / "motion-datasets")
    if not root.is_dir():
        raise MotionStyleError(
            f"{root}: motion datasets not found; unpack them with ../shared/datasets/unpack.sh [DEST] "
            "(from the project root) and set MOTION_STYLE_DATASETS=DEST for a non-default DEST"
        )
    return root


def _folder(path: Path) -> Path:
    if not path.is_dir():
        raise MotionStyleError(f"{path}: dataset folder not found (see ../shared/datasets/README.md)")
    return path


def _skip(path: Path, problem: str) -> str:
    message = f"{path}: {problem}; skipped"
    log.warning(message)
    return message


# --- indexing ---------------------------------------------------------------------------------


def bandai_dir(root: Path, dataset: int) -> Path:
    return _folder(root / "bandai-namco" / f"Bandai-Namco-Research-Motiondataset-{dataset}")


def split_rule(dataset: str, take: str) -> str:
    """The split of a Bandai take by the documented rule (see the module docstring)."""
    if dataset == "bandai-1":
        return "test" if int(take) > 1 else "train"
    r = int(take) % 20
    return "test" if r in (1, 8, 15) else "val" if r in (4, 11) else "train"


def _labels(path: Path, dataset: int) -> list[str]:
    try:
        lines = path.read_text(encoding="utf-8").split()
    except OSError as e:
        raise MotionStyleError(f"{path}: cannot read the label list ({e.strerror or e})") from None
    prefix = f"dataset-{dataset}_"
    return [line.removeprefix(prefix) for line in lines]


def _label_problem(path: Path, dataset: int, contents: list[str], styles: list[str]) -> str | None:
    """What is wrong with a Bandai file's name or its JSON labels, if anything."""
    m = _BANDAI_NAME.fullmatch(path.stem)
    if not m or int(m[1]) != dataset:
        return f"name is not dataset-{dataset}_<content>_<style>_<take>"
    content, style = m[2], m[3]
    if content not in contents or style not in styles:
        return f"content {content!r} or style {style!r} is not in the cfg/ label lists"
    label_path = path.with_suffix(".json")
    try:
        label = json.loads(label_path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        return f"no {label_path.name} beside it"
    except (OSError, ValueError) as e:
        return f"{label_path.name} is unreadable ({e})"
    indices = (label.get("content"), label.get("style")) if isinstance(label, dict) else (None, None)
    if not all(type(i) is int and 0 <= i < len(lst) for i, lst in zip(indices, (contents, styles))):
        return f"{label_path.name} holds no valid content and style indices: {str(label)[:60]}"
    said = contents[indices[0]], styles[indices[1]]
    if said != (content, style):
        return f"{label_path.name} says {said[0]}/{said[1]} but the file name says {content}/{style}"
    return None


def _scan_bandai(base: Path, dataset: int) -> tuple[list[ClipInfo], list[str]]:
    """Clips of one Bandai set (folder ``base``), split by :func:`split_rule`, and skip messages."""
    contents = _labels(base / "cfg" / "content_label.txt", dataset)
    styles = _labels(base / "cfg" / "style_label.txt", dataset)
    joints = canonical().names
    infos, problems = [], []
    for path in sorted(_folder(base / "data").glob("*.bvh")):
        problem = _label_problem(path, dataset, contents, styles) or bvh.check(path, joints)
        if problem:
            problems.append(_skip(path, problem))
            continue
        _, content, style, take = _BANDAI_NAME.fullmatch(path.stem).groups()
        name = f"bandai-{dataset}"
        style = style_label(name, style)
        infos.append(ClipInfo(name, path, path.stem, content, style, take, split_rule(name, take)))
    return infos, problems


def style_label(dataset: str, style: str) -> str:
    """The style label of a Bandai take: its file's style name, with ``-d1`` for a dataset-1 style
    named like a dataset-2 one (the same word, another performer's style)."""
    return style + DATASET1_SUFFIX if dataset == "bandai-1" and style in DATASET2_STYLES else style


@memoize
def _split_table() -> dict[str, str]:
    text = (resources.files("motion_style_ros") / SPLIT_FILE).read_text(encoding="utf-8")
    return {row["name"]: row["split"] for row in csv.DictReader(io.StringIO(text))}


def _with_committed_split(infos: Iterable[ClipInfo]) -> list[ClipInfo]:
    table = _split_table()
    infos = list(infos)
    missing = [i.name for i in infos if i.name not in table]
    if missing:
        raise MotionStyleError(
            f"{SPLIT_FILE}: no split for {len(missing)} Bandai clip(s) ({', '.join(missing[:3])}"
            f"{', ...' if len(missing) > 3 else ''}); if the dataset really changed, regenerate it "
            "with 'motion-style data split --write' and commit it"
        )
    return [replace(i, split=table[i.name]) for i in infos]


def index_bandai(root: Path | None = None, datasets: tuple[int, ...] = BANDAI_DATASETS) -> list[ClipInfo]:
    """Every valid clip of the Bandai Namco sets, with its committed split (sorted by name)."""
    root = root or datasets_root()
    return _with_committed_split(i for n in datasets for i in _scan_bandai(bandai_dir(root, n), n)[0])


def split_csv(root: Path | None = None) -> str:
    """The split file's text for the clips under ``root``, by :func:`split_rule`."""
    root = root or datasets_root()
    out = io.StringIO()
    writer = csv.writer(out, lineterminator="\n")
    writer.writerow(["name", "split"])
    for n in BANDAI_DATASETS:
        writer.writerows([i.name, i.split] for i in _scan_bandai(bandai_dir(root, n), n)[0])
    return out.getvalue()


def split_file() -> Path:
    """The committed split file (in an editable install, the one in the source tree)."""
    return Path(str(resources.files("motion_style_ros") / SPLIT_FILE))


def index_cmu(root: Path | None = None) -> list[ClipInfo]:
    """CMU clips (subjects 02 and 07); content: the category in ``cmu/labels.csv``, else "unknown"."""
    base = _folder((root or datasets_root()) / "cmu")
    try:
        with open(base / "labels.csv", newline="", encoding="utf-8") as f:
            categories = {Path(row["file"]).stem: row["category"] for row in csv.DictReader(f)}
    except (OSError, KeyError) as e:
        raise MotionStyleError(f"{base / 'labels.csv'}: cannot read the CMU labels ({e})") from None
    joints = cmu31().names
    infos = []
    for path in sorted(_folder(base / "data").glob("*/*.bvh")):
        m = _CMU_NAME.fullmatch(path.stem)
        problem = (None if m else "name is not <subject>_<trial>") or bvh.check(path, joints)
        if problem:
            _skip(path, problem)
            continue
        content = categories.get(path.stem, "unknown")
        infos.append(ClipInfo("cmu", path, path.stem, content, "neutral", m[2], "unseen"))
    return infos


def index_xia(root: Path | None = None) -> list[ClipInfo]:
    """Xia et al. clips retargeted to the CMU skeleton; research use only (split ``unseen``)."""
    base = _folder((root or datasets_root()) / "xia-test")
    joints = cmu31().names
    infos = []
    for path in sorted(base.glob("*.bvh")):
        m = _XIA_NAME.fullmatch(path.stem)
        problem = (None if m else "name is not <style>_<content id>_<take>") or bvh.check(path, joints)
        if problem:
            _skip(path, problem)
            continue
        style, content_id, take = m.groups()
        content = XIA_CONTENTS.get(content_id, f"unknown-{content_id}")
        infos.append(ClipInfo("xia", path, path.stem, content, style, take, "unseen"))
    return infos


# --- loading ----------------------------------------------------------------------------------


def _bandai_arrays(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """Local rotations ``(T, 22, 4)`` and the Hips translation ``(T, 3)`` (m) of a Bandai file;
    raises unless the file really is the canonical skeleton at 30 fps."""
    clip = bvh.read(path)
    if clip.fps != BANDAI_FPS:
        raise MotionStyleError(f"{path}: {clip.fps:g} fps; Bandai Namco clips are {BANDAI_FPS:g} fps")
    return canonical_arrays(clip, path)


def load_clip(info: ClipInfo) -> Motion:
    """One clip, parsed now (float64).

    Bandai: the canonical skeleton in metres at 30 fps. CMU and Xia: the file's own skeleton in file
    units at 120 fps; frame 0 of a CMU file is a T-pose (``motion[1:]`` drops it).
    """
    if info.dataset.startswith("bandai"):
        rotations, hips = _bandai_arrays(info.path)
        return Motion.from_rotations(canonical(), rotations, hips, BANDAI_FPS)
    return bvh.read(info.path).to_motion()


def _parse_for_cache(path: Path) -> tuple[np.ndarray, np.ndarray] | str:
    """Worker: float32 arrays of one clip, or the reason it cannot be loaded."""
    try:
        rotations, hips = _bandai_arrays(path)
    except MotionStyleError as e:
        return str(e)
    return rotations.astype(np.float32), hips.astype(np.float32)


@dataclass(eq=False)
class _Cached:
    infos: list[ClipInfo]  # loadable clips, split by the committed file
    rotations: np.ndarray  # (N, 22, 4) float32, all clips end to end
    hips: np.ndarray  # (N, 3) float32, metres
    starts: np.ndarray  # (len(infos) + 1,) first frame of each clip, then N
    problems: list[str]  # skip messages of the build
    build_seconds: float | None  # None: read from the cache

    def motion(self, k: int) -> Motion:
        s, e = self.starts[k], self.starts[k + 1]
        return Motion.from_rotations(canonical(), self.rotations[s:e], self.hips[s:e], BANDAI_FPS)


def _build(base: Path, dataset: int, progress: bool) -> dict[str, np.ndarray]:
    start = time.perf_counter()
    infos, problems = _scan_bandai(base, dataset)
    with ProcessPoolExecutor(max_workers=2) as pool:
        results = list(
            tqdm(
                pool.map(_parse_for_cache, [i.path for i in infos], chunksize=8),
                total=len(infos),
                desc=f"parsing bandai-{dataset}",
                unit="clip",
                disable=not progress,
            )
        )
    kept, arrays = [], []
    for info, result in zip(infos, results):
        if isinstance(result, str):
            problems.append(_skip(info.path, result.removeprefix(f"{info.path}: ")))
        else:
            kept.append([info.name, info.content, info.style, info.take])
            arrays.append(result)
    return pack(arrays, kept, problems, start)


def pack(parsed: list[tuple[np.ndarray, np.ndarray]], kept: list, problems: list[str], started: float
         ) -> dict[str, np.ndarray]:
    """The cache entry of parsed clips (float32 canonical rotations and Hips path each): the arrays
    end to end with each clip's first frame, the ``kept`` clips' labels, the skip messages and the
    seconds since ``started``."""
    return {
        "rotations": np.concatenate([r for r, _ in parsed]) if parsed else np.zeros((0, 22, 4), np.float32),
        "hips": np.concatenate([h for _, h in parsed]) if parsed else np.zeros((0, 3), np.float32),
        "starts": np.cumsum([0, *(len(r) for r, _ in parsed)]),
        "clips": np.array(json.dumps(kept)),
        "problems": np.array(json.dumps(problems)),
        "build_seconds": np.array(time.perf_counter() - started),
    }


def cached_clips(name: str, key: str, build: Callable[[], dict[str, np.ndarray]], rebuild: bool = False
                 ) -> tuple[dict[str, np.ndarray], list[str], bool]:
    """The cache entry ``name`` of parsed clips (:func:`pack`), built and saved when missing, stale
    or ``rebuild``; its skip messages (warned again when read from the cache, as a fresh parse
    warns them); whether it was built now."""
    arrays = None if rebuild else cache.load(name, key)
    fresh = arrays is None
    if fresh:
        arrays = build()
        cache.save(name, key, arrays)
    problems = json.loads(str(arrays["problems"]))
    if not fresh:
        for message in problems:
            log.warning(message)
    return arrays, problems, fresh


def _cached(base: Path, dataset: int, progress: bool, rebuild: bool = False) -> _Cached:
    """The parsed clips of one Bandai set (folder ``base``), from the cache or parsed and cached now."""
    sources = [*_folder(base / "data").glob("*.bvh"), *base.glob("data/*.json"), *base.glob("cfg/*.txt")]
    arrays, problems, fresh = cached_clips(f"bandai-{dataset}.v{CACHE_VERSION}", cache.source_key(sources),
                                           lambda: _build(base, dataset, progress), rebuild)
    data = base / "data"
    infos = _with_committed_split(
        ClipInfo(f"bandai-{dataset}", data / f"{n}.bvh", n, c, s, t, "")
        for n, c, s, t in json.loads(str(arrays["clips"]))
    )
    return _Cached(
        infos, arrays["rotations"], arrays["hips"], arrays["starts"], problems,
        float(arrays["build_seconds"]) if fresh else None,
    )


def build_cache(
    root: Path | None = None, datasets: tuple[int, ...] = BANDAI_DATASETS, rebuild: bool = False,
    progress: bool = True,
) -> dict[str, float | None]:
    """Bring the Bandai caches up to date; seconds each full parse took (None: was up to date)."""
    root = root or datasets_root()
    return {
        f"bandai-{n}": _cached(bandai_dir(root, n), n, progress, rebuild).build_seconds for n in datasets
    }


def load_bandai(infos: list[ClipInfo] | None = None, progress: bool = True) -> list[tuple[ClipInfo, Motion]]:
    """Bandai clips on the canonical skeleton (m, 30 fps), through the cache; default all of both sets.

    Rotations are float32 views into one array per set (about 140 MB for dataset-2); positions are
    float64 like the rest of the core. A clip that fails to load is skipped with a warning.
    """
    if infos is None:
        root = datasets_root()
        caches = [_cached(bandai_dir(root, n), n, progress) for n in BANDAI_DATASETS]
        return [(info, c.motion(k)) for c in caches for k, info in enumerate(c.infos)]
    groups: dict[tuple[Path, int], list[ClipInfo]] = {}
    for info in infos:
        if not info.dataset.startswith("bandai-"):
            raise MotionStyleError(f"{info.path}: load_bandai loads Bandai clips only, not {info.dataset}")
        groups.setdefault((info.path.parent.parent, int(info.dataset[-1])), []).append(info)
    loaded = {}
    for (base, dataset), wanted in groups.items():
        c = _cached(base, dataset, progress)
        where = {i.name: k for k, i in enumerate(c.infos)}
        for info in wanted:
            if info.name in where:
                loaded[info] = c.motion(where[info.name])
            elif not any(p.startswith(f"{info.path}: ") for p in c.problems):  # else warned already
                _skip(info.path, "not found when the cache was built")
    return [(info, loaded[info]) for info in infos if info in loaded]


# --- rotation statistics (what core.conform aligns retargeted joint frames to) -----------------


def rotation_stats_json(progress: bool = True) -> str:
    """The rotation statistics computed from the datasets, as the shipped file
    (:func:`motion_style_ros.io.resources.rotation_stats_file`) holds them."""
    from motion_style_ros.core.conform import statistics

    train = [m for info, m in load_bandai(progress=progress)
             if info.dataset == "bandai-2" and info.split == "train"]
    stats = statistics(train)
    return json.dumps({"data": f"Bandai Namco Research Motion Dataset 2, {len(train)} train takes",
                       "ankle_height": round(float(stats["ankle_height"]), 6),
                       "scale_reference": round(float(stats["scale_reference"]), 6),
                       "names": stats["names"].tolist(), "mean": stats["mean"].round(6).tolist(),
                       "std": stats["std"].round(6).tolist()}, indent=1) + "\n"
