"""Conforming retargeted joint frames: positions untouched, rotations made typical of the training data."""

import numpy as np

from motion_style_ros.core import rotations as rot
from motion_style_ros.core.conform import CHAINS, conform_rolls
from motion_style_ros.core.retarget import retarget
from motion_style_ros.core.skeleton import canonical
from motion_style_ros.io import bvh, datasets


def typicality(motion, stats) -> float:
    """Mean squared z-score of the arm joints' 6D rotations under the training statistics."""
    joints = [motion.skeleton.index(n) for chain in CHAINS for n in chain]
    z = (rot.to_6d(motion.rotations[:, joints]) - stats["mean"][joints]) / stats["std"][joints]
    return float(np.square(z).mean())


def test_a_retargeted_cmu_walk_keeps_its_positions_and_gets_typical_arms(datasets):
    stats = datasets_module().rotation_stats()
    source = bvh.read(datasets / "cmu/data/07/07_01.bvh").to_motion()[1:]
    raw = retarget(source, canonical())
    conformed = conform_rolls(raw, stats)
    assert np.abs(conformed.global_positions() - raw.global_positions()).max() < 1e-9
    assert typicality(conformed, stats) < 0.6 * typicality(raw, stats)  # 4.4 vs 9.4 on 07_01
    # Only the arm chains' frames turn.
    arms = {canonical().index(n) for chain in CHAINS for n in chain}
    others = [j for j in range(22) if j not in arms]
    assert np.array_equal(conformed.rotations[:, others], raw.rotations[:, others])


def test_a_bandai_clip_is_nearly_left_as_it_is(datasets):
    stats = datasets_module().rotation_stats()
    path = datasets / "bandai-namco/Bandai-Namco-Research-Motiondataset-2/data/dataset-2_walk_normal_001.bvh"
    clip = datasets_module().load_clip(datasets_module().ClipInfo("bandai-2", path, path.stem, "walk",
                                                                  "normal", "", ""))
    conformed = conform_rolls(clip, stats)
    # A clip of the training data itself turns by at most two 5-degree grid steps.
    assert np.degrees(rot.angle_between(conformed.rotations, clip.rotations)).max() < 10.1


def test_the_shipped_statistics_come_from_the_datasets(datasets):
    import os

    os.environ.setdefault("MOTION_STYLE_DATASETS", str(datasets))
    assert datasets_module().rotation_stats_file().read_text() == \
        datasets_module().rotation_stats_json(progress=False)


def datasets_module():
    return datasets
