"""Damaged MCAP bags: every reader refuses them in one line, and with ``skip_damaged`` plays only
the messages that check as JointStates. The bag is recorded here (io/bags.py's writer), then cut,
zeroed, flipped and overwritten in 13 ways; bag_player runs as a real process on some of them."""

import importlib.util
import shutil

import numpy as np
import pytest
from rosbags.rosbag2 import Reader

from motion_style_ros.io import bags

FRAMES = 1860  # 15.5 s at 120 Hz, 40 joints: two 1 MiB chunks
NAMES = [f"joint_{i:02d}_r{'xyz'[i % 3]}" for i in range(40)]
T0 = 1_700_000_000_000_000_000
PERIOD = 8_333_333


def _variants(good: bytes) -> dict[str, bytes]:
    n = len(good)
    rng = np.random.default_rng(42)

    def changed(at: int, data: bytes) -> bytes:
        out = bytearray(good)
        out[at:at + len(data)] = data
        return bytes(out)

    flipped = bytearray(good)
    for at in rng.choice(np.arange(8, n), 50, replace=False):
        flipped[at] ^= 0xFF
    noise = rng.integers(0, 256, 4096, dtype=np.uint8).tobytes()
    return {
        "cut_at_10_percent": good[:n // 10],
        "cut_in_half": good[:n // 2],
        "cut_at_90_percent": good[:9 * n // 10],
        "cut_in_the_footer": good[:n - 20],
        "cut_after_100_bytes": good[:100],
        "empty": b"",
        "eight_bytes": good[:8],
        "garbage_footer": changed(n - 64, rng.integers(0, 256, 64, dtype=np.uint8).tobytes()),
        "garbage_header": changed(8, rng.integers(0, 256, 64, dtype=np.uint8).tobytes()),
        "50_flipped_bytes": bytes(flipped),
        "zeroed_middle_half": changed(n // 4, bytes(n // 2)),
        "4k_overwritten_mid_file": changed(n // 2, noise),
        "4k_overwritten_in_a_chunk": changed(int(0.4866 * n), noise),
    }


VARIANTS = list(_variants(b"\x00" * 1000))
NOTHING_READABLE = {"empty", "eight_bytes", "cut_after_100_bytes"}
PAYLOAD_INTACT = {"cut_at_10_percent", "cut_in_half", "cut_at_90_percent", "cut_in_the_footer",
                  "garbage_footer", "garbage_header"}


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    """The bag as written and its records by log time."""
    rng = np.random.default_rng(1)
    records = [bags.JointStateRecord(T0 + PERIOD * i, NAMES, rng.normal(size=len(NAMES)))
               for i in range(FRAMES)]
    path = tmp_path_factory.mktemp("bags") / "good"
    assert bags.write_joint_states(path, records) == FRAMES
    return path, {r.stamp_ns: r for r in records}


@pytest.fixture(scope="module")
def damaged(recorded):
    """Bag folders (metadata.yaml as written) whose .mcap file is damaged, by variant."""
    good, _ = recorded
    out = {}
    for name, data in _variants((good / "good.mcap").read_bytes()).items():
        folder = good.parent / name
        shutil.copytree(good, folder)
        (folder / "good.mcap").write_bytes(data)
        out[name] = folder
    return out


def one_line_damage(exc_info, path):
    text = str(exc_info.value)
    assert "\n" not in text and text.startswith(f"{path}: ") and ("damaged" in text or "readable" in text)


def test_the_recorded_bag_reads_whole(recorded):
    path, originals = recorded
    contents = bags.read_checked(path)
    assert len(contents.messages) == FRAMES and contents.damage == "" and contents.skipped == 0
    assert [log for _, log, _, _ in contents.messages] == sorted(originals)


@pytest.mark.parametrize("variant", VARIANTS)
def test_every_reader_refuses_a_damaged_bag_in_one_line(damaged, variant):
    path = damaged[variant]
    for read in (bags.read_checked, bags.read_raw, bags.read_joint_states):
        with pytest.raises(bags.DamagedBag) as exc_info:
            read(path)
        one_line_damage(exc_info, path)
    with pytest.raises(bags.DamagedBag):  # the bare .mcap file as well
        bags.read_raw(path / "good.mcap")


@pytest.mark.parametrize("variant", VARIANTS)
def test_skip_damaged_keeps_only_messages_that_check(recorded, damaged, variant):
    _, originals = recorded
    path = damaged[variant]
    if variant in NOTHING_READABLE:
        with pytest.raises(bags.DamagedBag) as exc_info:
            bags.read_checked(path, skip_damaged=True)
        one_line_damage(exc_info, path)
        return
    contents = bags.read_checked(path, skip_damaged=True)
    assert contents.damage and "\n" not in contents.damage
    assert len(contents.messages) + contents.skipped == FRAMES  # metadata.yaml says how many
    logs = [log for _, log, _, _ in contents.messages]
    assert logs == sorted(set(logs)) and set(logs) <= set(originals)
    store = bags.typestore()
    same = 0
    for _, log, data, _ in contents.messages:  # decoded again here, independently of the reader
        msg = store.deserialize_cdr(data, bags.JOINT_STATE)
        assert len(msg.name) == len(msg.position) and np.isfinite(msg.position).all()
        same += list(msg.name) == NAMES and np.array_equal(msg.position, originals[log].positions)
    if variant in PAYLOAD_INTACT:
        assert same == len(contents.messages)
    else:  # without checksums a message can be changed yet decode; most are the originals
        assert same >= 0.97 * len(contents.messages)
    share = len(contents.messages) / FRAMES
    expected = {"cut_at_10_percent": (0.08, 0.11), "cut_in_half": (0.48, 0.52),
                "cut_at_90_percent": (0.88, 0.91), "zeroed_middle_half": (0.45, 0.55)}
    low, high = expected.get(variant, (0.99 if variant in PAYLOAD_INTACT else 0.95, 1.0))
    assert low <= share <= high, (variant, len(contents.messages))


def test_messages_lost_without_an_error_are_found_by_their_count(recorded):
    """One message record's opcode and length damaged: rosbags' reader then ends that chunk early
    without an error (it skips an unknown record by its length); the count metadata.yaml lists
    tells that messages are missing."""
    good, originals = recorded
    path = good.parent / "record_length_damaged"
    shutil.copytree(good, path)
    data = bytearray((path / "good.mcap").read_bytes())
    stamp = sorted(originals)[500]
    at = data.index(b"\x01\x00" + bytes(4) + stamp.to_bytes(8, "little")) - 9  # the record's opcode
    assert data[at] == 0x05
    data[at:at + 9] = b"\x07" + (2**40).to_bytes(8, "little")
    (path / "good.mcap").write_bytes(bytes(data))
    with Reader(path) as reader:
        assert 500 <= sum(1 for _ in reader.messages()) < FRAMES - 1
    with pytest.raises(bags.DamagedBag, match=f"lists {FRAMES} JointState messages"):
        bags.read_raw(path)
    contents = bags.read_checked(path, skip_damaged=True)  # the scan goes on after the damage
    assert len(contents.messages) == FRAMES - 1 and contents.skipped == 1
    assert stamp not in {log for _, log, _, _ in contents.messages}


def test_a_message_that_is_no_usable_joint_state(tmp_path):
    store = bags.typestore()
    good = [bags.JointStateRecord(T0 + PERIOD * i, ["a", "b"], np.array([i, -i], float)) for i in range(6)]
    nan = bags.JointStateRecord(T0 + PERIOD * 6, ["a", "b"], np.array([0.0, np.nan]))
    short = bags.JointStateRecord(T0 + PERIOD * 7, ["a", "b", "c"], np.array([0.0, 1.0]))
    with bags.BagWriter(tmp_path / "bad") as writer:
        for record in good[:3]:
            writer.write("/joint_states", record)
        writer.write_raw("/joint_states", T0 + PERIOD * 3 + 1, b"\x00\x01\x00\x00garbage")
        writer.write("/joint_states", nan)
        writer.write("/joint_states", short)
        for record in good[3:]:
            writer.write("/joint_states", record)
    with pytest.raises(bags.DamagedBag, match="message 5 on /joint_states: not a JointState"):
        bags.read_raw(tmp_path / "bad")
    contents = bags.read_checked(tmp_path / "bad", skip_damaged=True)
    assert contents.skipped == 3 and len(contents.messages) == 6
    assert [log for _, log, _, _ in contents.messages] == [r.stamp_ns for r in good]
    reasons = [bags.check_joint_state(store, store.serialize_cdr(m, bags.JOINT_STATE))[1] for m in (
        _message(store, nan), _message(store, short))]
    assert reasons == ["a non-finite position", "3 names but 2 positions"]


def _message(store, record):
    types = store.types
    header = types["std_msgs/msg/Header"](stamp=types["builtin_interfaces/msg/Time"](sec=0, nanosec=0),
                                          frame_id="")
    return types[bags.JOINT_STATE](header=header, name=record.names, position=record.positions,
                                   velocity=np.zeros(0), effort=np.zeros(0))


# bag_player as a real process
ros = pytest.mark.skipif(importlib.util.find_spec("rclpy") is None, reason="rclpy not installed")
TIMEOUT = 30.0


@ros
@pytest.mark.parametrize("variant", ["eight_bytes", "zeroed_middle_half", "4k_overwritten_in_a_chunk"])
def test_bag_player_refuses_a_damaged_bag_in_one_line(start, damaged, variant):
    says = "no message in it can be read"
    if variant not in NOTHING_READABLE:  # and what it would play on request
        readable = len(bags.read_checked(damaged[variant], skip_damaged=True).messages)
        says = f"skip_damaged:=true plays the {readable} messages that can be read"
    proc = start("bag_player", bag=damaged[variant])
    assert proc.wait(TIMEOUT) == 2
    err = proc.stderr.read()
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "ERROR" in lines[0] and "Traceback" not in err, err
    assert str(damaged[variant]) in lines[0] and lines[0].endswith(says), lines[0]


@ros
def test_bag_player_plays_the_readable_part_when_asked(listener, start, recorded, damaged):
    _, originals = recorded
    got = listener.subscribe("joint_states")
    proc = start("bag_player", bag=damaged["cut_in_half"], skip_damaged=True, rate=4.0,
                 wait_for_subscribers=1)
    listener.spin_while_running(proc)
    assert proc.wait(TIMEOUT) == 0
    err = proc.stderr.read()
    assert "Traceback" not in err
    readable = len(bags.read_checked(damaged["cut_in_half"], skip_damaged=True).messages)
    assert f"playing its {readable} readable messages, {FRAMES - readable} skipped" in err, err
    assert 0.8 * readable <= len(got) <= readable  # best effort: allow a few drops
    for msg in got:
        stamp = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
        np.testing.assert_array_equal(msg.position, originals[stamp].positions)
