"""The windowed ST-GCN session on real Bandai clips: overlap-add, latency and alignment, latent
seeds, reference clips and their rejection, with small exported networks (the real ONNX
interface); and, where the trained model ships, what it does with reference styles and alpha."""

import numpy as np
import pytest
from onnx_fixtures import windowed_model

from motion_style_ros.core.motion import Motion
from motion_style_ros.core.overlap_add import OverlapAdd, taper
from motion_style_ros.errors import MotionStyleError
from motion_style_ros.io import bvh
from motion_style_ros.io.datasets import ClipInfo, load_clip
from motion_style_ros.runtime.onnx_model import models_dir
from motion_style_ros.runtime.stgcn import StgcnSession
from motion_style_ros.runtime.windows import latent

STYLES = ["active", "elderly", "exhausted", "feminine", "masculine", "normal", "youthful"]
BANDAI = "bandai-namco/Bandai-Namco-Research-Motiondataset-2/data"


def bandai(datasets, name: str) -> Motion:
    return load_clip(ClipInfo("bandai-2", datasets / BANDAI / f"{name}.bvh", name, "", "", "", ""))


@pytest.fixture(scope="module")
def walk(datasets):
    return bandai(datasets, "dataset-2_walk-turn-right_masculine_003")


@pytest.fixture(scope="module")
def identity_model(tmp_path_factory):
    """A generator that returns its input (random mapping network and style encoder)."""
    return windowed_model(tmp_path_factory.mktemp("identity") / "stgcn.onnx", STYLES, residual=0.0)


@pytest.fixture(scope="module")
def random_model(tmp_path_factory):
    return windowed_model(tmp_path_factory.mktemp("random") / "stgcn.onnx", STYLES)


def test_overlap_add_of_identity_windows_reproduces_the_input_exactly():
    signal = np.random.default_rng(0).normal(size=(120, 5))
    for window, lookahead, hop in [(16, 0, 1), (16, 7, 4), (48, 16, 4), (48, 32, 8), (48, 47, 48)]:
        ola = OverlapAdd(window, lookahead, 1, 5)
        padded = np.concatenate([np.repeat(signal[:1], window - 1, axis=0), signal])
        out = []
        for n in range(len(signal)):
            ola.shift()
            if n % min(hop, lookahead + 1) == 0:
                ola.add(padded[None, n : n + window])  # the window ending at frame n
            if n >= lookahead:
                assert ola.covered()[0]
                out.append(ola.frame()[0])
        assert np.abs(np.array(out) - signal[: len(signal) - lookahead]).max() < 1e-12
    # windows fade in and out: the weights are positive, small at both ends, largest mid-way
    w = taper(17)
    assert (w > 0).all() and w[0] < 0.01 and w[-1] < 0.01 and w.argmax() == 8
    with pytest.raises(MotionStyleError, match="lookahead must be 0 to 15"):
        OverlapAdd(16, 16, 1, 5)


@pytest.mark.parametrize("lookahead,hop", [(0, 4), (8, 8), (16, 4), (32, 8)])
def test_identity_generator_streams_the_input_back_aligned(identity_model, walk, lookahead, hop):
    """Windows, overlap-add, latency, decoding and run()'s alignment add nothing of their own."""
    session = StgcnSession(identity_model, window=48, lookahead=lookahead, hop=hop, foot_lock=False,
                              follow_seconds=None)
    assert session.latency == pytest.approx(lookahead / 30)
    out = session.run(walk, "elderly")
    assert out.n_frames == walk.n_frames
    assert np.abs(out.global_positions() - walk.global_positions()).max() < 1e-5


def test_streaming_holds_the_first_frame_for_the_lookahead_then_lags(identity_model, walk):
    session = StgcnSession(identity_model, window=48, lookahead=8, hop=4, foot_lock=False, conform=False,
                              follow_seconds=None)
    roots = walk.root_positions
    out = np.array([session.step(walk.rotations[t], roots[t], t / 30)[1] for t in range(40)])
    assert np.abs(out[:9] - roots[0]).max() < 1e-6  # frame 0 held until frame 8 arrives
    assert np.abs(out[8:] - roots[: 40 - 8]).max() < 1e-5  # then frame t - 8 at frame t
    # a reset restarts the hold from the performer's current frame
    session.reset()
    again = np.array([session.step(walk.rotations[t], roots[t], t / 30)[1] for t in range(40, 52)])
    assert np.abs(again[:9] - roots[40]).max() < 1e-6
    assert np.abs(again[9:] - roots[41:44]).max() < 1e-5


def test_input_faster_than_the_model_is_resampled(identity_model, walk):
    session = StgcnSession(identity_model, window=48, lookahead=8, input_fps=120)
    frames = [session.step(walk.rotations[t // 4], walk.root_positions[t // 4], t / 120)
              for t in range(200)]
    assert len(frames) == 200 and all(np.isfinite(q).all() and np.isfinite(p).all() for q, p in frames)
    assert session.latency == pytest.approx(8 / 30 + 1 / 30 - 1 / 120)


def test_pipelined_windows_give_the_same_frames_one_input_frame_later(random_model, walk):
    """A seed change between frames applies to the model frames a pipelined step left, as it
    would have without pipelining; run() aligns the pipelined output to the input the same."""
    clip = walk[:60]
    sessions = [StgcnSession(random_model, window=16, lookahead=4, pipelined=p) for p in (False, True)]
    out = [[], []]
    for t in range(clip.n_frames):
        for s, o in zip(sessions, out):
            if t == 25:
                s.set_seed(5)
            o.append(s.step(clip.rotations[t], clip.root_positions[t], t / 30))
    (q, p), (q_pipe, p_pipe) = ([np.stack(x) for x in zip(*o)] for o in out)
    assert sessions[1].latency == pytest.approx(sessions[0].latency + 1 / 30)
    assert np.abs(p_pipe[1:] - p[:-1]).max() < 1e-9 and np.abs(q_pipe[1:] - q[:-1]).max() < 1e-9
    aligned = [s.run(clip, "elderly").global_positions() for s in sessions]
    assert np.abs(aligned[1] - aligned[0]).max() < 1e-9


def test_latent_seeds_are_deterministic_and_diverse(random_model, walk):
    # fixed numbers: PCG64's raw stream through Box-Muller does not depend on machine or version
    assert np.allclose(latent(0, 3), [0.9184837468, 1.609997441, 0.2418246229], atol=1e-9)
    assert np.array_equal(latent(7, 16), latent(7, 16)) and not np.allclose(latent(7, 16), latent(8, 16))
    clip = walk[:90]
    a, b = (StgcnSession(random_model, window=16, lookahead=8, latent_seed=3) for _ in range(2))
    out_a, out_b = a.run(clip, "elderly"), b.run(clip, "elderly")
    assert np.array_equal(out_a.global_positions(), out_b.global_positions())
    b.set_seed(4)
    other = b.run(clip, "elderly")
    assert np.abs(other.global_positions() - out_a.global_positions()).max() > 1e-3
    # mixing two seeds is interpolating their codes
    now = StgcnSession(random_model, window=16, lookahead=8, blend_seconds=0.0)
    codes = {}
    for seed in (3, 4):
        now.set_seed(seed)
        codes[seed] = now.codes()
    now.set_seed(3, mix_seed=4, mix_weight=0.5)
    assert np.allclose(now.codes(), 0.5 * (codes[3] + codes[4]))
    assert np.abs(codes[3] - codes[4]).max() > 1e-3
    with pytest.raises(MotionStyleError, match="latent seed must be a whole number"):
        b.set_seed(-1)
    with pytest.raises(MotionStyleError, match="seed mix weight must be in"):
        b.set_seed(3, mix_seed=4, mix_weight=2.0)


def test_the_seed_spread_scales_the_seeds_codes_about_their_styles_mean(random_model):
    session = StgcnSession(random_model, window=16, lookahead=8, blend_seconds=0.0)
    size = int(session.card["latent_dim"])
    trained = {seed: session.mapping.run(z=np.repeat(latent(seed, size)[None], len(STYLES), 0).astype(np.float32),
                                         style=np.eye(len(STYLES), dtype=np.float32))["code"]
               for seed in (3, 4)}
    codes = {}
    for spread in (0.0, 1.0, 2.0):
        for seed in (3, 4):
            session.set_seed(seed, spread=spread)
            codes[spread, seed] = session.codes()
    assert np.allclose(codes[1.0, 3], trained[3], atol=1e-6)  # 1: the mapping network's codes
    assert np.allclose(codes[0.0, 3], codes[0.0, 4])  # 0: every seed gets its style's mean code
    mean = codes[0.0, 3]
    assert np.allclose(codes[2.0, 3] - mean, 2.0 * (codes[1.0, 3] - mean))
    assert session.seed_spread == 2.0  # a spread given once stays for later seeds
    session.set_seed(3)
    assert np.allclose(session.codes(), codes[2.0, 3])
    for bad in (-0.5, 4.5, "wide", True, float("nan")):
        with pytest.raises(MotionStyleError, match="seed spread must be a number from 0 to 4"):
            session.set_seed(3, spread=bad)
    with pytest.raises(MotionStyleError, match="seed spread"):
        StgcnSession(random_model, window=16, lookahead=8, seed_spread=-1.0)


def test_bad_reference_clips_are_rejected_with_a_reason(random_model, walk, datasets):
    session = StgcnSession(random_model, window=16, lookahead=8)
    with pytest.raises(MotionStyleError, match=r"too short: 10 frames at 30 fps; it needs at least 16"):
        session.set_reference(walk[:10])
    cmu = bvh.read(next((datasets / "cmu").rglob("*.bvh"))).to_motion()
    with pytest.raises(MotionStyleError, match="must be on the canonical skeleton"):
        session.set_reference(cmu)
    rotations = walk.rotations.copy()
    rotations[5, 3] = np.nan
    broken = Motion.from_rotations(walk.skeleton, rotations, walk.root_positions, walk.fps)
    with pytest.raises(MotionStyleError, match="NaN"):
        session.set_reference(broken)
    with pytest.raises(MotionStyleError, match="a reference must be a Motion"):
        session.set_reference("walk.bvh")
    # a good clip sets its style (named, or recognised by the encoder) as the target
    assert session.set_reference(walk, style="youthful") == "youthful"
    assert session.set_reference(walk) in STYLES


def test_the_offline_stylizer_streams_clips_through_the_session(identity_model, walk):
    from motion_style_ros.runtime.offline import stylizer

    out = stylizer("stgcn", str(identity_model), follow_seconds=None)(walk, "elderly")
    assert out.n_frames == walk.n_frames
    # foot locking (on by default) may turn the legs; everything else is the input
    upper = [j for j, name in enumerate(walk.skeleton.names) if "Leg" not in name and "Foot" not in name
             and "Toes" not in name]
    moved = np.abs(out.global_positions() - walk.global_positions())
    assert moved[:, upper].max() < 1e-5


def test_measurements_of_the_identity_find_no_seams_and_no_cost(identity_model, random_model, walk):
    from motion_style_ros.evaluation import windowed

    rows = windowed.lookahead_costs([(walk, "elderly")], identity_model, lookaheads=(0, 8), hop=4)
    assert [r["lookahead"] for r in rows] == [0, 8]
    for row in rows:
        assert row["jump_ratio_max"] == pytest.approx(1.0, abs=1e-3)
        assert row["jump_over_most_lookahead_max"] == pytest.approx(1.0, abs=1e-3)
        # (under a millimetre, not zero: the foot lock on the legs of a stream conditioned to its
        # measured size engages a frame apart depending on how long the first frame is held)
        assert row["distance_from_most_lookahead_m"] < 1e-3
        assert row["style_accuracy"] == 0.0  # the input is masculine, not elderly
    spread = windowed.diversity([walk[:48]], ["elderly", "active"], random_model, seeds=(0, 1))
    assert spread["between_seeds_m"] > 0 and spread["between_styles_m"] > 0
    rows = windowed.seed_spread_costs([(walk[:48], "elderly")], [walk[:48]], ["elderly", "active"],
                                      random_model, spreads=(0.0, 2.0))
    assert [r["seed_spread"] for r in rows] == [0.0, 2.0]
    assert rows[0]["between_seeds_m"] == 0.0 < rows[1]["between_seeds_m"]  # 0: one code per style
    assert rows[1]["between_seeds_m"] > spread["between_seeds_m"] and 0 <= rows[1]["style_accuracy"] <= 1
    report, figures = windowed.bench_report(walk[:40], "stgcn", random_model, hops=(1, 8), lookahead=8)
    assert "one window, 8 performer(s)" in report and "hop 8:" in report
    amortised = figures["per_frame_amortised_ms"]
    assert amortised["hop 8"] == pytest.approx(amortised["hop 1"] / 8, abs=1e-3)  # both rounded to 1 us
    assert set(figures["step_ms"]) == {"hop 1", "hop 8"}


# --- the trained model ---------------------------------------------------------------------------

TRAINED = models_dir() / "stgcn.onnx"
needs_trained = pytest.mark.skipif(
    not TRAINED.is_file(),
    reason="models/stgcn.onnx is not trained yet (motion-style train stgcn)",
)


@needs_trained
def test_reference_style_from_a_clip_of_style_s_is_recognised_as_s(datasets):
    from motion_style_ros.evaluation.judges import Judge

    judge = Judge("style")
    source = bandai(datasets, "dataset-2_walk_normal_001")  # a test take
    session = StgcnSession(TRAINED)
    hits = 0
    for style in STYLES:
        reference = bandai(datasets, f"dataset-2_run_{style}_008")  # test take, another content
        assert session.set_reference(reference) == style  # the encoder recognises the clip
        out = session.run(source, style)  # the reference's code, not the seed's
        hits += judge.judge([out]).labels[0] == style
    assert hits >= 5


def test_control_pairs_take_one_take_per_cell_into_the_next_style():
    from motion_style_ros.evaluation.windowed import control_pairs

    cells = [(c, s, t) for c in ("walk", "run") for s in ("active", "elderly", "normal") for t in ("001", "002")]
    clips = [(ClipInfo("bandai-2", None, f"{c}_{s}_{t}", c, s, t, "test"), f"{c}_{s}_{t}") for c, s, t in cells]
    pairs = control_pairs(clips)
    assert len(pairs) == 6
    assert sorted(motion.rsplit("_", 1)[0] for motion, _ in pairs) == sorted(f"{c}_{s}" for c, s, _ in cells[::2])
    following = {"active": "elderly", "elderly": "normal", "normal": "active"}
    assert all(target == following[motion.split("_")[1]] for motion, target in pairs)
