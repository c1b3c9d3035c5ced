"""runtime/performer.py: what the stylizer node does with a frame, without ROS (the shipped
recurrent model, ONNX only)."""

import logging
import time

import numpy as np
import pytest

from motion_style_ros.core.synthetic import synthetic_motion
from motion_style_ros.io.joint_state import JointStateLayout
from motion_style_ros.runtime.backends import BACKENDS
from motion_style_ros.runtime.health import ERROR, OK, WARN
from motion_style_ros.runtime.intake import Bounds
from motion_style_ros.runtime.performer import PerformerStream, seconds
from motion_style_ros.runtime.trajectory import Chunker

LAYOUT = JointStateLayout.canonical()
T0 = 1_700_000_000 * 10**9
PERIOD = 33_333_333
CONTROLS = {"target_style": "elderly", "alpha": 1.0, "mix_style": "", "mix_weight": 0.0,
            "latent_seed": 0, "seed_spread": 1.0, "reference": ""}


class Recorded:
    """Outputs that keep what they are handed."""

    def __init__(self):
        self.states, self.chunks = [], []

    def state(self, names, positions, stamp_ns, frame_id, rotations, root):
        self.states.append((names, positions.copy(), stamp_ns, frame_id))

    def trajectory(self, names, chunk, frame_id):
        self.chunks.append((names, chunk, frame_id))

    def robot_state(self, *args):
        raise AssertionError("no robot here")

    robot_trajectory = robot_state


def session(input_fps=None):
    made = BACKENDS["recurrent"].session_class()(BACKENDS["recurrent"].default_model, input_fps=input_fps)
    made.set_style("elderly")
    return made


def stream(outputs, points=4, input_fps=None):
    s = session(input_fps)
    return PerformerStream("joint_states", s, LAYOUT, Bounds(), Chunker(points, PERIOD, s.gap_seconds),
                           outputs, logging.getLogger("test_performer"))


@pytest.fixture(scope="module")
def frames():
    return LAYOUT.encode_motion(synthetic_motion("walk", 30.0, 2.0))


def test_frames_come_out_as_the_session_stylizes_them_in_the_messages_name_order(frames):
    out = Recorded()
    performer = stream(out)
    order = np.random.default_rng(0).permutation(len(LAYOUT.names))
    names = [LAYOUT.names[i] for i in order]
    for k, values in enumerate(frames[:30]):
        performer.frame(names, values[order], T0 + k * PERIOD, T0 + k * PERIOD, "world")
    direct = session()
    for k, values in enumerate(frames[:30]):
        q, p = direct.step(*LAYOUT.decode(LAYOUT.names, values), seconds(T0 + k * PERIOD))
        got_names, got, stamp_ns, frame_id = out.states[k]
        assert got_names == tuple(names) and stamp_ns == T0 + k * PERIOD and frame_id == "world"
        np.testing.assert_allclose(got, LAYOUT.encode(q, p)[order], atol=1e-12)
    assert performer.counts["frames_in"] == performer.counts["frames_out"] == 30
    # 4 points a chunk, in the message's names; the half-full one goes out on flush
    assert len(out.chunks) == 7 and all(c[0] == tuple(names) for c in out.chunks)
    performer.flush()
    assert len(out.chunks) == 8 and len(out.chunks[-1][1].positions) == 2


def test_a_bad_frame_is_counted_and_the_next_good_frame_goes_on_as_if_it_never_came(frames):
    out, clean = Recorded(), Recorded()
    performer, reference = stream(out), stream(clean)
    for k, values in enumerate(frames[:20]):
        reference.frame(LAYOUT.names, values, T0 + k * PERIOD, T0 + k * PERIOD, "")
        if k == 10:
            nan = values.copy()
            nan[7] = np.nan
            performer.frame(LAYOUT.names, nan, T0 + k * PERIOD, T0 + k * PERIOD, "")
            performer.frame(LAYOUT.names[1:], values[1:], T0 + k * PERIOD, T0 + k * PERIOD, "")
            performer.frame(LAYOUT.names, np.full_like(values, 1e30), T0 + k * PERIOD, T0 + k * PERIOD, "")
        performer.frame(LAYOUT.names, values, T0 + k * PERIOD, T0 + k * PERIOD, "")
    assert performer.counts["dropped_non_finite"] == 1 and performer.counts["dropped_bad_names"] == 1
    assert performer.counts["dropped_implausible_angle"] == 1 and performer.dropped == 3
    assert len(out.states) == len(clean.states) == 20
    for (_, got, _, _), (_, want, _, _) in zip(out.states, clean.states):
        np.testing.assert_array_equal(got, want)
    level, message, values = performer.status(CONTROLS, "recurrent", 20.0)
    assert level == WARN and "3 dropped" in message and values["dropped_non_finite"] == 1
    assert values["target_style"] == "elderly" and values["backend"] == "recurrent"


def test_names_the_layout_does_not_stylize_ride_along_with_the_pose_they_came_with(frames):
    out = Recorded()
    performer = stream(out, input_fps=120.0)  # the output shows the input of stamp - 25 ms
    names = [*LAYOUT.names, "LeftIndexProximal_rx"]
    period = round(1e9 / 120)
    for k in range(40):
        performer.frame(names, np.append(frames[k // 4], float(k)), T0 + k * period, T0 + k * period, "")
    shown = [int(positions[-1]) for _, positions, _, _ in out.states]
    assert performer.latency_ns == 25_000_000
    assert shown == [max(0, k - 3) for k in range(40)]


def test_a_non_finite_model_output_restarts_the_stream_and_is_counted(frames):
    out = Recorded()
    performer = stream(out)
    step = performer.session.step
    calls = []

    def once_nan(q, p, t):
        calls.append(t)
        rotations, root = step(q, p, t)
        return (rotations * np.nan, root) if len(calls) == 5 else (rotations, root)

    performer.session.step = once_nan
    for k, values in enumerate(frames[:10]):
        performer.frame(LAYOUT.names, values, T0 + k * PERIOD, T0 + k * PERIOD, "")
    assert performer.counts["restarted_non_finite_output"] == 1
    assert len(out.states) == 9 and all(np.isfinite(p).all() for _, p, _, _ in out.states)
    level, message, _ = performer.status(CONTROLS, "recurrent", 20.0)
    assert level == ERROR and "not finite" in message


def test_an_unstamped_frame_goes_out_on_the_streams_clock(frames):
    out = Recorded()
    performer = stream(out)
    now = time.time_ns()  # receipt times: the latency runs from them to the output
    performer.frame(LAYOUT.names, frames[0], T0, now, "")
    performer.frame(LAYOUT.names, frames[1], 0, now + 1000, "")
    assert [s for _, _, s, _ in out.states] == [T0, T0 + 1000]
    level, message, _ = performer.status(CONTROLS, "recurrent", 1e3)
    assert (level, message) == (OK, "2 frames in, 2 out, 0 dropped")


def test_a_performer_far_from_the_origin_is_stylized_as_at_the_origin(frames):
    """An hour's walk takes a performer kilometres out: still inside the intake's box, and the
    stylized motion is the same, moved (to float precision)."""
    near, far = Recorded(), Recorded()
    out, base = stream(far), stream(near)
    offset = np.zeros(len(LAYOUT.names))
    offset[:2] = 5000.0, -3000.0  # root_tx, root_ty: 5.8 km out on the floor
    for k, values in enumerate(frames):
        base.frame(LAYOUT.names, values, T0 + k * PERIOD, T0 + k * PERIOD, "")
        out.frame(LAYOUT.names, values + offset, T0 + k * PERIOD, T0 + k * PERIOD, "")
    assert out.dropped == 0 and len(far.states) == len(near.states) == len(frames)
    moved = np.array([p for _, p, _, _ in far.states]) - offset
    np.testing.assert_allclose(moved, [p for _, p, _, _ in near.states], atol=1e-6)


def test_bone_lines_join_each_bone_to_its_parent_in_rep103_axes(frames):
    performer = stream(Recorded())
    rotations, root = LAYOUT.decode(LAYOUT.names, frames[10])
    lines = performer.bone_lines(rotations, root).reshape(-1, 2, 3)
    sk = performer.session.skeleton
    assert len(lines) == sk.n_joints - sk.pelvis - 1
    lengths = np.linalg.norm(lines[:, 1] - lines[:, 0], axis=1)
    np.testing.assert_allclose(lengths, np.linalg.norm(sk.offsets[sk.pelvis + 1:], axis=1), atol=1e-9)
    assert lines[:, :, 2].min() > -0.05  # Z up: the skeleton stands on the floor, not lies along Y
