"""MoST backend (issue 20): the exported graphs against torch on a real clip, the window step
through the session on real Bandai clips (the reference's features computed once), a few real
training iterations with resume and export, and bad references rejected (tiny networks, real
Bandai windows)."""

import json

import numpy as np
import pytest

torch = pytest.importorskip("torch", reason="tests the torch networks: pip install '.[train]'")
ort = pytest.importorskip("onnxruntime")

from motion_style_ros.core.features import encode
from motion_style_ros.core.motion import Motion
from motion_style_ros.errors import MotionStyleError
from motion_style_ros.io import bvh
from motion_style_ros.io.datasets import ClipInfo, load_clip
from motion_style_ros.models.most import PARTS, MoST, Step, tiny
from motion_style_ros.runtime.backends import BACKENDS
from motion_style_ros.runtime.contract import MOST, check_card
from motion_style_ros.runtime.most import MostSession
from motion_style_ros.training import data as training_data
from motion_style_ros.training import export as shared_export
from motion_style_ros.training import most

BANDAI = "bandai-namco/Bandai-Namco-Research-Motiondataset-2/data"


def bandai(datasets, name: str) -> Motion:
    return load_clip(ClipInfo("bandai-2", datasets / BANDAI / f"{name}.bvh", name, "", "", "", ""))


@pytest.fixture(scope="module", autouse=True)
def one_thread():
    """Tiny networks: one torch thread is faster than two on a busy machine (no waiting for a
    second thread at every operation)."""
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(threads)


@pytest.fixture(scope="module")
def data(datasets):
    return training_data.load_data((2,), progress=False, root=datasets, takes_per_cell=1)


@pytest.fixture(scope="module")
def clip(data):
    """A real val take, ``(T, 260)`` raw features."""
    return max(data.splits["val"].features, key=len)[:96]


@pytest.fixture(scope="module")
def model(data):
    """A random tiny model with the real normalisation."""
    mean, std = training_data.normalisation(data.splits["train"].features, 0.05)
    torch.manual_seed(0)
    return MoST(tiny(data.styles), mean, std).eval()


@pytest.fixture(scope="module")
def exported(model, data, tmp_path_factory):
    """The tiny model written as a backend's files, every style's mean features from train windows."""
    means = most.style_means(model, data.splits["train"], len(data.styles), 4, 0)
    path = tmp_path_factory.mktemp("most") / "most.onnx"
    most.write_model(model, path, {"data": "test"}, None, means)
    return path


def test_onnx_matches_torch_on_a_real_clip(model, clip, tmp_path):
    path = tmp_path / "most.onnx"
    means = (np.zeros((len(model.cfg.styles), len(PARTS), model.cfg.dim), np.float32),) * 2
    most.export_onnx(model, means, path)
    assert most.parity(model, path, clip) < 1e-4
    # the output depends on the style motion and on alpha, by far more than the tolerance
    x = clip[None, :16].astype(np.float32)
    with torch.no_grad():
        enc = model.encoder(torch.from_numpy(clip[None, 48:64]))
        style, pooled = enc[0].numpy(), enc[2].numpy()
    outs = {a: shared_export.run_onnx(path, MOST, x, style, pooled, np.full((1, 1), a, np.float32))[0][0]
            for a in (0.0, 1.0)}
    assert np.abs(outs[0.0] - outs[1.0]).max() > 1e-3
    d6 = outs[1.0][:, 4:].reshape(16, 21, 6)  # rotations come out orthonormal
    assert np.allclose(np.linalg.norm(d6[..., :3], axis=-1), 1, atol=1e-5)
    assert np.allclose((d6[..., :3] * d6[..., 3:]).sum(-1), 0, atol=1e-5)
    # any window length: the frame encoding is made inside the graph
    long = clip[None, :40].astype(np.float32)
    (got,) = shared_export.run_onnx(path, MOST, long, style, pooled, np.ones((1, 1), np.float32))
    with torch.no_grad():
        want = Step(model)(*map(torch.from_numpy, (long, style, pooled, np.ones((1, 1), np.float32)))).numpy()
    assert got.shape == (1, 40, 130) and np.abs(got - want).max() < 1e-4


def test_the_session_streams_a_real_clip_with_the_reference_encoded_once(exported, datasets):
    walk = bandai(datasets, "dataset-2_walk-turn-right_masculine_003")
    punch = bandai(datasets, "dataset-2_raise-up-both-hands_youthful_001")  # another action as the reference
    session = MostSession(exported, window=16, hop=4, lookahead=4)
    calls = {"style": 0, "step": 0}
    for name, key in ((session.style_encoder, "style"), (session.model, "step")):
        run = name.run
        name.run = lambda *a, _run=run, _key=key, **k: (calls.__setitem__(_key, calls[_key] + 1), _run(*a, **k))[1]
    means = session.features().copy()
    assert session.set_reference(punch, style="elderly") == "elderly"
    assert calls["style"] == 1
    k = session.styles.index("elderly")
    session.windows._code_progress[:] = 1.0  # the blend done
    assert np.abs(session.features()[k] - means[k]).max() > 1e-6  # the clip's features, not the mean
    assert np.array_equal(session.features()[k - 1], means[k - 1])  # the other styles keep theirs
    clip = walk[:90]
    out = session.run(clip, "elderly", alpha=1.0)
    assert out.n_frames == clip.n_frames
    assert np.isfinite(out.rotations).all() and np.isfinite(out.positions).all()
    assert calls["style"] == 1 and calls["step"] >= 90 // 4  # the reference was not encoded again
    # target_style through the styles' means: another style gives another motion
    other = session.run(clip, "youthful", alpha=1.0)
    assert np.abs(encode(other)[:, 4:130] - encode(out)[:, 4:130]).max() > 1e-4
    assert calls["style"] == 1


def test_training_reduces_reconstruction_resumes_identically_and_exports(data, clip, tmp_path):
    cfg = most.tiny_config(lr=1e-3)
    trainer = most.Trainer(cfg, data, tmp_path / "a", progress=False)
    before = trainer.validate(trainer.most)["val_rec"]
    trainer.run(iterations=16, log_every=4, val_every=8)
    after = trainer.validate(trainer.most)["val_rec"]
    assert after < 0.9 * before, (before, after)
    log = [json.loads(line) for line in trainer.log.read_text().splitlines()]
    losses = [e for e in log if "dis" in e]
    assert [e["iteration"] for e in losses] == [4, 8, 12, 16]
    assert all(np.isfinite(v) for e in losses for v in e.values())

    # 4 iterations at once == 2, a checkpoint, a new trainer resuming, 2 more
    whole = most.Trainer(cfg, data, tmp_path / "b", progress=False)
    whole.run(iterations=4, log_every=1, val_every=1000)
    first = most.Trainer(cfg, data, tmp_path / "c", progress=False)
    first.run(iterations=2, log_every=1, val_every=1000)
    resumed = most.Trainer(cfg, data, tmp_path / "c", progress=False)
    assert resumed.resume() and resumed.state["iteration"] == 2
    resumed.run(iterations=4, log_every=1, val_every=1000)
    for name in ("most", "dis", "most_ema"):
        a, b = getattr(whole, name).state_dict(), getattr(resumed, name).state_dict()
        assert all(torch.equal(a[k], b[k]) for k in a), name

    card = most.train(cfg, tmp_path / "models", iterations=5, resume=True, checkpoints=tmp_path / "c",
                      data=data, progress=False, val_every=1000, threads=1)
    assert card["training"]["history"]["iterations"] == 5
    assert card["training"]["onnx_torch_max_abs_diff"] < 1e-4
    check_card(card, tmp_path / "models" / "most.onnx", "most")
    assert card["kind"] == "most" and card["styles"] == list(data.styles)
    for name in ("most.onnx", "most.json", "most_style_encoder.onnx", "most_style_means.npz"):
        assert (tmp_path / "models" / name).is_file()
    with np.load(tmp_path / "models" / "most_style_means.npz") as means:
        assert means["style"].shape == (len(data.styles), len(PARTS), cfg.dim)
        assert np.abs(means["style"][0] - means["style"][1]).max() > 0  # a mean per style


def test_the_registry_entry_makes_sessions_as_the_node_does(exported):
    spec = BACKENDS["most"]
    assert spec.reference_clips and spec.lookahead and not spec.latent_seeds
    # the node's session settings for a windowed backend (runtime.stylizer_settings.sessions)
    common = {"input_fps": 120.0, "blend_seconds": 0.3, "threads": 1, "follow_seconds": 2.0,
              "foot_lock": True, "pipelined": True, "window": None, "hop": 4, "lookahead": 8, "bank": None}
    session = spec.session_class()(exported, **spec.settings(common), phase_seconds=1 / 120)
    assert session.window == 16 and session.latency == pytest.approx(8 / 30 + 1 / 30 - 1 / 120 + 1 / 120)


def test_style_pairs_differ_in_content_where_the_style_has_several(data):
    rng = np.random.default_rng(0)
    styles = np.arange(len(data.styles)).repeat(3)
    a, b, differ = most.style_pairs(data.splits["train"], 16, styles, rng)
    assert a.shape == b.shape == (len(styles), 16, 260) and differ.all()


def test_bad_references_are_rejected_with_a_reason(exported, datasets, tmp_path):
    walk = bandai(datasets, "dataset-2_walk-turn-right_masculine_003")
    session = MostSession(exported, window=16, lookahead=8)
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
    with pytest.raises(MotionStyleError, match="bank.json: no such style bank"):
        MostSession(exported, bank=tmp_path / "bank.json")
    with pytest.raises(MotionStyleError, match="lookahead must be 0 to 15 frames"):
        MostSession(exported, window=16, lookahead=16)
    # a good clip is recognised as one of the styles and made the target
    assert session.set_reference(walk) in session.styles


@pytest.mark.parametrize("flag, value, reason", [
    ("--content-weight", "-0.5", "--content-weight must be 0 or more, got -0.5"),
    ("--content-net-weight", "-1", "--content-net-weight must be 0 or more, got -1"),
    ("--dec-blocks", "0", "--dec-blocks must be 1 to 8 (the paper's code: 3), got 0"),
])
def test_a_bad_training_flag_is_one_line_before_any_data_is_read(tmp_path, flag, value, reason):
    import subprocess
    import sys

    out = subprocess.run([sys.executable, "-m", "motion_style_ros.cli.main", "train", "most", flag, value,
                          "--out", str(tmp_path)], check=False, capture_output=True, text=True)
    assert out.returncode == 2 and len(out.stderr.strip().splitlines()) == 1, out.stderr
    assert reason in out.stderr
    assert not any(tmp_path.iterdir())


def test_the_content_classifier_term_trains_its_network_first_and_moves_the_transfer(data, tmp_path):
    cfg = most.tiny_config(w_content_net=1.0, content_widths=(16,), content_iterations=20, content_batch=8)
    trainer = most.Trainer(cfg, data, tmp_path, progress=False)
    assert (tmp_path / "most_0" / "content_net.pt").is_file()
    assert trainer.summary()["content_network"]["iterations"] == 20
    terms = trainer.step(0)
    assert terms["content_net"] > 0.0 and np.isfinite(terms["content_net"])
    # the term alone has a gradient on the generator: the network is frozen, the transfer is not
    trainer.opt_g.zero_grad()
    x, _, content = training_data.windows(data.splits["train"], cfg.window, 4, np.random.default_rng(1))
    s1, _, _ = most.style_pairs(data.splits["train"], cfg.window, np.zeros(4, dtype=int), np.random.default_rng(2))
    fake = trainer.most(x, s1)
    torch.nn.functional.cross_entropy(trainer.content(trainer.losses.views(fake)["content"])[0], content).backward()
    assert any(p.grad is not None and p.grad.abs().sum() > 0 for p in trainer.most.generator.parameters())
    assert all(p.grad is None for p in trainer.content.parameters())
    # a second trainer with the same settings loads the saved network instead of training it again
    again = most.Trainer(cfg, data, tmp_path, progress=False)
    a, b = trainer.content.state_dict(), again.content.state_dict()
    assert all(torch.equal(a[k], b[k]) for k in a)
    # off (the shipped recipe): no network, no term
    off = most.Trainer(most.tiny_config(), data, tmp_path / "off", progress=False)
    assert off.content is None and off.summary()["content_network"] is None


def test_a_style_enrolled_from_clips_is_a_target_with_their_features(exported, datasets, tmp_path):
    from motion_style_ros.runtime import style_bank

    takes = ["dataset-2_walk_youthful_001", "dataset-2_run_youthful_001"]
    clips = [bandai(datasets, name) for name in takes]
    session = MostSession(exported, window=16, hop=4, lookahead=4)
    with pytest.raises(MotionStyleError, match="--head reads stgcn's encoder heads"):
        session.enrol(clips, takes, head="elderly")
    entry = session.enrol(clips, takes)
    assert entry.head == style_bank.FEATURES and entry.frames == sum(m.n_frames for m in clips)  # 30 fps
    own = [session.reference_codes(m)[0] for m in clips]
    np.testing.assert_allclose(np.array(entry.code).reshape(own[0].shape),
                               np.average(own, axis=0, weights=[m.n_frames for m in clips]), atol=1e-9)
    assert set(entry.probabilities) <= set(session.styles) and 0 < sum(entry.probabilities.values()) <= 1 + 1e-9
    bank = style_bank.path_beside(exported).with_name("mine.json")
    style_bank.write(bank, {"bouncy": entry}, "most", session.model_digest)

    enrolled = MostSession(exported, window=16, hop=4, lookahead=4, bank=bank)
    assert enrolled.styles == [*session.styles, "bouncy"]
    np.testing.assert_allclose(enrolled.features()[-1].ravel(), entry.code, atol=1e-6)  # the file keeps 7 decimals
    walk = bandai(datasets, "dataset-2_walk-turn-right_masculine_003")[:90]
    out, normal = enrolled.run(walk, "bouncy"), enrolled.run(walk, "normal")
    assert np.isfinite(out.positions).all()
    assert np.abs(encode(out)[:, 4:130] - encode(normal)[:, 4:130]).max() > 1e-4  # its features are used
    # a bank is for the model it was made with
    style_bank.write(bank, {"bouncy": entry}, "most", "0" * 16)
    with pytest.raises(MotionStyleError, match="made for another model"):
        MostSession(exported, bank=bank)


def test_the_style_cli_enrols_for_most_and_refuses_a_model_without_a_style_encoder(exported, datasets, tmp_path):
    import subprocess
    import sys

    bank = tmp_path / "mine.json"
    files = [str(datasets / BANDAI / f"{n}.bvh") for n in ("dataset-2_walk_youthful_001", "dataset-2_run_youthful_001")]

    def cli(model, *args):
        return subprocess.run([sys.executable, "-m", "motion_style_ros.cli.main", "style", *args, "--model",
                               str(model), "--bank", str(bank)], capture_output=True, text=True)

    added = cli(exported, "add", "bouncy", *files)
    assert added.returncode == 0, added.stderr
    assert "bouncy: 2 clips" in added.stdout and "read under 'features'" in added.stdout
    assert MostSession(exported, bank=bank).styles[-1] == "bouncy"
    refused = cli("style_erd.onnx", "list")
    assert refused.returncode == 2 and "a style bank needs a stgcn or most model" in refused.stderr
    assert "Traceback" not in refused.stderr


def test_val_targets_are_styles_that_have_val_takes_when_some_have_none():
    from motion_style_ros.training.data import Clips

    long, short = np.zeros((20, 3), np.float32), np.zeros((5, 3), np.float32)
    val = Clips([long, long, short, long], np.array([0, 1, 2, 3]), np.zeros(4, int))  # style 2: too short
    style = torch.tensor([0, 1, 3, 0, 1, 3] * 20)
    rng = np.random.default_rng(0)
    target = most.val_targets(val, style, 5, 16, rng).numpy()  # style 4 has no val take at all
    assert set(target) <= {0, 1, 3} and (target != style.numpy()).all() and len(set(target)) == 3
    every = Clips([long] * 3, np.array([0, 1, 2]), np.zeros(3, int))  # all have one: as other_styles
    a = most.val_targets(every, style[:3] % 3, 3, 16, np.random.default_rng(1))
    b = training_data.other_styles(style[:3] % 3, 3, np.random.default_rng(1))
    assert torch.equal(a, b)


def test_the_val_style_figure_reads_the_styles_the_val_windows_show(data, tmp_path):
    # Bandai dataset-1 has no val takes: its styles have no mean among the val windows' features
    # (64 windows: torch.cdist then takes its matrix form, where an infinite mean was NaN everywhere)
    trainer = most.Trainer(most.tiny_config(val_windows=64), data, tmp_path, progress=False)
    x, style, target, s1, s2 = trainer.val_windows
    keep = style != style[0]  # one style the windows do not show
    trainer.val_windows = (x[keep], style[keep], target[keep], s1[keep], s2[keep])
    got = trainer.validate(trainer.most)["val_transfer_style_acc"]
    m, (x, style, target, s1, _) = trainer.most, trainer.val_windows
    with torch.no_grad():
        enc_x = m.encoder(x)
        full = trainer._passes.full(m.transfer(enc_x, m.encoder(s1), x), x[..., trainer.losses.contact_cols])
        fake, real = m.encoder(full)[0].flatten(1), enc_x[0].flatten(1)
    shown = sorted(set(style.tolist()))
    means = {k: real[style == k].mean(0) for k in shown}
    nearest = [min(shown, key=lambda k: float((f - means[k]).norm())) for f in fake]
    assert got == round(float(np.mean(np.array(nearest) == target.numpy())), 4)


def test_a_residual_generator_starts_at_its_input_and_learns_a_change_that_exports(data, clip, tmp_path):
    from dataclasses import replace

    from motion_style_ros.training.most.trainer import paper_differences

    cfg = most.tiny_config(residual=True, lr=1e-3)
    trainer = most.Trainer(cfg, data, tmp_path / "ckpt", progress=False)
    m = trainer.most.eval()
    x = torch.from_numpy(clip[None, :16].astype(np.float32))
    s = torch.from_numpy(clip[None, 48:64].astype(np.float32))
    with torch.no_grad():
        start = m(x, s)[0].numpy()
    assert np.abs(start - clip[:16, :130]).max() < 1e-5  # the input's own frames, whatever the style
    trainer.run(iterations=4, log_every=4, val_every=1000)
    with torch.no_grad():
        moved = trainer.most.eval()(x, s)[0].numpy()
    assert np.abs(moved - clip[:16, :130]).max() > 1e-3  # trained: a change of its own
    path = tmp_path / "most.onnx"
    means = (np.zeros((len(data.styles), len(PARTS), cfg.dim), np.float32),) * 2
    most.export_onnx(trainer.most, means, path)
    assert most.parity(trainer.most, path, clip) < 1e-4
    assert any("residual" in line for line in paper_differences(cfg))
    assert not any("residual" in line for line in paper_differences(replace(cfg, residual=False)))


def test_the_residual_flag_reaches_the_config_and_the_resuming_command():
    from argparse import Namespace

    from motion_style_ros.training.command import model_flags

    args = Namespace(residual=True, dec_blocks=3, content_weight=None)
    changes, given = model_flags(args, {"residual": "residual", "dec_blocks": "dec_blocks",
                                         "content_weight": "w_content"})
    assert changes == {"residual": True, "dec_blocks": 3}
    assert given == " --residual --dec-blocks 3"


def _small_root(datasets, root, dataset2=("dataset-2_walk_normal_001", "dataset-2_walk_elderly_001")):
    """A datasets root of a few real files (symlinks): dataset-1's proud takes of four contents,
    the ``dataset2`` takes (by default the first walk takes of two styles, held-out test takes), one
    CMU walk and one Xia neutral clip."""
    sets = datasets / "bandai-namco"
    for n, names in ((1, [f"dataset-1_{c}_proud_001" for c in ("bow", "bye", "byebye", "dash")]),
                     (2, dataset2)):
        folder = f"Bandai-Namco-Research-Motiondataset-{n}"
        src, dst = sets / folder, root / "bandai-namco" / folder
        (dst / "data").mkdir(parents=True)
        (dst / "cfg").symlink_to(src / "cfg")
        for name in names:
            for ext in (".bvh", ".json"):
                if (src / "data" / f"{name}{ext}").exists():
                    (dst / "data" / f"{name}{ext}").symlink_to(src / "data" / f"{name}{ext}")
    cmu = root / "cmu"
    (cmu / "data" / "02").mkdir(parents=True)
    (cmu / "data" / "02" / "02_01.bvh").symlink_to(datasets / "cmu" / "data" / "02" / "02_01.bvh")
    lines = (datasets / "cmu" / "labels.csv").read_text().splitlines()
    (cmu / "labels.csv").write_text("\n".join([lines[0], *(x for x in lines if x.startswith("data/02/02_01.bvh"))])
                                    + "\n")
    (root / "xia-test").mkdir()
    (root / "xia-test" / "neutral_01_000.bvh").symlink_to(datasets / "xia-test" / "neutral_01_000.bvh")


def _tiny_exported(data, folder):
    """A tiny random MoST exported with its style means, windows long enough for the published
    lookahead: what the end-to-end CLI runs stylize with."""
    from dataclasses import replace

    mean, std = training_data.normalisation(data.splits["train"].features, 0.05)
    torch.manual_seed(0)
    model = MoST(replace(tiny(data.styles), window=24), mean, std).eval()
    exported = folder / "most.onnx"
    folder.mkdir()
    most.write_model(model, exported, {"data": "test"}, None,
                     most.style_means(model, data.splits["train"], len(data.styles), 4, 0))
    return exported


def test_eval_enrol_scores_a_style_enrolled_from_clips_end_to_end(data, datasets, tmp_path):
    """`motion-style eval --enrol` through the CLI on a small real datasets root (it broke once
    with no test running it): the enrolled style is asked of every held-out take and unseen clip,
    and both judge panels score it. A tiny random model with windows long enough for the published
    lookahead."""
    import os
    import subprocess
    import sys

    exported = _tiny_exported(data, tmp_path / "model")
    root = tmp_path / "datasets"
    _small_root(datasets, root)
    out = tmp_path / "out"
    run = subprocess.run([sys.executable, "-m", "motion_style_ros.cli.main", "eval", "--stylizer", "most",
                          "--model", str(exported), "--enrol", "proud", "--enrol-clips", "3", "--out", str(out),
                          "--quiet"], capture_output=True, text=True, timeout=600,
                         env={**os.environ, "MOTION_STYLE_DATASETS": str(root)})
    assert run.returncode == 0, run.stderr
    report = json.loads((out / "enrolment.json").read_text())
    assert report["style"] == "proud" and len(report["enrolled_from"]) == 3
    assert all(name.startswith("dataset-1_") and "_proud_" in name for name in report["enrolled_from"])
    assert report["bandai2_test"]["outputs"] == 2 and report["unseen"]["outputs"] == 2
    for part in ("bandai2_test", "unseen"):
        for k in (1, 2):
            assert 0.0 <= report[part][f"recognised_{k}"] <= 1.0
            assert np.isfinite(report[part][f"target_gain_median_{k}"])
    assert (out / "enrolled_proud.json").is_file()


def test_eval_consistency_reports_cc_and_sc_through_the_cli(data, datasets, tmp_path):
    """`motion-style eval --reference-codes --consistency` through the CLI (it failed for a stop
    with no test running it) on five held-out takes (walk and run, normal and elderly, two normal
    walks) and the train takes the SC++ figure compares with."""
    import os
    import subprocess
    import sys

    exported = _tiny_exported(data, tmp_path / "model")
    root = tmp_path / "datasets"
    takes = [f"dataset-2_{c}_{s}_{t}" for c in ("walk", "run") for s in ("normal", "elderly") for t in ("001", "002")]
    takes.append("dataset-2_walk_normal_008")  # a second held-out take of one cell: a same-content reference
    _small_root(datasets, root, takes)
    out = tmp_path / "out"
    run = subprocess.run([sys.executable, "-m", "motion_style_ros.cli.main", "eval", "--stylizer", "most",
                          "--model", str(exported), "--reference-codes", "--consistency", "--out", str(out),
                          "--quiet"], capture_output=True, text=True, timeout=600,
                         env={**os.environ, "MOTION_STYLE_DATASETS": str(root)})
    assert run.returncode == 0, run.stderr
    figures = json.loads((out / "report.json").read_text())["consistency"]["most"]
    assert 5 <= figures["pairs"] <= 20  # CC and SC++ of the 5 held-out takes, both reference kinds, where one exists
    for key in ("cc_same", "cc_other", "sc_same", "sc_other"):
        assert figures[key] is not None and np.isfinite(figures[key]) and figures[key] > 0.0, (key, figures)
    assert "CC" in run.stdout
