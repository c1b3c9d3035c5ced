"""The shipped ONNX judges: cards, torch parity, accuracy on real held-out takes, no torch at run time."""

import json
import subprocess
import sys

import numpy as np
import pytest

from motion_style_ros.core import rotations as rot
from motion_style_ros.core.motion import Motion
from motion_style_ros.core.resample import resample
from motion_style_ros.core.skeleton import cmu31
from motion_style_ros.errors import MotionStyleError
from motion_style_ros.evaluation.judges import Judge
from motion_style_ros.io.datasets import index_bandai, load_bandai
from motion_style_ros.runtime.onnx_model import models_dir

KINDS = ("style", "content")
PANELS = (1, 2)
# panel 3 has a style judge only: it chooses pseudo-pair targets beside panel 1's
JUDGES = [(kind, panel) for panel in PANELS for kind in KINDS] + [("style", 3)]


@pytest.fixture(scope="module")
def all_judges():
    return {(kind, panel): Judge(kind, panel=panel) for kind, panel in JUDGES}


@pytest.fixture(scope="module")
def judges(all_judges):
    """The first panel's."""
    return {kind: all_judges[kind, 1] for kind in KINDS}


@pytest.fixture(scope="module")
def test_split(datasets):
    infos = [i for i in index_bandai(datasets) if i.split == "test"]
    return load_bandai(infos, progress=False)


@pytest.fixture(scope="module")
def test_features(judges, test_split):
    return [judges["style"].features(m) for _, m in test_split]


def test_the_two_panels_are_built_differently_and_the_second_never_saw_val_takes(all_judges):
    for kind in KINDS:
        first, second = (all_judges[kind, p].card["training"] for p in PANELS)
        assert (first["config"]["architecture"], first["config"]["width"]) != (
            second["config"]["architecture"], second["config"]["width"])
        assert set(first["config"]["inputs"]) != set(second["config"]["inputs"])
        assert first["config"]["seed"] != second["config"]["seed"]
        assert not second["config"]["select"]
        assert all(h["val_accuracy"] is None for h in second["history"])
        assert second["selected_epoch"] == second["config"]["epochs"]


def test_the_third_panel_sees_motion_but_not_posture_and_differs_from_both(all_judges):
    third = all_judges["style", 3].card["training"]["config"]
    assert set(third["inputs"]) == {"root", "vel"}  # no joint positions, no contacts
    for panel in PANELS:
        other = all_judges["style", panel].card["training"]["config"]
        assert third["seed"] != other["seed"] and set(third["inputs"]) < set(other["inputs"])
    assert third["select"]  # it guides choices, as panel 1 does; panel 2 never does
    assert "reports nothing" in all_judges["style", 3].card["use"]


def test_shipped_judges_are_small_and_carry_their_cards(all_judges, datasets):
    bandai = index_bandai(datasets)
    for (kind, panel), judge in all_judges.items():
        assert judge.model.path.stat().st_size < 1_000_000
        card = judge.card
        assert card["labels"] == sorted({getattr(i, kind) for i in bandai})
        assert card["panel"] == panel
        assert judge.model.input_names == ["features"]
        assert judge.model.output_names == ["logits", "embedding"]
        assert card["fps"] == 30
        assert "arXiv:2306.08861" in card["attribution"] and "CC BY-NC 4.0" in card["licence"]
        matrix = np.array(card["confusion_matrix"]["matrix"])
        assert matrix.shape == (len(card["labels"]),) * 2
        assert matrix.sum() == card["accuracy"]["test_clips"]


def _torch_judge(judge):
    """The torch network with the shipped ONNX weights (its initializers carry the state_dict names;
    a CNN's do, the exporter re-packs a GRU's)."""
    torch = pytest.importorskip("torch", reason="compares the judges with torch: pip install '.[train]'")
    onnx = pytest.importorskip("onnx")
    from motion_style_ros.models.judge import ARCHITECTURES
    from motion_style_ros.training.judges import input_columns

    cfg = judge.card["training"]["config"]
    weights = {
        i.name: torch.from_numpy(onnx.numpy_helper.to_array(i).copy())
        for i in onnx.load(str(judge.model.path)).graph.initializer
    }
    net = ARCHITECTURES[cfg["architecture"]](
        weights["mean"].numpy(), weights["std"].numpy(), len(judge.labels), cfg["width"],
        cfg["embedding"], cfg["dropout"], input_columns(cfg["inputs"]))
    net.load_state_dict(weights)
    return net.eval()


def test_every_judge_was_exported_with_torch_parity(all_judges):
    for card in (j.card for j in all_judges.values()):
        assert card["onnx_torch_max_abs_diff"] < 1e-4
        assert card["parity_probe_clips"] >= 3


@pytest.mark.parametrize("kind,panel", [(k, p) for k, p in JUDGES if (k, p) != ("style", 2)])  # a GRU: above
def test_onnx_matches_torch_on_real_clips_of_any_length(kind, panel, all_judges, test_features):
    torch = pytest.importorskip("torch", reason="compares the judges with torch: pip install '.[train]'")
    net = _torch_judge(all_judges[kind, panel])
    judges = {kind: all_judges[kind, panel]}
    clips = [test_features[0][:1], test_features[1][:7], test_features[2], test_features[3][:200]]
    for f in clips:
        out = judges[kind].model.run(features=f[None])
        with torch.no_grad():
            logits, embedding = net(torch.from_numpy(f[None]))
        np.testing.assert_allclose(out["logits"], logits.numpy(), atol=1e-4, rtol=1e-4)
        np.testing.assert_allclose(out["embedding"], embedding.numpy(), atol=1e-4, rtol=1e-4)
    # A batch of equal-length crops gives each crop's own result.
    batch = np.stack([f[:40] for f in test_features if len(f) >= 40][:3])
    out = judges[kind].model.run(features=batch)
    with torch.no_grad():
        logits, _ = net(torch.from_numpy(batch))
    np.testing.assert_allclose(out["logits"], logits.numpy(), atol=1e-4, rtol=1e-4)


@pytest.mark.parametrize("architecture", ["cnn", "gru"])
def test_export_of_a_fresh_network_matches_torch(architecture, tmp_path):
    torch = pytest.importorskip("torch", reason="compares the judges with torch: pip install '.[train]'")
    from motion_style_ros.models.judge import ARCHITECTURES
    from motion_style_ros.runtime.onnx_model import OnnxModel
    from motion_style_ros.training.judges import export_onnx

    torch.manual_seed(0)
    rng = np.random.default_rng(0)
    net = ARCHITECTURES[architecture](rng.normal(size=12), rng.uniform(0.5, 2.0, size=12), 3,
                                      width=8, embedding=6)
    export_onnx(net, tmp_path / "j.onnx")
    model = OnnxModel(tmp_path / "j.onnx")
    for length in (1, 2, 33, 150):
        x = rng.normal(size=(2, length, 12)).astype(np.float32)
        out = model.run(features=x)
        with torch.no_grad():
            logits, embedding = net.eval()(torch.from_numpy(x))
        np.testing.assert_allclose(out["logits"], logits.numpy(), atol=1e-5)
        np.testing.assert_allclose(out["embedding"], embedding.numpy(), atol=1e-5)


@pytest.mark.parametrize("kind,panel", JUDGES)
def test_card_test_accuracy_matches_a_recomputation(kind, panel, all_judges, test_split, test_features):
    judge = all_judges[kind, panel]
    got = judge.judge_features(test_features).labels
    truth = [getattr(info, kind) for info, _ in test_split]
    accuracy = np.mean([g == t for g, t in zip(got, truth)])
    card = judge.card["accuracy"]
    assert card["test_clips"] == len(test_split)
    assert accuracy == pytest.approx(card["test_clip"], abs=1.5 / len(test_split))


def test_judges_recognise_held_out_takes_at_another_frame_rate(all_judges, test_split):
    chosen = test_split[:: len(test_split) // 20][:20]
    motions = [resample(m, 60.0) for _, m in chosen]
    for (kind, _), judge in all_judges.items():
        result = judge.judge(motions)
        truth = [getattr(info, kind) for info, _ in chosen]
        accuracy = np.mean([g == t for g, t in zip(result.labels, truth)])
        assert accuracy >= 0.8, (kind, result.labels, truth)  # chance: 1/22 and 1/24
        assert result.probabilities.shape == (20, len(judge.labels))
        np.testing.assert_allclose(result.probabilities.sum(axis=1), 1.0, atol=1e-6)
        assert result.embeddings.shape == (20, judge.card["training"]["config"]["embedding"])


def test_judges_need_the_canonical_skeleton(judges):
    sk = cmu31()
    m = Motion.from_rotations(sk, rot.identity((40, sk.n_joints)), np.zeros((40, 3)), 120.0)
    with pytest.raises(MotionStyleError, match="canonical"):
        judges["style"].judge([m])


def test_a_missing_judge_is_a_clear_error(tmp_path):
    with pytest.raises(MotionStyleError, match="not found"):
        Judge(tmp_path / "judge_nothing.onnx")
    (tmp_path / "j.onnx").write_bytes((models_dir() / "judge_style.onnx").read_bytes())
    with pytest.raises(MotionStyleError, match="model card"):
        Judge(tmp_path / "j.onnx")
    (tmp_path / "j.json").write_text(json.dumps({"labels": ["a"], "fps": 30, "feature_version": -1}))
    with pytest.raises(MotionStyleError, match="feature version"):
        Judge(tmp_path / "j.onnx")


def test_runtime_and_evaluation_do_not_import_torch():
    code = (
        "import sys\n"
        "import motion_style_ros.runtime.onnx_model, motion_style_ros.evaluation.judges\n"
        "import motion_style_ros.evaluation.metrics, motion_style_ros.evaluation.harness\n"
        "import motion_style_ros.cli.eval\n"
        "from motion_style_ros.cli.main import build_parser\n"
        "build_parser()  # every command's flags, the trainers' included\n"
        "print('torch' in sys.modules)\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"


@pytest.mark.parametrize("panel", PANELS)
def test_content_judges_read_motions_retargeted_from_other_rigs(panel, all_judges, datasets):
    """Unseen capture setups: CMU and Xia walks and runs, retargeted onto the canonical skeleton."""
    from motion_style_ros.core.retarget import retarget
    from motion_style_ros.core.skeleton import canonical
    from motion_style_ros.io.datasets import index_cmu, index_xia, load_clip

    infos = [i for i in index_cmu(datasets) + index_xia(datasets) if i.content in ("walk", "run")]
    motions = [load_clip(i)[2:] if i.dataset == "cmu" else load_clip(i) for i in infos]  # CMU: T-pose
    judged = all_judges["content", panel].judge([retarget(m, canonical()) for m in motions])
    accuracy = np.mean([j == i.content for j, i in zip(judged.labels, infos)])
    print(f"panel {panel}: content accuracy on {len(infos)} retargeted CMU/Xia walk/run clips: {accuracy:.2f}")
    assert len(infos) >= 20
    assert accuracy >= 0.7  # chance is 1/24; judges on local rotations scored 0.14
