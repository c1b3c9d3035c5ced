"""Restyling like reference clips, scored: the reference stylizer of any reference-clip backend,
and MoST's content and style consistencies (CC, SC++) on local poses."""

import numpy as np
import pytest
from onnx_fixtures import windowed_model

from motion_style_ros.core import rotations as rot
from motion_style_ros.core.motion import Motion
from motion_style_ros.errors import MotionStyleError
from motion_style_ros.evaluation.harness import PUBLISHED, Pair, SkipPair
from motion_style_ros.evaluation.references import (
    ReferenceStylizer,
    consistency,
    format_consistency,
    local_pose,
    pose_distance,
)
from motion_style_ros.io.datasets import ClipInfo, load_clip
from motion_style_ros.runtime.stgcn import StgcnSession

STYLES = ["active", "elderly", "exhausted", "feminine", "masculine", "normal", "youthful"]
BANDAI = "bandai-namco/Bandai-Namco-Research-Motiondataset-2/data"


@pytest.fixture(scope="module")
def random_model(tmp_path_factory):
    return windowed_model(tmp_path_factory.mktemp("random") / "stgcn.onnx", STYLES)


@pytest.fixture(scope="module")
def clips(datasets):
    names = [("walk", "normal", "001"), ("walk", "elderly", "008"), ("run", "elderly", "001"),
             ("walk", "elderly", "009")]
    infos = [ClipInfo("bandai-2", datasets / BANDAI / f"dataset-2_{c}_{s}_{t}.bvh",
                      f"dataset-2_{c}_{s}_{t}", c, s, t, "test") for c, s, t in names]
    return [(info, load_clip(info)) for info in infos]


def test_reference_stylizer_takes_its_code_from_another_content_or_the_same(random_model, clips):
    stylize = ReferenceStylizer(clips, "stgcn", random_model)
    source = clips[0][1]
    out = stylize(source, "elderly")  # the run, not an elderly walk, gives the code
    assert stylize.last_reference[0] == clips[2][0].name
    assert out.n_frames == source.n_frames and np.isfinite(out.global_positions()).all()
    session = StgcnSession(random_model, **PUBLISHED)
    session.set_reference(clips[2][1], style="elderly")
    assert np.array_equal(out.global_positions(), session.run(source, "elderly").global_positions())
    with pytest.raises(SkipPair, match="no test take in style youthful of another content than walk"):
        stylize(source, "youthful")
    stylize.same_content = True
    stylize(source, "elderly")
    assert stylize.last_reference[0] in (clips[1][0].name, clips[3][0].name)
    stylize(clips[1][1], "elderly")  # its own style: the other elderly walk, never itself
    assert stylize.last_reference[0] == clips[3][0].name
    unseen = clips[0][1][:90]  # a clip it was not built with: any take of the target style
    out = stylize(unseen, "elderly")
    assert out.n_frames == 90 and stylize.last_reference[0] in {i.name for i, _ in clips if i.style == "elderly"}


def test_a_backend_without_reference_clips_is_refused_naming_those_with_them(clips):
    with pytest.raises(MotionStyleError, match="reference codes need backend stgcn.*recurrent takes no"):
        ReferenceStylizer(clips, "recurrent")


def test_local_poses_leave_out_global_translation_and_heading(clips):
    motion = clips[0][1]
    turn = rot.from_yaw(np.full(motion.n_frames, 0.7))
    moved = Motion(motion.skeleton, motion.rotations.copy(), motion.positions.copy(), motion.fps)
    # the whole clip turned about +Y and carried 3 m away: the same local poses
    moved.rotations[:, 0] = rot.multiply(turn, motion.rotations[:, 0])
    moved.positions[:, 0] = rot.rotate(turn, motion.positions[:, 0]) + [3.0, 0.0, -2.0]
    np.testing.assert_allclose(local_pose(moved), local_pose(motion), atol=1e-9)
    assert pose_distance(local_pose(moved), local_pose(motion)) < 1e-8


def test_pose_distance_sums_joints_and_averages_the_frames_both_have():
    a = np.zeros((10, 3, 3))
    b = np.zeros((6, 3, 3))
    b[:, 1, 0] = 0.2  # one joint 20 cm off in every frame
    b[:3, 2, 1] = 0.1  # another 10 cm off in half the frames
    assert pose_distance(a, b) == pytest.approx(0.2 + 0.1 / 2)
    with pytest.raises(MotionStyleError, match="empty"):
        pose_distance(a[:0], b)


class _Returns:
    """A stylizer that gives its input back: CC 0, SC++ the input's own distance to the truth."""

    same_content = False

    def __call__(self, source: Motion, target_style: str) -> Motion:
        return source


def test_consistency_of_a_stylizer_that_returns_its_input(clips):
    by_name = {info.name: (info, m) for info, m in clips}
    walk_normal, walk_elderly = clips[0], clips[1]
    pairs = [Pair(walk_normal[0], "elderly"), Pair(walk_normal[0], "youthful")]  # youthful: no truth
    train = [walk_elderly, clips[3]]  # two elderly walks as the pseudo ground truth
    result = consistency({"identity": _Returns()}, list(by_name.values()), pairs, train, progress=False)
    figures = result["identity"]
    assert figures.cc_same == 0.0 and figures.cc_other == 0.0
    expected = np.mean([pose_distance(local_pose(walk_normal[1]), local_pose(m)) for _, m in train])
    assert figures.sc_same == pytest.approx(expected) and figures.sc_other == pytest.approx(expected)
    assert expected > 0.1  # a normal walk is not an elderly one
    assert figures.pairs == 4  # CC and SC++ once each, for same and other content
    table = format_consistency(result)
    assert "identity" in table and f"{expected:.3f}" in table
