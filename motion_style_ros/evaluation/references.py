"""Restyling like a reference clip, scored: a stylizer that takes each pair's style from another
test take (:class:`ReferenceStylizer`, any backend that takes reference clips) and MoST's content
and style consistency (Kim et al. 2024, appendix E, after Wen et al. 2021) on its outputs.

Both consistencies are distances between local poses (:func:`local_pose`: joint positions about
the pelvis, in the body's facing frame; the paper leaves global translation out "for a fair
comparison", and so does this, with the heading): per frame the sum over joints of the Euclidean
distance, averaged over the frames both motions have (:func:`pose_distance`, metres). Lower is
better for both, and they trade off: returning the input unchanged gives CC 0 and a high SC++.

- **CC**: the input restyled like a take of *its own* style (another take); the output should be
  the input, so CC is the distance between them.
- **SC++**: the input restyled like a take of another style; the output is compared with every
  *train* take of the input's content in the reference's style (the paper's pseudo ground truth)
  and the distances averaged.

Each is reported for references of the input's content and of another content, as the paper's
Table 1 does.
"""

from __future__ import annotations

import zlib
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from tqdm import tqdm

from motion_style_ros.core import rotations as rot
from motion_style_ros.core.features import facing_yaw
from motion_style_ros.core.motion import Motion
from motion_style_ros.errors import MotionStyleError
from motion_style_ros.evaluation.harness import PUBLISHED, Clip, Pair, SkipPair
from motion_style_ros.runtime.defaults import DEFAULTS


class ReferenceStylizer:
    """A reference-clip backend's session with each pair's style from a reference clip instead
    of the style's own input: a test take of the target style (not the source itself), of another
    content than the source's, or with ``same_content`` of the same content (chosen per pair with
    the seed; at least a window long), read as the target style's. A source not among ``clips``
    (an unseen clip) gets any of them in the target style. :attr:`last_reference` is the take the
    last call used, as ``(name, motion)``. ``session``: settings that replace the published ones
    (:data:`~motion_style_ros.evaluation.harness.PUBLISHED`)."""

    def __init__(self, clips: list[Clip], backend: str = "stgcn", model: str | Path | None = None,
                 alpha: float = DEFAULTS["alpha"], threads: int = 1, seed: int = 0, same_content: bool = False,
                 session: dict | None = None) -> None:
        from motion_style_ros.runtime.backends import backend as spec
        from motion_style_ros.runtime.backends import with_feature

        made_by = spec(backend)
        if not made_by.reference_clips:
            raise MotionStyleError(f"reference codes need backend {' or '.join(with_feature('reference_clips'))}; "
                                   f"{backend} takes no reference clip")
        self._info = {id(m): info for info, m in clips}
        self._by_style: dict[str, list[tuple[str, Motion]]] = {}
        for info, m in sorted(clips, key=lambda c: c[0].name):
            self._by_style.setdefault(info.style, []).append((info, m))
        settings = dict(threads=threads, **PUBLISHED, **(session or {}))
        self._make = lambda fps: made_by.open_session(model, input_fps=fps, **settings)
        self._sessions = {None: self._make(None)}  # per input rate
        self._alpha, self._seed, self.same_content = alpha, seed, same_content
        self.last_reference: tuple[str, Motion] | None = None

    def __call__(self, source: Motion, target_style: str) -> Motion:
        info = self._info.get(id(source))
        if source.fps not in self._sessions:
            self._sessions[source.fps] = self._make(source.fps)
        session = self._sessions[source.fps]
        window_seconds = session.window / session.fps
        candidates = [(ref, m) for ref, m in self._by_style.get(target_style, [])
                      if m is not source and m.n_frames / m.fps >= window_seconds
                      and (info is None or (ref.content == info.content) == self.same_content)]
        if not candidates:
            which = "any content" if info is None else (
                f"{'the same content as' if self.same_content else 'another content than'} {info.content}")
            raise SkipPair(f"no test take in style {target_style} of {which} with a window's "
                           f"{session.window} frames")
        key = info.name if info is not None else f"unseen {source.n_frames} {source.positions[0, 0]}"
        rng = np.random.default_rng([self._seed, zlib.crc32(f"{key}>{target_style}".encode())])
        ref, motion = candidates[int(rng.integers(len(candidates)))]
        session.set_reference(motion, style=target_style)
        self.last_reference = (ref.name, motion)
        return session.run(source, target_style, self._alpha)


def local_pose(motion: Motion) -> np.ndarray:
    """``(T, J, 3)`` joint positions about the pelvis, turned so that the body faces +Z."""
    positions = motion.global_positions()
    local = positions - positions[:, :1]
    yaw = facing_yaw(positions, motion.skeleton)
    return rot.rotate(rot.from_yaw(-yaw)[:, None], local)


def pose_distance(a: np.ndarray, b: np.ndarray) -> float:
    """Per frame the sum over joints of the distance between two local poses ``(T, J, 3)``,
    averaged over the frames both have (the paper's, from each clip's start)."""
    n = min(len(a), len(b))
    if n == 0:
        raise MotionStyleError("pose distance of an empty motion")
    return float(np.linalg.norm(a[:n] - b[:n], axis=-1).sum(axis=-1).mean())


@dataclass(frozen=True)
class Consistency:
    """The four figures of one stylizer, in metres (None where no pair had a reference)."""

    cc_same: float | None
    cc_other: float | None
    sc_same: float | None
    sc_other: float | None
    pairs: int


def consistency(stylizers: dict[str, ReferenceStylizer], clips: list[Clip], pairs: list[Pair],
                train: list[Clip], progress: bool = True) -> dict[str, Consistency]:
    """CC and SC++ of every stylizer with references of the same content and of another (each
    stylizer's ``same_content`` is set and restored): CC on each pair's source restyled into its
    own style, SC++ on each pair against the ``train`` takes of its source's content in the target
    style (a pair without such takes is left out of SC++)."""
    by_name = {info.name: m for info, m in clips}
    poses: dict[int, np.ndarray] = {}

    def pose(m: Motion) -> np.ndarray:
        if id(m) not in poses:
            poses[id(m)] = local_pose(m)
        return poses[id(m)]

    truth: dict[tuple[str, str], list[np.ndarray]] = {}
    for info, m in train:
        truth.setdefault((info.content, info.style), []).append(local_pose(m))
    sources = sorted({p.source.name: p.source for p in pairs}.values(), key=lambda i: i.name)
    result = {}
    for name, stylize in stylizers.items():
        was, figures, count = stylize.same_content, {}, 0
        for same in (True, False):
            stylize.same_content = same
            cc, sc = [], []
            for info in tqdm(sources, desc=f"{name} CC ({'same' if same else 'other'} content)",
                             disable=not progress):
                try:
                    cc.append(pose_distance(local_pose(stylize(by_name[info.name], info.style)),
                                            pose(by_name[info.name])))
                except SkipPair:
                    continue
            for pair in tqdm(pairs, desc=f"{name} SC++ ({'same' if same else 'other'} content)",
                             disable=not progress):
                ground = truth.get((pair.source.content, pair.target))
                if not ground:
                    continue
                try:
                    out = local_pose(stylize(by_name[pair.source.name], pair.target))
                except SkipPair:
                    continue
                sc.append(float(np.mean([pose_distance(out, g) for g in ground])))
            key = "same" if same else "other"
            figures[f"cc_{key}"] = float(np.mean(cc)) if cc else None
            figures[f"sc_{key}"] = float(np.mean(sc)) if sc else None
            count += len(cc) + len(sc)
        stylize.same_content = was
        result[name] = Consistency(pairs=count, **figures)
    return result


def format_consistency(result: dict[str, Consistency]) -> str:
    """A table of :func:`consistency`'s figures."""
    def cell(v: float | None) -> str:
        return "-" if v is None else f"{v:.3f}"

    lines = ["MoST's consistencies (m, lower is better): CC input into its own style, SC++ against "
             "train takes", f"{'':16s} {'CC same':>9s} {'CC other':>9s} {'SC++ same':>10s} {'SC++ other':>11s}"]
    for name, c in result.items():
        lines.append(f"{name:16s} {cell(c.cc_same):>9s} {cell(c.cc_other):>9s} {cell(c.sc_same):>10s} "
                     f"{cell(c.sc_other):>11s}")
    return "\n".join(lines)
