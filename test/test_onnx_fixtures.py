"""The tests' stand-in models (``onnx_fixtures.py``) keep to the shipped models' contract, so that
the runtime's tests without torch test what the runtime will run: the same ONNX inputs and outputs
(names, order, dtypes, dynamic axes), cards with every key the real card writers put in, and the
properties the tests lean on. Their requirements leave torch out."""

from pathlib import Path

import numpy as np
import onnxruntime as ort
import pytest
from onnx_fixtures import recurrent_model, windowed_model

from motion_style_ros.runtime.contract import check_card
from motion_style_ros.runtime.onnx_model import OnnxModel, models_dir, read_card

ROOT = Path(__file__).resolve().parents[1]
# What a card says for people (and the torch side's own numbers); the runtime reads none of it.
DESCRIPTIVE = {"task", "inputs", "outputs", "mapping", "style_encoder", "architecture", "licence",
               "attribution", "frames_multiple"}


def shipped(name: str) -> Path:
    path = models_dir() / name
    if not path.is_file():
        pytest.skip(f"models/{name} is not trained yet")
    return path


def signature(path: Path) -> list[tuple[str, str, list]]:
    """Every input and output of an ONNX file as (name, element type, shape), in order."""
    session = ort.InferenceSession(str(path), providers=["CPUExecutionProvider"])
    return [(a.name, a.type, a.shape) for a in (*session.get_inputs(), *session.get_outputs())]


def test_the_recurrent_stand_in_has_the_shipped_interface_and_card(tmp_path):
    real = shipped("style_erd.onnx")
    card = read_card(real)
    fake = recurrent_model(tmp_path / "erd.onnx", card["styles"], neutral=card["neutral_style"])
    fake_card = read_card(fake)
    check_card(fake_card, fake, "recurrent")
    state = card["state_size"]
    expected = [(name, kind, [fake_card["state_size"] if d == state else d for d in shape])
                for name, kind, shape in signature(real)]
    assert signature(fake) == expected
    assert set(card) - DESCRIPTIVE <= set(fake_card)
    assert fake_card["feature_layout"] == card["feature_layout"] and fake_card["fps"] == card["fps"]


def test_the_windowed_stand_ins_have_the_shipped_interfaces_and_card(tmp_path):
    real = shipped("stgcn.onnx")
    card = read_card(real)
    fake = windowed_model(tmp_path / "stgcn.onnx", card["styles"], window=card["window"],
                          style_dim=card["style_dim"], latent_dim=card["latent_dim"])
    fake_card = read_card(fake)
    check_card(fake_card, fake, "stgcn")
    assert signature(fake) == signature(real)
    for kind in ("mapping", "style_encoder"):
        companion = signature(real.with_name(card["files"][kind]))
        assert signature(fake.with_name(fake_card["files"][kind])) == companion
    assert set(card) - DESCRIPTIVE <= set(fake_card)
    assert fake_card["feature_layout"] == card["feature_layout"] and fake_card["fps"] == card["fps"]


def test_the_recurrent_stand_in_answers_to_every_input(tmp_path):
    styles = ["active", "elderly", "normal"]
    model = OnnxModel(recurrent_model(tmp_path / "erd.onnx", styles))
    rng = np.random.default_rng(0)
    x = rng.normal(0.0, 0.5, (3, 260)).astype(np.float32)
    one_hot = np.eye(3, dtype=np.float32)
    state = rng.normal(0.0, 0.3, (3, 32)).astype(np.float32)
    ones, zeros = np.ones((3, 1), np.float32), np.zeros((3, 1), np.float32)

    def run(style=one_hot, alpha=ones, state=state, reset=zeros, features=x):
        return model.run(features=features, style=style, alpha=alpha, state=state, reset=reset)

    base = run()
    assert np.isfinite(base["output"]).all() and np.abs(base["output"] - x[:, :130]).max() < 1.0
    off = run(alpha=zeros)["output"]
    assert np.array_equal(run(style=one_hot[[1, 2, 0]], alpha=zeros)["output"], off)  # alpha 0: no style
    assert np.allclose(base["output"][2], off[2], atol=1e-6)  # the neutral style is alpha 0
    assert np.abs(base["output"][0] - run(style=one_hot[[1, 1, 2]])["output"][0]).max() > 1e-2
    assert np.abs(run(state=state[[1, 2, 0]])["output"] - base["output"]).max() > 1e-3
    garbage = np.full_like(state, np.nan)
    fresh = run(reset=ones, state=garbage)  # reset: the learned initial state, whatever came in
    assert np.array_equal(fresh["output"], run(reset=ones)["output"])
    assert np.isfinite(fresh["state_out"]).all()
    assert np.abs(run(features=x[[1, 2, 0]])["output"] - base["output"]).max() > 1e-2


def test_the_identity_generator_is_exact_and_the_random_one_reads_window_and_code(tmp_path):
    styles = ["active", "normal"]
    rng = np.random.default_rng(0)
    x = rng.normal(0.0, 0.5, (2, 16, 260)).astype(np.float32)
    code = rng.normal(0.0, 1.0, (2, 8)).astype(np.float32)
    identity = OnnxModel(windowed_model(tmp_path / "identity" / "stgcn.onnx", styles, residual=0.0))
    assert np.array_equal(identity.run(features=x, code=code)["output"], x[..., :130])
    model = OnnxModel(windowed_model(tmp_path / "random" / "stgcn.onnx", styles))
    out = model.run(features=x, code=code)["output"]
    assert np.abs(out - x[..., :130]).max() < 0.1 + 1e-6  # small residuals on the input
    assert np.abs(model.run(features=x, code=code[::-1])["output"] - out).max() > 1e-3
    later = x.copy()
    later[:, :8] = 0.0  # other earlier frames: the later frames' output moves too (the window)
    assert np.abs(model.run(features=later, code=code)["output"][:, 8:] - out[:, 8:]).max() > 1e-4


def test_the_runtime_test_requirements_leave_torch_out():
    def requirements(name: str) -> list[str]:
        lines = (ROOT / name).read_text().splitlines()
        return [s for s in (line.split("#")[0].strip() for line in lines) if s]

    test = requirements("requirements-test.txt")
    assert "onnx" in test and "pytest" in test
    assert not [r for r in test if r.startswith("torch") or r.startswith("-r requirements-dev")]
    assert "-r requirements-test.txt" in requirements("requirements-dev.txt")
