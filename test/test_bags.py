"""rosbag2 MCAP bags of sensor_msgs/JointState, written and read with rosbags."""

import numpy as np
import pytest
from ruamel.yaml import YAML

from motion_style_ros.errors import MotionStyleError
from motion_style_ros.io import bags


def records(n=25):
    rng = np.random.default_rng(3)
    names = ["root_tx", "Spine_rx", "Head_rz"]
    return [bags.JointStateRecord(1_700_000_000_000_000_000 + 16_666_667 * i, names, rng.normal(size=3),
                                  rng.normal(size=3) if i % 2 else None, "world")
            for i in range(n)]


def test_write_then_read_back(tmp_path):
    written = records()
    assert bags.write_joint_states(tmp_path / "take", written, topic="/performer/joint_states") == 25
    got = bags.read_joint_states(tmp_path / "take")
    assert len(got) == len(written)
    for a, b in zip(got, written):
        assert a.stamp_ns == b.stamp_ns == a.log_time_ns
        assert a.names == b.names and a.frame_id == "world"
        np.testing.assert_array_equal(a.positions, b.positions)
        if b.velocities is None:
            assert a.velocities is None
        else:
            np.testing.assert_array_equal(a.velocities, b.velocities)


def test_bag_folder_is_what_ros2_bag_expects(tmp_path):
    bags.write_joint_states(tmp_path / "take", records(7), topic="joint_states")
    meta = YAML(typ="safe").load((tmp_path / "take" / "metadata.yaml").read_text())
    info = meta["rosbag2_bagfile_information"]
    assert info["storage_identifier"] == "mcap" and info["message_count"] == 7
    assert [p for p in info["relative_file_paths"]] == ["take.mcap"]
    assert (tmp_path / "take" / "take.mcap").read_bytes()[:5] == b"\x89MCAP"
    (topic,) = info["topics_with_message_count"]
    assert topic["topic_metadata"]["type"] == "sensor_msgs/msg/JointState"
    assert topic["topic_metadata"]["serialization_format"] == "cdr"
    # A bare .mcap file reads as well.
    assert len(bags.read_joint_states(tmp_path / "take" / "take.mcap")) == 7


def test_topic_filter_and_raw_bytes(tmp_path):
    with bags.BagWriter(tmp_path / "two") as writer:
        for r in records(4):
            writer.write("/a", r)
        writer.write("/b", records(1)[0])
    assert len(bags.read_joint_states(tmp_path / "two", topics=["b"])) == 1
    raw = list(bags.read_raw(tmp_path / "two"))
    assert [t for t, _, _ in raw].count("/a") == 4 and all(isinstance(d, bytes) for _, _, d in raw)


def test_user_errors(tmp_path):
    with pytest.raises(MotionStyleError, match="no such bag"):
        bags.read_joint_states(tmp_path / "missing")
    bags.write_joint_states(tmp_path / "take", records(2))
    with pytest.raises(MotionStyleError, match="already exists"):
        bags.write_joint_states(tmp_path / "take", records(2))
    with pytest.raises(MotionStyleError, match="no sensor_msgs/msg/JointState messages on other"):
        bags.read_joint_states(tmp_path / "take", topics=["other"])
    (tmp_path / "junk.mcap").write_bytes(b"not a bag")
    with pytest.raises(MotionStyleError, match="junk.mcap"):
        bags.read_joint_states(tmp_path / "junk.mcap")
