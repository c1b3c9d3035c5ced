"""Players, recorder and synthetic performer as real processes talking over DDS to a test node."""

import time

import numpy as np
import pytest

rclpy = pytest.importorskip("rclpy")
from rclpy.qos import QoSProfile, ReliabilityPolicy  # noqa: E402
from ros_helpers import TIMEOUT, stamps, stop  # noqa: E402
from sensor_msgs.msg import JointState  # noqa: E402

from motion_style_ros.io import bags  # noqa: E402
from motion_style_ros.io.joint_state import JointStateLayout  # noqa: E402

CMU_CLIP = "cmu/data/02/02_02.bvh"


def in_order_subsequence(rows, expected):
    """Indices of ``rows`` in ``expected``, each found after the previous one."""
    found, k = [], 0
    for row in rows:
        while k < len(expected) and not np.array_equal(expected[k], row):
            k += 1
        assert k < len(expected), "a received frame is not the next frame of the file"
        found.append(k)
        k += 1
    return found


def test_synthetic_performer_streams_the_canonical_layout(listener, start):
    got = listener.subscribe("performer/joint_states")
    proc = start("synthetic_performer", motion="run", fps=60, topic="performer/joint_states")
    listener.spin_until(lambda: len(got) >= 90, "90 messages from synthetic_performer", procs=[proc])
    names = JointStateLayout.canonical().names
    assert all(list(m.name) == names and len(m.position) == len(names) for m in got)
    assert np.all(np.diff(stamps(got)) > 0)
    root_x = np.array([m.position[0] for m in got])  # REP-103 forward
    assert root_x[-1] > root_x[0] and np.isfinite([p for m in got for p in m.position]).all()
    assert stop(proc) == 0


def test_bvh_player_plays_every_frame_in_order(listener, start, datasets):
    from motion_style_ros.nodes.bvh_player import load

    path = datasets / CMU_CLIP
    frames, _ = load(str(path), JointStateLayout.canonical())
    got = listener.subscribe("joint_states")
    proc = start("bvh_player", file=path, rate=4.0, wait_for_subscribers=1)
    listener.spin_while_running(proc)  # it exits at the end of the file
    assert proc.wait(TIMEOUT) == 0, proc.stderr.read()
    assert 0.9 * len(frames) <= len(got) <= len(frames)  # best effort: allow a few drops
    in_order_subsequence([np.array(m.position) for m in got], frames)
    assert np.all(np.diff(stamps(got)) > 0)


def write_bag(path, n=40, topic="/recorded/joint_states"):
    t0 = 1_600_000_000 * 10**9
    records = [bags.JointStateRecord(t0 + 20_000_000 * i, ["a", "b"], np.array([i, -i], float))
               for i in range(n)]
    bags.write_joint_states(path, records, topic=topic)
    return records


def test_bag_player_keeps_stamps_and_remaps(listener, start, tmp_path):
    records = write_bag(tmp_path / "bag")
    got = listener.subscribe("joint_states")
    proc = start("bag_player", bag=tmp_path / "bag", topic="joint_states", rate=2.0,
                 wait_for_subscribers=1)
    listener.spin_while_running(proc)
    assert proc.wait(TIMEOUT) == 0, proc.stderr.read()
    assert 0.9 * len(records) <= len(got) <= len(records)
    recorded = {r.stamp_ns: r for r in records}
    for m, stamp in zip(got, stamps(got)):
        assert list(m.name) == ["a", "b"]
        np.testing.assert_array_equal(m.position, recorded[stamp].positions)
    assert np.all(np.diff(stamps(got)) > 0)


def test_bag_player_loops(listener, start, tmp_path):
    records = write_bag(tmp_path / "bag", n=20)
    got = listener.subscribe("recorded/joint_states")
    proc = start("bag_player", bag=tmp_path / "bag", loop=True, rate=4.0, wait_for_subscribers=1)
    listener.spin_until(lambda: len(got) >= 50, "50 messages from a looping 20-message bag",
                        procs=[proc])
    recorded = [r.stamp_ns for r in records]
    assert set(stamps(got)) <= set(recorded)
    assert np.sum(np.diff(stamps(got)) < 0) >= 2  # wrapped around at least twice
    assert stop(proc) == 0


def test_recorder_writes_what_was_published(listener, start, tmp_path):
    bag = tmp_path / "recorded"
    proc = start("recorder", bag=bag, topics="['joint_states', 'other/joint_states']",
                 qos_reliability="reliable")
    reliable = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE)
    pub = listener.node.create_publisher(JointState, "joint_states", reliable)
    listener.spin_until(lambda: pub.get_subscription_count() > 0, "the recorder to subscribe",
                        procs=[proc])
    sent = []
    for i in range(50):
        msg = JointState(name=["root_tx", "Spine_rx"], position=[0.01 * i, -0.02 * i])
        msg.header.stamp.sec, msg.header.stamp.nanosec = 100 + i, 5
        pub.publish(msg)
        sent.append(msg)
    assert pub.wait_for_all_acked(rclpy.duration.Duration(seconds=TIMEOUT))
    time.sleep(1.0)  # acked means delivered to the recorder's reader; give its callback a moment
    assert stop(proc) == 0, proc.stderr.read()
    got = bags.read_joint_states(bag)
    assert len(got) == len(sent)
    for r, m in zip(got, sent):
        assert r.stamp_ns == (m.header.stamp.sec * 10**9 + 5) and r.names == list(m.name)
        np.testing.assert_array_equal(r.positions, m.position)
    assert (bag / "metadata.yaml").is_file()


@pytest.mark.parametrize("node, params, expected", [
    ("bvh_player", {"file": "/nonexistent/take.bvh"}, "take.bvh"),
    ("bvh_player", {"file": "x.bvh", "rate": 0.0}, "rate"),
    ("bag_player", {"bag": "/nonexistent/bag"}, "no such bag"),
    ("synthetic_performer", {"motion": "dance"}, "walk, run, wave"),
    ("recorder", {"qos_reliability": "sometimes"}, "best_effort, reliable"),
])
def test_a_node_that_cannot_start_says_why_in_one_line(start, node, params, expected):
    proc = start(node, **params)
    assert proc.wait(TIMEOUT) == 2
    err = proc.stderr.read().strip().splitlines()
    assert len(err) == 1 and "ERROR" in err[0] and expected in err[0], err


def test_a_looped_clip_walks_on_from_where_it_ended(datasets):
    from motion_style_ros.nodes.bvh_player import lap, load

    layout = JointStateLayout.canonical()
    frames, _ = load(str(datasets / CMU_CLIP), layout)
    shift = lap(frames, layout)
    root = [layout.names.index(f"root_t{a}") for a in "xyz"]
    assert np.count_nonzero(shift) == 2 and shift[root[2]] == 0.0  # horizontal root channels only
    flat = root[:2]  # the next pass starts one step on from the end, horizontally
    step = frames[1, flat] - frames[0, flat]
    np.testing.assert_allclose((frames[0] + shift)[flat] - frames[-1][flat], step, atol=1e-9)
    assert np.linalg.norm(frames[-1, flat] - frames[0, flat]) > 0.5  # without it: a jump back
