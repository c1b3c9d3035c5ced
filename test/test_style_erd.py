"""Style-ERD: the exported streaming step against torch, state and reset semantics, alpha, and a
few real training iterations with checkpoint/resume (tiny networks, real Bandai windows)."""

import json

import numpy as np
import pytest

torch = pytest.importorskip("torch", reason="tests the torch model: pip install '.[train]'")
ort = pytest.importorskip("onnxruntime")

from motion_style_ros.models.style_erd import StepGraph, StyleERD, tiny
from motion_style_ros.training import data as training_data
from motion_style_ros.training import recurrent


@pytest.fixture(scope="module")
def data(datasets):
    return training_data.load_data((2,), progress=False, root=datasets, takes_per_cell=1)


@pytest.fixture(scope="module")
def clip(data):
    """A real val take, ``(T, 260)`` raw features."""
    return max(data.splits["val"].features, key=len)[:90]


@pytest.fixture(scope="module")
def model(data):
    """A random tiny generator with the real normalisation and a non-trivial initial state."""
    frames = np.concatenate(data.splits["train"].features)
    mean, std = frames.mean(0), np.maximum(frames.std(0), 0.05)
    torch.manual_seed(0)
    m = StyleERD(tiny(data.styles), mean, std, mean[:130], std[:130])
    with torch.no_grad():
        for p in m.initial:
            p.normal_(0.0, 0.5)
        m.decoder[-1].weight.mul_(30.0)  # untrained outputs hardly move; make them move by ~std
    return m.eval()


def _controls(model, b=3, seed=0):
    rng = np.random.default_rng(seed)
    style = rng.dirichlet(np.ones(len(model.cfg.styles)), b).astype(np.float32)
    style[0] = np.eye(len(model.cfg.styles))[1]
    alpha = np.array([[1.0], [0.4], [0.0]], np.float32)[:b]
    return style, alpha


def test_onnx_stepped_frame_by_frame_matches_torch_on_a_real_clip(model, clip, tmp_path):
    path = tmp_path / "erd.onnx"
    recurrent.export_onnx(model, path)
    session = ort.InferenceSession(str(path), providers=["CPUExecutionProvider"])
    assert [i.name for i in session.get_inputs()] == ["features", "style", "alpha", "state", "reset"]
    assert [o.name for o in session.get_outputs()] == ["output", "state_out"]
    style, alpha = _controls(model)
    x = np.repeat(clip[None], len(style), axis=0)
    with torch.no_grad():
        expected, final = model(torch.from_numpy(x), torch.from_numpy(style), torch.from_numpy(alpha))
    state = np.zeros((len(style), model.cfg.state_size), np.float32)
    outputs = []
    for t in range(len(clip)):
        reset = np.full((len(style), 1), float(t == 0), np.float32)
        out, state = session.run(None, {"features": x[:, t], "style": style, "alpha": alpha,
                                        "state": state, "reset": reset})
        outputs.append(out)
    outputs = np.stack(outputs, axis=1)
    assert outputs.shape == (len(style), len(clip), 130)
    assert np.abs(outputs - expected.numpy()).max() < 1e-4
    assert np.abs(state - final.numpy()).max() < 1e-4
    assert outputs.std(axis=1).mean() > 50 * 1e-4  # the clip moves the output well beyond the tolerance
    # rotations come out orthonormal (6D halves: unit length, orthogonal)
    d6 = outputs[..., 4:].reshape(*outputs.shape[:2], 21, 6)
    assert np.allclose(np.linalg.norm(d6[..., :3], axis=-1), 1, atol=1e-5)
    assert np.allclose((d6[..., :3] * d6[..., 3:]).sum(-1), 0, atol=1e-5)


def test_stepping_equals_the_whole_sequence_and_state_is_carried(model, clip):
    style, alpha = _controls(model)
    s, a = torch.from_numpy(style), torch.from_numpy(alpha)
    x = torch.from_numpy(np.repeat(clip[None], len(style), axis=0))
    step = StepGraph(model)
    with torch.no_grad():
        whole, _ = model(x, s, a)
        state = torch.zeros(len(style), model.cfg.state_size)
        stepped = []
        for t in range(x.shape[1]):
            out, state = step(x[:, t], s, a, state, torch.full((len(style), 1), float(t == 0)))
            stepped.append(out)
        # splitting the clip in two and carrying the state gives the same as one run
        first, mid = model(x[:, :40], s, a)
        second, _ = model(x[:, 40:], s, a, mid)
    assert torch.allclose(torch.stack(stepped, 1), whole, atol=1e-5)
    assert torch.allclose(torch.cat([first, second], 1), whole, atol=1e-5)


def test_reset_uses_the_learned_initial_state(model, clip):
    style, alpha = _controls(model)
    s, a = torch.from_numpy(style), torch.from_numpy(alpha)
    b = len(style)
    x = torch.from_numpy(np.repeat(clip[None, 0], b, axis=0))
    step = StepGraph(model)
    with torch.no_grad():
        fresh, fresh_state = model(x[:, None], s, a)  # from the learned initial state
        garbage = torch.full((b, model.cfg.state_size), float("nan"))
        out, state = step(x, s, a, garbage, torch.ones(b, 1))
        assert torch.allclose(out, fresh[:, 0], atol=1e-6) and torch.allclose(state, fresh_state, atol=1e-6)
        # without reset the given state is used: another state gives another output
        other = torch.randn(b, model.cfg.state_size)
        kept, _ = step(x, s, a, other, torch.zeros(b, 1))
        assert (kept - fresh[:, 0]).abs().max() > 1e-3
        # reset is per performer
        mixed, _ = step(x, s, a, other, torch.tensor([[1.0], [0.0], [1.0]]))
    assert torch.allclose(mixed[[0, 2]], fresh[[0, 2], 0], atol=1e-6)
    assert torch.allclose(mixed[1], kept[1], atol=1e-6)


def test_alpha_zero_ignores_the_style_weights(model, clip):
    x = torch.from_numpy(np.repeat(clip[None], 3, axis=0))
    n = len(model.cfg.styles)
    styles = torch.from_numpy(np.random.default_rng(1).dirichlet(np.ones(n), 3).astype(np.float32))
    neutral = torch.eye(n)[model.cfg.styles.index(model.cfg.neutral)].expand(3, -1)
    with torch.no_grad():
        off, _ = model(x, styles, torch.zeros(3, 1))
        as_neutral, _ = model(x, neutral, torch.ones(3, 1))
        on, _ = model(x, styles, torch.ones(3, 1))
    assert torch.allclose(off[0], off[1], atol=1e-6) and torch.allclose(off[0], off[2], atol=1e-6)
    assert torch.allclose(off, as_neutral, atol=1e-6)  # alpha 0 = target style "normal"
    assert (on[0] - on[1]).abs().max() > 1e-3  # with alpha 1 the weights matter


def test_training_reduces_reconstruction_and_resumes_identically(data, tmp_path):
    cfg = recurrent.tiny_config(lr_gen=3e-3, lr_dis=1e-3)
    trainer = recurrent.Trainer(cfg, data, tmp_path / "a", progress=False)
    before = trainer.validate(trainer.model)["val_rec"]
    trainer.run(iterations=60, log_every=10, val_every=1000)
    after = trainer.validate(trainer.model)["val_rec"]
    assert after < 0.9 * before

    # 6 iterations at once == 3, a checkpoint, a new trainer resuming, 3 more
    whole = recurrent.Trainer(cfg, data, tmp_path / "b", progress=False)
    whole.run(iterations=6, log_every=1, val_every=1000)
    first = recurrent.Trainer(cfg, data, tmp_path / "c", progress=False)
    first.run(iterations=3, log_every=1, val_every=1000)
    resumed = recurrent.Trainer(cfg, data, tmp_path / "c", progress=False)
    assert resumed.resume() and resumed.state["iteration"] == 3
    resumed.run(iterations=6, log_every=1, val_every=1000)
    for name in ("model", "ema", "dis"):
        a, b = getattr(whole, name).state_dict(), getattr(resumed, name).state_dict()
        assert all(torch.equal(a[k], b[k]) for k in a), name

    def losses(t):
        return [e for e in map(json.loads, t.log.read_text().splitlines()) if "rec" in e]

    assert [e["rec"] for e in losses(whole)] == [e["rec"] for e in losses(resumed)]
    assert len(losses(resumed)) == 6


def test_the_style_adversary_learns_the_input_style_and_the_generator_gets_its_reversed_gradient(data, tmp_path):
    cfg = recurrent.tiny_config(w_style_adversary=1.0, warmup=0)
    trainer = recurrent.Trainer(cfg, data, tmp_path / "a", progress=False)
    assert "adversary" in trainer.PARTS and "adversary" not in recurrent.Trainer.PARTS
    # the reversal: the adversary's loss falls along its own gradient and rises along the one the
    # generator's neutral output receives
    x, style, _ = training_data.windows(data.splits["train"], cfg.window, 8, np.random.default_rng(0))
    _, neutral = trainer.model.stylize(x, style, with_neutral=True)
    neutral = neutral.detach().requires_grad_(True)
    loss = torch.nn.functional.cross_entropy(trainer.adversary(neutral), style)
    loss.backward()
    with torch.no_grad():
        step = 1e-2 * neutral.grad / neutral.grad.norm()
        assert torch.nn.functional.cross_entropy(trainer.adversary(neutral - step), style) > loss
    before = [p.detach().clone() for p in trainer.adversary.parameters()]
    trainer.run(iterations=4, log_every=1, val_every=1000)
    assert all(not torch.equal(a, b) for a, b in zip(before, trainer.adversary.parameters()))
    told = [e["style_told"] for e in map(json.loads, trainer.log.read_text().splitlines()) if "rec" in e]
    assert len(told) == 4 and all(np.isfinite(told))
    # it is checkpointed with its optimiser: a resumed run continues it
    resumed = recurrent.Trainer(cfg, data, tmp_path / "a", progress=False)
    assert resumed.resume()
    a, b = trainer.adversary.state_dict(), resumed.adversary.state_dict()
    assert all(torch.equal(a[k], b[k]) for k in a)


@pytest.mark.parametrize("flags, reason", [
    (["--style-adversary", "-1"], "--style-adversary must be 0 or more, got -1"),
    (["--distil-weight", "0.5"], "--distil-weight weighs the pairs of --distil: give --distil too"),
    (["--distil-weight", "-2", "--distil", "pairs.npz"], "--distil-weight must be 0 or more, got -2"),
])
def test_a_bad_training_flag_is_one_line_before_any_data_is_read(tmp_path, flags, reason):
    import subprocess
    import sys

    out = subprocess.run([sys.executable, "-m", "motion_style_ros.cli.main", "train", "recurrent", *flags,
                          "--out", str(tmp_path)], check=False, capture_output=True, text=True)
    assert out.returncode == 2 and len(out.stderr.strip().splitlines()) == 1, out.stderr
    assert reason in out.stderr
    assert not any(tmp_path.iterdir())
