"""The posture instrument: knee and hip flexion, the floor, and how far real styles move them."""

import numpy as np
import pytest

from motion_style_ros.core import rotations as rot
from motion_style_ros.core.motion import Motion
from motion_style_ros.core.synthetic import synthetic_motion
from motion_style_ros.evaluation import posture
from motion_style_ros.evaluation.unseen import canonical_unseen
from motion_style_ros.io import datasets as data
from motion_style_ros.io.resources import rotation_stats
from motion_style_ros.runtime import offline


def bent(motion: Motion, degrees: float) -> Motion:
    """``motion`` with both knees bent ``degrees`` further about their hinge (local Z)."""
    q = motion.rotations.copy()
    turn = rot.from_axis_angle(np.array([0.0, 0.0, 1.0]), np.radians(degrees))
    for side in "LR":
        j = motion.skeleton.index(f"LowerLeg_{side}")
        q[:, j] = rot.multiply(q[:, j], turn)
    return Motion.from_rotations(motion.skeleton, q, motion.root_positions, motion.fps)


def test_a_knee_bent_further_reads_that_much_more_flexion():
    walk = bent(synthetic_motion("walk", 30.0, 2.0), 40.0)  # knees well bent: 10 more is 10 more
    before, after = posture.posture(walk), posture.posture(bent(walk, 10.0))
    assert after["knee_p10"] - before["knee_p10"] == pytest.approx(10.0, abs=0.5)
    assert 8.0 < after["knee_mean"] - before["knee_mean"] <= 10.5
    assert after["hip_mean"] == pytest.approx(before["hip_mean"])  # the thighs did not move
    row = posture.compare(walk, walk)
    assert row["knee_mean_shift"] == 0.0 and row["floor_offset_cm"] == 0.0


def test_style_shifts_are_each_styles_mean_against_normals_content_by_content():
    class Info:
        def __init__(self, content, style):
            self.content, self.style = content, style

    walk = bent(synthetic_motion("walk", 30.0, 2.0), 40.0)
    clips = [(Info("walk", "normal"), walk), (Info("walk", "elderly"), bent(walk, 12.0)),
             (Info("wave", "elderly"), walk)]  # no normal wave: left out
    shifts = posture.style_shifts(clips)
    assert shifts["normal"]["knee_p10"] == 0.0
    assert shifts["elderly"]["knee_p10"] == pytest.approx(12.0, abs=0.5)


def test_a_cmu_walk_into_normal_keeps_its_knees_and_its_floor(datasets):
    """One clip of another rig, the shipped recurrent model, the node's defaults: the table's row
    for normal keeps the knees within the allowance, the feet on the input's floor."""
    info = next(i for i in data.index_cmu(datasets) if i.name == "02_01")
    clip = canonical_unseen(info, rotation_stats())
    report = posture.evaluate(offline.stylizer("recurrent"), ["normal"], [("cmu 02_01 (walk)", clip)], {})
    row = report["per_style"]["normal"]
    assert row["knee_mean_ok"] and row["knee_p10_ok"], row
    assert row["floor_offset_cm_max"] < 2.5
    assert row["foot_skating_ratio_median"] < 1.0
    assert "normal" in posture.format_table("recurrent", report)
