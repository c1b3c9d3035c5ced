"""The streaming stylizer session on real Bandai clips, with a small random-weight Style-ERD model
(the real ONNX interface; its outputs are not stylish, but every property tested here is the
runtime's: state carried across calls, batching, rates, controls, gaps, bad input)."""

import importlib.util

import numpy as np
import pytest
from onnx_fixtures import recurrent_model

from motion_style_ros.core import features as F
from motion_style_ros.core import rotations as rot
from motion_style_ros.core.resample import resample
from motion_style_ros.errors import MotionStyleError
from motion_style_ros.io.datasets import ClipInfo, load_clip
from motion_style_ros.runtime.controls import Controls
from motion_style_ros.runtime.onnx_model import OnnxModel, models_dir
from motion_style_ros.runtime.recurrent import RecurrentSession

STYLES = ["active", "elderly", "exhausted", "feminine", "masculine", "normal", "youthful"]
CLIPS = ("dataset-2_walk_normal_010", "dataset-2_walk-turn-right_masculine_003",
         "dataset-2_wave-both-hands_active_002")


@pytest.fixture(scope="module")
def model(tmp_path_factory):
    return recurrent_model(tmp_path_factory.mktemp("erd") / "style_erd.onnx", STYLES)


@pytest.fixture(scope="module")
def clips(datasets):
    data = datasets / "bandai-namco/Bandai-Namco-Research-Motiondataset-2/data"
    return [load_clip(ClipInfo("bandai-2", data / f"{n}.bvh", n, "", "", "", "")) for n in CLIPS]


def frames(motion):
    """The clip as (rotations (T, 1, 22, 4), pelvis positions (T, 1, 3)): one performer."""
    return motion.rotations[:, None], motion.positions[:, None, 1]


def stream(session, rotations, roots, stamps=None):
    """Step every frame; stacked outputs (T, P, 22, 4), (T, P, 3)."""
    out = [session.step(rotations[t], roots[t], None if stamps is None else stamps[t])
           for t in range(len(rotations))]
    return np.stack([q for q, _ in out]), np.stack([p for _, p in out])


def largest_jump(positions):
    """Largest distance any joint moves between consecutive frames (m)."""
    return float(np.linalg.norm(np.diff(positions, axis=0), axis=-1).max())


def test_stepping_equals_direct_onnx_runs(model, clips):
    """Without foot locking, grounding and conditioning, the session is encode -> the ONNX graph
    with its state carried -> decode, nothing else."""
    walk = clips[0]
    session = RecurrentSession(model, foot_lock=False, ground=False, conform=False, follow_seconds=None)
    session.set_style("elderly")
    q, p = stream(session, *frames(walk))

    onnx = OnnxModel(model)
    features = F.encode(walk)
    style = np.eye(len(STYLES), dtype=np.float32)[[STYLES.index("elderly")]]
    state = np.zeros((1, session.card["state_size"]), np.float32)
    outputs = []
    for t in range(walk.n_frames):
        out = onnx.run(features=features[t : t + 1], style=style, alpha=np.ones((1, 1), np.float32),
                       state=state, reset=np.full((1, 1), float(t == 0), np.float32))
        state = out["state_out"]
        outputs.append(out["output"][0])
    g = walk.global_positions()[0]
    ref = F.decode(np.array(outputs), walk.fps, start_ground=g[1],
                   start_yaw=F.facing_yaw(g, walk.skeleton))
    assert np.abs(rot.angle_between(q[:, 0], ref.rotations)).max() < 1e-6
    assert np.abs(p[:, 0] - ref.positions[:, 1]).max() < 1e-6
    # The stylized root starts where the performer stands, then moves on its own velocities.
    assert np.allclose(p[0, 0, [0, 2]], walk.positions[0, 1, [0, 2]])
    assert np.linalg.norm(p[-1, 0] - p[0, 0]) > 0.5


def test_foot_locking_changes_the_legs_only(model, clips):
    walk = clips[0]
    free = RecurrentSession(model, foot_lock=False, follow_seconds=None).run(walk, "elderly")
    locked = RecurrentSession(model, follow_seconds=None).run(walk, "elderly")
    legs = [walk.skeleton.index(f"{b}_{s}") for b in ("UpperLeg", "LowerLeg", "Foot") for s in "LR"]
    others = [j for j in range(walk.skeleton.n_joints) if j not in legs]
    assert np.allclose(locked.rotations[:, others], free.rotations[:, others])
    assert np.allclose(locked.positions[:, 1], free.positions[:, 1])
    assert not np.allclose(locked.rotations[:, legs], free.rotations[:, legs])


def test_state_carried_across_steps_equals_run(model, clips):
    walk = clips[1]
    # (conditioned from the whole clip at once, run() and a stream differ: test_conform.py and
    # test_proportions.py compare them)
    whole = RecurrentSession(model, conform=False).run(walk, "feminine", alpha=0.7)
    session = RecurrentSession(model, conform=False)
    session.set_style("feminine")
    session.set_alpha(0.7)
    q, p = stream(session, *frames(walk[:60]))
    q2, p2 = stream(session, *frames(walk[60:]), stamps=np.arange(60, walk.n_frames) / walk.fps)
    assert np.array_equal(np.concatenate([q, q2])[:, 0], whole.rotations)
    assert np.array_equal(np.concatenate([p, p2])[:, 0], whole.positions[:, 1])
    assert whole.n_frames == walk.n_frames and whole.fps == walk.fps


def test_a_streams_conditioning_holds_across_gaps_until_reset_recalibrates(model, clips):
    walk = clips[1]
    rotations, roots = frames(walk)
    session = RecurrentSession(model)
    stream(session, rotations, roots * 0.8)
    measured = session._scale.scale.copy(), session._rolls.frames.copy()
    assert measured[1][0] > 0 and abs(measured[0][0] - 1.0) > 0.05
    stream(session, rotations[:10], roots[:10] * 0.8, np.arange(10) / walk.fps + 100.0)  # a gap
    assert session._scale.scale[0] == pytest.approx(measured[0][0], abs=0.05)
    assert session._rolls.frames[0] > measured[1][0]  # still adding to what it had
    session.reset(recalibrate=True)
    assert session._scale.scale[0] == 1.0 and session._rolls.frames[0] == 0


def test_alpha_zero_is_independent_of_style(model, clips):
    walk = clips[0]
    session = RecurrentSession(model)
    neutral = [session.run(walk, s, alpha=0.0).global_positions() for s in ("active", "elderly")]
    styled = [session.run(walk, s, alpha=1.0).global_positions() for s in ("active", "elderly")]
    assert np.abs(neutral[0] - neutral[1]).max() < 1e-5
    assert np.abs(styled[0] - styled[1]).max() > 1e-3  # the style does matter at alpha 1


def switch_jumps(model, walk, blend, switch=100, foot_lock=True):
    """Largest per-frame joint jump of the output around a style switch at frame ``switch``
    (over the blend and a frame either side), and before it."""
    session = RecurrentSession(model, blend_seconds=blend, foot_lock=foot_lock)
    session.set_style("active")
    rotations, roots = frames(walk)
    out = []
    for t in range(walk.n_frames):
        if t == switch:
            session.set_style("exhausted")
        out.append(session.step(rotations[t], roots[t]))
    q, p = np.stack([o[0][0] for o in out]), np.stack([o[1][0] for o in out])
    g = type(walk).from_rotations(walk.skeleton, q, p, walk.fps).global_positions()
    during = g[switch - 1 : switch + int(blend * walk.fps) + 2]
    return largest_jump(during), largest_jump(g[: switch - 1])


def test_style_switch_mid_stream_is_continuous(model, clips):
    """A random model's outputs are far rougher in the style weights than a trained one's (whose
    style space interpolates, Style-ERD Fig. 6): an untrained decoder swings limbs by tens of
    degrees between two styles' weights. So here the runtime's part is checked: the blend spreads
    the change, and over a long enough blend the largest jump is the input's own. (Without the
    foot lock, which would lift the random legs' feet to the input's.)"""
    walk = clips[0]
    input_jump = largest_jump(walk.global_positions())
    jumps = {blend: switch_jumps(model, walk, blend, foot_lock=False) for blend in (0.0, 0.3, 1.0)}
    print(f"largest per-frame joint jump: input {100 * input_jump:.1f} cm; random-model output "
          f"before the switch {100 * jumps[0.0][1]:.1f} cm; at the switch: "
          + ", ".join(f"{blend:g} s blend {100 * j:.1f} cm" for blend, (j, _) in jumps.items()))
    assert jumps[0.3][0] < jumps[0.0][0]
    assert jumps[1.0][0] < 0.5 * jumps[0.0][0] and jumps[1.0][0] < 1.5 * input_jump


def test_style_switch_with_the_shipped_model(clips):
    if not (models_dir() / "style_erd.onnx").is_file():
        pytest.skip("models/style_erd.onnx is not trained yet")
    walk = clips[0]
    input_jump = largest_jump(walk.global_positions())
    blend, before = switch_jumps("style_erd.onnx", walk, 0.3)
    print(f"shipped model, largest per-frame joint jump: input {100 * input_jump:.1f} cm; output "
          f"before the switch {100 * before:.1f} cm; during the 0.3 s blend {100 * blend:.1f} cm")
    assert blend < 2.0 * max(input_jump, before)


def test_batched_performers_equal_separate_sessions(model, clips):
    n = min(c.n_frames for c in clips)
    rotations = np.stack([c.rotations[:n] for c in clips], axis=1)
    roots = np.stack([c.positions[:n, 1] for c in clips], axis=1)
    styles = ["elderly", "youthful", "normal"]

    def drive(session, t, k):
        """The same controls, to performer k of a batched session or to a single one."""
        performer = k if session.performers > 1 else None
        if t == 0:
            session.set_style(styles[k], performer)
        if t == 50 and k == 1:
            session.set_alpha(0.3, performer)
        if t == 70 and k == 2:
            session.reset(performer)

    batched = RecurrentSession(model, performers=3)
    singles = [RecurrentSession(model) for _ in clips]
    out_b, out_s = [], []
    for t in range(n):
        for k, s in enumerate(singles):
            drive(batched, t, k)
            drive(s, t, k)
        out_b.append(batched.step(rotations[t], roots[t]))
        out_s.append([s.step(rotations[t, k], roots[t, k]) for k, s in enumerate(singles)])
    qb = np.stack([q for q, _ in out_b])
    qs = np.stack([[q for q, _ in row] for row in out_s])
    pb = np.stack([p for _, p in out_b])
    ps = np.stack([[p for _, p in row] for row in out_s])
    assert qb.shape == (n, 3, 22, 4) and qs.shape == (n, 3, 22, 4)
    assert np.abs(rot.angle_between(qb, qs)).max() < 1e-4
    assert np.abs(pb - ps).max() < 1e-4
    # Performer 2 was reset at frame 70: its root snapped back onto the input's.
    assert np.allclose(pb[70, 2, [0, 2]], roots[70, 2, [0, 2]])


def test_120_hz_input_gives_120_hz_output(model, clips):
    walk = clips[0][:90]
    fast = resample(walk, 120.0)
    s30, s120 = RecurrentSession(model), RecurrentSession(model, input_fps=120.0)
    for s in (s30, s120):
        s.set_style("masculine")
    q30, p30 = stream(s30, *frames(walk))
    q120, p120 = stream(s120, *frames(fast), stamps=np.arange(fast.n_frames) / 120.0)
    assert len(q120) == fast.n_frames and s120.latency == pytest.approx(0.025)
    # The model runs at 30 Hz on every 4th input frame; with 25 ms latency, output 4k + 3 shows
    # model frame k, and the frames in between interpolate.
    assert np.abs(p120[3::4] - p30[: len(p120[3::4])]).max() < 1e-5
    assert np.abs(rot.angle_between(q120[3::4], q30[: len(q120[3::4])])).max() < 1e-4
    # In between: the cubic Hermite segment from model frame k to k + 1, its tangents the
    # backward differences (core.resample.hermite).
    quarter = p120[8::4]  # a quarter of the way from model frame k to k + 1 (k >= 1)
    h = (27 / 32, 9 / 64, 5 / 32, -3 / 64)  # Hermite weights of x0, m0, x1, m1 at s = 1/4
    k0, k1, kp = p30[1:-1], p30[2:], p30[:-2]
    expected = h[0] * k0 + h[1] * (k0 - kp) + h[2] * k1 + h[3] * (k1 - k0)
    assert np.abs(quarter - expected[: len(quarter)]).max() < 1e-5
    g = type(walk).from_rotations(walk.skeleton, q120[:, 0], p120[:, 0], 120.0).global_positions()
    assert largest_jump(g) < 0.5 * largest_jump(
        type(walk).from_rotations(walk.skeleton, q30[:, 0], p30[:, 0], 30.0).global_positions())


def test_a_phase_moves_the_model_frames_to_other_input_frames(model, clips):
    """Sessions serving streams in step (one node, several performers) spread their model frames
    over the input frames; the output stays as smooth as without the phase."""
    fast = resample(clips[0][:90], 120.0)
    stamps = np.arange(fast.n_frames) / 120.0
    calls = {}
    outputs = {}
    for phase in (0.0, 1 / 120.0, 3 / 120.0):
        session = RecurrentSession(model, input_fps=120.0, phase_seconds=phase)
        run, ran = session.model.run, []
        session.model.run = lambda _run=run, _ran=ran, **kw: (_ran.append(True), _run(**kw))[1]
        ticks = []
        q, p = [], []
        for k in range(fast.n_frames):
            before = len(ran)
            out = session.step(fast.rotations[k], fast.positions[k, 1], stamps[k])
            q.append(out[0])
            p.append(out[1])
            ticks += [k] * (len(ran) - before)
        calls[phase] = ticks
        outputs[phase] = type(fast).from_rotations(fast.skeleton, np.stack(q), np.stack(p), 120.0)
    assert calls[0.0][:4] == [0, 4, 8, 12]
    assert calls[1 / 120.0][:4] == [0, 1, 5, 9]  # one input frame later, after the first
    assert calls[3 / 120.0][:4] == [0, 3, 7, 11]
    smooth = largest_jump(outputs[0.0].global_positions())
    for phase in (1 / 120.0, 3 / 120.0):
        assert largest_jump(outputs[phase].global_positions()) < 1.5 * smooth
    with pytest.raises(MotionStyleError, match="phase_seconds"):
        RecurrentSession(model, phase_seconds=1 / 30.0)


@pytest.mark.parametrize("rate", [120.0, 100.0, 30.0])
def test_pipelined_outputs_are_the_same_one_input_frame_later(model, clips, rate):
    """Pipelined, a step runs none of its own frame's model frames (those wait for catch_up or
    the next step) and its output is the unpipelined session's of the frame before, also across a
    style change, a reset and a gap."""
    walk = resample(clips[1], rate)
    stamps = np.arange(walk.n_frames) / rate
    stamps[70:] += 1.0  # a gap: the stream restarts
    sessions = [RecurrentSession(model, input_fps=rate, pipelined=p) for p in (False, True)]
    ran = []
    run = sessions[1].model.run
    sessions[1].model.run = lambda **kw: (ran.append(True), run(**kw))[1]
    outputs = [[], []]
    for k in range(walk.n_frames):
        for s in sessions:
            if k == 30:
                s.set_style("elderly")
            if k == 50:
                s.reset()
        for s, out in zip(sessions, outputs):
            before = len(ran)
            out.append(s.step(walk.rotations[k], walk.positions[k, 1], stamps[k]))
            if s.pipelined:
                if (k - 1) % 2 == 0 and k not in (0, 70):  # caught up, not a stream's first frame
                    assert len(ran) == before
                if k % 2 == 0:
                    s.catch_up()  # else the next step runs them first
    (q, p), (q_pipe, p_pipe) = ([np.stack(x) for x in zip(*out)] for out in outputs)
    assert sessions[1].latency == pytest.approx(sessions[0].latency + 1.0 / rate)
    later = np.r_[0, 0:69, 70, 70:walk.n_frames - 1]  # frame k shows frame k - 1's output
    assert np.abs(p_pipe - p[later]).max() < 1e-9
    assert np.abs(rot.angle_between(q_pipe, q[later])).max() < 1e-6
    assert len(ran) >= walk.n_frames * 30.0 / rate - 3  # the model frames did run, in catch_up


def test_a_stream_on_a_higher_floor_comes_out_on_that_floor(model, clips):
    """Grounding: the same walk 10 cm higher (another rig's ankles, another floor) is stylized the
    same and stays 10 cm higher."""
    walk = clips[0]
    rotations, roots = frames(walk)
    up = np.array([0.0, 0.1, 0.0])
    q, p = stream(RecurrentSession(model), rotations, roots)
    q_up, p_up = stream(RecurrentSession(model), rotations, roots + up)
    assert np.abs(q_up - q).max() < 1e-6 and np.abs(p_up - up - p).max() < 1e-6
    _, p_free = stream(RecurrentSession(model, ground=False), rotations, roots + up)
    assert np.abs(p_free - up - p).max() > 0.01  # without it, the model sees another motion


def test_gaps_and_restarts_reset_the_stream(model, clips):
    walk = clips[1]
    rotations, roots = frames(walk)
    n = walk.n_frames
    fresh = RecurrentSession(model, conform=False)
    q_fresh, p_fresh = stream(fresh, rotations[60:], roots[60:])
    stamps = np.arange(n) / walk.fps
    for later, resets in ((stamps + 1.0, True), (stamps - 10.0, True), (stamps + 0.2, False)):
        session = RecurrentSession(model, conform=False)
        stream(session, rotations[:60], roots[:60], stamps[:60])
        q, p = stream(session, rotations[60:], roots[60:], later[60:])
        same = np.abs(p - p_fresh).max() < 1e-9 and np.abs(q - q_fresh).max() < 1e-9
        assert same == resets, f"jump to {later[60] - stamps[59]:+.2f} s"
    session = RecurrentSession(model, conform=False)
    stream(session, rotations[:60], roots[:60])
    session.reset()
    q, p = stream(session, rotations[60:], roots[60:])
    assert np.abs(p - p_fresh).max() < 1e-9 and np.abs(q - q_fresh).max() < 1e-9


def test_follow_bounds_the_drift_from_the_input_trajectory(model, clips):
    walk = clips[1]  # a turning walk: the random model's root barely moves, it falls behind
    end = walk.positions[-1, 1, [0, 2]]
    far = {}
    for follow in (None, 0.3):
        out = RecurrentSession(model, follow_seconds=follow).run(walk, "elderly")
        far[follow] = np.linalg.norm(out.positions[-1, 1, [0, 2]] - end)
    print(f"root distance from the input's after {walk.duration:.1f} s: free {far[None]:.2f} m, "
          f"following with 0.3 s {far[0.3]:.2f} m")
    assert far[None] > 1.0 and far[0.3] < 0.25 * far[None]


def test_bad_input_is_rejected_without_touching_the_state(model, clips):
    walk = clips[0][:40]
    rotations, roots = frames(walk)
    clean = RecurrentSession(model, performers=1)
    q_ref, p_ref = stream(clean, rotations, roots)
    nan = rotations[20].copy()
    nan[0, 5, 2] = np.nan
    zero = rotations[20].copy()
    zero[0, 7] = 0.0
    bad = [
        ((nan, roots[20]), "NaN"),
        ((rotations[20], roots[20] + np.inf), "NaN or infinite"),
        ((rotations[20][:, :21], roots[20]), r"\(1, 22, 4\)"),
        ((rotations[20].astype(int), roots[20]), "dtype int"),
        ((rotations[20].astype(object), roots[20]), "dtype object"),
        ((zero, roots[20]), "UpperArm_L has norm 0"),
        ((rotations[20] * 1.5, roots[20]), "unit quaternions"),
    ]
    session = RecurrentSession(model, performers=1)
    out = []
    for t in range(walk.n_frames):
        if t == 20:
            for args, message in bad:
                with pytest.raises(MotionStyleError, match=message):
                    session.step(*args)
            with pytest.raises(MotionStyleError, match="finite"):
                session.step(rotations[t], roots[t], stamp=float("nan"))
        # Slightly off-unit quaternions (float32 messages) are normalised, not rejected.
        out.append(session.step(rotations[t] * (1.02 if t % 2 else 1.0), roots[t]))
    q = np.stack([o[0] for o in out])
    p = np.stack([o[1] for o in out])
    assert np.abs(p - p_ref).max() < 1e-9 and np.abs(q - q_ref).max() < 1e-9


def test_single_performer_frames_without_batch_axis(model, clips):
    walk = clips[0]
    a, b = RecurrentSession(model), RecurrentSession(model)
    qa, pa = a.step(walk.rotations[0], walk.positions[0, 1])
    qb, pb = b.step(walk.rotations[:1], walk.positions[:1, 1])
    assert qa.shape == (22, 4) and pa.shape == (3,)
    assert np.array_equal(qa, qb[0]) and np.array_equal(pa, pb[0])


def test_controls_and_models_are_checked(model):
    session = RecurrentSession(model, performers=2)
    with pytest.raises(MotionStyleError, match="unknown style 'sad'.*active, elderly"):
        session.set_style("sad")
    with pytest.raises(MotionStyleError, match=r"alpha must be in \[0, 1\], got 1.5"):
        session.set_alpha(1.5)
    with pytest.raises(MotionStyleError, match=r"mix weight must be in \[0, 1\]"):
        session.set_mix("elderly", -0.1)
    with pytest.raises(MotionStyleError, match="performer 2 out of range.*0-1"):
        session.set_style("elderly", performer=2)
    with pytest.raises(MotionStyleError, match="missing.onnx: model file not found"):
        RecurrentSession(model.parent / "missing.onnx")
    with pytest.raises(MotionStyleError, match="judge_style.json: model card lacks kind"):
        RecurrentSession("judge_style.onnx")


def test_controls_blend_smoothly_from_wherever_they_are():
    c = Controls(["a", "b", "c"], performers=2, style="a", blend_seconds=0.3)
    style, alpha = c.advance(0.1)  # alpha per part: torso, arms, legs
    assert np.array_equal(style, [[1, 0, 0], [1, 0, 0]]) and np.array_equal(alpha, np.ones((2, 3)))
    c.set_style("b", performer=1)
    path = np.array([c.advance(0.05)[0][1] for _ in range(6)])
    assert np.all(np.diff(path[:, 1]) > 0) and np.allclose(path[-1], [0, 1, 0])
    assert np.allclose(path.sum(axis=1), 1.0)  # weights stay a mix
    c.set_style("c", performer=1)
    before = c.advance(0.15)[0][1]
    c.set_mix("a", 0.5, performer=1)  # mid-blend: continues from where it is
    first = c.advance(0.001)[0][1]
    assert 0.1 < before[2] < 0.9 and np.abs(first - before).max() < 1e-3
    for _ in range(40):
        style, _ = c.advance(0.01)
    assert np.allclose(style[1], [0.5, 0, 0.5]) and np.allclose(style[0], [1, 0, 0])
    c.set_alpha(0.5)
    c.set_part_alpha([1.0, 1.0, 0.0], performer=0)  # legs as performed
    path = np.array([c.advance(0.05)[1] for _ in range(8)])
    assert np.allclose(path[-1], [[0.5, 0.5, 0.0], [0.5, 0.5, 0.5]])
    assert np.all(np.diff(path[:, 0, 2]) <= 0) and np.all(np.diff(path[:, 1, 0]) <= 0)  # eased there
    for bad in ([1.0, 1.0], [1.0, 1.0, 1.5], ["x", 0, 0], [float("nan"), 1, 1]):
        with pytest.raises(MotionStyleError, match=r"part alpha must be 3 numbers in \[0, 1\], for torso, arms, legs"):
            c.set_part_alpha(bad)


def test_bench_command(model, capsys):
    from motion_style_ros.cli.main import main

    assert main(["bench", "recurrent", "--model", str(model), "--performers", "1,3",
                 "--seconds", "0.05"]) == 0
    out = capsys.readouterr().out
    print(out)
    rows = [line.split() for line in out.splitlines() if line.split()[:1] in (["1"], ["3"])]
    assert [r[0] for r in rows] == ["1", "3"] and all(len(r) == 6 for r in rows)
    assert "random-weight model" in out and "latency 25.0 ms" in out
    largest = next(line for line in out.splitlines() if line.startswith("largest number"))
    assert int(largest.rsplit(":", 1)[1].split()[-1]) >= 0
    assert "model call alone, 1 performer, onnxruntime: p50" in out
    assert "model call alone, 1 performer, onnxruntime, 33 ms apart: p50" in out
    paced = {line.split()[0]: line.split() for line in out.splitlines()
             if line.split()[:1] in (["default"], ["pipelined"])}
    assert paced["default"][1:3] == ["25.0", "ms"] and paced["pipelined"][1:3] == ["33.3", "ms"]
    # The torch generator is timed only from a checkpoint of the same model.
    assert "model call alone, 1 performer, torch" not in out
    assert "whole model frame back to back (1 performer, input at the model's 30 Hz): p50" in out
    # Beside the reference architecture, timed in the same run where torch is installed.
    if importlib.util.find_spec("torch") is None:
        assert "torch not installed: the reference generator is not timed" in out
    else:
        line = next(line for line in out.splitlines() if line.startswith("reference Style-ERD generator"))
        assert float(line.rsplit(": ", 1)[1].rstrip("x")) > 0.0


def test_an_anchored_root_is_only_ever_held_back(clips):
    # The shipped model's "active" walks faster than a normal walk's legs carry it: the foot lock
    # holds the root back (anchor_root), along its own path, never backwards, never up or down.
    walk = clips[0]
    anchored = RecurrentSession("style_erd.onnx", follow_seconds=None)
    free = RecurrentSession("style_erd.onnx", follow_seconds=None)
    free._foot_lock.anchor_root = False
    a, f = (s.run(walk, "active").positions[:, walk.skeleton.pelvis] for s in (anchored, free))
    assert np.allclose(a[:, 1], f[:, 1])
    step_a, step_f = np.diff(a[:, [0, 2]], axis=0), np.diff(f[:, [0, 2]], axis=0)
    assert (np.linalg.norm(step_a, axis=-1) <= np.linalg.norm(step_f, axis=-1) + 1e-9).all()
    assert (np.einsum("ij,ij->i", step_a, step_f) >= -1e-12).all()
    path_a, path_f = np.linalg.norm(step_a, axis=-1).sum(), np.linalg.norm(step_f, axis=-1).sum()
    print(f"active on a normal walk: root path {path_f:.2f} m free, {path_a:.2f} m anchored")
    assert path_a < path_f - 0.05


def test_calibration_says_what_the_stream_has_shown(model):
    from motion_style_ros.core.synthetic import synthetic_motion
    from motion_style_ros.runtime.performer import describe_calibration

    walk, wave = synthetic_motion("walk", 30.0, 4.0), synthetic_motion("wave", 30.0, 4.0)
    session = RecurrentSession(model)
    assert session.calibration()["state"] == "measuring"
    stream(session, walk.rotations[:30], walk.root_positions[:30])
    assert session.calibration()["state"] == "measuring"  # the first two seconds
    stream(session, walk.rotations[30:], walk.root_positions[30:], np.arange(30, walk.n_frames) / 30.0)
    measured = session.calibration()
    assert measured["state"] == "measured" and measured["arm_rolls_deg"] == [0.0] * 8  # Bandai-like arms
    # A waving arm never hangs: said once, in a line that names what to do.
    waving = RecurrentSession(model)
    stream(waving, wave.rotations, wave.root_positions)
    assert waving.calibration()["state"] == "arms never hung"
    assert "until they hang" in describe_calibration(waving.calibration())
    waving.run(wave, "elderly")
    assert waving.calibration()["state"] == "clip"
    assert RecurrentSession(model, conform=False).calibration() == {"state": "off"}
