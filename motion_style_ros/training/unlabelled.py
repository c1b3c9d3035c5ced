"""Unlabelled content for the stylizers' training: motion from other capture setups (a CMU
subject, a folder of any rig's BVH files) that has no style label, so it is never reconstructed or
judged as real, only restyled. The generator learns to move *these* inputs into every style (the
critic's and the content network's terms), which labelled Bandai takes alone never asked of it.

Each clip is conditioned as a stream is in the node (retargeted, grounded, arm rolls conformed,
root displacements scaled to the training performers' size; :mod:`motion_style_ros.runtime.stream`)
and resampled to the training rate, so that the model sees in training what it sees live.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np
from tqdm import tqdm

from motion_style_ros.core.conform import ARM_JOINTS, apply_rolls, clip_rolls, planted_ankle_height
from motion_style_ros.core.features import encode
from motion_style_ros.core.mirror import mirror as mirror_motion
from motion_style_ros.core.motion import Motion
from motion_style_ros.core.proportions import clip_scale
from motion_style_ros.core.resample import at_speed, resample
from motion_style_ros.errors import MotionStyleError
from motion_style_ros.evaluation.unseen import canonical_unseen, clip_name
from motion_style_ros.io import datasets
from motion_style_ros.io.canonical import canonical_clip
from motion_style_ros.io.resources import rotation_stats

CMU_PREFIX = "cmu:"  # "cmu:07": every clip of CMU subject 07 in the datasets folder


def sources(spec: str, stats: dict[str, np.ndarray]) -> list[tuple[str, Motion]]:
    """The clips ``spec`` names, each ``(name, motion on the canonical skeleton, grounded)``:
    ``cmu:SUBJECT`` or ``cmu:SUBJECT_TRIAL`` (named and loaded as ``eval --unseen`` names and loads
    them) or a BVH file or folder of BVH files (any rig :func:`canonical_clip` takes)."""
    if spec.startswith(CMU_PREFIX):
        wanted = spec[len(CMU_PREFIX):]
        infos = [i for i in datasets.index_cmu() if wanted in (i.name, i.name.split("_")[0])]
        if not infos:
            raise MotionStyleError(f"{spec}: no CMU clip or subject {wanted!r}")
        return [(clip_name(i), canonical_unseen(i, stats)) for i in infos]
    path = Path(spec).expanduser()
    files = sorted(path.rglob("*.bvh")) if path.is_dir() else [path]
    if not files or not files[0].is_file():
        raise MotionStyleError(f"{spec}: no BVH file there (give cmu:SUBJECT, a .bvh or a folder)")
    return [(str(f), canonical_clip(str(f))) for f in files]


def conditioning(source: Motion, fps: float, stats: dict[str, np.ndarray]) -> Callable[[Motion], Motion]:
    """How a stream session conditions ``source`` for a model at ``fps`` (arm rolls conformed, root
    displacements divided by the performer's size, grounded again; ``stats``:
    :func:`~motion_style_ros.io.resources.rotation_stats`), as a function that applies the same
    rolls, scale and height to ``source`` or to any motion of the same frames (its stylized output)."""
    sk = source.skeleton
    joints = [sk.index(n) for n in ARM_JOINTS]
    rolls = clip_rolls(source, stats)
    rolled = Motion(sk, apply_rolls(source.rotations, joints, rolls), source.positions, source.fps)
    scale = clip_scale(resample(rolled, fps), float(stats["scale_reference"]))
    origin = source.positions[:1, sk.pelvis]

    def placed(motion: Motion) -> Motion:
        root = motion.positions[:, sk.pelvis]
        scaled = origin + (root - origin) / scale
        return resample(Motion.from_rotations(sk, apply_rolls(motion.rotations, joints, rolls), scaled, motion.fps),
                        fps)

    lift = float(stats["ankle_height"]) - planted_ankle_height(placed(source))

    def apply(motion: Motion) -> Motion:
        out = placed(motion)
        positions = out.positions.copy()
        positions[:, sk.pelvis, 1] += lift
        return Motion(sk, out.rotations, positions, out.fps)

    return apply


def conditioned(motion: Motion, fps: float, stats: dict[str, np.ndarray]) -> Motion:
    """``motion`` as a stream session feeds it to a model at ``fps`` (:func:`conditioning`)."""
    return conditioning(motion, fps, stats)(motion)


def load_unlabelled(specs: tuple[str, ...], fps: float, speeds: tuple[float, ...] = (), mirror: bool = False,
                    progress: bool = True) -> tuple[list[np.ndarray], list[str]]:
    """Encoded features of every clip ``specs`` name (also at ``speeds`` and mirrored, as the
    labelled takes), and the clip names (for the model card and ``eval --unseen``)."""
    stats = rotation_stats()
    features, names = [], []
    for spec in specs:
        for name, motion in tqdm(sources(spec, stats), desc=f"unlabelled {spec}", disable=not progress):
            base = conditioned(motion, fps, stats)
            variants = [base, *(at_speed(base, v) for v in speeds)]
            if mirror:
                variants += [mirror_motion(v) for v in variants]
            features += [encode(v) for v in variants]
            names.append(name)
    return features, names
