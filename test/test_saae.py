"""The sequence adversarial autoencoder (issue 21): the exported networks against torch on a real
clip, restyling a real clip through the stream session, the prior sampler's joins, and a few real
training iterations with resume and export (tiny networks, real Bandai windows)."""

import json

import numpy as np
import pytest

torch = pytest.importorskip("torch", reason="tests the torch networks: pip install '.[train]'")
ort = pytest.importorskip("onnxruntime")

from motion_style_ros.errors import MotionStyleError
from motion_style_ros.evaluation import generative, metrics
from motion_style_ros.io.datasets import ClipInfo, load_clip
from motion_style_ros.models.saae import (
    Critic,
    Decoder,
    Encoder,
    positions,
    tiny,
)
from motion_style_ros.models.style_erd import reverse
from motion_style_ros.runtime.contract import check_card
from motion_style_ros.runtime.saae import SaaeSession, Sampler, prior_windows
from motion_style_ros.training import data as training_data
from motion_style_ros.training import saae

BANDAI = "bandai-namco/Bandai-Namco-Research-Motiondataset-2/data"


@pytest.fixture(scope="module")
def data(datasets):
    return training_data.load_data((2,), progress=False, root=datasets, takes_per_cell=1)


@pytest.fixture(scope="module")
def walk(datasets):
    name = "dataset-2_walk-turn-right_masculine_003"
    return load_clip(ClipInfo("bandai-2", datasets / BANDAI / f"{name}.bvh", name, "", "", "", ""))


@pytest.fixture(scope="module")
def normalisation(data):
    frames = np.concatenate(data.splits["train"].features)
    return frames.mean(0), np.maximum(frames.std(0), 0.05)


@pytest.fixture(scope="module")
def models(data, normalisation, tmp_path_factory):
    """Tiny random Model1 and Model2 with the real normalisation, exported (decoder file paths)."""
    folder = tmp_path_factory.mktemp("saae")
    mean, std = normalisation
    paths = {}
    for variant in ("model1", "model2"):
        cfg = tiny(data.styles, variant)
        torch.manual_seed(0)
        enc, dec = Encoder(cfg, mean, std).eval(), Decoder(cfg, mean, std).eval()
        classifier = Critic(cfg.style_dim, cfg.critic_hidden, len(data.styles)) if variant == "model2" else None
        inputs, spread = saae.export.random_style_inputs(cfg)
        paths[variant] = folder / f"{variant}.onnx"
        saae.write_model(enc, dec, classifier, paths[variant], inputs, spread, {"data": "random", "seed": 0})
    return paths


def test_onnx_matches_torch_on_a_real_clip(data, normalisation, tmp_path):
    clip = max(data.splits["val"].features, key=len)[:64]
    mean, std = normalisation
    for variant in ("saae", "model1", "model2"):
        cfg = tiny(data.styles, variant)
        torch.manual_seed(1)
        enc, dec = Encoder(cfg, mean, std).eval(), Decoder(cfg, mean, std).eval()
        classifier = Critic(cfg.style_dim, cfg.critic_hidden, len(data.styles)).eval()
        path = tmp_path / f"{variant}.onnx"
        saae.export_onnx(enc, dec, classifier if variant == "model2" else None, path)
        assert saae.parity(enc, dec, classifier if variant == "model2" else None, path, clip) < 1e-4
        assert sorted(p.name for p in tmp_path.glob(f"{variant}*.onnx")) == sorted(
            [path.name, *(p.name for p in saae.companions(path, variant).values())])
    # the decoder takes any length and outputs orthonormal 6D rotations that depend on the code
    session = ort.InferenceSession(str(tmp_path / "model2.onnx"), providers=["CPUExecutionProvider"])
    z = np.random.default_rng(0).standard_normal((2, cfg.content_dim)).astype(np.float32)
    out = session.run(None, {"content": z, "style": np.zeros((2, cfg.style_width), np.float32),
                             "position": positions(40, cfg.window, 2).numpy().copy()})[0]
    assert out.shape == (2, 40, 130) and np.abs(out[0] - out[1]).max() > 1e-3
    d6 = out[..., 4:].reshape(2, 40, 21, 6)
    assert np.allclose(np.linalg.norm(d6[..., :3], axis=-1), 1, atol=1e-5)
    assert np.allclose((d6[..., :3] * d6[..., 3:]).sum(-1), 0, atol=1e-5)


def test_gradient_reversal_flips_and_scales_the_gradient():
    x = torch.ones(3, requires_grad=True)
    (reverse(x, 0.5) * torch.tensor([1.0, 2.0, 3.0])).sum().backward()
    assert torch.equal(x.grad, torch.tensor([-0.5, -1.0, -1.5]))
    assert torch.equal(reverse(x, 0.5), x)


def test_restyling_a_real_clip_through_the_stream_session(models, walk):
    outs = {}
    for variant, path in models.items():
        session = SaaeSession(path, input_fps=walk.fps, hop=4, lookahead=8)
        for style in ("elderly", "youthful"):
            out = session.run(walk, style)
            assert out.n_frames == walk.n_frames
            assert np.isfinite(out.rotations).all() and np.isfinite(out.positions).all()
            outs[variant, style] = out
    for variant in models:  # the target style changes the motion
        a, b = outs[variant, "elderly"], outs[variant, "youthful"]
        assert np.abs(a.rotations - b.rotations).max() > 1e-3
    # Model1 at alpha 0 gives the input's frames back: the output is the input's motion
    session = SaaeSession(models["model1"], input_fps=walk.fps, hop=4, lookahead=8, foot_lock=False)
    kept = session.run(walk, "elderly", alpha=0.0)
    moved = outs["model1", "elderly"]
    below = slice(walk.skeleton.pelvis + 1, None)  # local rotations under the pelvis (no heading)

    def angle(a):  # largest angle (rad) between the clip's and the input's local rotations
        return (2 * np.arccos(np.clip(np.abs((a.rotations * walk.rotations).sum(-1)), 0, 1)))[:, below].max()

    assert angle(kept) < 0.05 < angle(moved)


def test_reference_clips_move_model2s_style_input_and_only_model2_takes_them(models, walk):
    session = SaaeSession(models["model2"], input_fps=walk.fps)
    code, logits = session.reference_codes(walk)
    assert code.shape == (3,) and logits.shape == (7,)
    before = session.style_inputs()[session.styles.index("elderly")].copy()
    assert session.set_reference(walk, "elderly") == "elderly"
    for _ in range(200):  # the blend to the reference's code runs as frames stream
        session.step(walk.rotations[0], walk.positions[0, walk.skeleton.pelvis])
    after = session.style_inputs()[session.styles.index("elderly")]
    assert np.allclose(after, code, atol=1e-6) and np.abs(after - before).max() > 1e-3
    with pytest.raises(MotionStyleError, match="Model2"):
        SaaeSession(models["model1"], input_fps=walk.fps).reference_codes(walk)
    with pytest.raises(MotionStyleError, match="too short"):
        session.reference_codes(walk.__class__.from_rotations(
            walk.skeleton, walk.rotations[:10], walk.positions[:10, walk.skeleton.pelvis], walk.fps))


def test_node_settings_set_and_drop_a_reference_on_a_backend_without_seeds(models, walk):
    """The node's apply (runtime.stylizer_settings) puts a reference's code over its style's input
    and, when the parameter is emptied, gives every style its own input back."""
    from motion_style_ros.runtime import stylizer_settings
    from motion_style_ros.runtime.backends import BACKENDS
    from motion_style_ros.runtime.defaults import DEFAULTS

    spec = BACKENDS["saae"]
    session = SaaeSession(models["model2"], input_fps=walk.fps, blend_seconds=0.0)
    own = session.style_inputs().copy()
    reference = session.reference_codes(walk)
    current = {**DEFAULTS, "target_style": "normal", "alpha": 1.0, "mix_style": "", "mix_weight": 0.0,
               "reference": "", "latent_seed": 0}
    stylizer_settings.apply([session], spec, current, {"reference": "walk.bvh", "target_style": "elderly"},
                            reference)
    k = session.styles.index("elderly")
    assert np.allclose(session.style_inputs()[k], reference[0]) and session.controls._primary[0] == k
    others = [i for i in range(len(session.styles)) if i != k]
    assert np.allclose(session.style_inputs()[others], own[others])
    stylizer_settings.apply([session], spec, {**current, "reference": "walk.bvh", "target_style": "elderly"},
                            {"reference": ""}, None)
    assert np.allclose(session.style_inputs(), own)


def test_the_backend_entry_names_this_session():
    from motion_style_ros.runtime.backends import BACKENDS

    spec = BACKENDS["saae"]
    assert spec.session_class() is SaaeSession and spec.reference_clips and not spec.latent_seeds
    assert spec.settings({"hop": 4, "lookahead": 8, "seed_spread": 1.0}) == {"hop": 4, "lookahead": 8}


def test_a_plain_saae_samples_but_does_not_restyle(tmp_path):
    path = tmp_path / "plain.onnx"
    card = saae.export_random_model(path, ["active", "elderly", "normal"], "saae")
    check_card(card, path, "saae")
    with pytest.raises(MotionStyleError, match="cannot restyle"):
        SaaeSession(path)
    assert np.isfinite(Sampler(path).frames(50)).all()


def test_the_samplers_joins_are_no_seams(models):
    sampler = Sampler(models["model2"], "elderly", seed=3)
    stream = sampler.frames(240)
    assert stream.shape == (240, 130) and np.isfinite(stream).all()
    steps = np.abs(np.diff(stream, axis=0)).max(axis=1)
    within = max(np.abs(np.diff(w, axis=0)).max() for w in sampler.windows)
    assert steps.max() <= within
    # against the windows laid end to end: their joins jump, the sampler's do not
    hop = sampler.hop
    naive = np.concatenate([w[:hop] for w in sampler.windows])[:240]
    joins = np.arange(hop, 240, hop) - 1
    assert steps[joins].max() < np.abs(np.diff(naive, axis=0)).max(axis=1)[joins].max()
    # the same seed gives the same stream; another style another one; poses go on from the stream
    again = Sampler(models["model2"], "elderly", seed=3)
    assert np.array_equal(again.frames(240), stream)
    assert np.abs(Sampler(models["model2"], "youthful", seed=3).frames(240) - stream).max() > 1e-3
    q, p = again.poses(30)
    assert q.shape == (30, 22, 4) and p.shape == (30, 3) and np.isfinite(q).all()
    with pytest.raises(MotionStyleError, match="unknown style"):
        again.set_style("sleepy")

    # chunks at a performer node's rate go on where the last ended: 1 s at 60 fps in pieces is the
    # same as at once, and it follows the model's own frames
    pieces = Sampler(models["model2"], "elderly", seed=3)
    parts = [pieces.chunk(0.25, 60.0) for _ in range(4)]
    whole = Sampler(models["model2"], "elderly", seed=3).chunk(1.0, 60.0)
    joined = np.concatenate([m.rotations for m in parts])
    assert whole.n_frames == 60 and np.abs(joined - whole.rotations).max() < 1e-9
    model_rate = Sampler(models["model2"], "elderly", seed=3).poses(30)[0]
    assert np.abs(np.abs((whole.rotations[::2] * model_rate).sum(-1)) - 1).max() < 1e-9


def test_the_samplers_feet_are_locked_and_nothing_else_changes(models):
    locked = Sampler(models["model2"], "elderly", seed=3).motion(4.0)
    free = Sampler(models["model2"], "elderly", seed=3, foot_lock=False).motion(4.0)
    sk = locked.skeleton
    legs = [sk.index(f"{part}_{side}") for part in ("UpperLeg", "LowerLeg", "Foot") for side in "LR"]
    others = [j for j in range(sk.n_joints) if j not in legs]
    assert np.array_equal(locked.rotations[:, others], free.rotations[:, others])
    assert np.array_equal(locked.positions[:, sk.pelvis, 1], free.positions[:, sk.pelvis, 1])
    assert metrics.foot_skating(locked) <= metrics.foot_skating(free)
    assert metrics.largest_jump(locked) <= 1.5 * metrics.largest_jump(free)


def test_the_papers_measures_of_prior_windows_against_real_ones(models, data):
    generated, which = prior_windows(models["model1"], 40, seed=1, styles=["elderly", "normal"])
    assert generated.shape == (40, 16, 130) and set(which) == {1, 5}
    assert not np.array_equal(generated[0], generated[2])  # every window its own prior sample
    real = generative.clip_windows(data.splits["val"].features, 16, 16, channels=130)
    figures = generative.measures(generated, real[::2], real[1::2])
    assert np.isfinite(figures["parzen_log_likelihood"]) and figures["dims"] == 16 * 130
    # untrained windows are far from real ones; real windows are nearer each other than to them
    assert figures["g2t"] > generative.measures(real[1::2][:40], real[::2], real[1::2])["g2t"]


def test_the_papers_table_for_model_files(models, datasets):
    rows = generative.table([models["model1"], models["model2"]], generated=24, test=30, root=datasets)
    assert list(rows) == ["model1", "model2"]
    assert all(r["test"] == 30 and r["generated"] == 24 and np.isfinite(r["parzen_log_likelihood"])
               and r["g2t"] > 0 for r in rows.values())


def test_training_reduces_reconstruction_resumes_identically_and_exports(data, walk, tmp_path):
    cfg = saae.tiny_config(variant="model2")
    trainer = saae.Trainer(cfg, data, tmp_path / "a", progress=False)
    before = trainer.validate(live=True)["val_rec"]
    trainer.run(iterations=40, log_every=10, val_every=20)
    after = trainer.validate(live=True)["val_rec"]
    assert after < 0.8 * before
    log = [json.loads(line) for line in trainer.log.read_text().splitlines()]
    losses = [e for e in log if "prior" in e]
    assert [e["iteration"] for e in losses] == [10, 20, 30, 40]
    assert all(np.isfinite(v) for e in losses for v in e.values())
    assert losses[-1]["hidden_style"] > 0 and losses[-1]["cls"] > 0

    # 4 iterations at once == 2, a checkpoint, a new trainer resuming, 2 more
    whole = saae.Trainer(cfg, data, tmp_path / "b", progress=False)
    whole.run(iterations=4, log_every=1, val_every=1000)
    first = saae.Trainer(cfg, data, tmp_path / "c", progress=False)
    first.run(iterations=2, log_every=1, val_every=1000)
    resumed = saae.Trainer(cfg, data, tmp_path / "c", progress=False)
    assert resumed.resume() and resumed.state["iteration"] == 2
    resumed.run(iterations=4, log_every=1, val_every=1000)
    for name in ("enc", "dec", "prior_critic", "style_critic", "classifier", "dec_ema"):
        a, b = getattr(whole, name).state_dict(), getattr(resumed, name).state_dict()
        assert all(torch.equal(a[k], b[k]) for k in a), name

    card = saae.train(cfg, tmp_path / "models", iterations=6, resume=True, checkpoints=tmp_path / "c",
                      data=data, progress=False, val_every=1000)
    path = tmp_path / "models" / "saae_model2_3d.onnx"
    check_card(card, path, "saae")
    assert card["training"]["history"]["iterations"] == 6
    assert card["training"]["onnx_torch_max_abs_diff"] < 1e-4
    assert card["variant"] == "model2" and card["styles"] == list(data.styles)
    assert len(card["style_inputs"]["elderly"]) == 3
    for name in ("saae_model2_3d.onnx", "saae_model2_3d.json", "saae_model2_3d_encoder.onnx",
                 "saae_model2_3d_style_encoder.onnx"):
        assert (tmp_path / "models" / name).is_file()
    # the exported model restyles a real clip through the session
    out = SaaeSession(path, input_fps=walk.fps, hop=8, lookahead=8).run(walk, "elderly")
    assert out.n_frames == walk.n_frames and np.isfinite(out.positions).all()


def test_the_cycle_term_and_model1_train(data, tmp_path):
    for variant in ("model1", "model2"):
        trainer = saae.Trainer(saae.tiny_config(variant=variant, w_cycle=1.0), data, tmp_path / variant,
                               progress=False)
        trainer.run(iterations=2, log_every=2, val_every=2)
        entry = json.loads(trainer.log.read_text().splitlines()[0])
        assert entry["cycle"] > 0 and np.isfinite(entry["rec"])
        assert ("val_transfer_style_acc" in trainer.state["val"][-1]) == (variant == "model2")
