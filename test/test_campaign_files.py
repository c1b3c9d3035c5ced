"""The bad-input campaign's files and start-up values (issue 18): the players, the recorder and the
bridge as real processes, and the ``motion-style`` commands, each given a file that is not what it
should be or a value it cannot take. Each says why in one line on stderr and exits with 2, never a
traceback."""

import subprocess
from pathlib import Path

import numpy as np
import pytest
from rosbags.rosbag2 import StoragePlugin, Writer
from ros_helpers import TIMEOUT
from test_package import motion_style_command

from motion_style_ros.core.synthetic import synthetic_motion
from motion_style_ros.io import bags, bvh

FRAMES = 60


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    """A folder of bad inputs beside one good canonical BVH clip."""
    d = tmp_path_factory.mktemp("bad_files")
    bvh.write(d / "good.bvh", bvh.BvhClip.from_motion(synthetic_motion("walk", 30.0, FRAMES / 30.0),
                                                      scale=100.0), precision=6)
    good = (d / "good.bvh").read_text()
    head, _, motion = good.partition("MOTION")
    lines = motion.strip().splitlines()
    first = lines[2].split()
    first[4] = "nan"
    huge = lines[3].split()
    huge[0] = "1e30"
    binary = np.random.default_rng(0).integers(0, 256, 4096, dtype=np.uint8).tobytes()
    assert b"MOTION" not in binary
    (d / "binary.bvh").write_bytes(binary)
    (d / "binary.yaml").write_bytes(binary)
    (d / "text.bvh").write_text("hello, this is not a BVH file\n")
    (d / "empty.bvh").write_bytes(b"")
    (d / "truncated.bvh").write_text(good[: 2 * len(good) // 3])
    (d / "nan.bvh").write_text("\n".join([head + "MOTION", *lines[:2], " ".join(first), *lines[3:]]))
    (d / "huge.bvh").write_text("\n".join([head + "MOTION", *lines[:3], " ".join(huge), *lines[4:]]))
    (d / "zero_frames.bvh").write_text(head + "MOTION\nFrames: 0\nFrame Time: 0.0333333\n")
    (d / "alien.bvh").write_text(
        "HIERARCHY\nROOT Blob\n{\n OFFSET 0 0 0\n CHANNELS 6 Xposition Yposition Zposition Zrotation "
        "Yrotation Xrotation\n End Site\n {\n  OFFSET 0 1 0\n }\n}\nMOTION\nFrames: 1\n"
        "Frame Time: 0.0333333\n0 0 0 0 0 0\n")
    (d / "folder.bvh").mkdir()
    (d / "not_a_bag").mkdir()
    (d / "not_a_bag" / "notes.txt").write_text("no bag here\n")
    (d / "garbage.mcap").write_bytes(binary)
    (d / "bad_metadata").mkdir()
    (d / "bad_metadata" / "metadata.yaml").write_text(": : [\n")
    store = bags.typestore()
    text = store.types["std_msgs/msg/String"](data="hello")
    with bags.BagWriter(d / "chatter_bag") as writer:
        writer.write_raw("/chatter", 1, bytes(store.serialize_cdr(text, "std_msgs/msg/String")),
                         "std_msgs/msg/String")
    silent = Writer(d / "silent_bag", version=9, storage_plugin=StoragePlugin.MCAP)
    silent.open()
    silent.add_connection("/joint_states", bags.JOINT_STATE, typestore=store)
    silent.close()
    (d / "garbage.onnx").write_bytes(binary)
    (d / "garbage.json").write_text("{not json")
    return d


GOOD = {"file": "{d}/good.bvh"}
NODE_CASES = [
    ("bvh_player", {"file": "{d}/text.bvh"}, "no MOTION section"),
    ("bvh_player", {"file": "{d}/binary.bvh"}, "no MOTION section"),
    ("bvh_player", {"file": "{d}/empty.bvh"}, "no MOTION section"),
    ("bvh_player", {"file": "{d}/truncated.bvh"}, "(truncated)"),
    ("bvh_player", {"file": "{d}/nan.bvh"}, "non-finite value at frame 0"),
    ("bvh_player", {"file": "{d}/huge.bvh"}, "value 1e+30 (a corrupt file) at frame 1, channel 0"),
    ("bvh_player", {"file": "{d}/zero_frames.bvh"}, "has 0 frames"),
    ("bvh_player", {"file": "{d}/alien.bvh"}, "not a humanoid skeleton"),
    ("bvh_player", {"file": "{d}/folder.bvh"}, "is a directory; a bvh must be a regular file"),
    ("bvh_player", {**GOOD, "rate": "fast"}, "expecting type 'DOUBLE'"),
    ("bvh_player", {**GOOD, "rate": -1.0}, "out of range"),
    ("bvh_player", {**GOOD, "loop": "maybe"}, "expecting type 'BOOL'"),
    ("bvh_player", {**GOOD, "start_frame": 1000}, f"has {FRAMES} frames"),
    ("bvh_player", {**GOOD, "topic": "bad topic!"}, "Invalid topic name"),
    ("bvh_player", {**GOOD, "layout": "{d}/binary.yaml"}, "not a text file"),
    ("bag_player", {"bag": "{d}/not_a_bag"}, "not a readable rosbag2 bag"),
    ("bag_player", {"bag": "{d}/garbage.mcap"}, "not a readable rosbag2 bag"),
    ("bag_player", {"bag": "{d}/bad_metadata"}, "not a readable rosbag2 bag"),
    ("bag_player", {"bag": "{d}/good.bvh"}, "not a readable rosbag2 bag"),
    ("bag_player", {"bag": "{d}/chatter_bag"}, "the bag has: /chatter (std_msgs/msg/String)"),
    ("bag_player", {"bag": "{d}/silent_bag"}, "hold no messages"),
    ("bag_player", {"bag": "{d}/chatter_bag", "rate": 0.0}, "out of range"),
    ("bag_player", {"bag": "{d}/chatter_bag", "loop": "often"}, "expecting type 'BOOL'"),
    ("recorder", {"bag": "{d}/good.bvh/bag"}, "cannot create bag"),
    ("recorder", {"bag": "{d}/not_a_bag"}, "already exists"),
    ("recorder", {"bag": "{d}/new_bag", "topics": "['bad topic!']"}, "topic name must not contain"),
    ("recorder", {"bag": "{d}/new_bag", "qos_depth": 0}, "out of range"),
    ("vmc_bridge", {"osc_port": 0, "send_host": "no.such.host.invalid"}, "cannot send VMC"),
    ("vmc_bridge", {"osc_host": "no.such.host.invalid"}, "cannot receive VMC"),
    ("vmc_bridge", {"osc_port": 0, "output_topic": "bad topic!"}, "Invalid topic name"),
    ("relay", {"performers": "['a', 'a']"}, "give distinct topic prefixes"),
]


@pytest.mark.parametrize("node, params, expected", NODE_CASES,
                         ids=[f"{n}-{'-'.join(f'{k}={v}' for k, v in p.items())}" for n, p, _ in NODE_CASES])
def test_a_node_given_a_bad_file_or_value_says_why_in_one_line(start, files, node, params, expected):
    proc = start(node, **{k: str(v).format(d=files) for k, v in params.items()})
    assert proc.wait(TIMEOUT) == 2
    err = proc.stderr.read()
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "ERROR" in lines[0] and expected in lines[0], err


CLI_CASES = [
    ("stylize {d}/missing.bvh -o {d}/out.bvh --style active", "missing.bvh: cannot read"),
    ("stylize {d}/text.bvh -o {d}/out.bvh --style active", "no MOTION section"),
    ("stylize {d}/binary.bvh -o {d}/out.bvh --style active", "no MOTION section"),
    ("stylize {d}/folder.bvh -o {d}/out.bvh --style active", "is a directory; a bvh must be a regular file"),
    ("stylize {d}/good.bvh -o {d}/folder.bvh --style active", "Is a directory"),
    ("stylize {d}/good.bvh -o {d}/out.bvh --style active --alpha high", "invalid float value"),
    ("stylize {d}/good.bvh -o {d}/out.bvh --style active --alpha 5", "alpha must be in [0, 1]"),
    ("stylize {d}/good.bvh -o {d}/out.bvh --style sad", "unknown style 'sad'"),
    ("stylize {d}/good.bvh -o {d}/out.bvh --style active --threads 0", "threads must be a whole number, at least 1"),
    ("stylize {d}/good.bvh -o {d}/out.bvh --style active --backend nope", "invalid choice: 'nope'"),
    ("stylize {d}/good.bvh -o {d}/out.bvh --style active --model {d}/missing.onnx", "not found"),
    ("stylize {d}/good.bvh -o {d}/out.bvh --style active --model {d}/garbage.onnx", "not valid JSON"),
    ("retarget {d}/truncated.bvh {d}/out.bvh", "(truncated)"),
    ("retarget {d}/good.bvh {d}/folder.bvh", "Is a directory"),
    ("retarget {d}/huge.bvh {d}/out.bvh", "a corrupt file"),
    ("style add mine {d}/binary.bvh --bank {d}/bank.json", "no MOTION section"),
    ("style add Bad! {d}/good.bvh --bank {d}/bank.json", "style name"),
    ("robot map {d}/good.bvh --urdf {d}/text.bvh --out {d}/out.csv", "not a readable URDF"),
    ("robot map {d}/good.bvh --urdf {d}/missing.urdf --out {d}/out.csv", "no such URDF file"),
    ("bench recurrent --performers x,y", "whole numbers"),
    ("bench recurrent --performers 1 --seconds -1", "must be positive"),
    ("eval --stylizer nope", "invalid choice: 'nope'"),
]


@pytest.mark.parametrize("command, expected", CLI_CASES, ids=[c for c, _ in CLI_CASES])
def test_a_command_given_a_bad_file_or_value_says_why_in_one_line(files, command, expected):
    args = [a.format(d=files) for a in command.split()]
    proc = subprocess.run(motion_style_command() + args, capture_output=True, text=True,
                          timeout=TIMEOUT * 5, cwd=files)
    lines = proc.stderr.strip().splitlines()
    assert proc.returncode == 2, proc.stderr
    assert len(lines) == 1 and lines[0].startswith("motion-style") and expected in lines[0], proc.stderr
    assert not (Path(files) / "out.bvh").exists()
