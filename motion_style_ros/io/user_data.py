"""A user's own labelled BVH folder as training data: its labels, its split by take, its cache.

Any humanoid skeleton :func:`motion_style_ros.io.canonical.canonical_clip` can read (the canonical
Bandai skeleton, or one :mod:`motion_style_ros.core.retarget` maps) at any frame rate; each file is
one take. Labels come from ``labels.csv`` in the folder (columns ``file`` relative to the folder,
``style``, and optionally ``content``) or, without one, from the layout: the first folder under it
is the style (``PATH/<style>/**/*.bvh``, as 100STYLE ships). A take with no content label has the
content ``unlabelled``.

Split (``motion_style_split.csv`` beside the clips, columns ``file,split``): written when the folder
is first indexed, read on every later use. Within each style, takes sorted by file name, the k-th
take goes to test when ``k % 20`` is 1, 8 or 15, to val when it is 2 or 11, else to train: a style
with 3 takes has one of each, one with 20 has 15 / 2 / 3. A file added later is not in the split
file and is refused (the rule would move other takes), with the fix in the message.

Every file is parsed (and retargeted) into the cache when the folder is indexed, since only that
tells whether it can be used: a file that is not BVH, truncated, not a humanoid the retargeter
maps, or unlabelled is skipped with one line naming it and counted.
"""

from __future__ import annotations

import csv
import hashlib
import json
import logging
import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from tqdm import tqdm

from motion_style_ros.core.motion import Motion
from motion_style_ros.core.resample import resample
from motion_style_ros.core.skeleton import canonical
from motion_style_ros.errors import MotionStyleError
from motion_style_ros.io import cache
from motion_style_ros.io.canonical import canonical_clip
from motion_style_ros.io.datasets import BANDAI_FPS, ClipInfo, cached_clips, pack

log = logging.getLogger(__name__)

LABELS = "labels.csv"
SPLIT = "motion_style_split.csv"
UNLABELLED = "unlabelled"
MIN_TAKES = 3  # one train, one val and one test take per style (the split rule's first three)
CACHE_VERSION = 1


@dataclass(eq=False)
class Folder:
    """The usable takes of a folder with their split, on the canonical skeleton at the training rate."""

    infos: list[ClipInfo]
    motions: list[Motion]
    problems: list[str]  # one line per skipped file
    build_seconds: float | None  # None: read from the cache

    def too_few(self) -> dict[str, int]:
        """Styles with fewer than :data:`MIN_TAKES` takes, and how many they have."""
        counts: dict[str, int] = {}
        for info in self.infos:
            counts[info.style] = counts.get(info.style, 0) + 1
        return {s: n for s, n in sorted(counts.items()) if n < MIN_TAKES}


def _skip(path: Path, problem: str) -> str:
    message = f"{path}: {problem}; skipped"
    log.warning(message)
    return message


def folder_id(path: Path | str) -> str:
    """``<folder name>-<hash of its absolute path>``: names the folder's cache entry and the
    checkpoints of runs on it."""
    folder = Path(path).resolve()
    return f"{folder.name}-{hashlib.sha256(str(folder).encode()).hexdigest()[:8]}"


def split_rule(position: int) -> str:
    """The split of the ``position``-th take (0-based, by file name) of a style."""
    r = position % 20
    return "test" if r in (1, 8, 15) else "val" if r in (2, 11) else "train"


def _labels(folder: Path, files: list[Path], problems: list[str]) -> dict[str, tuple[str, str]]:
    """``{relative file: (style, content)}`` from ``labels.csv`` or the style folders."""
    rel = {f.relative_to(folder).as_posix(): f for f in files}
    table = folder / LABELS
    if not table.is_file():
        labels = {}
        for name, path in rel.items():
            if "/" in name:
                labels[name] = (name.split("/")[0], UNLABELLED)
            else:
                problems.append(_skip(path, f"not in a style folder and there is no {LABELS}"))
        return labels
    try:
        with open(table, newline="", encoding="utf-8-sig") as f:  # a spreadsheet's BOM too
            rows = list(csv.DictReader(f))
    except (OSError, UnicodeDecodeError, csv.Error) as e:
        raise MotionStyleError(f"{table}: cannot read the labels ({e})") from None
    if not rows or not {"file", "style"} <= set(rows[0]):
        raise MotionStyleError(f"{table}: needs the columns file, style (and optionally content)")
    labels = {}
    for row in rows:
        name, style = Path(row["file"] or "").as_posix(), (row["style"] or "").strip()
        if name not in rel:
            problems.append(_skip(folder / name, f"listed in {LABELS} but not a .bvh file in the folder"))
        elif not style:
            problems.append(_skip(rel[name], f"no style in {LABELS}"))
        else:
            labels[name] = (style, (row.get("content") or "").strip() or UNLABELLED)
    for name in sorted(set(rel) - set(labels) - {Path(r["file"] or "").as_posix() for r in rows}):
        problems.append(_skip(rel[name], f"not listed in {LABELS}"))
    return labels


def _parse(path: Path) -> tuple[np.ndarray, np.ndarray] | str:
    """Worker: float32 canonical rotations and pelvis path of one take at the training rate, or why not."""
    try:
        m = resample(canonical_clip(str(path)), BANDAI_FPS)
    except MotionStyleError as e:
        return str(e).removeprefix(f"{path}: ")
    return m.rotations.astype(np.float32), m.positions[:, canonical().pelvis].astype(np.float32)


def _build(folder: Path, names: list[str], progress: bool) -> dict[str, np.ndarray]:
    start = time.perf_counter()
    with ProcessPoolExecutor(max_workers=2) as pool:
        results = list(tqdm(pool.map(_parse, [folder / n for n in names], chunksize=4), total=len(names),
                            desc=f"parsing {folder.name}", unit="clip", disable=not progress))
    kept, arrays, problems = [], [], []
    for name, result in zip(names, results):
        if isinstance(result, str):
            problems.append(_skip(folder / name, result))
        else:
            kept.append(name)
            arrays.append(result)
    return pack(arrays, kept, problems, start)


def _split(folder: Path, labelled: list[tuple[str, str]]) -> dict[str, str]:
    """``{relative file: split}`` from the split file, written by the rule when there is none."""
    path = folder / SPLIT
    if path.is_file():
        try:
            with open(path, newline="", encoding="utf-8") as f:
                table = {row["file"]: row["split"] for row in csv.DictReader(f)}
        except (OSError, KeyError, UnicodeDecodeError, csv.Error) as e:
            raise MotionStyleError(f"{path}: cannot read the split ({e})") from None
        new = [name for name, _ in labelled if name not in table]
        odd = sorted({s for s in table.values() if s not in ("train", "val", "test")})
        if new or odd:
            raise MotionStyleError(
                f"{path}: " + (f"splits {', '.join(odd)} are not train, val or test" if odd else
                               f"no split for {len(new)} take(s) ({', '.join(new[:3])}"
                               f"{', ...' if len(new) > 3 else ''})")
                + "; delete it to split the folder afresh (the held-out takes change)")
        return table
    positions: dict[str, int] = {}
    table = {}
    for name, style in sorted(labelled):
        table[name] = split_rule(positions.setdefault(style, 0))
        positions[style] += 1
    try:
        with open(path, "w", newline="", encoding="utf-8") as f:
            writer = csv.writer(f, lineterminator="\n")
            writer.writerow(["file", "split"])
            writer.writerows(sorted(table.items()))
    except OSError as e:
        raise MotionStyleError(f"{path}: cannot write the split ({e.strerror or e})") from None
    return table


def load_folder(path: Path | str, progress: bool = True, rebuild: bool = False) -> Folder:
    """Every usable take of a labelled BVH folder, parsed through the cache, with its split."""
    folder = Path(path).resolve()
    if not folder.is_dir():
        raise MotionStyleError(f"{path}: not a folder of BVH files")
    files = sorted(p for p in folder.rglob("*") if p.suffix.lower() == ".bvh" and p.is_file())
    problems: list[str] = []
    labels = _labels(folder, files, problems)
    names = sorted(labels)
    entry = f"user-{folder_id(folder)}.v{CACHE_VERSION}"
    arrays, built, fresh = cached_clips(entry, cache.source_key(folder / n for n in names),
                                        lambda: _build(folder, names, progress), rebuild)
    problems += built
    kept = json.loads(str(arrays["clips"]))
    if not kept:
        raise MotionStyleError(f"{folder}: no usable labelled BVH take ({len(problems)} skipped)")
    split = _split(folder, [(n, labels[n][0]) for n in kept])
    infos, motions, starts = [], [], arrays["starts"]
    for k, name in enumerate(kept):
        style, content = labels[name]
        infos.append(ClipInfo("user", folder / name, name.removesuffix(Path(name).suffix), content, style,
                              name, split[name]))
        s, e = starts[k], starts[k + 1]
        motions.append(Motion.from_rotations(canonical(), arrays["rotations"][s:e], arrays["hips"][s:e],
                                             BANDAI_FPS))
    return Folder(infos, motions, problems, float(arrays["build_seconds"]) if fresh else None)
