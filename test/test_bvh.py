"""BVH reading/writing on real dataset files and on files the tests write themselves."""

import numpy as np
import pytest

from motion_style_ros.core import rotations as rot
from motion_style_ros.core.motion import Motion
from motion_style_ros.core.skeleton import canonical
from motion_style_ros.io import bvh

BANDAI2 = "bandai-namco/Bandai-Namco-Research-Motiondataset-2/data/dataset-2_walk_normal_001.bvh"
BANDAI1 = "bandai-namco/Bandai-Namco-Research-Motiondataset-1/data/dataset-1_bow_old_001.bvh"
CMU = "cmu/data/02/02_01.bvh"
XIA = "xia-test/neutral_01_000.bvh"


@pytest.mark.parametrize("rel", [BANDAI2, BANDAI1, CMU, XIA])
def test_real_file_round_trip_exact_to_file_precision(datasets, tmp_path, rel):
    clip = bvh.read(datasets / rel)
    out = tmp_path / "copy.bvh"
    bvh.write(out, clip)
    again = bvh.read(out)
    assert again.skeleton.names == clip.skeleton.names
    assert again.skeleton.parents == clip.skeleton.parents
    assert again.channels == clip.channels
    assert np.array_equal(again.skeleton.offsets, clip.skeleton.offsets)
    assert again.skeleton.end_sites.keys() == clip.skeleton.end_sites.keys()
    assert again.frame_time == clip.frame_time
    assert np.array_equal(again.data, clip.data)
    bvh.write(tmp_path / "short.bvh", clip, precision=6)
    assert np.abs(bvh.read(tmp_path / "short.bvh").data - clip.data).max() <= 5e-7 + 1e-12
    bvh.write(tmp_path / "copy2.bvh", again)
    assert (tmp_path / "copy2.bvh").read_text() == out.read_text()


def test_bandai_file_is_the_canonical_skeleton(datasets):
    clip = bvh.read(datasets / BANDAI2)
    m = clip.to_motion(scale=0.01)
    assert clip.fps == 30.0
    assert m.skeleton.names == canonical().names
    assert np.allclose(m.skeleton.offsets[2:], canonical().offsets[2:], atol=1e-3)  # sub-millimetre
    # Y up, feet on the floor, facing +Z with the left side at +X.
    g = m.global_positions()
    sk = canonical()
    assert abs(g[:, [sk.index("Toes_L"), sk.index("Toes_R")], 1].min()) < 0.06  # toe joints sit ~4 cm above the floor
    assert 1.3 < g[:, sk.index("Head"), 1].mean() < 1.7  # head joint of a ~1.7 m person
    assert g[-1, sk.index("Hips"), 2] - g[0, sk.index("Hips"), 2] > 3.0
    assert (g[:, sk.index("UpperLeg_L"), 0] > g[:, sk.index("UpperLeg_R"), 0]).mean() > 0.9


def test_cmu_rates_and_channel_orders(datasets):
    clip = bvh.read(datasets / CMU)
    assert clip.fps == 120.0
    assert clip.channels[0] == ("Xposition", "Yposition", "Zposition", "Zrotation", "Yrotation", "Xrotation")
    assert all(len(c) == 3 for c in clip.channels[1:])
    assert len(clip.skeleton.names) == 31


def test_motion_round_trip_through_written_file(tmp_path):
    sk = canonical()
    rng = np.random.default_rng(1)
    t = 40
    rotations = rot.normalize(rng.normal(size=(t, sk.n_joints, 4)))
    root = np.cumsum(rng.normal(scale=0.01, size=(t, 3)), axis=0) + [0, 0.9, 0]
    m = Motion.from_rotations(sk, rotations, root, fps=60.0)
    path = tmp_path / "m.bvh"
    bvh.write(path, bvh.BvhClip.from_motion(m, scale=100.0), precision=8)
    back = bvh.read(path).to_motion(scale=0.01)
    assert back.fps == 60.0
    assert np.abs(rot.angle_between(back.rotations, m.rotations)).max() < 1e-6
    assert np.allclose(back.global_positions(), m.global_positions(), atol=1e-6)


def test_custom_channel_orders_and_three_channel_joints(tmp_path):
    sk = canonical()
    chans = tuple(
        ("Yposition", "Xposition", "Zposition", "Xrotation", "Zrotation", "Yrotation") if j == 1
        else ("Yrotation", "Xrotation", "Zrotation")
        for j in range(sk.n_joints)
    )
    rng = np.random.default_rng(2)
    rotations = rot.normalize(rng.normal(size=(5, sk.n_joints, 4)))
    m = Motion.from_rotations(sk, rotations, rng.normal(size=(5, 3)), fps=30.0)
    path = tmp_path / "c.bvh"
    bvh.write(path, bvh.BvhClip.from_motion(m, channels=chans), precision=10)
    clip = bvh.read(path)
    assert clip.channels == chans
    assert np.allclose(clip.to_motion().global_positions(), m.global_positions(), atol=1e-8)


GOOD_HEADER = """HIERARCHY
ROOT Hips
{
  OFFSET 0 0 0
  CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation
  JOINT Spine
  {
    OFFSET 0 10 0
    CHANNELS 3 Zrotation Xrotation Yrotation
    End Site
    {
      OFFSET 0 5 0
    }
  }
}
"""


@pytest.mark.parametrize(
    "motion_text, problem",
    [
        ("MOTION\nFrames: 2\nFrame Time: 0.033\n0 0 0 0 0 0 0 0 0\n", "truncated"),
        ("MOTION\nFrames: 0\nFrame Time: 0.033\n", "0 frames"),
        ("MOTION\nFrames: 1\nFrame Time: 0.033\n0 0 nan 0 0 0 0 0 0\n", "non-finite"),
        ("MOTION\nFrames: 1\nFrame Time: 0.033\n0 0 x 0 0 0 0 0 0\n", "non-number"),
        ("MOTION\nFrames: 1\nFrame Time: 0\n0 0 0 0 0 0 0 0 0\n", "frame time"),
    ],
)
def test_bad_motion_sections_name_file_and_problem(tmp_path, motion_text, problem):
    path = tmp_path / "bad.bvh"
    path.write_text(GOOD_HEADER + motion_text)
    with pytest.raises(bvh.BvhError) as e:
        bvh.read(path)
    assert str(path) in str(e.value) and problem in str(e.value)
    assert "\n" not in str(e.value)


@pytest.mark.parametrize(
    "text, problem",
    [
        ("", "no MOTION"),
        (GOOD_HEADER.replace("CHANNELS 3", "CHANNELS 4"), "channels"),
        (GOOD_HEADER.replace("Zrotation Xrotation Yrotation\n    End", "Zrotation Xrotation Wrotation\n    End"), "unknown channel"),
        (GOOD_HEADER[: GOOD_HEADER.index("End Site")], "ends early"),
        (GOOD_HEADER.replace("JOINT Spine", "JOINT Hips"), "duplicate"),
    ],
)
def test_bad_headers(tmp_path, text, problem):
    path = tmp_path / "bad.bvh"
    motion = "MOTION\nFrames: 1\nFrame Time: 0.033\n" + " ".join(["0"] * 9) + "\n"
    path.write_text(text + (motion if text else ""))
    with pytest.raises(bvh.BvhError, match=problem):
        bvh.read(path)


def test_missing_file(tmp_path):
    with pytest.raises(bvh.BvhError, match="cannot read"):
        bvh.read(tmp_path / "nope.bvh")
