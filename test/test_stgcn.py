"""ST-GCN stylizer: the skeleton graph and its pooling, the exported networks against torch on a
real clip, and a few real training iterations end to end with checkpoint/resume and export (tiny
networks, real Bandai windows)."""

import json

import numpy as np
import pytest

torch = pytest.importorskip("torch", reason="tests the torch networks: pip install '.[train]'")
ort = pytest.importorskip("onnxruntime")

from motion_style_ros.core import graph
from motion_style_ros.core.features import feature_layout
from motion_style_ros.core.skeleton import canonical
from motion_style_ros.models.stgcn import Generator, MappingNetwork, StyleEncoder, tiny
from motion_style_ros.training import data as training_data
from motion_style_ros.training import stgcn


@pytest.fixture(scope="module")
def data(datasets):
    return training_data.load_data((2,), progress=False, root=datasets, takes_per_cell=1)


@pytest.fixture(scope="module")
def clip(data):
    """A real val take, ``(T, 260)`` raw features."""
    return max(data.splits["val"].features, key=len)[:96]


@pytest.fixture(scope="module")
def networks(data):
    """Random tiny networks with the real normalisation; the generator's last layer randomised
    (it starts at zero: the identity) so that its output depends on input and code."""
    frames = np.concatenate(data.splits["train"].features)
    mean, std = frames.mean(0), np.maximum(frames.std(0), 0.05)
    cfg = tiny(data.styles)
    torch.manual_seed(0)
    gen, mapping, encoder = Generator(cfg, mean, std), MappingNetwork(cfg), StyleEncoder(cfg, mean, std)
    with torch.no_grad():
        gen.last.weight.normal_(0.0, 0.3)
    return gen.eval(), mapping.eval(), encoder.eval()


def test_partitions_are_self_parent_and_children():
    g = graph.skeleton_graph()
    sk, joints = canonical(), feature_layout().joints
    assert g.n == 21 and g.parents[0] == -1
    assert all(joints[g.parents[k]] == sk.parents[j] for k, j in enumerate(joints) if k)
    a = graph.Graph(g.parents).adjacency()
    assert np.array_equal(a[0], np.eye(21))
    assert np.array_equal(a[1].sum(1), [0] + [1] * 20)  # one parent each, none for the pelvis
    chest = joints.index(sk.index("Chest"))
    assert sorted(np.flatnonzero(a[2][chest])) == [joints.index(sk.index(n)) - 0 for n in
                                                    ("Neck", "Shoulder_L", "Shoulder_R")]
    assert np.allclose(a[2][chest][a[2][chest] > 0], 1 / 3)  # children averaged (1/Z)
    hands = [joints.index(sk.index(n)) for n in ("Hand_L", "Hand_R", "Head", "Toes_L", "Toes_R")]
    assert not a[2][hands].any()


def test_pooling_clusters_stay_inside_body_parts():
    adjacency, pools = graph.hierarchy()
    assert [a.shape[-1] for a in adjacency] == [21, 11, 5]
    for p in pools:
        assert np.allclose(p.sum(0), 1.0)  # every cluster averages its members
        assert np.array_equal((p > 0).sum(1), np.ones(len(p)))  # every node in one cluster
    fine, coarse = graph.pool_clusters()
    assert fine[0] == [0]  # the pelvis keeps a cluster of its own (root channels)
    joints = feature_layout().joints
    part_of = {joints.index(j): name for name, part in canonical().parts.items() for j in part}
    for members in fine:
        assert len({part_of[m] for m in members}) == 1
    assert sorted(len(c) for c in coarse) == [2, 2, 2, 2, 3]
    # the coarsest graph: the torso with two arms and two legs hanging from it
    assert graph.pooled_graph(graph.pooled_graph(graph.skeleton_graph(), fine), coarse).parents == (
        -1, 0, 0, 0, 0)


def test_node_layout_of_real_features(clip):
    nodes = (clip @ graph.node_scatter()).reshape(len(clip), 21, graph.ALL_CHANNELS)
    s, c = feature_layout().slices, graph.NODE_CHANNELS
    assert np.array_equal(nodes[..., c["rot6d"]].reshape(len(clip), -1), clip[:, s["rot6d"]])
    assert np.array_equal(nodes[..., c["vel"]].reshape(len(clip), -1), clip[:, s["vel"]])
    assert np.array_equal(nodes[:, 0, c["root"]], clip[:, s["root"]])
    assert not nodes[:, 1:, c["root"]].any()
    feet = [feature_layout().joints.index(j) for j in canonical().feet]
    assert np.array_equal(nodes[:, feet, c["contact"]][..., 0], clip[:, s["contact"]])
    assert clip[:, s["contact"]].any()  # the walk has contacts to move


def test_onnx_matches_torch_on_a_real_clip(networks, clip, tmp_path):
    gen, mapping, encoder = networks
    path = tmp_path / "stgcn.onnx"
    stgcn.export_onnx(gen, mapping, encoder, path)
    assert stgcn.parity(gen, mapping, encoder, path, clip) < 1e-4
    # the windows really move: the output differs from the input by far more than the tolerance
    x = torch.from_numpy(clip[None, :16])
    with torch.no_grad():
        out = gen(x, torch.randn(1, gen.cfg.style_dim))[0].numpy()
    assert np.abs(out - clip[:16, :130]).max() > 1e-2
    d6 = out[:, 4:].reshape(16, 21, 6)  # rotations come out orthonormal
    assert np.allclose(np.linalg.norm(d6[..., :3], axis=-1), 1, atol=1e-5)
    assert np.allclose((d6[..., :3] * d6[..., 3:]).sum(-1), 0, atol=1e-5)
    # the style encoder takes any multiple of 4 frames, and its output depends on the clip
    files = stgcn.companions(path)
    session = ort.InferenceSession(str(files["style_encoder"]), providers=["CPUExecutionProvider"])
    long, short = (session.run(None, {"features": clip[None, :n]}) for n in (96, 16))
    assert long[0].shape == (1, len(gen.cfg.styles), gen.cfg.style_dim)
    assert np.abs(long[0] - short[0]).max() > 1e-4


def test_untrained_generator_is_the_identity(data, clip):
    frames = np.concatenate(data.splits["train"].features)
    gen = Generator(tiny(data.styles), frames.mean(0), np.maximum(frames.std(0), 0.05)).eval()
    with torch.no_grad():
        out = gen(torch.from_numpy(clip[None, :32]), torch.randn(1, gen.cfg.style_dim))[0].numpy()
    assert np.abs(out - clip[:32, :130]).max() < 1e-5


def test_training_runs_resumes_identically_and_exports(data, clip, tmp_path):
    cfg = stgcn.tiny_config()
    trainer = stgcn.Trainer(cfg, data, tmp_path / "a", progress=False)
    trainer.run(iterations=8, log_every=2, val_every=4)
    log = [json.loads(line) for line in trainer.log.read_text().splitlines()]
    losses = [e for e in log if "adv" in e]
    assert [e["iteration"] for e in losses] == [2, 4, 6, 8]
    assert all(np.isfinite(v) for e in losses for v in e.values())
    assert trainer.gen.last.weight.abs().max() > 0  # the generator has left the identity
    assert [e["iteration"] for e in trainer.state["val"]] == [4, 8]

    # 4 iterations at once == 2, a checkpoint, a new trainer resuming, 2 more
    whole = stgcn.Trainer(cfg, data, tmp_path / "b", progress=False)
    whole.run(iterations=4, log_every=1, val_every=1000)
    first = stgcn.Trainer(cfg, data, tmp_path / "c", progress=False)
    first.run(iterations=2, log_every=1, val_every=1000)
    resumed = stgcn.Trainer(cfg, data, tmp_path / "c", progress=False)
    assert resumed.resume() and resumed.state["iteration"] == 2
    resumed.run(iterations=4, log_every=1, val_every=1000)
    for name in ("gen", "mapping", "encoder", "dis", "gen_ema"):
        a, b = getattr(whole, name).state_dict(), getattr(resumed, name).state_dict()
        assert all(torch.equal(a[k], b[k]) for k in a), name

    card = stgcn.train(cfg, tmp_path / "models", iterations=6, resume=True,
                       checkpoints=tmp_path / "c", data=data, progress=False, val_every=1000)
    assert card["training"]["history"]["iterations"] == 6
    assert card["training"]["onnx_torch_max_abs_diff"] < 1e-4
    assert card["kind"] == "stgcn" and card["styles"] == list(data.styles)
    for name in ("stgcn.onnx", "stgcn.json", "stgcn_mapping.onnx", "stgcn_style_encoder.onnx"):
        assert (tmp_path / "models" / name).is_file()
