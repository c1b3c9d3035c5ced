"""JointState codec: canonical layout round trip, REP-103 frames, validation, YAML maps."""

from pathlib import Path

import numpy as np
import pytest

from motion_style_ros.core import rotations as rot
from motion_style_ros.core.retarget import tpose
from motion_style_ros.core.skeleton import canonical
from motion_style_ros.errors import MotionStyleError
from motion_style_ros.io import datasets as ds
from motion_style_ros.io.joint_state import (
    FINGER_BONES,
    FrameDelay,
    JointStateLayout,
    default_names,
    rotation_names,
    rotation_values,
    rotations_from_values,
)

ROOT = Path(__file__).resolve().parents[1]
LAYOUTS = ROOT / "config" / "layouts"
BANDAI_WALK = "bandai-namco/Bandai-Namco-Research-Motiondataset-2/data/dataset-2_walk_normal_001.bvh"


@pytest.fixture(scope="module")
def clip(datasets):
    return ds.load_clip(ds.ClipInfo("bandai-2", datasets / BANDAI_WALK, "", "", "", "", ""))


@pytest.fixture
def layout():
    return JointStateLayout.canonical()


def test_canonical_names_root_first_then_every_joint_below_hips():
    names = JointStateLayout.canonical().names
    bones = canonical().names[2:]
    assert names[:6] == ["root_tx", "root_ty", "root_tz", "root_rx", "root_ry", "root_rz"]
    assert len(names) == 6 + 3 * len(bones) == len(set(names))
    assert names[6:9] == [f"{bones[0]}_rx", f"{bones[0]}_ry", f"{bones[0]}_rz"]
    assert "UpperLeg_L_rx" in names and names[-1] == "Toes_R_rz"


def test_round_trip_on_a_bandai_clip(clip, layout):
    rotations, root = clip.rotations[::5], clip.root_positions[::5]
    values = layout.encode(rotations, root)
    assert values.shape == (len(rotations), len(layout.names)) and values.dtype == np.float64
    for k in range(len(values)):
        got_rot, got_root = layout.decode(layout.names, values[k])
        np.testing.assert_array_equal(got_root, root[k])
        hips = rot.multiply(rotations[k, 0], rotations[k, 1])  # joint_Root is folded into Hips
        assert rot.angle_between(got_rot[1], hips) < 1e-9
        assert rot.angle_between(got_rot[2:], rotations[k, 2:]).max() < 1e-9
        assert rot.angle(got_rot[0]) == 0.0


def test_single_frame_encode_matches_the_batch(clip, layout):
    batch = layout.encode(clip.rotations[:3], clip.root_positions[:3])
    np.testing.assert_allclose(layout.encode(clip.rotations[2], clip.root_positions[2]), batch[2])


def test_names_in_any_order(clip, layout):
    values = layout.encode(clip.rotations[10], clip.root_positions[10])
    expected = layout.decode(layout.names, values)
    rng = np.random.default_rng(0)
    for _ in range(3):  # alternate orders, so a cached permutation must not leak into the next
        perm = rng.permutation(len(values))
        got = layout.decode([layout.names[i] for i in perm], values[perm])
        np.testing.assert_array_equal(got[0], expected[0])
        np.testing.assert_array_equal(got[1], expected[1])
        again = layout.decode(layout.names, values)
        np.testing.assert_array_equal(again[0], expected[0])


def test_rep103_axes(layout):
    rotations = rot.identity((22,))
    names = layout.names
    at = {n: i for i, n in enumerate(names)}
    forward = layout.encode(rotations, [0.0, 0.9, 1.0])  # core +Z (forward), +Y (up)
    assert forward[at["root_tx"]] == 1.0 and forward[at["root_tz"]] == 0.9
    left = layout.encode(rotations, [0.5, 0.0, 0.0])  # core +X is the character's left
    assert left[at["root_ty"]] == 0.5 and left[at["root_tx"]] == 0.0
    rotations[1] = rot.from_yaw(0.3)  # turning left about core up = about ROS +Z
    turned = layout.encode(rotations, [0.0, 0.9, 0.0])
    np.testing.assert_allclose(turned[[at["root_rx"], at["root_ry"], at["root_rz"]]], [0, 0, 0.3],
                               atol=1e-12)
    rotations[1] = rot.identity()
    rotations[2] = rot.from_euler([0.1, 0.2, 0.3], "XYZ")  # core XYZ -> ROS Y Z X
    bent = layout.encode(rotations, [0.0, 0.9, 0.0])
    r_ros = rot.to_matrix(rot.from_euler(bent[[at["Spine_rx"], at["Spine_ry"], at["Spine_rz"]]],
                                         "XYZ"))
    c = np.array([[0, 0, 1], [1, 0, 0], [0, 1, 0]], dtype=float)
    np.testing.assert_allclose(r_ros, c @ rot.to_matrix(rotations[2]) @ c.T, atol=1e-12)


@pytest.mark.parametrize("names, values, reason", [
    (["root_tx"], [0.0, 1.0], "1 names but 2 positions"),
    (None, "nan", "non-finite"),
    (None, "inf", "non-finite"),
    ("unknown", None, "unknown joint names ['Tail_rx']"),
    ("missing", None, "missing joint names ['Toes_R_rz']"),
    ("duplicate", None, "duplicate joint names ['root_tx']"),
])
def test_bad_messages_are_rejected_with_a_reason(layout, names, values, reason):
    good = list(layout.encode(tpose(canonical()).local_rotations, [0.0, 0.9, 0.0]))
    all_names = list(layout.names)
    if names == "unknown":
        names, values = all_names + ["Tail_rx"], good + [0.0]
    elif names == "missing":
        names, values = all_names[:-1], good[:-1]
    elif names == "duplicate":
        names, values = all_names + ["root_tx"], good + [0.0]
    elif values in ("nan", "inf"):
        names, values = all_names, good[:4] + [float(values)] + good[5:]
    with pytest.raises(MotionStyleError, match=reason.replace("[", r"\[").replace("]", r"\]")):
        layout.decode(names, values)


def test_yaml_maps_load():
    canonical_map = JointStateLayout.from_yaml(LAYOUTS / "canonical.yaml")
    assert canonical_map.names == default_names()
    cmu = JointStateLayout.from_yaml(LAYOUTS / "cmu_bvh.yaml")
    assert "LeftArm_Zrotation" in cmu.names and "Hips_Xposition" in cmu.names
    robot = JointStateLayout.from_yaml(LAYOUTS / "example_robot.yaml")
    assert "left_shoulder_pitch_joint" in robot.names and robot.ignore_unknown


def test_maps_carry_the_canonical_values(clip, layout):
    rotations, root = clip.rotations[40], clip.root_positions[40]
    values = dict(zip(layout.names, layout.encode(rotations, root)))
    cmu = JointStateLayout.from_yaml(LAYOUTS / "cmu_bvh.yaml")
    cmu_values = dict(zip(cmu.names, cmu.encode(rotations, root)))
    assert cmu_values["LeftArm_Zrotation"] == values["UpperArm_L_rz"]
    assert cmu_values["Hips_Zposition"] == values["root_tz"]


def test_robot_map_round_trip_ignores_extra_joints(clip):
    robot = JointStateLayout.from_yaml(LAYOUTS / "example_robot.yaml")
    values = robot.encode(clip.rotations[30], clip.root_positions[30])
    assert values.shape == (len(robot.names),) and np.all(np.abs(values[3:]) <= np.pi)
    names = ["left_wrist_joint"] + robot.names[::-1]
    rotations, root = robot.decode(names, np.concatenate([[0.7], values[::-1]]))
    np.testing.assert_allclose(robot.encode(rotations, root), values, atol=1e-9)
    # DOFs the map leaves out come from the canonical T-pose (the head is not in the robot map).
    head = canonical().index("Head")
    assert rot.angle_between(rotations[head], tpose(canonical()).local_rotations[head]) < 1e-9


@pytest.mark.parametrize("text, problem", [
    ("joints: [", "not valid YAML"),
    ("joints: []", "non-empty 'joints' list"),
    ("joints:\n  - {name: a, dof: Tail_rx}", "unknown dof 'Tail_rx'"),
    ("joints:\n  - {name: a, dof: root_tx, scale: 0}", "scale non-zero"),
    ("joints:\n  - {name: a, dof: root_tx}\n  - {name: a, dof: root_ty}", "duplicate name 'a'"),
    ("joints:\n  - {name: a}", "needs 'name' and 'dof'"),
    ("unknown_names: maybe\njoints:\n  - {name: a, dof: root_tx}", "allowed: error, ignore"),
    ("joint:\n  - {name: a, dof: root_tx}", "'joints' list"),
    ("passthrough: '*'\njoints:\n  - {name: a, dof: root_tx}", "list of name patterns"),
])
def test_bad_yaml_names_the_file_and_problem(tmp_path, text, problem):
    path = tmp_path / "bad_map.yaml"
    path.write_text(text)
    with pytest.raises(MotionStyleError) as err:
        JointStateLayout.from_yaml(path)
    message = str(err.value)
    assert str(path) in message and problem in message and "\n" not in message


def test_missing_yaml_file(tmp_path):
    with pytest.raises(MotionStyleError, match="nope.yaml"):
        JointStateLayout.from_yaml(tmp_path / "nope.yaml")


def test_finger_names_pass_through_the_canonical_layout_and_its_yaml(clip, layout):
    fingers = rotation_names(FINGER_BONES[:2]) + ["Jaw_rx", "Jaw_ry", "Jaw_rz"]
    values = layout.encode(clip.rotations[10], clip.root_positions[10])
    names = layout.names + fingers
    extra = np.linspace(-1.0, 1.0, len(fingers))
    for lay in (layout, JointStateLayout.from_yaml(LAYOUTS / "canonical.yaml")):
        rotations, root = lay.decode(names, np.concatenate([values, extra]))
        np.testing.assert_allclose(lay.encode(rotations, root), values, atol=1e-9)
        assert lay.passes("LeftThumbProximal_rx") and not lay.passes("Spine_rx")
        with pytest.raises(MotionStyleError, match="unknown joint names \\['Tail_rx'\\]"):
            lay.decode(names + ["Tail_rx"], np.concatenate([values, extra, [0.0]]))


def test_rotation_values_use_the_layout_convention(clip, layout):
    # A body bone's values through rotation_values are the layout's own for that bone.
    rotations = clip.rotations[20]
    values = dict(zip(layout.names, layout.encode(rotations, clip.root_positions[20])))
    j = canonical().index("LowerArm_L")
    np.testing.assert_allclose(rotation_values(rotations[j][None]),
                               [values[f"LowerArm_L_{a}"] for a in ("rx", "ry", "rz")], atol=1e-12)
    back = rotations_from_values(rotation_values(rotations[j][None]))
    assert rot.angle_between(back[0], rotations[j]) < 1e-9


def test_frame_delay_gives_the_frame_nearest_the_moment_shown():
    delay = FrameDelay(gap_seconds=0.5)
    period = 16_666_667
    for k in range(5):
        delay.push(10**9 + k * period, np.array([float(k)]))
    assert delay.at(10**9 + 4 * period - period)[0] == 3.0  # one frame of latency
    assert delay.at(10**9 + 4 * period - 25_000_000)[0] == 3.0  # 25 ms: 8.3 from frame 3
    assert delay.at(10**9 + 4 * period - 50_000_001)[0] == 1.0
    assert delay.at(10**9 + 2 * period + period // 2)[0] == 2.0  # halfway: the older frame
    assert delay.at(0)[0] == 0.0  # before the first: the oldest kept
    delay.push(10**9 + 4 * period + 600_000_000, np.array([9.0]))  # a gap: the stream starts afresh
    assert delay.at(10**9)[0] == 9.0
    delay.push(10**9, np.array([7.0]))  # a stamp before the last one: afresh too
    assert delay.at(10**9 + 5 * period)[0] == 7.0
    delay.clear()
    with pytest.raises(IndexError):
        delay.at(10**9)
