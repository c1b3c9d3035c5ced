"""The reference ST-GCN generator timing stand-in: its size matches the reference's defaults, its
graphs are the reference's, and one pass on the default test clip has the reference's output."""

import math

import numpy as np
import pytest

torch = pytest.importorskip("torch", reason="the reference ST-GCN is torch: pip install '.[train]'")

from motion_style_ros.models.reference_stgcn import (
    CLUSTERS,
    PARENTS,
    ReferenceSTGCN,
    ReferenceStgcnSizes,
    pool_matrix,
    reference_window_times,
    spatial_partitions,
    unpool_matrix,
)

# Parameter count at the reference's defaults (7 channels in and out, ngf 64, style code 64, two
# down and two up blocks, 3 spatial partitions, temporal kernel 3; graph conv = 1x1 conv to 3 c_out
# with bias; temporal conv (3, 1) with bias; bias-free 1x1 projections):
#   input 1x1    7*64+64 = 512
#   down 64->128 norms 2*2*64 = 256; graph 64*192+192 = 12,480; time 64*64*3+64 = 12,352;
#                graph 64*384+384 = 24,960; time 128*128*3+128 = 49,280; project 64*128 = 8,192
#                                                                             -> 107,520
#   down 128->256 norms 2*2*128 = 512; graph 128*384+384 = 49,536; time 128*128*3+128 = 49,280;
#                graph 128*768+768 = 99,072; time 256*256*3+256 = 196,864; project 128*256 = 32,768
#                                                                             -> 428,032
#   up 256->128  AdaIN 64*512+512 = 33,280, 64*256+256 = 16,640; graph 256*384+384 = 98,688;
#                time 49,280; graph 128*384+384 = 49,536; time 49,280; project 256*128 = 32,768
#                                                                             -> 329,472
#   up 128->64   AdaIN 64*256+256 = 16,640, 64*128+128 = 8,320; graph 128*192+192 = 24,768;
#                time 12,352; graph 64*192+192 = 12,480; time 12,352; project 128*64 = 8,192
#                                                                             ->  95,104
#   output 1x1   64*7+7 = 455
#   total 512 + 107,520 + 428,032 + 329,472 + 95,104 + 455 = 961,095
REFERENCE_PARAMETERS = 961_095


@pytest.fixture(scope="module")
def model():
    return ReferenceSTGCN(seed=0)


def _clip(frames: int = 326, seed: int = 3) -> tuple["torch.Tensor", "torch.Tensor"]:
    gen = torch.Generator().manual_seed(seed)
    return torch.randn(1, 7, frames, 21, generator=gen), torch.rand(1, 64, generator=gen) * 2 - 1


def test_sizes_and_parameter_count(model):
    s = model.sizes
    assert s == ReferenceStgcnSizes()
    assert ReferenceStgcnSizes(frames=64).output_frames == 64  # the training clip length keeps its frames
    assert (s.channels, s.joints, s.frames, s.style_dim) == (7, 21, 326, 64)
    assert s.widths == (64, 128, 256)
    assert s.output_frames == 324
    assert sum(p.numel() for p in model.parameters()) == REFERENCE_PARAMETERS


def test_graphs():
    """Three levels (21, 10, 5 nodes), three partitions each, every joint's weights summing to 1;
    pooling averages clusters and unpooling copies them back."""
    for parents, n in zip(PARENTS, (21, 10, 5)):
        a = spatial_partitions(parents)
        assert a.shape == (3, n, n)
        np.testing.assert_allclose(a.sum(axis=(0, 1)), np.ones(n), rtol=1e-6)
    # the reference's 1-hop distance quirk: only edges touching a centre neighbour split off
    assert np.count_nonzero(spatial_partitions(PARENTS[0])[2]) == 6
    for clusters, n in zip(CLUSTERS, (21, 10)):
        pool, unpool = pool_matrix(clusters, n), unpool_matrix(clusters, n)
        np.testing.assert_allclose(pool.sum(axis=0), np.ones(len(clusters)), rtol=1e-6)
        np.testing.assert_array_equal(unpool.sum(axis=0), np.ones(n))  # each joint in one cluster


def test_forward_shape(model):
    x, code = _clip()
    with torch.inference_mode():
        out = model(x, code)
    assert out.shape == (1, 7, 324, 21)  # time halves twice (326 -> 163 -> 81), doubles twice
    assert torch.isfinite(out).all()
    with torch.inference_mode():
        other = model(x, -code)
    assert not torch.allclose(out, other)  # the style code reaches the output


def test_weights_deterministic():
    a, b, c = ReferenceSTGCN(seed=5), ReferenceSTGCN(seed=5), ReferenceSTGCN(seed=6)
    for (name, p), q, r in zip(a.named_parameters(), b.parameters(), c.parameters()):
        torch.testing.assert_close(p, q, rtol=0, atol=0)
        if p.ndim > 1:  # conv and linear weights are random; norms and biases start at 1 and 0
            assert not torch.equal(p, r), name
    before = torch.random.get_rng_state()
    ReferenceSTGCN(seed=7)
    assert torch.equal(before, torch.random.get_rng_state())  # the global RNG untouched


def test_window_times_restores_threads():
    before = torch.get_num_threads()
    p50, p99, frames = reference_window_times(threads=1, calls=3, warmup=1)
    assert math.isfinite(p50) and math.isfinite(p99)
    assert 0 < p50 <= p99
    assert frames == 326
    assert torch.get_num_threads() == before
