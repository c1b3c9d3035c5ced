"""The learned performer (issue 21): endless new motion sampled from an SAAE's prior as JointState.

The stream without ROS (runtime.learned_performer: the Sampler's chunks in the layout, the live
parameters' checks), the real node as a process over DDS (rate, names, the very frames the stream
gives, continuity, a live style change applied at a chunk's start, bad values rejected with their
reason, a missing model), the launch file's new performer and ``motion-style perform``.

The model is an untrained tiny SAAE with the real interface (the test_saae.py pattern: tiny networks
around a normalisation). Its normalisation is a procedural walk's (mean, and std with the 0.05 floor
test_saae uses), so its random outputs are poses near a walk: with the identity normalisation of
``export_random_model`` every 6D rotation is noise and the model's own frames jump by up to pi, and
no seam could be told from the motion. The CLI tests use ``export_random_model`` itself.
"""

import ast
import re

import numpy as np
import pytest

torch = pytest.importorskip("torch", reason="builds the random-weight SAAE: pip install '.[train]'")
rclpy = pytest.importorskip("rclpy")

from rcl_interfaces.srv import GetParameters, SetParameters  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402
from ros_helpers import TIMEOUT, stamps  # noqa: E402
from test_launch import LAUNCH, ROOT, declared, node_calls  # noqa: E402

from motion_style_ros.cli.main import main as cli  # noqa: E402
from motion_style_ros.core.features import encode  # noqa: E402
from motion_style_ros.core.skeleton import canonical  # noqa: E402
from motion_style_ros.core.synthetic import synthetic_motion  # noqa: E402
from motion_style_ros.errors import MotionStyleError  # noqa: E402
from motion_style_ros.io import bvh  # noqa: E402
from motion_style_ros.io.joint_state import JointStateLayout  # noqa: E402
from motion_style_ros.models.saae import Critic, Decoder, Encoder, tiny  # noqa: E402
from motion_style_ros.runtime.learned_performer import CHUNK_SECONDS, LearnedStream  # noqa: E402
from motion_style_ros.runtime.onnx_model import models_dir  # noqa: E402
from motion_style_ros.runtime.saae import DEFAULT_MODEL, Sampler  # noqa: E402
from motion_style_ros.training import saae  # noqa: E402

STYLES = ["active", "elderly", "normal"]
FPS = 60
SEED = 1
LAYOUT = JointStateLayout.canonical()
# The largest joint rotation (rad) and pelvis move (m) allowed between two consecutive frames at 60
# fps. The fixture model's stream (seed 1) moves a joint by at most 0.018 rad a frame and its pelvis
# by 0.017 m (a 1 m/s walk) over 20 s with two style changes; a cut to another point of its prior (a
# seam) turns some joint by 0.10 rad or more (8 other seeds), a restart by 0.13 rad and puts the
# pelvis back at the origin (5 m). 0.05 lies between: about 3x the motion's own largest step (a
# message lost on the way, two steps, stays under it) and half the smallest cut.
# test_the_bound_tells_a_seam_from_the_motion checks both sides on the fixture.
MAX_TURN, MAX_MOVE = 0.05, 0.05
# The stream those bounds were measured on: the untrained model's legs do not step, so the foot lock
# would drag its feet behind a gliding pelvis (the lock has its own tests: test_foot_lock, test_saae).
PLAIN = {"spread": 1.0, "foot_lock": False}


@pytest.fixture(scope="module")
def model(tmp_path_factory):
    """An untrained tiny Model2 (torch seed 2) around a procedural walk's normalisation."""
    walk = encode(synthetic_motion("walk", 30.0, 8.0))
    mean, std = walk.mean(0), np.maximum(walk.std(0), 0.05)
    cfg = tiny(tuple(STYLES), "model2")
    torch.manual_seed(2)
    enc, dec = Encoder(cfg, mean, std).eval(), Decoder(cfg, mean, std).eval()
    classifier = Critic(cfg.style_dim, cfg.critic_hidden, len(STYLES))
    inputs, spread = saae.export.random_style_inputs(cfg, 2)
    path = tmp_path_factory.mktemp("learned") / "saae_walk.onnx"
    saae.write_model(enc, dec, classifier, path, inputs, spread, {"data": "none: random weights", "seed": 2})
    return path


@pytest.fixture(scope="module")
def random_model(tmp_path_factory):
    path = tmp_path_factory.mktemp("random") / "saae_random.onnx"
    saae.export_random_model(path, STYLES, "model2", seed=0)
    return path


def steps(frames):
    """Per consecutive pair of layout frames: the largest joint rotation (rad) and the pelvis move (m)."""
    poses = [LAYOUT.decode(LAYOUT.names, f) for f in frames]
    q = np.array([p[0] for p in poses])
    root = np.array([p[1] for p in poses])
    dot = np.abs(np.sum(q[1:] * q[:-1], axis=-1)).clip(0.0, 1.0)
    return (2 * np.arccos(dot)).max(axis=1), np.linalg.norm(np.diff(root, axis=0), axis=1)


def offline(model, n, style="elderly", changes=None):
    """The stream's first ``n`` frames as the node makes them; ``changes``: {frame: style} set before it."""
    stream = LearnedStream(model, style, SEED, fps=FPS, **PLAIN)
    out = []
    for k in range(n):
        if changes and k in changes:
            stream.set_style(changes[k])
        out.append(stream.next_frame())
    return np.array(out)


def positions_in(rows, expected, start=0):
    """Index in ``expected`` of each row, each after the previous (None if a row is not there)."""
    found, k = [], start
    for row in rows:
        while k < len(expected) and not np.allclose(expected[k], row, rtol=0, atol=1e-9):
            k += 1
        if k == len(expected):
            return None
        found.append(k)
        k += 1
    return found


# --- the stream without ROS ---------------------------------------------------------------------


def test_the_stream_is_the_samplers_chunks_in_the_layout(model):
    stream = LearnedStream(model, "elderly", SEED, fps=FPS, **PLAIN)
    frames = np.array([stream.next_frame() for _ in range(100)])
    assert frames.shape == (100, len(LAYOUT.names)) and np.isfinite(frames).all()
    sampler = Sampler(model, "elderly", seed=SEED, **PLAIN)
    n = round(CHUNK_SECONDS * FPS)
    chunks = np.concatenate([LAYOUT.encode_motion(sampler.chunk(CHUNK_SECONDS, FPS)) for _ in range(-(-100 // n))])
    np.testing.assert_array_equal(frames, chunks[:100])
    # the pelvis is published as the stream integrates it: it walks away from the origin
    roots = np.array([LAYOUT.decode(LAYOUT.names, f)[1] for f in frames])
    assert np.linalg.norm(roots[-1] - roots[0]) > 0.5
    # '' is the card's neutral style; a seed is its own stream and the same seed the same one
    assert LearnedStream(model, "", SEED).style == "normal"
    assert np.array_equal(offline(model, 40), frames[:40])
    other = LearnedStream(model, "elderly", SEED + 1, fps=FPS, **PLAIN)
    assert np.abs(np.array([other.next_frame() for _ in range(40)]) - frames[:40]).max() > 1e-3


def test_another_layout_carries_the_same_poses(model):
    robot = JointStateLayout.from_yaml(ROOT / "config" / "layouts" / "example_robot.yaml")
    stream = LearnedStream(model, "elderly", SEED, fps=FPS, layout=robot, **PLAIN)
    frames = np.array([stream.next_frame() for _ in range(30)])
    assert frames.shape == (30, len(robot.names)) and robot.names != LAYOUT.names
    np.testing.assert_allclose(frames, robot.encode_motion(Sampler(model, "elderly", seed=SEED, **PLAIN).chunk(0.5, FPS)),
                               atol=1e-12)


def test_live_values_are_checked_with_their_reason(model):
    stream = LearnedStream(model, "elderly", SEED)
    assert stream.problem("style", "active") is None and stream.problem("style", "") is None
    assert stream.problem("style", "sad") == "unknown style 'sad'; this model knows: active, elderly, normal ('' = normal)"
    assert stream.problem("style", 3) == "style must be of type string, got integer 3"
    assert stream.problem("frame_id", 1.5) == "frame_id must be of type string, got double 1.5"
    for kwargs, message in [({"style": "sad"}, "unknown style 'sad'"),
                            ({"seed": -1}, "seed must be a whole number from 0"),
                            ({"fps": 0}, "fps must be a positive number"),
                            ({"spread": 5.0}, "spread must be a number from 0 to 4"),
                            ({"model": "/nonexistent/saae.onnx"}, "/nonexistent/saae.onnx: model file not found")]:
        with pytest.raises(MotionStyleError, match=re.escape(message)):
            LearnedStream(**{"model": model, **kwargs})


def test_the_default_model_is_the_registrys_shipped_one():
    assert DEFAULT_MODEL == "saae_model2_5d.onnx"
    shipped = models_dir() / DEFAULT_MODEL
    if shipped.is_file():
        assert LearnedStream().sampler.path == shipped
    else:
        with pytest.raises(MotionStyleError, match=re.escape(f"{shipped}: model file not found")):
            LearnedStream()


def test_the_bound_tells_a_seam_from_the_motion(model):
    frames = offline(model, 1200, changes={300: "active", 600: "normal"})  # 20 s, two style changes
    turn, move = steps(frames)
    assert turn.max() < MAX_TURN / 2 and move.max() < MAX_MOVE / 2
    assert np.linalg.norm(LAYOUT.decode(LAYOUT.names, frames[-1])[1]) > 5  # it does move
    # a cut to another seed's stream, or back to this one's start, jumps past the bound
    for seed in range(SEED + 1, SEED + 9):
        cut = LearnedStream(model, "active", seed, fps=FPS, **PLAIN).next_frame()
        assert steps([frames[299], cut])[0][0] > MAX_TURN, seed
    restart = steps([frames[299], frames[0]])
    assert restart[0][0] > MAX_TURN and restart[1][0] > MAX_MOVE


# --- the node -----------------------------------------------------------------------------------


def set_parameters(listener, proc, **values):
    client = listener.node.create_client(SetParameters, "/learned_performer/set_parameters")
    request = SetParameters.Request(parameters=[Parameter(k, value=v).to_parameter_msg()
                                                for k, v in values.items()])
    return listener.call(client, request, procs=[proc]).results


def get_parameter(listener, proc, name):
    client = listener.node.create_client(GetParameters, "/learned_performer/get_parameters")
    (value,) = listener.call(client, GetParameters.Request(names=[name]), procs=[proc]).values
    return value.string_value


def test_the_node_streams_the_sampled_motion_and_changes_style_live(listener, start, model):
    got = listener.subscribe("performer/joint_states")
    proc = start("learned_performer", model=model, style="elderly", seed=SEED, fps=FPS,
                 topic="performer/joint_states", frame_id="pelvis", **PLAIN)
    listener.spin_until(lambda: len(got) >= 1, "a message from learned_performer", procs=[proc])
    listener.spin_for(3.0)
    before = list(got)
    # roughly the rate: by the messages' stamps (the node's timer) and by what arrived here
    period = np.diff(stamps(before)) / 1e9
    assert abs(np.median(period) - 1 / FPS) < 0.2 / FPS, np.median(period)
    assert 0.5 * 3.0 * FPS <= len(before) <= 1.3 * 3.0 * FPS + 5, len(before)
    assert all(list(m.name) == LAYOUT.names and m.header.frame_id == "pelvis" for m in before)
    rows = np.array([m.position for m in before])
    assert np.isfinite(rows).all()
    # the very frames of the stream, in order, chunk joins included; few lost on the way
    expected = offline(model, 60 * FPS)
    index = positions_in(rows, expected)
    assert index is not None, "a published frame is not the next frame of the sampled stream"
    assert index[-1] - index[0] + 1 - len(index) <= 0.1 * len(index)
    turn, move = steps(rows)
    assert turn.max() < MAX_TURN and move.max() < MAX_MOVE, (turn.max(), move.max())

    # a live style change: accepted, applied from a chunk's start on, no seam
    (result,) = set_parameters(listener, proc, style="active")
    assert result.successful, result.reason
    assert get_parameter(listener, proc, "style") == "active"
    count = len(got)
    listener.spin_until(lambda: len(got) >= count + 2 * FPS, "two more seconds of motion", procs=[proc])
    rows = np.array([m.position for m in got])
    turn, move = steps(rows)
    assert turn.max() < MAX_TURN and move.max() < MAX_MOVE, (turn.max(), move.max())
    after = rows[count + FPS:]  # a second after the change
    assert positions_in(after, expected) is None  # no longer the elderly stream
    chunk = round(CHUNK_SECONDS * FPS)
    first = index[-1] // chunk * chunk
    starts = [k for k in range(first, first + 10 * FPS, chunk)
              if positions_in(after, offline(model, k + 5 * FPS, changes={k: "active"})) is not None]
    assert len(starts) == 1, starts  # the stream with the style set at exactly one chunk's start

    # bad values are rejected with their reason and change nothing
    rejected = [("style", "sad", "unknown style 'sad'; this model knows: active, elderly, normal"),
                ("style", 3, "style must be of type string, got integer 3"),
                ("seed", 5, "read-only")]
    for name, value, reason in rejected:
        (result,) = set_parameters(listener, proc, **{name: value})
        assert not result.successful and reason in result.reason, (name, value, result.reason)
    assert get_parameter(listener, proc, "style") == "active"
    assert proc.poll() is None


@pytest.mark.parametrize("params, expected", [
    ({"model": "/nonexistent/saae.onnx"}, "/nonexistent/saae.onnx: model file not found"),
    ({"style": "sad"}, "unknown style 'sad'; this model knows: active, elderly, normal"),
    ({"spread": 9.0}, "spread"),
])
def test_a_node_that_cannot_start_says_why_in_one_line(start, model, params, expected):
    proc = start("learned_performer", **{"model": model, **params})
    assert proc.wait(TIMEOUT) == 2
    err = proc.stderr.read().strip().splitlines()
    assert len(err) == 1 and "ERROR" in err[0] and expected in err[0], err


# --- launch file and setup.py -------------------------------------------------------------------


def test_the_launch_file_offers_the_learned_performer():
    tree = ast.parse(LAUNCH.read_text())
    call = node_calls(tree)["learned_performer"]
    assert ast.literal_eval(call["name"]) == "learned_performer"
    assert re.search(r"'learned_performer = motion_style_ros\.nodes\.learned_performer:main'",
                     (ROOT / "setup.py").read_text())
    (parameters,) = call["parameters"].elts
    assert {ast.literal_eval(k) for k in parameters.keys} == {"style"} <= declared("learned_performer")
    assert "LaunchConfiguration('learned_style')" in ast.unparse(parameters.values[0])
    assert ast.unparse(call["condition"]) == "IfCondition(LaunchConfiguration('use_learned'))"
    arguments = {ast.literal_eval(c.args[0]): {k.arg: k.value for k in c.keywords} for c in ast.walk(tree)
                 if isinstance(c, ast.Call) and getattr(c.func, "id", None) == "DeclareLaunchArgument"
                 and isinstance(c.args[0], ast.Constant)}
    assert ast.literal_eval(arguments["use_learned"]["default_value"]) == "false"
    assert ast.literal_eval(arguments["use_learned"]["choices"]) == ["true", "false"]
    assert ast.literal_eval(arguments["learned_style"]["default_value"]) == ""  # the model's neutral style
    assert {"model", "style", "seed", "spread", "foot_lock", "fps", "topic", "frame_id", "layout"} == declared("learned_performer")


# --- motion-style perform -----------------------------------------------------------------------


def test_perform_writes_a_clip_of_the_stream(random_model, tmp_path, capsys):
    out = tmp_path / "clip.bvh"
    assert cli(["perform", "--style", "elderly", "--seconds", "2.5", "--out", str(out), "--model",
                str(random_model), "--seed", "4", "--fps", "30"]) == 0
    assert f"wrote {out}: 75 frames at 30 fps, style elderly" in capsys.readouterr().out
    clip = bvh.read(out)
    assert clip.n_frames == 75 and clip.fps == 30.0
    assert list(clip.skeleton.names) == list(canonical().names)
    motion = clip.to_motion(scale=0.01)
    expected = LearnedStream(random_model, "elderly", 4, fps=30).motion(2.5)
    assert np.abs(motion.root_positions - expected.root_positions).max() < 1e-5  # written in cm, 6 decimals
    dot = np.abs(np.sum(motion.rotations * expected.rotations, axis=-1))
    assert dot.min() > 1 - 1e-8


@pytest.mark.parametrize("args, expected", [
    (["--style", "sad"], "motion-style: error: unknown style 'sad'; this model knows: active, elderly, normal"),
    (["--style", "elderly", "--seconds", "0"], "motion-style: error: seconds must be a positive number"),
    (["--style", "elderly", "--model", "/nonexistent/saae.onnx"],
     "motion-style: error: /nonexistent/saae.onnx: model file not found"),
])
def test_perform_says_what_is_wrong_in_one_line(random_model, tmp_path, capsys, args, expected):
    argv = ["perform", "--seconds", "1", "--out", str(tmp_path / "x.bvh"), "--model", str(random_model), *args]
    assert cli(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(expected), err
    assert not (tmp_path / "x.bvh").exists()
