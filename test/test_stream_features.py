"""The streaming encoder/decoder against the batch ones, frame by frame, two performers at once."""

import numpy as np
import pytest

from motion_style_ros.core import features as F
from motion_style_ros.errors import MotionStyleError
from motion_style_ros.io.datasets import ClipInfo, load_clip

CLIPS = ("dataset-2_walk-turn-left_elderly_010", "dataset-2_run_youthful_004",
         "dataset-2_wave-left-hand_feminine_002")


@pytest.fixture(scope="module")
def clips(datasets):
    data = datasets / "bandai-namco/Bandai-Namco-Research-Motiondataset-2/data"
    return [load_clip(ClipInfo("bandai-2", data / f"{n}.bvh", n, "", "", "", "")) for n in CLIPS]


def test_stream_encoder_equals_encode(clips):
    """Performer 0 plays clip A; performer 1 plays clip B, is reset and plays clip C."""
    a, b, c = clips
    nb = 40
    n = min(a.n_frames, nb + c.n_frames)
    enc = F.StreamEncoder(2, a.fps)
    got = []
    for t in range(n):
        second = b if t < nb else c
        if t == nb:
            enc.reset([1])
        k = t if t < nb else t - nb
        rotations = np.stack([a.rotations[t], second.rotations[k]])
        roots = np.stack([a.positions[t, 1], second.positions[k, 1]])
        got.append(enc(rotations, roots))
    got = np.stack(got)
    assert np.abs(got[:, 0] - F.encode(a)[:n]).max() < 1e-5
    assert np.abs(got[:nb, 1] - F.encode(b)[:nb]).max() < 1e-5
    assert np.abs(got[nb:, 1] - F.encode(c)[: n - nb]).max() < 1e-5
    # The velocities really were carried across calls (not zero after the first frame).
    vel = F.feature_layout().slices["vel"]
    assert np.abs(got[1:, 0, vel]).max() > 0.5

    ground, yaw = enc.facing()
    g = c.global_positions()[n - nb - 1]
    assert np.allclose(ground[1], g[1] * [1, 0, 1]) and np.isclose(yaw[1], F.facing_yaw(g, c.skeleton))


def test_stream_decoder_equals_decode(clips):
    a, b, _ = clips
    n = min(a.n_frames, b.n_frames)
    fa, fb = F.encode(a)[:n], F.encode(b)[:n, :130]  # full features, and the model's blocks alone
    starts = np.array([[1.0, 5.0, 2.0], [-3.0, 0.0, 0.5]]), np.array([0.3, -2.5])
    dec = F.StreamDecoder(2, a.fps)
    dec.start(*starts)
    frames = [dec(np.stack([fa[t, :130], fb[t]])) for t in range(n)]
    rotations = np.stack([r for r, _ in frames], axis=1)
    roots = np.stack([p for _, p in frames], axis=1)
    for k, f in enumerate((fa, fb)):
        ref = F.decode(f, a.fps, start_ground=starts[0][k], start_yaw=starts[1][k])
        assert np.abs(rotations[k] - ref.rotations).max() < 1e-12
        assert np.abs(roots[k] - ref.positions[:, 1]).max() < 1e-9
    # Started on the floor below the given point, then integrated: the walk moved away from it.
    assert np.allclose(roots[0, 0] * [1, 0, 1], [1.0, 0.0, 2.0])
    assert np.linalg.norm(roots[0, -1] - roots[0, 0]) > 1.0


def test_stream_decoder_pull_bounds_the_drift(clips):
    a = clips[0]
    f = F.encode(a)
    f[:, 0:2] *= 0.5  # a stylized walk at half speed falls behind the input
    g = a.global_positions()
    ground = g[:, 1] * [1, 0, 1]
    yaw = F.facing_yaw(g, a.skeleton)
    free, pulled = F.StreamDecoder(1, a.fps), F.StreamDecoder(1, a.fps)
    for d in (free, pulled):
        d.start(ground[:1], yaw[:1])
    far = []
    for t in range(a.n_frames):
        _, p_free = free(f[t : t + 1])
        _, p_pulled = pulled(f[t : t + 1])
        pulled.pull(ground[t : t + 1], yaw[t : t + 1], 0.1)
        far.append([np.linalg.norm((p - g[t, 1])[0, [0, 2]]) for p in (p_free, p_pulled)])
    far = np.array(far)
    print(f"drift after {a.duration:.1f} s: free {far[-1, 0]:.2f} m, pulled {far[-1, 1]:.2f} m")
    assert far[-1, 0] > 1.0 and far[:, 1].max() < 0.3 * far[-1, 0]


def test_stream_decoder_checks_shapes():
    dec = F.StreamDecoder(2, 30.0)
    with pytest.raises(MotionStyleError, match="260"):
        dec(np.zeros((2, 100)))
    with pytest.raises(MotionStyleError, match="3 performers"):
        dec(np.zeros((3, 130)))
